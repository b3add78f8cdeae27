"""
The UR10 of ``example-robot-data`` in Pinocchio, with a tool tip frame.

Frames: ``base_link`` is the URDF's base_link (Pinocchio's universe frame); the tool tip is a
frame ``tool_tip`` at ``tool_offset`` (metres, expressed in ``tool0``) from the flange frame
``tool0``. A pen or a stirrer held along the flange axis has ``tool_offset = (0, 0, length)``.

Joint velocity limits are the stricter of the URDF's and the official UR10 (CB3) ones:
120 deg/s for the two shoulder joints, 180 deg/s for the others.
"""

from __future__ import annotations

from importlib import metadata
import os
from pathlib import Path

from etdmp_ros.geometry.arrays import Array, Points3, Rotations
import numpy as np
from numpy.typing import ArrayLike
import pinocchio as pin

JOINT_NAMES = ('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint',
               'wrist_2_joint', 'wrist_3_joint')
OFFICIAL_VELOCITY_LIMITS = np.radians([120.0, 120.0, 180.0, 180.0, 180.0, 180.0])
#: Simulated s without a velocity command before the robot brakes (ur10_sim's watchdog): 7
#: missed commands at 125 Hz; the speed servos bring the arm to rest some 20 ms later, within
#: 0.1 s of the last command. A real UR stops its external-control program when no command
#: arrives within its receive timeout (ur_client_library: 20 ms by default, 200 ms at most).
WATCHDOG_TIMEOUT = 0.06
TOOL_FRAME = 'tool_tip'
FLANGE_FRAME = 'tool0'
#: Joint positions (rad) or velocities (rad/s), (6,) in the order of JOINT_NAMES, or (n, 6).
Joints = Array


def robot_data_dir() -> Path:
    """
    Return the ``example-robot-data`` robots folder (holding ``ur_description/``).

    Looked up in this order: ``$EXAMPLE_ROBOT_DATA_DIR``, the PyPI wheel (cmeel prefix), the ROS
    package of the same name (ament index).
    """
    env = os.environ.get('EXAMPLE_ROBOT_DATA_DIR')
    candidates = [Path(env)] if env else []
    try:
        dist = metadata.distribution('example-robot-data')
        candidates.append(Path(str(dist.locate_file(
            'cmeel.prefix/share/example-robot-data/robots'))))
    except metadata.PackageNotFoundError:
        pass
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.append(Path(get_package_share_directory('example-robot-data')) / 'robots')
    except Exception:   # noqa: B902 - not a ROS install, or the package is not there
        pass
    for path in candidates:
        if (path / 'ur_description' / 'urdf' / 'ur10_robot.urdf').is_file():
            return path
    raise FileNotFoundError(
        'example-robot-data not found: pip install example-robot-data, install the ROS package '
        'ros-jazzy-example-robot-data, or set EXAMPLE_ROBOT_DATA_DIR to its robots/ folder '
        f'(looked in: {", ".join(str(c) for c in candidates) or "nothing"})')


def ur10_urdf_path() -> Path:
    """Return the path of the UR10 URDF shipped by ``example-robot-data``."""
    return robot_data_dir() / 'ur_description' / 'urdf' / 'ur10_robot.urdf'


class UR10Model:
    """
    UR10 kinematics: forward kinematics, Jacobian and pose IK of the tool tip, limits.

    The one kinematics module of the project: the simulation checks itself against it, the
    controller drives it (:class:`DifferentialIK` calls :meth:`kinematics` /
    :meth:`tool_jacobian`) and the planner and the demo find the tool with it.

    The Pinocchio model and data are created once and reused; call from one thread at a time
    (or give each thread its own UR10Model).
    """

    def __init__(self, tool_offset: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        """Load the URDF and add the ``tool_tip`` frame ``tool_offset`` metres from tool0."""
        self.urdf_path = ur10_urdf_path()
        self.model = pin.buildModelFromUrdf(str(self.urdf_path))
        self.data = self.model.createData()
        names = tuple(self.model.names[1:])
        if names != JOINT_NAMES:
            raise RuntimeError(f'unexpected UR10 joints in {self.urdf_path}: {names}')
        flange = self.model.getFrameId(FLANGE_FRAME)
        self.tool_offset = np.asarray(tool_offset, dtype=float).reshape(3)
        parent = self.model.frames[flange]
        placement = parent.placement * pin.SE3(np.eye(3), self.tool_offset)
        frame = pin.Frame(TOOL_FRAME, parent.parentJoint, flange, placement,
                          pin.FrameType.OP_FRAME)
        self.tool_frame_id = self.model.addFrame(frame)
        self.data = self.model.createData()
        self.flange_frame_id = flange
        self.lower = self.model.lowerPositionLimit.copy()
        self.upper = self.model.upperPositionLimit.copy()
        self.velocity_limits = np.minimum(self.model.velocityLimit, OFFICIAL_VELOCITY_LIMITS)

    def frame_pose(self, q: ArrayLike, frame_id: int | None = None) -> tuple[Points3, Rotations]:
        """Return (position (3,), rotation (3, 3)) of a frame (default: tool tip) in base_link."""
        frame_id = self.tool_frame_id if frame_id is None else frame_id
        pin.forwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        pose = pin.updateFramePlacement(self.model, self.data, frame_id)
        return pose.translation.copy(), pose.rotation.copy()

    def tool_position(self, q: ArrayLike) -> Points3:
        """Return the tool tip position (3,) in base_link."""
        return self.frame_pose(q)[0]

    def tool_jacobian(self, q: ArrayLike) -> Array:
        """
        Return the 6x6 Jacobian of the tool tip (linear; angular) in base_link axes.

        Columns are joints; rows map joint velocities to the tool tip's linear velocity and the
        tool's angular velocity, both expressed in base_link (LOCAL_WORLD_ALIGNED).
        """
        # Pinocchio returns a new array (it copies data.J out).
        return pin.computeFrameJacobian(self.model, self.data, np.asarray(q, dtype=float),
                                        self.tool_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)

    def kinematics(self, q: ArrayLike) -> tuple[Points3, Rotations, Array]:
        """
        Return the tool tip (position (3,), rotation (3, 3), Jacobian (6, 6)) at ``q``.

        One Pinocchio call for all three (the Jacobian as in :meth:`tool_jacobian`): what the
        controller needs every control period.
        """
        jac = self.tool_jacobian(q)
        pose = self.data.oMf[self.tool_frame_id]   # updated by computeFrameJacobian
        return pose.translation.copy(), pose.rotation.copy(), jac

    def solve_pose(self, position: Points3, rotation: Rotations, q0: ArrayLike,
                   iterations: int = 60, tolerance: float = 1e-6,
                   max_step: float = 0.3) -> tuple[Joints, Array]:
        """
        Return joints putting the tool tip at ``position`` with ``rotation``, and the error.

        Pose IK by damped Newton from ``q0`` (not modified): ``q += J^T (J J^T + 1e-6 I)^-1
        e`` with the step norm clipped to ``max_step`` rad, where the pose error is
        ``e = (position - p(q), log3(rotation R(q)^T))`` (m; rad, base_link axes). Stops when
        ``|e| < tolerance`` or after ``iterations`` steps. Returns ``(q, e)``: ``q`` (6,) the
        last iterate, ``e`` (6,) the pose error at that ``q``; ``np.linalg.norm(e)`` is the
        residual and ``np.linalg.norm(e[:3])`` the position error. It does not check joint
        limits (compare ``q`` with :attr:`lower` / :attr:`upper`) nor wrap angles; which
        solution it finds (elbow up or down, ...) is the one nearest ``q0`` in Newton's sense.
        """
        q = np.array(q0, dtype=float)
        damping = 1e-6 * np.eye(6)
        for k in range(iterations + 1):
            p, rot, jac = self.kinematics(q)
            error = np.r_[position - p, pin.log3(rotation @ rot.T)]
            if k == iterations or np.linalg.norm(error) < tolerance:
                break
            step = jac.T @ np.linalg.solve(jac @ jac.T + damping, error)
            step_norm = np.linalg.norm(step)
            if step_norm > max_step:
                step *= max_step / step_norm
            q = q + step
        return q, error

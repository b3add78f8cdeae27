"""
Kinesthetic teaching in the simulation: a hand leading the tool in freedrive, scripted.

On a real UR10 a person teaches a movement in freedrive: the arm is compliant, the hand moves
the tool, and ``/joint_states`` is recorded (``ros2 bag record``). In the simulation the hand is
a script, :class:`GuidedMotion`: a tool tip path (times and positions, any demonstration file
of 3 columns in metres), played as offsets from where the tool is when it starts, the tool's
orientation held as it was. It is turned into joint positions at every control period before
the first one moves (pose IK of :class:`UR10Model`, each from the last), so a script that leaves
the workspace or asks a joint for more than its velocity limit is refused before the arm moves,
with the reason; while it plays, each period's joint velocity command leads the arm to the
next joint positions (feed-forward plus a proportional term), as the hand's force would.

What is recorded is what the arm did (the joint states), not the script: learning from the
recording (:func:`etdmp_ros.skills.library.joint_state_path`) never sees the script.
"""

from __future__ import annotations

import math

from etdmp_ros.robot._trajectory import PoseTrajectory, TrajectoryError
from etdmp_ros.robot._ur10 import Joints, UR10Model
import numpy as np
from numpy.typing import ArrayLike

#: Proportional gain (1/s) pulling the joints back onto the script's joint path.
GAIN = 20.0
#: Largest position error of the pose IK of a scripted sample (m; rad for the orientation).
IK_TOLERANCE = 1e-6
#: Longest script (s): the joint path is computed before the arm moves.
MAX_DURATION = 120.0


class GuideError(ValueError):
    """A script the arm cannot follow (empty, unreachable, too fast); the message says why."""


class GuidedMotion:
    """
    The tool tip led along ``offsets`` (n, 3) at times ``t`` (n,) from joints ``q0``.

    ``model``: the :class:`UR10Model`; ``period``: the control period (s). The script's
    positions are taken relative to its first one and added to the tool tip's position at
    ``q0``. Raises GuideError for a script that cannot be followed.
    """

    def __init__(self, model: UR10Model, q0: ArrayLike, t: ArrayLike, offsets: ArrayLike,
                 period: float, velocity_limits: ArrayLike | None = None) -> None:
        """Compute the joint path of the script at every period; check it."""
        q0 = np.asarray(q0, dtype=float).reshape(6)
        offsets = np.asarray(offsets, dtype=float)
        if offsets.ndim != 2 or offsets.shape[1] != 3 or len(offsets) < 2:
            raise GuideError(f'the script needs at least 2 positions of 3 coordinates (x, y, z '
                             f'metres), got shape {offsets.shape}')
        p0, rot0 = model.frame_pose(q0)
        try:
            path = PoseTrajectory(t, p0 + offsets - offsets[0],
                                  np.repeat(rot0[None], len(offsets), axis=0))
        except TrajectoryError as err:
            raise GuideError(f'bad script: {err}') from None
        if path.duration > MAX_DURATION:
            raise GuideError(f'the script lasts {path.duration:.1f} s, more than MAX_DURATION = '
                             f'{MAX_DURATION:g} s')
        self.period = float(period)
        self.duration = path.duration
        limits = model.velocity_limits if velocity_limits is None else np.asarray(
            velocity_limits, dtype=float)
        steps = max(1, math.ceil(self.duration / self.period - 1e-9))
        joints = [q0]
        for k in range(1, steps + 1):
            p, rot = path.pose(min(k * self.period, self.duration))
            q, error = model.solve_pose(p, rot, joints[-1])
            if np.linalg.norm(error) > IK_TOLERANCE or np.any(q < model.lower) \
                    or np.any(q > model.upper):
                raise GuideError(f"the script leaves the UR10's reach at t = "
                                 f'{k * self.period:.2f} s (tool tip at '
                                 f'{np.round(p, 3).tolist()} m)')
            speed = np.abs(q - joints[-1]) / self.period
            if np.any(speed > limits):
                j = int(np.argmax(speed / limits))
                raise GuideError(f'the script moves joint {j + 1} at {speed[j]:.2f} rad/s at t = '
                                 f'{k * self.period:.2f} s, beyond its limit {limits[j]:.2f} '
                                 'rad/s: slow it down')
            joints.append(q)
        self.joints = np.array(joints)
        self.velocity_limits = np.asarray(limits, dtype=float)
        self.tick = 0

    @property
    def done(self) -> bool:
        """Whether the script has been played to its end."""
        return self.tick >= len(self.joints) - 1

    def command(self, q: ArrayLike) -> Joints:
        """Return the joint velocities (6,) for the next period from measured joints ``q``."""
        k = self.tick
        if self.done:
            return np.zeros(6)
        self.tick += 1
        feed_forward = (self.joints[k + 1] - self.joints[k]) / self.period
        qd = feed_forward + GAIN * (self.joints[k] - np.asarray(q, dtype=float))
        return np.clip(qd, -self.velocity_limits, self.velocity_limits)

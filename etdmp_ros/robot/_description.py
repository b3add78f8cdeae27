"""
The robot description and its frame tree, as a UR driver, robot_state_publisher and a RealSense.

What they publish, computed without ROS.

:func:`robot_description` is the ``example-robot-data`` UR10 URDF that the simulation is built
from, with the tool: a link ``tool_tip`` on a fixed joint ``tool_offset`` from ``tool0``, and
mesh URIs made absolute (``file://``) so a viewer finds them without the ROS package.
:class:`FrameTree` reads such a URDF as robot_state_publisher does: a fixed joint is one static
transform (parent link -> child link), a revolute joint one transform that moves with its angle.
:func:`camera_transforms` are the static frames of a RealSense in base_link as realsense-ros
names them (``camera_link`` -> ``camera_color_frame`` -> ``camera_color_optical_frame``).
Quaternions are ``[x, y, z, w]`` (ROS order).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from xml.etree import ElementTree


from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Points3, Quaternions, Rotations
from etdmp_ros.geometry.camera import CameraPose
from etdmp_ros.robot._ur10 import (FLANGE_FRAME, JOINT_NAMES, robot_data_dir, TOOL_FRAME,
                                   ur10_urdf_path)

import numpy as np
from numpy.typing import ArrayLike

#: Name of the fixed joint that carries the tool tip in :func:`robot_description`.
TOOL_JOINT = f'{FLANGE_FRAME}-{TOOL_FRAME}_fixed_joint'
#: realsense-ros's frames of the colour stream, base first.
CAMERA_LINK = 'camera_link'
CAMERA_COLOR_FRAME = 'camera_color_frame'
CAMERA_OPTICAL_FRAME = 'camera_color_optical_frame'
#: Rotation from a REP-103 body frame (x forward, y left, z up) to its optical frame (z forward,
#: x right, y down): the quaternion realsense-ros and every ROS camera driver use.
OPTICAL_ROTATION = np.array([-0.5, 0.5, -0.5, 0.5])


@dataclass(frozen=True)
class Transform:
    """A transform from ``parent`` to ``child``: ``p_parent = R(quaternion) p_child + t``."""

    parent: str
    child: str
    translation: tuple[float, ...]
    quaternion: tuple[float, ...]


def robot_description(tool_offset: Sequence[float] = (0.0, 0.0, 0.0)) -> str:
    """Return the URDF text of the UR10 with the tool tip link ``tool_offset`` m from tool0."""
    tree = ElementTree.parse(ur10_urdf_path())
    robot = tree.getroot()
    package_root = robot_data_dir().parent   # holds robots/ : package://example-robot-data/...
    prefix = 'package://example-robot-data/'
    for mesh in robot.iter('mesh'):
        filename = mesh.get('filename', '')
        if filename.startswith(prefix):
            mesh.set('filename', (package_root / filename[len(prefix):]).as_uri())
    ElementTree.SubElement(robot, 'link', name=TOOL_FRAME)
    joint = ElementTree.SubElement(robot, 'joint', name=TOOL_JOINT, type='fixed')
    ElementTree.SubElement(joint, 'parent', link=FLANGE_FRAME)
    ElementTree.SubElement(joint, 'child', link=TOOL_FRAME)
    ElementTree.SubElement(joint, 'origin', rpy='0 0 0',
                           xyz=' '.join(repr(float(v)) for v in tool_offset))
    ElementTree.indent(robot)
    return ElementTree.tostring(robot, encoding='unicode', xml_declaration=True)


class FrameTree:
    """
    The link frames of a URDF, as robot_state_publisher computes them.

    :attr:`fixed` holds a :class:`Transform` per fixed joint (``/tf_static``). The revolute
    joints named ``joint_names`` (in the order of the joint positions given to :meth:`moving`)
    are the moving transforms (``/tf``): :attr:`parents`, :attr:`children` and
    :attr:`translations` do not change with the angles, :meth:`moving` returns the rotations.
    """

    def __init__(self, urdf_text: str, joint_names: Sequence[str] = JOINT_NAMES) -> None:
        """Read the joints of ``urdf_text``; ValueError if one of ``joint_names`` is missing."""
        joints = {j.get('name'): j for j in ElementTree.fromstring(urdf_text).iter('joint')
                  if j.find('parent') is not None}
        missing = [n for n in joint_names if n not in joints]
        if missing:
            raise ValueError(f'joints {missing} are not in the URDF')
        self.fixed = [Transform(*_joint_origin(j)) for j in joints.values()
                      if j.get('type') == 'fixed']
        moving = [_joint_origin(joints[n]) for n in joint_names]
        self.parents = [m[0] for m in moving]
        self.children = [m[1] for m in moving]
        self.translations = np.array([m[2] for m in moving])
        self._origins = np.array([m[3] for m in moving])
        axes = []
        for name in joint_names:
            axis = joints[name].find('axis')
            xyz = axis.get('xyz') if axis is not None else '1 0 0'
            a = np.array([float(v) for v in xyz.split()])  # type: ignore[union-attr]
            axes.append(a / np.linalg.norm(a))
        self._axes = np.array(axes)
        # origin * (axis sin(q/2), cos(q/2)) is linear in sin and cos: = S sin(q/2) + C cos(q/2).
        self._s = quat.multiply(self._origins, np.concatenate(
            [self._axes, np.zeros((len(axes), 1))], axis=1))
        self._c = self._origins

    def moving(self, q: ArrayLike) -> Quaternions:
        """Return the quaternions (n, 4) of the moving transforms at joint positions ``q``."""
        half = 0.5 * np.asarray(q, dtype=float)[:, None]
        return self._s * np.sin(half) + self._c * np.cos(half)

    def moving_reference(self, q: ArrayLike) -> Quaternions:
        """Return :meth:`moving` computed plainly: origin times the joint's rotation (tests)."""
        half = 0.5 * np.asarray(q, dtype=float)[:, None]
        turn = np.concatenate([self._axes * np.sin(half), np.cos(half)], axis=1)
        return quat.multiply(self._origins, turn)

    def transforms(self, q: ArrayLike) -> list[Transform]:
        """Return every transform, moving ones at ``q`` then the fixed ones (tests, tools)."""
        return [Transform(p, c, tuple(t), tuple(r)) for p, c, t, r in
                zip(self.parents, self.children, self.translations, self.moving(q))] + self.fixed


def chain_pose(transforms: Iterable[Transform], source: str,
               target: str) -> tuple[Points3, Rotations]:
    """
    Return (position (3,), rotation (3, 3)) of frame ``target`` in frame ``source``.

    ``transforms`` is a list of :class:`Transform` making a tree (what a tf2 buffer holds);
    ``source`` must be an ancestor of ``target``. ValueError if no chain joins them.
    """
    by_child = {t.child: t for t in transforms}
    position, rotation = np.zeros(3), np.eye(3)
    frame = target
    while frame != source:
        if frame not in by_child:
            raise ValueError(f'no chain of transforms from {source} to {target}')
        t = by_child[frame]
        r = quat.to_matrix(quat.normalized(t.quaternion))
        position = r @ position + np.asarray(t.translation, dtype=float)
        rotation = r @ rotation
        frame = t.parent
    return position, rotation


def camera_transforms(pose: CameraPose, parent: str = 'base_link') -> list[Transform]:
    """
    Return the static transforms of a camera whose colour optical frame has ``pose`` in ``parent``.

    ``pose`` is a :class:`CameraPose` (the optical frame in base_link). As realsense-ros does:
    ``camera_link`` (x forward, z up) in ``parent``, ``camera_color_frame`` at it (the colour
    sensor is the reference of this simulated camera, so no offset), and the optical frame
    rotated from it by :data:`OPTICAL_ROTATION`.
    """
    optical = quat.from_matrix(pose.rotation)
    link = quat.multiply(optical, OPTICAL_ROTATION * [-1, -1, -1, 1])   # R_opt R_o^T
    return [Transform(parent, CAMERA_LINK, tuple(map(float, pose.position)),
                      tuple(map(float, link))),
            Transform(CAMERA_LINK, CAMERA_COLOR_FRAME, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
            Transform(CAMERA_COLOR_FRAME, CAMERA_OPTICAL_FRAME, (0.0, 0.0, 0.0),
                      tuple(map(float, OPTICAL_ROTATION)))]


def _joint_origin(
        joint: ElementTree.Element) -> tuple[str, str, tuple[float, ...], tuple[float, ...]]:
    """Return (parent, child, translation, quaternion) of a URDF joint element."""
    origin = joint.find('origin')
    xyz = [float(v) for v in (origin.get('xyz', '0 0 0') if origin is not None else '0 0 0')
           .split()]
    rpy = [float(v) for v in (origin.get('rpy', '0 0 0') if origin is not None else '0 0 0')
           .split()]
    # A URDF joint names its parent and child links (a joint without them fails here).
    ends = [joint.find(end) for end in ('parent', 'child')]
    parent, child = (end.get('link') for end in ends)  # type: ignore[union-attr]
    return parent, child, tuple(xyz), tuple(quat.from_rpy(*rpy))  # type: ignore[return-value]

"""
The MuJoCo model of the workcell: the UR10 from its URDF, the tool, the table, the objects.

See :mod:`etdmp_ros.sim._sim` for what the model is made for (actuation, contacts, camera). The
geoms are added in a fixed order, so that geom ids (and with them contact names) are the same
in every build of one scene.
"""

from __future__ import annotations

import functools
import math
import os
import sys
from typing import Any
import xml.etree.ElementTree as ElementTree

from etdmp_ros.geometry.arrays import Array
from etdmp_ros.geometry.camera import CameraIntrinsics, CameraPose
from etdmp_ros.robot._scene import (GOAL_MARKER_THICKNESS, PEN_RADIUS, PEN_TIP_LENGTH,
                                    PEN_TIP_RADIUS, SceneConfig)
from etdmp_ros.robot._ur10 import JOINT_NAMES, robot_data_dir, ur10_urdf_path
import numpy as np
from numpy.typing import ArrayLike, NDArray


@functools.cache
def import_mujoco() -> Any:
    """
    Import MuJoCo once, headless by default; return the module.

    MuJoCo chooses its OpenGL platform when it is imported; without a display only EGL works.
    So when nobody chose one (``MUJOCO_GL``) and there is no display, choose EGL, as the Makefile
    does: here, when a simulation is first built, not when a module is imported.
    """
    if sys.platform.startswith('linux') and not os.environ.get('DISPLAY'):
        os.environ.setdefault('MUJOCO_GL', 'egl')
    import mujoco
    return mujoco


CAMERA_NAME = 'd435_color'
MAX_OBSTACLES = 8
# Velocity-servo gains (N m s/rad): time constants M_ii / kv of about 10 ms for the big joints.
DEFAULT_KV = (2000.0, 2000.0, 1000.0, 100.0, 100.0, 100.0)
ARMATURE = 0.1   # kg m^2
ROBOT_COLOR = (0.72, 0.74, 0.78, 1.0)
PEN_COLOR = (0.15, 0.15, 0.18, 1.0)
WHITEBOARD_THICKNESS = 0.0005
BOTTLE_WALL = 0.004
BOTTLE_FLOOR = 0.01
#: Boxes making the bottle's wall for collisions: the polygon's faces lie at most
#: (radius - wall) (1 / cos(pi / n) - 1), 0.35 mm, outside the round wall's inner surface.
BOTTLE_WALL_BOXES = 24
#: A tool tip pressed into the table deeper than this (m) is a contact; less is writing.
WRITING_DEPTH = 0.002
# Collision bitmasks (contype of the robot's geoms, conaffinity of the objects'): a pair
# collides when the robot geom's bit is in the object's mask. Objects have contype 0 and robot
# geoms conaffinity 0, so neither two objects nor two robot geoms are ever a pair.
_ARM, _TIP, _BASE = 1, 2, 4
_ANY_ROBOT = _ARM | _TIP | _BASE
TABLE_THICKNESS = 0.04
# Geom groups: MjvOption shows groups 0-2 by default; obstacles not in use go to group 3.
VISIBLE_GROUP = 0
HIDDEN_GROUP = 3


def _urdf_for_mujoco() -> str:
    """Return the UR10 URDF text with absolute mesh paths, collision geometry only."""
    tree = ElementTree.parse(ur10_urdf_path())
    robot = tree.getroot()
    package_root = robot_data_dir().parent   # holds robots/ : package://example-robot-data/...
    for link in robot.iter('link'):
        for visual in link.findall('visual'):   # .dae visual meshes: MuJoCo reads STL/OBJ
            link.remove(visual)
    for mesh in robot.iter('mesh'):
        filename = mesh.get('filename', '')
        prefix = 'package://example-robot-data/'
        if not filename.startswith(prefix):
            raise ValueError(f'unexpected mesh path in the UR10 URDF: {filename}')
        mesh.set('filename', str(package_root / filename[len(prefix):]))
    # Keep the massless frames (tool0, base) as bodies instead of fusing them into their parents.
    mujoco_element = ElementTree.SubElement(robot, 'mujoco')
    ElementTree.SubElement(mujoco_element, 'compiler', fusestatic='false', strippath='false',
                           discardvisual='false')
    return ElementTree.tostring(robot, encoding='unicode')


def _tube_mesh(radius: float, height: float, wall: float, floor: float,
               segments: int = 32) -> tuple[Array, NDArray[np.int_]]:
    """Return (vertices, faces) of an open container: a cylinder wall and a floor, watertight."""
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    inner = radius - wall
    rings = [np.column_stack([ring * r, np.full(segments, z)])
             for r, z in ((radius, 0.0), (radius, height), (inner, height), (inner, floor))]
    vertices = np.vstack(rings + [[[0.0, 0.0, 0.0]], [[0.0, 0.0, floor]]])
    bottom, top_out, top_in, floor_in = (k * segments for k in range(4))
    centre_bottom, centre_floor = 4 * segments, 4 * segments + 1
    faces: list[list[int]] = []
    for i in range(segments):
        j = (i + 1) % segments
        for a, b in ((bottom, top_out), (top_out, top_in), (top_in, floor_in)):
            # Quad between two rings, counter-clockwise seen from outside the solid.
            faces += [[a + i, a + j, b + j], [a + i, b + j, b + i]]
        faces.append([floor_in + i, floor_in + j, centre_floor])
        faces.append([bottom + j, bottom + i, centre_bottom])
    return vertices, np.asarray(faces)


def _mujoco_camera_quat(pose: CameraPose) -> Array:
    """Return the MuJoCo camera orientation (w, x, y, z) for a ROS optical-frame pose."""
    mujoco = import_mujoco()
    rotation = pose.rotation @ np.diag([1.0, -1.0, -1.0])   # optical (z fwd, y down) -> GL
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, rotation.ravel())
    return quat


def has_geom(model: Any, name: str) -> bool:
    """Return whether ``model`` has a geom called ``name``."""
    try:
        model.geom(name)
    except KeyError:
        return False
    return True


def build_model(scene: SceneConfig, intrinsics: CameraIntrinsics, timestep: float,
                multisamples: int, kv: ArrayLike) -> Any:
    """
    Return the compiled ``mujoco.MjModel`` of the workcell ``scene``.

    ``intrinsics``: the camera's (its image size is the offscreen buffer's); ``timestep``:
    physics step (s); ``multisamples``: MSAA samples; ``kv``: velocity-servo gains (6,).
    """
    mujoco = import_mujoco()
    spec = mujoco.MjSpec.from_string(_urdf_for_mujoco())
    _set_options(spec, intrinsics, timestep, multisamples)
    _add_robot(spec, np.broadcast_to(kv, (6,)))
    _add_tool(spec, np.asarray(scene.tool_offset, dtype=float))
    world = spec.worldbody
    world.add_light(name='sun', pos=[0.5, 0.0, 3.0], dir=[0.0, 0.0, -1.0],
                    diffuse=[0.5, 0.5, 0.5], specular=[0.1, 0.1, 0.1], castshadow=False)
    _add_table(world, scene)
    _add_bottle(spec, world, scene)
    _add_objects(world, scene)
    world.add_camera(name=CAMERA_NAME, pos=scene.camera_pose.position,
                     quat=_mujoco_camera_quat(scene.camera_pose), fovy=intrinsics.fovy_deg)
    return spec.compile()


def _set_options(spec: Any, intrinsics: CameraIntrinsics, timestep: float,
                 multisamples: int) -> None:
    """Set the physics (no contacts in the dynamics) and the offscreen rendering."""
    mujoco = import_mujoco()
    spec.modelname = 'ur10_workcell'
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    spec.stat.extent = 2.0      # sets the clipping planes: near 0.02 m, far 20 m
    spec.stat.center = [0.5, 0.0, 0.3]
    spec.visual.map.znear = 0.01
    spec.visual.map.zfar = 10.0
    spec.visual.global_.offwidth = intrinsics.width
    spec.visual.global_.offheight = intrinsics.height
    spec.visual.quality.shadowsize = 0
    spec.visual.quality.offsamples = int(multisamples)
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
    spec.visual.headlight.specular = [0.05, 0.05, 0.05]


def _add_robot(spec: Any, kv: Array) -> None:
    """Colour and group the URDF's collision meshes; add armature and velocity servos."""
    mujoco = import_mujoco()
    for geom in spec.geoms:      # the robot: URDF collision meshes, drawn in one colour
        geom.rgba = ROBOT_COLOR
        geom.group = VISIBLE_GROUP
        # The base is bolted to the table; every other link may touch it.
        geom.contype = _BASE if geom.parent.name in ('base_link', 'base') else _ARM
        geom.conaffinity = 0
    for name in JOINT_NAMES:
        # Reflected rotor inertia of the geared joints (MuJoCo Menagerie's UR10e value);
        # the bare wrist links (~5e-4 kg m^2) would make the servo needlessly stiff.
        joint = spec.joint(name)
        joint.armature = ARMATURE
        # The importer turns the URDF effort into a joint torque limit: lift it (above).
        joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_FALSE
    for name, gain in zip(JOINT_NAMES, kv):
        actuator = spec.add_actuator(name=name, target=name,
                                     trntype=mujoco.mjtTrn.mjTRN_JOINT)
        actuator.set_to_velocity(kv=float(gain))


def _add_tool(spec: Any, offset: Array) -> None:
    """Add the sites tool0 and tool_tip (``offset`` from tool0) and the pen between them."""
    mujoco = import_mujoco()
    tool0 = spec.body('tool0')
    tool0.add_site(name='tool0', size=[0.005] * 3)
    tool0.add_site(name='tool_tip', pos=offset, size=[0.003] * 3, rgba=[0, 0, 0, 0])
    length = float(np.linalg.norm(offset))
    if length > 1e-6:
        tip_start = offset * max(0.0, 1.0 - PEN_TIP_LENGTH / length)
        if np.linalg.norm(tip_start) > 1e-6:
            tool0.add_geom(name='pen', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                           fromto=[0, 0, 0, *tip_start], size=[PEN_RADIUS, 0, 0],
                           rgba=PEN_COLOR, contype=_ARM, conaffinity=0)
        tool0.add_geom(name='pen_tip', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                       fromto=[*tip_start, *offset], size=[PEN_TIP_RADIUS, 0, 0],
                       rgba=PEN_COLOR, contype=_TIP, conaffinity=0)


def _add_table(world: Any, s: SceneConfig) -> None:
    """Add the floor, the table (top and legs) and the whiteboard sheet on it."""
    mujoco = import_mujoco()
    # Objects: contype 0; conaffinity says which parts of the robot they collide with.
    world.add_geom(name='floor', type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1],
                   pos=[0, 0, -s.table_height], rgba=[0.35, 0.36, 0.38, 1],
                   contype=0, conaffinity=_ANY_ROBOT)
    half = np.asarray(s.table_size) / 2
    # The tip collides with the table top too: contacts() keeps it past WRITING_DEPTH only.
    world.add_geom(name='table', type=mujoco.mjtGeom.mjGEOM_BOX,
                   size=[*half, TABLE_THICKNESS / 2],
                   pos=[*s.table_center, -TABLE_THICKNESS / 2], rgba=s.table_color,
                   contype=0, conaffinity=_ARM | _TIP)
    leg = (s.table_height - TABLE_THICKNESS) / 2
    for k, (sx, sy) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1))):
        world.add_geom(name=f'table_leg_{k}', type=mujoco.mjtGeom.mjGEOM_BOX,
                       size=[0.03, 0.03, leg],
                       pos=[s.table_center[0] + sx * (half[0] - 0.05),
                            s.table_center[1] + sy * (half[1] - 0.05),
                            -TABLE_THICKNESS - leg], rgba=s.table_color,
                       contype=0, conaffinity=_ANY_ROBOT)
    if np.all(s.whiteboard_size > 0):
        world.add_geom(name='whiteboard', type=mujoco.mjtGeom.mjGEOM_BOX,
                       size=[*(s.whiteboard_size / 2), WHITEBOARD_THICKNESS / 2],
                       pos=[*s.task_plane_origin[:2], WHITEBOARD_THICKNESS / 2],
                       rgba=s.whiteboard_color, contype=0, conaffinity=_ARM)


def _add_bottle(spec: Any, world: Any, s: SceneConfig) -> None:
    """Add the open bottle: its mesh drawn, a ring of boxes and a disc for collisions."""
    mujoco = import_mujoco()
    vertices, faces = _tube_mesh(s.bottle_radius, s.bottle_height, wall=BOTTLE_WALL,
                                 floor=BOTTLE_FLOOR)
    spec.add_mesh(name='bottle', uservert=vertices.ravel(), userface=faces.ravel())
    # A mocap body: it moves at runtime (set_bottle), its collision geometry with it. The
    # mesh is drawn only; the wall's boxes and the floor's disc collide, undrawn.
    bottle = world.add_body(name='bottle', mocap=True, pos=[*s.bottle_position, 0.0])
    bottle.add_geom(name='bottle', type=mujoco.mjtGeom.mjGEOM_MESH, meshname='bottle',
                    rgba=s.bottle_color, contype=0, conaffinity=0)
    n = BOTTLE_WALL_BOXES
    middle = s.bottle_radius - BOTTLE_WALL / 2
    for k in range(n):
        a = 2.0 * math.pi * k / n
        bottle.add_geom(name=f'bottle_wall_{k}', type=mujoco.mjtGeom.mjGEOM_BOX,
                        size=[BOTTLE_WALL / 2, s.bottle_radius * math.tan(math.pi / n),
                              s.bottle_height / 2],
                        pos=[middle * math.cos(a), middle * math.sin(a),
                             s.bottle_height / 2],
                        quat=[math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)],
                        group=HIDDEN_GROUP, rgba=[0, 0, 0, 0], contype=0,
                        conaffinity=_ANY_ROBOT)
    bottle.add_geom(name='bottle_floor', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                    size=[s.bottle_radius, BOTTLE_FLOOR / 2, 0],
                    pos=[0.0, 0.0, BOTTLE_FLOOR / 2], group=HIDDEN_GROUP, rgba=[0, 0, 0, 0],
                    contype=0, conaffinity=_ANY_ROBOT)


def _add_objects(world: Any, s: SceneConfig) -> None:
    """Add the goal marker and MAX_OBSTACLES obstacle cylinders, movable (mocap bodies)."""
    mujoco = import_mujoco()
    # The goal marker lies on the table: the pen writes on it, a link would touch the table.
    goal = world.add_body(name='goal_marker', mocap=True, pos=s.goal_position)
    goal.add_geom(name='goal_marker', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                  size=[s.goal_radius, GOAL_MARKER_THICKNESS / 2, 0],
                  pos=[0, 0, -GOAL_MARKER_THICKNESS / 2], rgba=s.goal_color,
                  contype=0, conaffinity=_ARM)
    for i in range(MAX_OBSTACLES):
        body = world.add_body(name=f'obstacle_{i}', mocap=True)
        body.add_geom(name=f'obstacle_{i}', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                      size=[s.obstacle_radius, s.obstacle_height / 2, 0],
                      pos=[0, 0, -s.obstacle_height / 2], rgba=s.obstacle_color,
                      contype=0, conaffinity=_ANY_ROBOT)

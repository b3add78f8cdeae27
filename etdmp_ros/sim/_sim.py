"""
The simulated workcell: a MuJoCo UR10 driven by joint velocities, and a RealSense-style camera.

:class:`UR10Sim` is ROS-free (the ``ur10_sim`` node is a thin shell around it) and can be used
in-process by tests::

    sim = UR10Sim(scene_config())         # the default workcell (etdmp_ros.ros.system)
    sim.set_velocity_command([0.1, 0, 0, 0, 0, 0])
    sim.advance(0.5)                      # 0.5 s of simulated time
    sim.q, sim.qd, sim.tool_tip_position
    rgb, depth_mm = sim.render_rgb_depth()

Model. The robot is built from the same ``example-robot-data`` URDF that :class:`UR10Model`
(Pinocchio) loads, with its STL collision meshes as geometry: MuJoCo's URDF importer reads the
kinematics, so there is one source of truth (tests check the forward kinematics against
Pinocchio). The MuJoCo world frame IS base_link (the URDF's ``world`` link coincides with it).
Sites ``tool0`` (the flange frame) and ``tool_tip`` (``tool_offset`` from tool0) mark the tool.

Actuation. Each joint has a MuJoCo velocity actuator (torque = kv (qd_cmd - qd)) integrated
implicitly (``implicitfast``: stable for any gain), and the bias forces (gravity, Coriolis and
centrifugal) are compensated exactly every step, as a real UR's speed interface does: commanded
velocities are tracked with no steady-state error and a time constant of a few milliseconds.
Torques are not limited (a servo saturating at the URDF effort leaves the implicit scheme and
oscillated on the light wrist links); joints carry the reflected rotor inertia (``armature``)
of geared drives. Commands are clamped to :attr:`UR10Model.velocity_limits`; a step from rest
to full speed overshoots them by about 0.15 % (measured; inertial coupling). Joint position
limits are enforced.

Contacts are seen, not felt. The dynamics have no contacts (``mjDSBL_CONTACT``): nothing pushes
the arm away, as nothing would stop a real one but a protective stop. After each
:meth:`UR10Sim.step` call (one control period in the node) a collision-only pass (MuJoCo's
``mj_collision`` with contacts enabled for that call alone) finds every geom of the arm (its
links' URDF collision meshes, by their convex hulls) or of the tool that touches an obstacle,
the bottle, the table (top, legs), the whiteboard or the floor: :attr:`UR10Sim.contacts`. The
collision bitmasks leave out pairs of arm links (the URDF's meshes overlap at the joints), the
base on the table it is bolted to, and the tool tip on the writing surface (the task): the tip
counts against the table only once it is pressed in deeper than :data:`WRITING_DEPTH`, never
against the whiteboard sheet or the goal marker it writes on. The bottle is open: its mesh is
drawn, and for collisions it is a ring of thin boxes (its wall, :data:`BOTTLE_WALL_BOXES`) and
a disc (its floor), since MuJoCo collides a mesh by its convex hull, which would fill it.

Watchdog. A real ``forward_velocity_controller`` applies the last command forever; here a
command older than ``watchdog_timeout`` seconds of simulated time is replaced by zero (brake),
until the next command. ``watchdog_timeout = 0`` disables it.

Camera. A D435-style colour camera with aligned depth, at :attr:`SceneConfig.camera_pose`;
intrinsics from the vertical field of view (:meth:`CameraIntrinsics.from_fovy`). MuJoCo cameras
look along their -z with y up; the ROS optical frame looks along +z with y down, so the MuJoCo
camera's axes are the optical frame's with y and z negated. Depth is the z coordinate in the
optical frame (as a RealSense reports it), in millimetres (uint16), 0 outside the valid range.
Shadows and multisampling are off by default: on a software renderer (llvmpipe) 4096-px shadow
maps cost ~40 ms a frame instead of ~2 ms.
"""

from dataclasses import dataclass
import math
import os
import sys
import xml.etree.ElementTree as ElementTree

from etdmp_ros.geometry.camera import CameraIntrinsics
from etdmp_ros.robot._scene import (GOAL_MARKER_THICKNESS, obstacle_radii_for,
                                    parse_bottle_position, parse_goal_position,
                                    parse_obstacle_positions, parse_obstacle_radii, PEN_RADIUS,
                                    PEN_TIP_LENGTH, PEN_TIP_RADIUS, SceneConfig)
from etdmp_ros.robot._ur10 import JOINT_NAMES, robot_data_dir, ur10_urdf_path, UR10Model
import numpy as np

mujoco = None   # imported by _import_mujoco() when the first simulation is built


def _import_mujoco():
    """
    Import MuJoCo once, headless by default.

    MuJoCo chooses its OpenGL platform when it is imported; without a display only EGL works.
    So when nobody chose one (``MUJOCO_GL``) and there is no display, choose EGL, as the Makefile
    does: here, when a simulation is first built, not when a module is imported.
    """
    global mujoco
    if mujoco is None:
        if sys.platform.startswith('linux') and not os.environ.get('DISPLAY'):
            os.environ.setdefault('MUJOCO_GL', 'egl')
        import mujoco as module
        mujoco = module
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


def _urdf_for_mujoco():
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


def _tube_mesh(radius, height, wall, floor, segments=32):
    """Return (vertices, faces) of an open container: a cylinder wall and a floor, watertight."""
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    inner = radius - wall
    rings = [np.column_stack([ring * r, np.full(segments, z)])
             for r, z in ((radius, 0.0), (radius, height), (inner, height), (inner, floor))]
    vertices = np.vstack(rings + [[[0.0, 0.0, 0.0]], [[0.0, 0.0, floor]]])
    bottom, top_out, top_in, floor_in = (k * segments for k in range(4))
    centre_bottom, centre_floor = 4 * segments, 4 * segments + 1
    faces = []
    for i in range(segments):
        j = (i + 1) % segments
        for a, b in ((bottom, top_out), (top_out, top_in), (top_in, floor_in)):
            # Quad between two rings, counter-clockwise seen from outside the solid.
            faces += [[a + i, a + j, b + j], [a + i, b + j, b + i]]
        faces.append([floor_in + i, floor_in + j, centre_floor])
        faces.append([bottom + j, bottom + i, centre_bottom])
    return vertices, np.asarray(faces)


def _mujoco_camera_quat(pose):
    """Return the MuJoCo camera orientation (w, x, y, z) for a ROS optical-frame pose."""
    rotation = pose.rotation @ np.diag([1.0, -1.0, -1.0])   # optical (z fwd, y down) -> GL
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, rotation.ravel())
    return quat


@dataclass(frozen=True)
class CameraState:
    """
    What the camera sees at one instant: simulated time (s), joint and mocap positions.

    ``obstacles``: how many obstacles are in use (the others are hidden); ``obstacle_radii``
    (MAX_OBSTACLES,): each one's radius (m). Everything a render needs besides the model, so a
    copy of the model (another process) can render it too.
    """

    time: float
    qpos: np.ndarray
    mocap_pos: np.ndarray
    mocap_quat: np.ndarray
    obstacles: int
    obstacle_radii: np.ndarray = None


@dataclass(frozen=True)
class Contact:
    """
    A part of the robot touching an object of the workcell (see the module docstring).

    ``part``: the robot's link (URDF name, e.g. ``wrist_2_link``), or ``tool`` / ``tool_tip``
    for the pen or stirrer; ``item``: what of the workcell it touches, ``obstacle_<i>``,
    ``bottle``, ``table``, ``whiteboard``, ``goal_marker`` or ``floor``; ``position`` (3,):
    the contact point in base_link; ``depth``: how far the two geometries overlap (m, >= 0).
    """

    part: str
    item: str
    position: np.ndarray
    depth: float


class UR10Sim:
    """
    MuJoCo UR10 workcell: velocity-commanded joints, movable goal and obstacles, a camera.

    Not thread-safe: call from one thread at a time. :meth:`camera_state` snapshots can be
    rendered later, also by another UR10Sim built from the same scene (the ``ur10_sim`` node
    renders in a process of its own). The camera's OpenGL context is created on the first
    :meth:`render_rgb_depth` call and is current in the thread that made that call.
    """

    def __init__(self, scene, *, timestep=0.002, watchdog_timeout=0.1,
                 image_size=(640, 480), fovy_deg=42.5, depth_range=(0.1, 3.0),
                 depth_noise=0.0, seed=None, multisamples=0, kv=DEFAULT_KV,
                 detect_contacts=True):
        """
        Build the model of the workcell ``scene``, a :class:`SceneConfig`.

        The system's default workcell is ``etdmp_ros.ros.system.scene_config()``.

        ``timestep``: physics step (s). ``watchdog_timeout``: brake after this long without a
        command (s of simulated time; 0 disables). ``image_size``: (width, height) of the camera
        images; ``fovy_deg``: vertical field of view (a D435 colour camera at 640x480:
        about 42.5). ``depth_range``: (min, max) metres; depth outside it reads 0.
        ``depth_noise``: standard deviation of the depth noise at 1 m (metres), growing with
        z^2 like a stereo camera's; 0 for none. ``multisamples``: MSAA samples (0 is fastest).
        ``kv``: velocity-servo gains per joint (N m s/rad). ``detect_contacts``: find the
        contacts after each :meth:`step` call (False: :attr:`contacts` stays empty; benchmarks).
        """
        self.scene = scene
        _import_mujoco()
        if not timestep > 0:
            raise ValueError(f'timestep must be positive, got {timestep}')
        self.watchdog_timeout = float(watchdog_timeout)
        if not self.watchdog_timeout >= 0:
            raise ValueError(f'watchdog_timeout must be >= 0, got {watchdog_timeout}')
        self.depth_range = (float(depth_range[0]), float(depth_range[1]))
        if not 0 <= self.depth_range[0] < self.depth_range[1] <= 65.0:
            raise ValueError(f'depth_range must be 0 <= min < max <= 65 m, got {depth_range}')
        self.depth_noise = float(depth_noise)
        self.intrinsics = CameraIntrinsics.from_fovy(image_size[0], image_size[1], fovy_deg)
        self.camera_pose = self.scene.camera_pose
        self.ur10 = UR10Model(tool_offset=self.scene.tool_offset)
        self.velocity_limits = self.ur10.velocity_limits.copy()
        self.joint_names = JOINT_NAMES
        self._rng = np.random.default_rng(seed)
        self.contacts_enabled = bool(detect_contacts)
        self.contacts = ()
        self.model = self._build(timestep, multisamples, np.broadcast_to(kv, (6,)))
        self.data = mujoco.MjData(self.model)
        self._ids()
        self._camera = None
        self._render_data = None
        self._command = np.zeros(6)
        self._command_time = -math.inf
        self.braked_at = None
        self.watchdog_active = self.watchdog_timeout > 0
        self.reset()

    # ----------------------------------------------------------------------------- model build
    def _build(self, timestep, multisamples, kv):
        s = self.scene
        spec = mujoco.MjSpec.from_string(_urdf_for_mujoco())
        spec.modelname = 'ur10_workcell'
        spec.option.timestep = timestep
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        spec.stat.extent = 2.0      # sets the clipping planes: near 0.02 m, far 20 m
        spec.stat.center = [0.5, 0.0, 0.3]
        spec.visual.map.znear = 0.01
        spec.visual.map.zfar = 10.0
        spec.visual.global_.offwidth = self.intrinsics.width
        spec.visual.global_.offheight = self.intrinsics.height
        spec.visual.quality.shadowsize = 0
        spec.visual.quality.offsamples = int(multisamples)
        spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
        spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
        spec.visual.headlight.specular = [0.05, 0.05, 0.05]

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

        tool0 = spec.body('tool0')
        tool0.add_site(name='tool0', size=[0.005] * 3)
        offset = np.asarray(s.tool_offset, dtype=float)
        tool0.add_site(name='tool_tip', pos=offset, size=[0.003] * 3, rgba=[0, 0, 0, 0])
        length = np.linalg.norm(offset)
        if length > 1e-6:
            tip_start = offset * max(0.0, 1.0 - PEN_TIP_LENGTH / length)
            if np.linalg.norm(tip_start) > 1e-6:
                tool0.add_geom(name='pen', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                               fromto=[0, 0, 0, *tip_start], size=[PEN_RADIUS, 0, 0],
                               rgba=PEN_COLOR, contype=_ARM, conaffinity=0)
            tool0.add_geom(name='pen_tip', type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                           fromto=[*tip_start, *offset], size=[PEN_TIP_RADIUS, 0, 0],
                           rgba=PEN_COLOR, contype=_TIP, conaffinity=0)

        world = spec.worldbody
        world.add_light(name='sun', pos=[0.5, 0.0, 3.0], dir=[0.0, 0.0, -1.0],
                        diffuse=[0.5, 0.5, 0.5], specular=[0.1, 0.1, 0.1], castshadow=False)
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

        world.add_camera(name=CAMERA_NAME, pos=self.camera_pose.position,
                         quat=_mujoco_camera_quat(self.camera_pose),
                         fovy=self.intrinsics.fovy_deg)
        return spec.compile()

    def _ids(self):
        m = self.model
        self._qpos_adr = np.array([m.jnt_qposadr[m.joint(n).id] for n in JOINT_NAMES])
        self._dof_adr = np.array([m.jnt_dofadr[m.joint(n).id] for n in JOINT_NAMES])
        self._actuator_ids = np.array([m.actuator(n).id for n in JOINT_NAMES])
        self.tool0_site = m.site('tool0').id
        self.tool_tip_site = m.site('tool_tip').id
        self.camera_id = m.camera(CAMERA_NAME).id
        self._goal_mocap = m.body_mocapid[m.body('goal_marker').id]
        self._bottle_mocap = m.body_mocapid[m.body('bottle').id]
        self._obstacle_mocap = [m.body_mocapid[m.body(f'obstacle_{i}').id]
                                for i in range(MAX_OBSTACLES)]
        self._obstacle_geoms = [m.geom(f'obstacle_{i}').id for i in range(MAX_OBSTACLES)]
        # _set_radii resizes an obstacle's one bounding-volume node with its one geom.
        assert all(m.body_bvhnum[m.geom_bodyid[g]] == 1 for g in self._obstacle_geoms)
        # What a contact's geoms are called: the robot's by link (tool, tool_tip), the
        # objects' by name (a table leg is the table, the bottle's wall boxes the bottle).
        tool = {'pen': 'tool', 'pen_tip': 'tool_tip'}
        self._contact_names = []
        for g in range(m.ngeom):
            name = m.geom(g).name
            if m.geom_contype[g]:
                name = tool.get(name, m.body(m.geom_bodyid[g]).name)
            elif name.startswith('table_leg_'):
                name = 'table'
            elif name.startswith('bottle_'):
                name = 'bottle'
            self._contact_names.append(name)
        self._tip_geom = m.geom('pen_tip').id if _has_geom(m, 'pen_tip') else -1
        self._table_geom = m.geom('table').id

    # ------------------------------------------------------------------------------- state
    def reset(self, q=None):
        """Reset time to 0, joints to ``q`` (default: the scene's initial positions) at rest."""
        mujoco.mj_resetData(self.model, self.data)
        q = self.scene.initial_joint_positions if q is None else q
        q = np.asarray(q, dtype=float).reshape(6)
        if not np.all(np.isfinite(q)):
            raise ValueError(f'joint positions must be finite, got {q.tolist()}')
        self.data.qpos[self._qpos_adr] = q
        self._command[:] = 0.0
        self._command_time = -math.inf
        self.braked_at = None
        self.watchdog_active = self.watchdog_timeout > 0
        self.set_goal(self.scene.goal_position)
        self.set_bottle(self.scene.bottle_position)
        self.set_obstacles(self.scene.obstacle_positions, self.scene.obstacle_radii)
        mujoco.mj_forward(self.model, self.data)
        self.contacts = self.detect_contacts() if self.contacts_enabled else ()

    @property
    def time(self):
        """Return the simulated time in seconds since :meth:`reset`."""
        return self.data.time

    @property
    def timestep(self):
        """Physics time step in seconds."""
        return self.model.opt.timestep

    @property
    def q(self):
        """Joint positions (6,) in rad, UR order (a copy)."""
        return self.data.qpos[self._qpos_adr].copy()

    @property
    def qd(self):
        """Joint velocities (6,) in rad/s, UR order (a copy)."""
        return self.data.qvel[self._dof_adr].copy()

    @property
    def command(self):
        """Velocity command in force (6,): the last accepted one, or 0 if the watchdog braked."""
        return self.data.ctrl[self._actuator_ids].copy()

    @property
    def tool_tip_position(self):
        """Tool tip position (3,) in base_link."""
        return self.data.site_xpos[self.tool_tip_site].copy()

    def site_pose(self, site_id):
        """Return (position (3,), rotation (3, 3)) of a site (e.g. :attr:`tool0_site`)."""
        return (self.data.site_xpos[site_id].copy(),
                self.data.site_xmat[site_id].reshape(3, 3).copy())

    def set_joint_positions(self, q):
        """Teleport the joints to ``q`` (6,) at rest; update kinematics and contacts (tests)."""
        q = np.asarray(q, dtype=float).reshape(6)
        self.data.qpos[self._qpos_adr] = q
        self.data.qvel[self._dof_adr] = 0.0
        mujoco.mj_forward(self.model, self.data)
        if self.contacts_enabled:
            self.contacts = self.detect_contacts()

    # ------------------------------------------------------------------------------ commands
    def validate_velocity_command(self, qd):
        """
        Return ``qd`` as a float array (6,) clamped to the velocity limits.

        Raises ValueError (and nothing is applied) if it does not hold 6 finite numbers.
        """
        try:
            qd = np.asarray(qd, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f'velocity command must be 6 numbers, got {qd!r}') from None
        if qd.shape != (6,):
            raise ValueError(f'velocity command must have 6 values (UR joint order), '
                             f'got {qd.size}')
        if not np.all(np.isfinite(qd)):
            raise ValueError(f'velocity command must be finite, got {qd.tolist()}')
        return np.clip(qd, -self.velocity_limits, self.velocity_limits)

    def set_velocity_command(self, qd):
        """
        Command joint velocities ``qd`` (6,) rad/s, UR order, from now on; return them as applied.

        Values beyond the UR10 limits are clamped. A command that is not 6 finite numbers raises
        ValueError and changes nothing. Each accepted command re-arms the watchdog.
        """
        qd = self.validate_velocity_command(qd)
        self._command[:] = qd
        self._command_time = self.data.time
        self.watchdog_active = False
        self.data.ctrl[self._actuator_ids] = qd
        return qd.copy()

    @property
    def command_time(self):
        """Return the simulated time (s) of the last accepted velocity command (-inf: none)."""
        return self._command_time

    def _check_watchdog(self):
        if (not self.watchdog_active and self.watchdog_timeout > 0
                and self.data.time - self._command_time > self.watchdog_timeout):
            self.watchdog_active = True
            self.braked_at = self.data.time     # simulated s; see command_time
            self.data.ctrl[self._actuator_ids] = 0.0

    def step(self, n=1):
        """
        Advance ``n`` physics steps (watchdog checked at every step), then find the contacts.

        :attr:`contacts` holds those at the end of the call (module docstring); :meth:`reset`
        and :meth:`set_joint_positions` update it too, :meth:`detect_contacts` finds them now.
        """
        m, d = self.model, self.data
        for _ in range(int(n)):
            self._check_watchdog()
            mujoco.mj_step1(m, d)
            # Exact bias compensation (gravity, Coriolis, centrifugal): the servo only has to
            # accelerate, so velocity commands are tracked with no steady-state error.
            d.qfrc_applied[:] = d.qfrc_bias
            mujoco.mj_step2(m, d)
        # mj_step leaves positions of bodies and sites at the state BEFORE its last integration:
        # recompute them so the tool tip, ground truth and camera match q.
        mujoco.mj_kinematics(m, d)
        if self.contacts_enabled:
            self.contacts = self.detect_contacts()

    def detect_contacts(self):
        """
        Return the contacts of the robot with the workcell now: a tuple of :class:`Contact`.

        One per pair of a robot part and an object, at its deepest point.

        A collision-only pass on the current kinematics (the dynamics never see contacts):
        MuJoCo's broad phase leaves out every pair whose bounding boxes are apart, so with
        nothing near the arm it costs a few microseconds.
        """
        m, d = self.model, self.data
        flags = m.opt.disableflags
        m.opt.disableflags = flags & ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        try:
            mujoco.mj_collision(m, d)
        finally:
            m.opt.disableflags = flags
        if d.ncon == 0:
            return ()
        n, contact = d.ncon, d.contact
        geoms, depths = contact.geom[:n], np.maximum(0.0, -contact.dist[:n])
        positions = contact.pos[:n].copy()
        d.ncon = 0              # the dynamics have none (the next step would clear them too)
        names, found = self._contact_names, {}
        for (a, b), depth, position in zip(geoms, depths, positions):
            robot, other = (a, b) if m.geom_contype[a] else (b, a)
            if robot == self._tip_geom and other == self._table_geom and \
                    depth <= WRITING_DEPTH:
                continue        # the pen writing on the table, not pressed through it
            # One per pair of part and item (MuJoCo gives up to 4 points a pair): the deepest.
            pair = (names[robot], names[other])
            if pair not in found or depth > found[pair].depth:
                found[pair] = Contact(*pair, position, float(depth))
        return tuple(found.values())

    def advance(self, duration):
        """Advance ``duration`` seconds of simulated time (rounded to whole physics steps)."""
        self.step(max(0, round(duration / self.model.opt.timestep)))

    # ------------------------------------------------------------------ goal and obstacles
    @property
    def goal_position(self):
        """Goal marker position (3,): centre of its top face, base_link."""
        return self.data.mocap_pos[self._goal_mocap].copy()

    def set_goal(self, position):
        """Move the goal marker (top face centre) to ``position`` [x, y, z]; ValueError if bad."""
        self.data.mocap_pos[self._goal_mocap] = parse_goal_position(position)
        mujoco.mj_kinematics(self.model, self.data)   # the camera sees it at once

    @property
    def bottle_position(self):
        """Bottle position (2,): [x, y] of its axis on the table, base_link."""
        return self.data.mocap_pos[self._bottle_mocap, :2].copy()

    @property
    def bottle_mouth(self):
        """Centre of the bottle's mouth (3,): on its axis at z = its height, base_link."""
        return np.array([*self.bottle_position, self.scene.bottle_height])

    def set_bottle(self, position):
        """Move the bottle (its axis) to ``position`` [x, y] on the table; ValueError if bad."""
        self.data.mocap_pos[self._bottle_mocap] = [*parse_bottle_position(position), 0.0]
        mujoco.mj_kinematics(self.model, self.data)

    @property
    def obstacle_positions(self):
        """Obstacle positions (N, 3): centres of the cylinders' top faces, base_link."""
        return self._obstacles.copy()

    @property
    def obstacle_radii(self):
        """Obstacle radii (N,) in metres, in the order of :attr:`obstacle_positions`."""
        return self._radii[:len(self._obstacles)].copy()

    def set_obstacles(self, positions, radii=None):
        """
        Place obstacles at ``positions`` ((N, 3) or flat [x1, y1, z1, ...]); ValueError if bad.

        ``radii``: each one's radius (m; those beyond the list have the scene's
        ``obstacle.radius``), None to keep the radii they have. At most :data:`MAX_OBSTACLES`;
        the others are hidden.
        """
        points = parse_obstacle_positions(positions)
        if len(points) > MAX_OBSTACLES:
            raise ValueError(f'at most {MAX_OBSTACLES} obstacles, got {len(points)}')
        if radii is not None:
            radii = obstacle_radii_for(MAX_OBSTACLES, parse_obstacle_radii(radii),
                                       self.scene.obstacle_radius)
            self._set_radii(self.model, radii)
            self._radii = radii
        for i, (mocap, geom) in enumerate(zip(self._obstacle_mocap, self._obstacle_geoms)):
            used = i < len(points)
            # Unused ones are hidden from the camera and parked far below the floor.
            self.data.mocap_pos[mocap] = points[i] if used else (0.0, 0.0, -100.0 - i)
            self.model.geom_group[geom] = VISIBLE_GROUP if used else HIDDEN_GROUP
        self._obstacles = points
        mujoco.mj_kinematics(self.model, self.data)

    def set_obstacle_radii(self, radii):
        """Size the obstacles: ``radii`` as in :meth:`set_obstacles`; ValueError if bad."""
        self.set_obstacles(self._obstacles, radii)

    def _set_radii(self, model, radii):
        """Give the obstacle cylinders of ``model`` these radii (MAX_OBSTACLES,)."""
        half = 0.5 * self.scene.obstacle_height
        for geom, r in zip(self._obstacle_geoms, radii):
            model.geom_size[geom, 0] = r
            # What the collision broad phase bounds the cylinder by: its bounding sphere and
            # box, and its body's bounding volume hierarchy (one node: the body has one geom).
            model.geom_rbound[geom] = math.hypot(r, half)
            model.geom_aabb[geom, 3:] = (r, r, half)
            body = model.geom_bodyid[geom]
            model.bvh_aabb[model.body_bvhadr[body], 3:] = (r, r, half)

    # -------------------------------------------------------------------------------- camera
    def camera_state(self):
        """
        Return a copy of what the camera would see now, to render later (elsewhere).

        A :class:`CameraState`: the simulated time, joint and mocap (goal, obstacles) positions.
        Taking it costs microseconds; :meth:`render_rgb_depth` of it costs milliseconds, in
        this object or in another one built with the same scene (another process).
        """
        d = self.data
        return CameraState(float(d.time), d.qpos.copy(), d.mocap_pos.copy(),
                           d.mocap_quat.copy(), len(self._obstacles), self._radii.copy())

    def render_rgb_depth(self, state=None):
        """
        Render the camera: return ``(rgb, depth_mm)``.

        ``state``: a :meth:`camera_state` taken earlier (rendered from a private copy of the
        simulation data, so the physics may go on stepping meanwhile), or None for now.
        ``rgb``: uint8 (H, W, 3); ``depth_mm``: uint16 (H, W), z in the optical frame in
        millimetres, aligned with ``rgb``, 0 where out of :attr:`depth_range`. Both are new
        arrays (safe to keep). Row 0 is the top of the image.
        """
        if self._camera is None:
            self._camera = _OffscreenCamera(self.model, self.camera_id, self.intrinsics)
        data = self.data
        if state is not None:
            if self._render_data is None:
                self._render_data = mujoco.MjData(self.model)
            data = self._render_data
            data.time = state.time
            data.qpos[:] = state.qpos
            data.mocap_pos[:] = state.mocap_pos
            data.mocap_quat[:] = state.mocap_quat
            for i, geom in enumerate(self._obstacle_geoms):
                self.model.geom_group[geom] = VISIBLE_GROUP if i < state.obstacles \
                    else HIDDEN_GROUP
            if state.obstacle_radii is not None and \
                    not np.array_equal(state.obstacle_radii, self._radii):
                self._set_radii(self.model, state.obstacle_radii)
                self._radii = np.array(state.obstacle_radii, dtype=float)
            mujoco.mj_kinematics(self.model, data)
            mujoco.mj_camlight(self.model, data)
        rgb, depth = self._camera.render(data)
        if self.depth_noise > 0:
            depth = depth + self._rng.standard_normal(depth.shape, dtype=np.float32) * \
                np.float32(self.depth_noise) * depth * depth
        valid = (depth >= self.depth_range[0]) & (depth <= self.depth_range[1])
        depth_mm = np.where(valid, np.rint(depth * np.float32(1000.0)), 0).astype(np.uint16)
        return rgb, depth_mm

    def close(self):
        """Free the OpenGL resources of the camera (also done when garbage-collected)."""
        if self._camera is not None:
            self._camera.close()
            self._camera = None

    @classmethod
    def from_parameters(cls, p):
        """Return the simulation of ur10_sim's parameter values ``p`` (name -> value)."""
        if p['depth_min'] >= p['depth_max']:
            raise ValueError(f'depth_min ({p["depth_min"]}) must be below depth_max '
                             f'({p["depth_max"]})')
        return cls(SceneConfig.from_parameters(p), timestep=p['physics_timestep'],
                   watchdog_timeout=p['watchdog_timeout'],
                   image_size=(p['image_width'], p['image_height']),
                   fovy_deg=p['fovy_deg'], depth_range=(p['depth_min'], p['depth_max']),
                   depth_noise=p['depth_noise'], multisamples=p['multisamples'])

    def __enter__(self):
        """Return self (``with UR10Sim() as sim:`` closes the camera at the end)."""
        return self

    def __exit__(self, *exc):
        """Close the camera."""
        self.close()


def _has_geom(model, name):
    """Return whether ``model`` has a geom called ``name``."""
    try:
        model.geom(name)
    except KeyError:
        return False
    return True


class _OffscreenCamera:
    """One offscreen render pass reading colour AND depth (mujoco.Renderer needs two)."""

    def __init__(self, model, camera_id, intrinsics):
        self.model = model
        w, h = intrinsics.width, intrinsics.height
        self._gl = mujoco.GLContext(w, h)
        self._gl.make_current()
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        # Reversed z (1 at near, 0 at far) with a float depth buffer: precise at any distance.
        self._context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=1000)
        self._option = mujoco.MjvOption()
        self._option.geomgroup[:] = 0
        self._option.geomgroup[VISIBLE_GROUP] = 1
        self._option.sitegroup[:] = 0
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = camera_id
        self._rect = mujoco.MjrRect(0, 0, w, h)
        self._rgb = np.empty((h, w, 3), dtype=np.uint8)
        self._depth = np.empty((h, w), dtype=np.float32)
        near = model.vis.map.znear * model.stat.extent
        far = model.vis.map.zfar * model.stat.extent
        # OpenGL projection z_ndc = (c z + d) / -z (glFrustum), remapped to reversed z in
        # [0, 1]: window depth = (c' z + d') / -z, so the distance -z = d' / (depth + c').
        c = -(far + near) / (far - near)
        d = -2.0 * far * near / (far - near)
        self._c = np.float32(-0.5 * c - 0.5)
        self._d = np.float32(-0.5 * d)

    def render(self, data):
        """Return rgb uint8 (H, W, 3) and depth float32 metres (H, W) (inf where nothing)."""
        self._gl.make_current()
        mujoco.mjv_updateScene(self.model, data, self._option, None, self._camera,
                               mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        mujoco.mjr_render(self._rect, self._scene, self._context)
        mujoco.mjr_readPixels(self._rgb, self._depth, self._rect, self._context)
        # OpenGL rows start at the bottom of the image.
        rgb = self._rgb[::-1].copy()
        with np.errstate(divide='ignore'):
            depth = self._d / (self._depth[::-1] + self._c)
        return rgb, depth

    def close(self):
        """Free the OpenGL context."""
        if self._gl is not None:
            self._gl.make_current()
            self._context.free()
            self._gl.free()
            self._gl = None

    def __del__(self):
        """Free the OpenGL context if still held."""
        try:
            self.close()
        except Exception:   # noqa: B902 - interpreter shutdown: nothing left to free
            pass

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
until the next command. ``watchdog_timeout = 0`` disables it; the default is
:data:`etdmp_ros.robot.WATCHDOG_TIMEOUT` (why: its comment).

Camera. A D435-style colour camera with aligned depth, at :attr:`SceneConfig.camera_pose`;
intrinsics from the vertical field of view (:meth:`CameraIntrinsics.from_fovy`). MuJoCo cameras
look along their -z with y up; the ROS optical frame looks along +z with y down, so the MuJoCo
camera's axes are the optical frame's with y and z negated. Depth is the z coordinate in the
optical frame (as a RealSense reports it), in millimetres (uint16), 0 outside the valid range.
Shadows and multisampling are off by default: on a software renderer (llvmpipe) 4096-px shadow
maps cost ~40 ms a frame instead of ~2 ms.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

from etdmp_ros.geometry.arrays import Array
from etdmp_ros.geometry.camera import CameraIntrinsics
from etdmp_ros.robot._scene import (obstacle_radii_for, parse_bottle_position,
                                    parse_goal_position, parse_obstacle_positions,
                                    parse_obstacle_radii, SceneConfig)
from etdmp_ros.robot._ur10 import JOINT_NAMES, UR10Model, WATCHDOG_TIMEOUT
from etdmp_ros.sim._camera import OffscreenCamera
from etdmp_ros.sim._workcell import (build_model, CAMERA_NAME, DEFAULT_KV, has_geom,
                                     HIDDEN_GROUP, import_mujoco, MAX_OBSTACLES, VISIBLE_GROUP,
                                     WRITING_DEPTH)
import numpy as np
from numpy.typing import ArrayLike, NDArray

#: The mujoco module, imported when the first simulation is built (:func:`import_mujoco`).
mujoco: Any = None


@dataclass(frozen=True)
class CameraState:
    """
    What the camera sees at one instant: simulated time (s), joint and mocap positions.

    ``obstacles``: how many obstacles are in use (the others are hidden); ``obstacle_radii``
    (MAX_OBSTACLES,): each one's radius (m). Everything a render needs besides the model, so a
    copy of the model (another process) can render it too.
    """

    time: float
    qpos: Array
    mocap_pos: Array
    mocap_quat: Array
    obstacles: int
    obstacle_radii: Array | None = None


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
    position: Array
    depth: float


class UR10Sim:
    """
    MuJoCo UR10 workcell: velocity-commanded joints, movable goal and obstacles, a camera.

    Not thread-safe: call from one thread at a time. :meth:`camera_state` snapshots can be
    rendered later, also by another UR10Sim built from the same scene (the ``ur10_sim`` node
    renders in a process of its own). The camera's OpenGL context is created on the first
    :meth:`render_rgb_depth` call and is current in the thread that made that call.
    """

    def __init__(self, scene: SceneConfig, *, timestep: float = 0.002,
                 watchdog_timeout: float = WATCHDOG_TIMEOUT,
                 image_size: tuple[int, int] = (640, 480),
                 fovy_deg: float = 42.5, depth_range: tuple[float, float] = (0.1, 3.0),
                 depth_noise: float = 0.0, seed: int | None = None, multisamples: int = 0,
                 kv: ArrayLike = DEFAULT_KV, detect_contacts: bool = True) -> None:
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
        global mujoco
        mujoco = import_mujoco()
        self.scene = scene
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
        self.contacts: tuple[Contact, ...] = ()
        self.model = build_model(scene, self.intrinsics, timestep, multisamples, kv)
        self.data = mujoco.MjData(self.model)
        self._ids()
        self._camera: OffscreenCamera | None = None
        self._render_data: Any = None
        self._command = np.zeros(6)
        self._command_time = -math.inf
        self.braked_at: float | None = None
        #: Simulated s: the longest a non-zero command stayed in force unreplaced (reset()).
        self.largest_command_age = 0.0
        self._obstacles: Array   # set by reset(), like the radii
        self._radii: Array
        self.watchdog_active = self.watchdog_timeout > 0
        self.reset()

    # ----------------------------------------------------------------------------- model ids
    def _ids(self) -> None:
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
        self._contact_names: list[str] = []
        for g in range(m.ngeom):
            name = m.geom(g).name
            if m.geom_contype[g]:
                name = tool.get(name, m.body(m.geom_bodyid[g]).name)
            elif name.startswith('table_leg_'):
                name = 'table'
            elif name.startswith('bottle_'):
                name = 'bottle'
            self._contact_names.append(name)
        self._tip_geom = m.geom('pen_tip').id if has_geom(m, 'pen_tip') else -1
        self._table_geom = m.geom('table').id

    # ------------------------------------------------------------------------------- state
    def reset(self, q: ArrayLike | None = None) -> None:
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
        self.largest_command_age = 0.0
        self.watchdog_active = self.watchdog_timeout > 0
        self.set_goal(self.scene.goal_position)
        self.set_bottle(self.scene.bottle_position)
        self.set_obstacles(self.scene.obstacle_positions, self.scene.obstacle_radii)
        mujoco.mj_forward(self.model, self.data)
        self.contacts = self.detect_contacts() if self.contacts_enabled else ()

    @property
    def time(self) -> float:
        """Return the simulated time in seconds since :meth:`reset`."""
        return self.data.time

    @property
    def timestep(self) -> float:
        """Physics time step in seconds."""
        return self.model.opt.timestep

    @property
    def q(self) -> Array:
        """Joint positions (6,) in rad, UR order (a copy)."""
        return self.data.qpos[self._qpos_adr].copy()

    @property
    def qd(self) -> Array:
        """Joint velocities (6,) in rad/s, UR order (a copy)."""
        return self.data.qvel[self._dof_adr].copy()

    @property
    def command(self) -> Array:
        """Velocity command in force (6,): the last accepted one, or 0 if the watchdog braked."""
        return self.data.ctrl[self._actuator_ids].copy()

    @property
    def tool_tip_position(self) -> Array:
        """Tool tip position (3,) in base_link."""
        return self.data.site_xpos[self.tool_tip_site].copy()

    def site_pose(self, site_id: int) -> tuple[Array, Array]:
        """Return (position (3,), rotation (3, 3)) of a site (e.g. :attr:`tool0_site`)."""
        return (self.data.site_xpos[site_id].copy(),
                self.data.site_xmat[site_id].reshape(3, 3).copy())

    def set_joint_positions(self, q: ArrayLike) -> None:
        """Teleport the joints to ``q`` (6,) at rest; update kinematics and contacts (tests)."""
        q = np.asarray(q, dtype=float).reshape(6)
        self.data.qpos[self._qpos_adr] = q
        self.data.qvel[self._dof_adr] = 0.0
        mujoco.mj_forward(self.model, self.data)
        if self.contacts_enabled:
            self.contacts = self.detect_contacts()

    # ------------------------------------------------------------------------------ commands
    def validate_velocity_command(self, qd: ArrayLike) -> Array:
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

    def set_velocity_command(self, qd: ArrayLike) -> Array:
        """
        Command joint velocities ``qd`` (6,) rad/s, UR order, from now on; return them as applied.

        Values beyond the UR10 limits are clamped. A command that is not 6 finite numbers raises
        ValueError and changes nothing. Each accepted command re-arms the watchdog.
        """
        qd = self.validate_velocity_command(qd)
        self._note_command_age()
        self._command[:] = qd
        self._command_time = self.data.time
        self.watchdog_active = False
        self.data.ctrl[self._actuator_ids] = qd
        return qd.copy()

    @property
    def command_time(self) -> float:
        """Return the simulated time (s) of the last accepted velocity command (-inf: none)."""
        return self._command_time

    def _note_command_age(self) -> None:
        """Keep the longest a moving command was in force (how near the watchdog came)."""
        if not self.watchdog_active and np.any(self._command):
            age = self.data.time - self._command_time
            self.largest_command_age = max(self.largest_command_age, age)

    def _check_watchdog(self) -> None:
        if (not self.watchdog_active and self.watchdog_timeout > 0
                and self.data.time - self._command_time > self.watchdog_timeout):
            self._note_command_age()
            self.watchdog_active = True
            self.braked_at = self.data.time     # simulated s; see command_time
            self.data.ctrl[self._actuator_ids] = 0.0

    def step(self, n: int = 1) -> None:
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

    def detect_contacts(self) -> tuple[Contact, ...]:
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
        names = self._contact_names
        found: dict[tuple[str, str], Contact] = {}
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

    def advance(self, duration: float) -> None:
        """Advance ``duration`` seconds of simulated time (rounded to whole physics steps)."""
        self.step(max(0, round(duration / self.model.opt.timestep)))

    # ------------------------------------------------------------------ goal and obstacles
    @property
    def goal_position(self) -> Array:
        """Goal marker position (3,): centre of its top face, base_link."""
        return self.data.mocap_pos[self._goal_mocap].copy()

    def set_goal(self, position: ArrayLike) -> None:
        """Move the goal marker (top face centre) to ``position`` [x, y, z]; ValueError if bad."""
        self.data.mocap_pos[self._goal_mocap] = parse_goal_position(position)
        mujoco.mj_kinematics(self.model, self.data)   # the camera sees it at once

    @property
    def bottle_position(self) -> Array:
        """Bottle position (2,): [x, y] of its axis on the table, base_link."""
        return self.data.mocap_pos[self._bottle_mocap, :2].copy()

    @property
    def bottle_mouth(self) -> Array:
        """Centre of the bottle's mouth (3,): on its axis at z = its height, base_link."""
        return np.array([*self.bottle_position, self.scene.bottle_height])

    def set_bottle(self, position: ArrayLike) -> None:
        """Move the bottle (its axis) to ``position`` [x, y] on the table; ValueError if bad."""
        self.data.mocap_pos[self._bottle_mocap] = [*parse_bottle_position(position), 0.0]
        mujoco.mj_kinematics(self.model, self.data)

    @property
    def obstacle_positions(self) -> Array:
        """Obstacle positions (N, 3): centres of the cylinders' top faces, base_link."""
        return self._obstacles.copy()

    @property
    def obstacle_radii(self) -> Array:
        """Obstacle radii (N,) in metres, in the order of :attr:`obstacle_positions`."""
        return self._radii[:len(self._obstacles)].copy()

    def set_obstacles(self, positions: ArrayLike, radii: ArrayLike | None = None) -> None:
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
            sizes = obstacle_radii_for(MAX_OBSTACLES, parse_obstacle_radii(radii),
                                       self.scene.obstacle_radius)
            self._set_radii(self.model, sizes)
            self._radii = sizes
        for i, (mocap, geom) in enumerate(zip(self._obstacle_mocap, self._obstacle_geoms)):
            used = i < len(points)
            # Unused ones are hidden from the camera and parked far below the floor.
            self.data.mocap_pos[mocap] = points[i] if used else (0.0, 0.0, -100.0 - i)
            self.model.geom_group[geom] = VISIBLE_GROUP if used else HIDDEN_GROUP
        self._obstacles = points
        mujoco.mj_kinematics(self.model, self.data)

    def set_obstacle_radii(self, radii: ArrayLike) -> None:
        """Size the obstacles: ``radii`` as in :meth:`set_obstacles`; ValueError if bad."""
        self.set_obstacles(self._obstacles, radii)

    def _set_radii(self, model: Any, radii: Array) -> None:
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
    def camera_state(self) -> CameraState:
        """
        Return a copy of what the camera would see now, to render later (elsewhere).

        A :class:`CameraState`: the simulated time, joint and mocap (goal, obstacles) positions.
        Taking it costs microseconds; :meth:`render_rgb_depth` of it costs milliseconds, in
        this object or in another one built with the same scene (another process).
        """
        d = self.data
        return CameraState(float(d.time), d.qpos.copy(), d.mocap_pos.copy(),
                           d.mocap_quat.copy(), len(self._obstacles), self._radii.copy())

    def render_rgb_depth(self, state: CameraState | None = None
                         ) -> tuple[NDArray[np.uint8], NDArray[np.uint16]]:
        """
        Render the camera: return ``(rgb, depth_mm)``.

        ``state``: a :meth:`camera_state` taken earlier (rendered from a private copy of the
        simulation data, so the physics may go on stepping meanwhile), or None for now.
        ``rgb``: uint8 (H, W, 3); ``depth_mm``: uint16 (H, W), z in the optical frame in
        millimetres, aligned with ``rgb``, 0 where out of :attr:`depth_range`. Both are new
        arrays (safe to keep). Row 0 is the top of the image.
        """
        if self._camera is None:
            self._camera = OffscreenCamera(self.model, self.camera_id, self.intrinsics)
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

    def close(self) -> None:
        """Free the OpenGL resources of the camera (also done when garbage-collected)."""
        if self._camera is not None:
            self._camera.close()
            self._camera = None

    @classmethod
    def from_parameters(cls, p: Mapping[str, Any]) -> UR10Sim:
        """Return the simulation of ur10_sim's parameter values ``p`` (name -> value)."""
        if p['depth_min'] >= p['depth_max']:
            raise ValueError(f'depth_min ({p["depth_min"]}) must be below depth_max '
                             f'({p["depth_max"]})')
        return cls(SceneConfig.from_parameters(p), timestep=p['physics_timestep'],
                   watchdog_timeout=p['watchdog_timeout'],
                   image_size=(p['image_width'], p['image_height']),
                   fovy_deg=p['fovy_deg'], depth_range=(p['depth_min'], p['depth_max']),
                   depth_noise=p['depth_noise'], multisamples=p['multisamples'])

    def __enter__(self) -> UR10Sim:
        """Return self (``with UR10Sim() as sim:`` closes the camera at the end)."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the camera."""
        self.close()

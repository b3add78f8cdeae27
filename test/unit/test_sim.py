"""
The MuJoCo workcell without ROS.

Kinematics against Pinocchio, velocity tracking, watchdog, command validation, scene objects,
contacts (seen, not felt), and the camera's geometry (pixels + depth -> base_link).
"""

import os

from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.camera import CameraIntrinsics, CameraPose
from etdmp_ros.robot import SCENE_PARAMETERS, SceneConfig, UR10Model
from etdmp_ros.robot._scene import OPTIONAL_SCENE_PARAMETERS

from etdmp_ros.ros import system

from etdmp_ros.ros.config_files import read_parameter_file

from etdmp_ros.ros.paths import config_path

from etdmp_ros.sim import MAX_OBSTACLES, UR10Sim

import numpy as np
import pytest

os.environ.setdefault('MUJOCO_GL', 'egl')

CONTROL_PERIOD = 0.008   # a 125 Hz controller
VELOCITY = np.array([0.3, -0.25, 0.4, 0.5, -0.6, 0.8])


@pytest.fixture(scope='module')
def sim():
    with UR10Sim(system.scene_config()) as s:
        yield s


@pytest.fixture(scope='module')
def frame(sim):
    sim.reset()
    rgb, depth_mm = sim.render_rgb_depth()
    return rgb, depth_mm


def _run(sim, velocity, duration):
    """Send ``velocity`` every control period for ``duration`` s, as a controller would."""
    for _ in range(round(duration / CONTROL_PERIOD)):
        sim.set_velocity_command(velocity)
        sim.advance(CONTROL_PERIOD)


def _deproject(sim, u, v, depth_mm):
    """Pixels + depth (mm) -> base_link points, the way perception does it."""
    return sim.camera_pose.to_base(sim.intrinsics.deproject(u, v, depth_mm / 1000.0))


def _mask(rgb, color, tolerance=0.25):
    """Pixels whose colour direction is close to ``color`` (rgb 0..1), whatever the shading."""
    pixels = rgb.reshape(-1, 3).astype(float)
    norm = np.linalg.norm(pixels, axis=1) + 1e-9
    target = np.asarray(color[:3]) / np.linalg.norm(color[:3])
    cos = pixels @ target / norm
    return ((cos > 1.0 - tolerance ** 2 / 2) & (norm > 60)).reshape(rgb.shape[:2])


# ---------------------------------------------------------------------------------- kinematics
def test_forward_kinematics_matches_pinocchio(sim):
    model = UR10Model(tool_offset=sim.scene.tool_offset)
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = rng.uniform(model.lower, model.upper)
        q[2] = rng.uniform(-np.pi, np.pi)
        sim.set_joint_positions(q)
        p_mj, r_mj = sim.site_pose(sim.tool0_site)
        p_pin, r_pin = model.frame_pose(q, model.flange_frame_id)
        assert np.linalg.norm(p_mj - p_pin) < 1e-4          # 0.1 mm (it is ~1e-15)
        assert np.abs(r_mj - r_pin).max() < 1e-6
        assert np.linalg.norm(sim.tool_tip_position - model.tool_position(q)) < 1e-4
    sim.reset()


def test_world_frame_is_base_link(sim):
    base = sim.model.body('base_link').id
    assert np.allclose(sim.data.xpos[base], 0.0)
    assert np.allclose(sim.data.xmat[base].reshape(3, 3), np.eye(3))


def test_initial_pose_is_the_scene_one(sim):
    sim.reset()
    assert np.allclose(sim.q, sim.scene.initial_joint_positions)
    assert np.allclose(sim.qd, 0.0)
    assert sim.time == 0.0


# ---------------------------------------------------------------------------------- actuation
def test_constant_velocity_is_tracked_within_2_percent():
    with UR10Sim(system.scene_config()) as s:
        _run(s, VELOCITY, 0.2)                   # settle the servo
        q0, t0 = s.q, s.time
        _run(s, VELOCITY, 0.8)
        mean_velocity = (s.q - q0) / (s.time - t0)
        assert np.all(np.abs(mean_velocity / VELOCITY - 1.0) < 0.02), mean_velocity
        assert np.all(np.abs(s.qd / VELOCITY - 1.0) < 0.02), s.qd
        # Ground truth while moving is the kinematics of the current joints, not a step behind.
        model = UR10Model(tool_offset=s.scene.tool_offset)
        assert np.linalg.norm(s.tool_tip_position - model.tool_position(s.q)) < 1e-9
        # The transient: within 5 % after 50 ms from rest (a stiff, UR-like speed servo).
        s.reset()
        _run(s, VELOCITY, 0.05)
        assert np.all(np.abs(s.qd / VELOCITY - 1.0) < 0.05), s.qd


def test_watchdog_brakes_when_commands_stop():
    with UR10Sim(system.scene_config(), watchdog_timeout=0.1) as s:
        _run(s, VELOCITY, 0.3)
        stopped_sending = s.time
        s.advance(0.05)                          # within the timeout: still moving
        assert not s.watchdog_active
        assert np.allclose(s.qd, VELOCITY, rtol=0.02)
        s.advance(0.15)
        assert s.watchdog_active
        assert np.allclose(s.command, 0.0)
        # Braked at the first physics step past the timeout (ur10_sim logs both times).
        assert 0.1 < s.braked_at - s.command_time <= 0.1 + s.model.opt.timestep + 1e-9
        assert s.time - stopped_sending < 0.25
        assert np.abs(s.qd).max() < 1e-3
        q_braked = s.q
        s.advance(0.5)
        assert np.abs(s.q - q_braked).max() < 1e-4   # stays put (gravity compensated)
        # A new command re-arms it.
        _run(s, VELOCITY, 0.1)
        assert not s.watchdog_active and np.allclose(s.qd, VELOCITY, rtol=0.05)


def test_the_longest_a_moving_command_stayed_in_force_is_kept():
    """How near the watchdog came: a moving command's age when replaced or braked, not a zero's."""
    with UR10Sim(system.scene_config(), watchdog_timeout=0.1) as s:
        s.set_velocity_command(np.zeros(6))
        s.advance(0.5)                             # at rest: the zero command's age is no risk
        s.set_velocity_command(VELOCITY)
        assert s.largest_command_age == 0.0
        s.advance(0.03)
        s.set_velocity_command(VELOCITY)
        assert abs(s.largest_command_age - 0.03) < 0.003
        s.advance(0.3)                             # braked at the timeout: that age, no more
        assert 0.1 <= s.largest_command_age <= 0.1 + s.model.opt.timestep + 1e-9
        s.set_velocity_command(VELOCITY)           # after the brake: nothing older counts
        assert s.largest_command_age <= 0.1 + s.model.opt.timestep + 1e-9
        s.reset()
        assert s.largest_command_age == 0.0


def test_without_watchdog_the_last_command_applies_forever():
    with UR10Sim(system.scene_config(), watchdog_timeout=0.0) as s:
        s.set_velocity_command(VELOCITY)
        s.advance(1.0)
        assert np.allclose(s.qd, VELOCITY, rtol=0.02)


def test_arm_holds_still_without_commands(sim):
    sim.reset()
    q0 = sim.q
    sim.advance(2.0)
    assert np.abs(sim.q - q0).max() < 1e-6


def test_velocity_is_clamped_to_ur10_limits():
    with UR10Sim(system.scene_config()) as s:
        limits = s.velocity_limits
        assert np.allclose(limits, UR10Model().velocity_limits)
        applied = s.set_velocity_command(10 * np.ones(6))
        assert np.allclose(applied, limits)
        peak = np.zeros(6)
        for _ in range(50):
            s.set_velocity_command(-10 * np.ones(6))
            s.advance(CONTROL_PERIOD)
            peak = np.maximum(peak, np.abs(s.qd))
        # The servo itself may overshoot a step from rest to full speed by a hair (coupled
        # inertia: 0.15 % measured on the shoulder pan).
        assert np.all(peak <= limits * 1.005), peak / limits
        assert np.allclose(s.qd, -limits, rtol=0.02)


@pytest.mark.parametrize('bad', [[0.1] * 5, [0.1] * 7, [], [0.1, 0.1, float('nan'), 0, 0, 0],
                                 [0.1, 0.1, 0, float('inf'), 0, 0], 'fast', None])
def test_bad_commands_are_rejected_and_never_applied(bad):
    with UR10Sim(system.scene_config()) as s:
        s.set_velocity_command(VELOCITY)
        with pytest.raises(ValueError):
            s.set_velocity_command(bad)
        assert np.array_equal(s.command, VELOCITY)     # the previous command stays
        s.advance(0.05)
        assert np.all(np.isfinite(s.q)) and np.all(np.isfinite(s.qd))


# ------------------------------------------------------------------------- goal and obstacles
def test_goal_and_obstacles_move_and_bad_values_are_refused(sim):
    sim.reset()
    assert np.allclose(sim.goal_position, sim.scene.goal_position)
    assert np.allclose(sim.obstacle_positions, sim.scene.obstacle_positions)
    sim.set_goal([0.6, 0.2, 0.002])
    assert np.allclose(sim.goal_position, [0.6, 0.2, 0.002])
    sim.set_obstacles([0.7, 0.0, 0.08])
    assert sim.obstacle_positions.shape == (1, 3)
    for bad in ([0.6, 0.2], [0.6, float('nan'), 0.0], 'here'):
        with pytest.raises(ValueError):
            sim.set_goal(bad)
    for bad in ([0.7, 0.0], [0.7, 0.0, float('inf')], [0.7, 0.0, 0.08] * (MAX_OBSTACLES + 1)):
        with pytest.raises(ValueError):
            sim.set_obstacles(bad)
    assert np.allclose(sim.goal_position, [0.6, 0.2, 0.002])
    assert np.allclose(sim.obstacle_positions, [[0.7, 0.0, 0.08]])
    sim.set_obstacles([])
    assert sim.obstacle_positions.shape == (0, 3)
    sim.reset()


def test_moved_objects_are_seen_where_they_are(sim):
    sim.reset()
    red = sim.scene.obstacle_color
    n_red = _mask(sim.render_rgb_depth()[0], red).sum()
    sim.set_obstacles(sim.scene.obstacle_positions[:1])
    assert _mask(sim.render_rgb_depth()[0], red).sum() < 0.7 * n_red   # one hidden
    goal = np.array([0.60, 0.05, 0.002])
    sim.set_goal(goal)
    rgb, depth = sim.render_rgb_depth()
    assert np.linalg.norm(_goal_from_image(sim, rgb, depth) - goal) < 0.002
    sim.reset()


def test_the_bottle_moves_with_its_collision_geometry_and_bad_values_are_refused(sim):
    # bottle.position at runtime (ur10_sim's parameter): the bottle's geometry, the one that
    # collides and the one the camera renders, stands where it was put.
    import mujoco
    sim.reset()
    start = np.array(sim.scene.bottle_position, dtype=float)
    np.testing.assert_allclose(sim.bottle_mouth, [*start, sim.scene.bottle_height])
    moved = start + [0.0, 0.02]
    sim.set_bottle(moved)
    np.testing.assert_allclose(sim.bottle_position, moved)
    geom = sim.model.geom('bottle').id
    np.testing.assert_allclose(sim.data.geom_xpos[geom][:2], moved, atol=1e-9)
    body = sim.model.geom_bodyid[geom]
    # The mesh is drawn; the wall's boxes and the floor's disc, on the same body, collide.
    assert not (sim.model.geom_contype[geom] or sim.model.geom_conaffinity[geom])
    colliding = [g for g in range(sim.model.ngeom)
                 if sim.model.geom_bodyid[g] == body and sim.model.geom_conaffinity[g]]
    assert len(colliding) == 25

    def wall_hit(x, y):
        # A ray down onto the wall's top: the bottle's geometry is there, or it is not.
        point = np.array([x, y, sim.scene.bottle_height + 0.1])
        geomid = np.array([-1], dtype=np.int32)
        mujoco.mj_ray(sim.model, sim.data, point, np.array([0.0, 0.0, -1.0]), None, 1, -1,
                      geomid)
        return int(geomid[0]) >= 0 and sim.model.geom_bodyid[geomid[0]] == body

    rim = sim.scene.bottle_radius - 0.002
    assert wall_hit(moved[0] + rim, moved[1])
    assert not wall_hit(start[0], start[1] - rim)      # where its wall was: nothing now
    for bad in ([0.7], [0.7, float('nan')], 'here'):
        with pytest.raises(ValueError):
            sim.set_bottle(bad)
    np.testing.assert_allclose(sim.bottle_position, moved)
    sim.reset()
    np.testing.assert_allclose(sim.bottle_position, start)


# ------------------------------------------------------------------------------------- camera
def _pose_with_tip(sim, target):
    """Return joints putting the tool tip at ``target`` (base_link), pointing down."""
    q0 = sim.scene.initial_joint_positions
    rotation = sim.ur10.frame_pose(q0)[1]
    q, error = sim.ur10.solve_pose(np.asarray(target, dtype=float), rotation, q0)
    assert np.linalg.norm(error) < 1e-6
    return q


def _touching(sim):
    """Return {(part, object): depth mm} of the simulation's contacts now."""
    return {(c.part, c.item): round(c.depth * 1e3, 1) for c in sim.contacts}


def test_contacts_are_seen_not_felt(sim):
    # The robot in the workcell: nothing touches at the scene's start; a link through an
    # obstacle is a contact, named by link and object, with its depth; the dynamics never see
    # it (the arm moves through as it would without).
    sim.reset()
    assert sim.contacts == ()
    tip = sim.tool_tip_position
    q_start = sim.q
    sim.set_obstacles([[tip[0], tip[1], 0.08]], [0.02])    # under the pen, 8 cm tall
    assert sim.contacts == ()                           # ... until the next step sees it
    assert _touching(sim) == {} and sim.detect_contacts() != ()
    sim.set_joint_positions(q_start)
    touching = _touching(sim)
    assert set(touching) == {('tool_tip', 'obstacle_0')}, touching
    assert touching[('tool_tip', 'obstacle_0')] == pytest.approx(3.3, abs=0.1)
    # A link: an obstacle (8 cm tall, its top at 0.3 m) under the first wrist joint, 0.33 m
    # up, whose housing belongs to the forearm's mesh.
    wrist = sim.data.xpos[sim.model.body('wrist_1_link').id]
    sim.set_obstacles([[wrist[0], wrist[1], 0.30]], [0.02])
    sim.set_joint_positions(q_start)
    assert set(_touching(sim)) == {('forearm_link', 'obstacle_0')}, _touching(sim)
    # Felt? No: the same velocity command moves the arm the same with and without it.
    sim.reset(q_start)
    sim.set_obstacles([[wrist[0], wrist[1], 0.30]], [0.02])
    with UR10Sim(sim.scene) as free:
        free.set_obstacles([])
        for s in (sim, free):
            s.set_velocity_command([0.0, 0.0, 0.0, 0.0, 0.3, 0.0])
            s.advance(0.2)
        np.testing.assert_allclose(sim.q, free.q, atol=1e-12)
    assert sim.contacts and not free.contacts
    sim.reset()


def test_the_pen_writes_on_the_table_without_contact_but_presses_through_with_one(sim):
    sim.reset()
    sim.set_obstacles([])
    at = [0.75, 0.15, 0.0]                                  # on the whiteboard, z = 0
    sim.set_joint_positions(_pose_with_tip(sim, at))
    assert _touching(sim) == {}
    sim.set_joint_positions(_pose_with_tip(sim, [0.75, 0.15, -0.0015]))   # 1.5 mm in: writing
    assert _touching(sim) == {}
    sim.set_joint_positions(_pose_with_tip(sim, [0.75, 0.15, -0.004]))    # pressed in
    assert _touching(sim) == {('tool_tip', 'table'): 4.0}
    sim.set_joint_positions(_pose_with_tip(sim, [0.75, 0.15, -0.03]))     # the pen's body too
    assert set(_touching(sim)) >= {('tool_tip', 'table'), ('tool', 'whiteboard')}
    sim.reset()


def test_the_stirrer_in_the_open_bottle_touches_only_its_wall_or_floor(sim):
    # The bottle is open: a stirrer in it touches nothing (MuJoCo's convex hull of the mesh
    # would fill it); against its wall or on its floor it does.
    sim.reset()
    mouth = sim.bottle_mouth
    radius = sim.scene.bottle_radius
    inside = mouth + [0.0, 0.0, -0.15]                      # 5 cm above the floor (1 cm thick)
    sim.set_joint_positions(_pose_with_tip(sim, inside))
    assert _touching(sim) == {}
    near_wall = inside + [radius - 0.004 - 0.009 - 0.001, 0.0, 0.0]   # 1 mm from the wall
    sim.set_joint_positions(_pose_with_tip(sim, near_wall))
    assert _touching(sim) == {}
    sim.set_joint_positions(_pose_with_tip(sim, near_wall + [0.003, 0.0, 0.0]))
    assert set(_touching(sim)) == {('tool', 'bottle')}
    # 2 mm into the floor: the 16 cm stirrer is too short for the 20 cm bottle, so the wrist
    # hits its mouth too.
    sim.set_joint_positions(_pose_with_tip(sim, [*mouth[:2], 0.008]))
    touching = _touching(sim)
    assert touching[('tool_tip', 'bottle')] == 2.0
    assert {'wrist_2_link', 'wrist_3_link'} <= {part for part, _ in touching}, touching
    sim.reset()


def test_obstacle_radii_size_the_cylinders_the_camera_sees_and_the_arm_touches(sim):
    sim.reset()
    tip = sim.tool_tip_position                             # 77 mm above the table
    beside = [tip[0] + 0.05, tip[1], 0.10]                  # axis 50 mm from the pen's
    sim.set_obstacles([beside, [0.5, -0.2, 0.08]], [0.03])
    np.testing.assert_allclose(sim.obstacle_radii, [0.03, sim.scene.obstacle_radius])
    assert sim.detect_contacts() == ()
    sim.set_obstacle_radii([0.045])                         # 45 mm reaches the pen (9 mm)
    np.testing.assert_allclose(sim.obstacle_radii, [0.045, sim.scene.obstacle_radius])
    sim.set_joint_positions(sim.q)
    assert set(_touching(sim)) == {('tool', 'obstacle_0')}
    state = sim.camera_state()
    np.testing.assert_allclose(state.obstacle_radii[:2], [0.045, sim.scene.obstacle_radius])
    for bad in ([0.0], [-0.01], [float('nan')], 'big'):
        with pytest.raises(ValueError):
            sim.set_obstacle_radii(bad)
    np.testing.assert_allclose(sim.obstacle_radii, [0.045, sim.scene.obstacle_radius])
    sim.set_obstacles(sim.scene.obstacle_positions, [])
    sim.reset()


def test_intrinsics_are_a_d435_colour_camera(sim):
    k = sim.intrinsics
    assert (k.width, k.height) == (640, 480)
    assert k.fx == pytest.approx(617.0, abs=1.0) and k.fy == k.fx
    assert k.fovx_deg == pytest.approx(55.0, abs=1.0)
    assert k.fovy_deg == pytest.approx(42.5, abs=1e-9)
    assert (k.cx, k.cy) == (319.5, 239.5)
    assert np.allclose(k.P[:, :3], k.K) and np.allclose(k.P[:, 3], 0)


def test_camera_pose_in_scene_sees_the_workspace(sim):
    """Task plane area (+-0.2 m), goal, obstacles and bottle project inside the image."""
    s = sim.scene
    corners = s.task_plane_origin + np.array([[x, y, 0] for x in (-.2, .2) for y in (-.2, .2)])
    points = np.vstack([corners, s.goal_position, s.obstacle_positions,
                        [*s.bottle_position, s.bottle_height]])
    cam = sim.camera_pose.from_base(points)
    uv = sim.intrinsics.project(cam)
    assert np.all(cam[:, 2] > 0.3)
    assert np.all((uv >= 0) & (uv <= [639, 479])), uv


def _goal_from_image(sim, rgb, depth):
    mask = _mask(rgb, sim.scene.goal_color) & (depth > 0)
    v, u = np.nonzero(mask)
    assert len(u) > 100
    return _deproject(sim, u.mean(), v.mean(), np.median(depth[v, u]))[0]


def test_pixel_of_goal_deprojects_onto_goal(sim, frame):
    rgb, depth = frame
    goal = sim.scene.goal_position
    # The pixel where the goal point projects, deprojected with camera_info K and depth.
    u, v = sim.intrinsics.project(sim.camera_pose.from_base(goal))[0]
    z_mm = depth[int(round(v)), int(round(u))]
    assert z_mm > 0
    assert np.linalg.norm(_deproject(sim, u, v, z_mm)[0] - goal) < 0.002
    # Segmenting the marker by colour (what perception does) finds it as precisely.
    assert np.linalg.norm(_goal_from_image(sim, rgb, depth) - goal) < 0.002


def test_obstacle_tops_deproject_onto_obstacle_positions(sim, frame):
    rgb, depth = frame
    v, u = np.nonzero(_mask(rgb, sim.scene.obstacle_color) & (depth > 0))
    points = _deproject(sim, u, v, depth[v, u])
    for top in sim.scene.obstacle_positions:
        near = np.linalg.norm(points[:, :2] - top[:2], axis=1) < 2 * sim.scene.obstacle_radius
        face = points[near & (np.abs(points[:, 2] - top[2]) < 0.002)]
        assert len(face) > 50
        # Top-face points lie on the disc; their centre is the obstacle position.
        radial = np.linalg.norm(face[:, :2] - top[:2], axis=1)
        assert radial.max() < sim.scene.obstacle_radius + 0.002
        assert np.linalg.norm(face.mean(axis=0)[:2] - top[:2]) < 0.002


def test_depth_is_z_of_the_optical_frame(sim):
    """The whiteboard (a plane) comes out flat across the whole image: depth is z, not range."""
    sim.set_joint_positions([np.pi, -1.2, 1.9, -2.27, -1.57, 0.0])   # arm away from the board
    rgb, depth = sim.render_rgb_depth()
    sim.reset()
    white = _mask(rgb, sim.scene.whiteboard_color, tolerance=0.05) & (rgb.min(axis=2) > 200)
    v, u = np.nonzero(white & (depth > 0))
    points = _deproject(sim, u, v, depth[v, u])
    on_board = np.all(np.abs(points[:, :2] - sim.scene.task_plane_origin[:2]) <
                      sim.scene.whiteboard_size / 2 - 0.01, axis=1)
    assert on_board.sum() > 10000
    assert (u[on_board].max() - u[on_board].min()) > 200      # spans the image
    z = points[on_board, 2]
    assert np.abs(z - 0.0005).max() < 0.002


def test_depth_range_and_noise():
    with UR10Sim(system.scene_config(), depth_range=(0.1, 1.3)) as s:
        _, depth = s.render_rgb_depth()
        assert depth.max() <= 1300 and (depth == 0).sum() > 1000    # far table/floor: no data
    with UR10Sim(system.scene_config(), depth_noise=0.002, seed=3) as noisy, \
            UR10Sim(system.scene_config()) as exact:
        _, d_noisy = noisy.render_rgb_depth()
        _, d_exact = exact.render_rgb_depth()
        both = (d_noisy > 0) & (d_exact > 0)
        z = d_exact[both] / 1000.0
        residual = (d_noisy[both].astype(float) - d_exact[both]) / 1000.0
        assert np.std(residual / z ** 2) == pytest.approx(0.002, rel=0.2)


def test_render_gives_fresh_arrays_of_the_right_types(sim):
    rgb, depth = sim.render_rgb_depth()
    rgb2, _ = sim.render_rgb_depth()
    assert rgb.dtype == np.uint8 and rgb.shape == (480, 640, 3)
    assert depth.dtype == np.uint16 and depth.shape == (480, 640)
    assert rgb is not rgb2 and not np.shares_memory(rgb, rgb2)


# ------------------------------------------------------------------------------ camera model
def test_pinhole_projection_round_trip():
    k = CameraIntrinsics.from_fovy(640, 480, 42.5)
    points = np.array([[0.1, -0.2, 1.3], [-0.4, 0.3, 2.0], [0.0, 0.0, 0.5]])
    uv = k.project(points)
    assert np.allclose(k.deproject(uv[:, 0], uv[:, 1], points[:, 2]), points)
    assert np.allclose(uv[2], [319.5, 239.5])
    with pytest.raises(ValueError):
        CameraIntrinsics.from_fovy(640, 480, 0.0)


def test_look_at_points_the_optical_axis_at_the_target():
    pose = CameraPose.look_at([1.5, 0.1, 0.9], [0.7, 0.0, 0.0])
    target_in_camera = pose.from_base([[0.7, 0.0, 0.0]])[0]
    assert np.allclose(target_in_camera[:2], 0.0, atol=1e-12) and target_in_camera[2] > 0
    up_in_camera = pose.rotation.T @ np.array([0.0, 0.0, 1.0])
    assert up_in_camera[1] < 0        # base_link up is image up (optical y points down)
    assert np.allclose(pose.to_base(pose.from_base([[1, 2, 3]])), [[1, 2, 3]])


def test_quaternion_conversions_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[3] >= 0 else -q
        r = quat.to_matrix(quat.normalized(q))
        assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
        assert np.allclose(quat.from_matrix(r), q)
    with pytest.raises(ValueError):
        quat.to_matrix(quat.normalized([0, 0, 0, 0]))


# ------------------------------------------------------------------------------------- scene
def test_scene_file_has_every_parameter_and_camera_pose_is_shared():
    params = read_parameter_file(_scene_path())
    assert set(SCENE_PARAMETERS) - set(OPTIONAL_SCENE_PARAMETERS) <= set(params)
    scene = system.scene_config()
    assert np.allclose(scene.camera_pose.position, params['camera.position'])


def test_scene_parameters_are_validated():
    params = read_parameter_file(_scene_path())
    SceneConfig.from_parameters(params)
    # Each value by its description where values are typed (the nodes, scene_config), what no
    # single value says (a rotation; objects on the table) by SceneConfig itself.
    for name, bad in (('goal_position', [0.1, 0.2]), ('obstacle_positions', [0.1, 0.2]),
                      ('obstacle_radii', [0.02, -0.01]), ('obstacle_radii', [float('inf')]),
                      ('camera.orientation', [0, 0, 0, 0]), ('bottle.radius', -0.1),
                      ('table.color', [2.0, 0, 0]), ('tool_offset', [0, 0, float('nan')]),
                      ('table.height', 'high'), ('table.color', [0.5, 0.5]),
                      ('initial_joint_positions', [0.0] * 5)):
        with pytest.raises(ValueError, match=name.split('.')[0]):
            system.scene_config({name: bad})
    for name, bad in (('camera.orientation', [0, 0, 0, 0]), ('goal_position', [0.1, 0.2]),
                      ('obstacle_positions', [0.1, 0.2]), ('obstacle_radii', [0.02, -0.01])):
        with pytest.raises(ValueError, match=name.split('.')[0]):
            SceneConfig.from_parameters({**params, name: bad})
    missing = dict(params)
    del missing['bottle.height']
    with pytest.raises(ValueError, match='bottle.height'):
        SceneConfig.from_parameters(missing)


#: Where the objects may not be put (ur10_sim accepted all of them before).
MISPLACED = [
    ('goal_position', [1e308, 0.0, 0.0],
     r'goal_position has a coordinate of 1e\+308 m, beyond 100 m'),
    ('goal_position', [1.39, 0.1, 0.002], r'the goal marker at \(1.390, 0.100, 0.002\) is off the '
                                          r'table: .* x -0.470 to 1.370 m'),
    ('goal_position', [0.05, 0.05, 0.002], "the goal marker .* is inside the robot's base"),
    ('bottle.position', [0.7, -0.74], r'the bottle at \(0.700, -0.740\) is off the table'),
    ('bottle.position', [2.0, 0.0], 'is off the table'),
    ('bottle.position', [0.0, 0.0], r"inside the robot's base: 0.000 m from its axis, less than "
                                    r'ROBOT_BASE_RADIUS 0.115 m \+ its radius 0.045 m'),
    ('obstacle_positions', [0.8, 0.1, 0.08, 0.1, -0.05, 0.08], "obstacle 2 .* inside the robot's"),
    ('obstacle_positions', [0.8, 0.1, 0.08, 0.8, 0.9, 0.08], 'obstacle 2 .* off the table'),
]


@pytest.mark.parametrize('name, value, reason', MISPLACED,
                         ids=[f'{row[0]} {row[1]}' for row in MISPLACED])
def test_objects_stand_on_the_table_and_clear_of_the_robot(name, value, reason):
    scene = system.scene_config()
    with pytest.raises(ValueError, match=reason):
        scene.placed(name, value)
    params = read_parameter_file(_scene_path())
    with pytest.raises(ValueError, match=reason):
        SceneConfig.from_parameters({**params, name: value})


def test_objects_anywhere_on_the_table_are_taken():
    scene = system.scene_config()
    np.testing.assert_allclose(scene.placed('goal_position', [1.36, -0.71, 0.002]),
                               [1.36, -0.71, 0.002])
    # Below the table top (hidden from the camera, as test_perception_node.py does): taken.
    np.testing.assert_allclose(scene.placed('goal_position', [0.7, 0.2, -0.3]), [0.7, 0.2, -0.3])
    assert scene.placed('obstacle_positions', []).shape == (0, 3)
    np.testing.assert_allclose(scene.placed('bottle.position', [0.0, 0.161]), [0.0, 0.161])


def _scene_path():
    return config_path('scene.yaml')

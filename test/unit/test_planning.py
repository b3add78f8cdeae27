"""Planning for /generalize without ROS: task plane mapping, checks, and the core's plan mapped."""

import math

from etdmp_ros.dmp import (builtin_demo, Demonstration, learn, nrmse, ObstacleGains,
                           unit_quaternions)
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.robot import PEN_RADIUS, UR10Model
from etdmp_ros.skills.following import FollowedPlan
from etdmp_ros.skills.planning import (place_demo, plan_path, PlanningError, PlanSettings,
                                       TOOL_DOWN, Workspace)
import numpy as np
import pytest

PLANE = TaskPlane.create([0.75, 0.15, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02)
# A whiteboard: vertical, facing the robot, 40 cm above the table.
WALL = TaskPlane.create([0.9, 0.0, 0.4], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], 0.01)
START, GOAL = np.array([0.80, 0.20, 0.0]), np.array([0.74, 0.15, 0.0])


@pytest.fixture(scope='module')
def g_skill():
    return learn(builtin_demo('G'))


def test_task_plane_maps_to_demo_units_and_back():
    p = np.array([[0.95, 0.05, 0.3], [0.75, 0.15, -0.1]])
    uv = PLANE.to_plane(p)
    np.testing.assert_allclose(uv, [[10.0, -5.0], [0.0, 0.0]])
    np.testing.assert_allclose(PLANE.from_plane(uv), p * [1, 1, 0])
    np.testing.assert_allclose(PLANE.distance(p), [0.3, -0.1])
    q = WALL.from_plane([[3.0, 4.0]])
    np.testing.assert_allclose(q, [[0.9, -0.03, 0.44]])
    np.testing.assert_allclose(WALL.normal, [-1.0, 0.0, 0.0])
    unnormalised = TaskPlane.create([0, 0, 0], [2.0, 0.0, 0.0], [0.0, 0.5, 0.0], 1.0)
    np.testing.assert_allclose(unnormalised.axes, [[1, 0, 0], [0, 1, 0]])


@pytest.mark.parametrize('args, message', [
    (([0, 0], [1, 0, 0], [0, 1, 0], 0.02), 'origin must be 3'),
    (([0, 0, 0], [1, 0, 0], [1, 0.01, 0], 0.02), 'orthogonal'),
    (([0, 0, 0], [0, 0, 0], [0, 1, 0], 0.02), 'x_axis must not be zero'),
    (([0, 0, math.nan], [1, 0, 0], [0, 1, 0], 0.02), 'finite'),
    (([0, 0, 0], [1, 0, 0], [0, 1, 0], 0.0), 'scale'),
    # Accepted before, then every plan failed with "overflow encountered in divide".
    (([1e308, 0, 0], [1, 0, 0], [0, 1, 0], 0.02),
     r'origin has a coordinate of 1e\+308 m, beyond 100 m \(MAX_REQUEST_COORDINATE\)'),
    (([0, 100.5, 0], [1, 0, 0], [0, 1, 0], 0.02), 'beyond 100 m'),
])
def test_task_plane_refuses_bad_parameters(args, message):
    with pytest.raises(ValueError, match=message):
        TaskPlane.create(*args)


def test_task_plane_axes_of_any_finite_length_are_normalised():
    # [1e308, 1e308, 0] squared overflowed: its norm was inf, the axis the zero vector.
    plane = TaskPlane.create([0.5, 0.0, 0.0], [1e308, 1e308, 0.0], [0.0, 0.0, 1e-6], 0.02)
    np.testing.assert_allclose(plane.x_axis, [math.sqrt(0.5), math.sqrt(0.5), 0.0])
    np.testing.assert_allclose(plane.y_axis, [0.0, 0.0, 1.0])


def test_2d_plan_is_the_core_plan_in_the_task_plane(g_skill):
    above = START + [0.0, 0.0, 0.08]
    plan = plan_path(g_skill, above, GOAL, plane=PLANE)
    np.testing.assert_allclose(plan.positions[0], START, atol=1e-12)    # projected start
    assert np.linalg.norm(plan.positions[-1] - GOAL) < 1e-3
    np.testing.assert_allclose(PLANE.distance(plan.positions), 0.0, atol=1e-12)
    core = g_skill.generalize(PLANE.to_plane(START), PLANE.to_plane(GOAL), dt=0.01)
    np.testing.assert_allclose(plan.positions, PLANE.from_plane(core.x), atol=1e-12)
    np.testing.assert_allclose(plan.velocities[:, :2], core.v * 0.02, atol=1e-12)
    np.testing.assert_allclose(plan.t, core.t)
    assert nrmse(PLANE.to_plane(plan.positions), g_skill.demo) < 0.005
    assert plan.orientation == pytest.approx(TOOL_DOWN)
    # The same request in demo units on a vertical whiteboard: the same letter there.
    on_wall = plan_path(g_skill, WALL.from_plane(PLANE.to_plane(START)),
                        WALL.from_plane(PLANE.to_plane(GOAL)), plane=WALL)
    np.testing.assert_allclose(WALL.to_plane(on_wall.positions),
                               PLANE.to_plane(plan.positions), atol=1e-9)


def test_timing_orientation_and_method_settings(g_skill):
    settings = PlanSettings(duration=5.0, output_period=0.01, orientation=(0, 0, 0, 2.0),
                            method='dmp')
    plan = plan_path(g_skill, START, GOAL, settings=settings, plane=PLANE)
    assert len(plan.t) == 501 and plan.t[-1] == pytest.approx(5.0)
    assert plan.orientation == (0.0, 0.0, 0.0, 1.0)
    core = g_skill.generalize(PLANE.to_plane(START), PLANE.to_plane(GOAL), method='dmp',
                              tau=5.0, dt=0.01)
    np.testing.assert_allclose(plan.positions, PLANE.from_plane(core.x), atol=1e-12)


def test_3d_skill_uses_base_link_coordinates():
    stir = learn(builtin_demo('stir'))
    mouth = np.array([0.70, -0.30, 0.20])
    start, goal = mouth + stir.start + [0.02, 0.0, 0.05], mouth + stir.goal
    for mode in (1, 2):
        plan = plan_path(stir, start, goal, settings=PlanSettings(mode=mode))
        np.testing.assert_allclose(plan.positions[0], start, atol=1e-12)
        assert np.linalg.norm(plan.positions[-1] - goal) < 1e-3
        core = stir.generalize(start, goal, mode=mode, dt=0.01)
        np.testing.assert_allclose(plan.positions, core.x, atol=1e-12)
    assert nrmse(plan_path(stir, start, goal).positions, stir.demo) < 0.005


def test_obstacles_are_projected_avoided_and_k_is_in_metres(g_skill):
    free = plan_path(g_skill, START, GOAL, plane=PLANE)
    obstacles = free.positions[[60, 120]] + [0.0, 0.0, 0.08]     # cylinder tops on the path
    plan = plan_path(g_skill, START, GOAL, obstacles, plane=PLANE)
    size = np.ptp(free.positions, axis=0).max()
    gap = np.linalg.norm(plan.positions[:, None] - (obstacles * [1, 1, 0])[None], axis=2).min()
    assert gap > 0.05 * size
    assert np.linalg.norm(plan.positions[-1] - GOAL) < 1e-3
    assert plan.t[-1] == pytest.approx(1.5 * g_skill.tau)        # obstacle_margin 0.5
    np.testing.assert_allclose(plan.obstacles, obstacles * [1, 1, 0], atol=1e-12)
    # obstacle_k is 1/m: the core's default k = 10 / |x0 - g| written in 1/m is the same plan.
    k_metres = 10.0 / np.linalg.norm(START - GOAL)
    same = plan_path(g_skill, START, GOAL, obstacles, plane=PLANE,
                     settings=PlanSettings(obstacle_k=k_metres))
    np.testing.assert_allclose(same.positions, plan.positions, atol=1e-9)
    weaker = plan_path(g_skill, START, GOAL, obstacles, plane=PLANE,
                       settings=PlanSettings(gains=ObstacleGains(gamma=0.0, gamma2=0.0)))
    np.testing.assert_allclose(weaker.positions[:201], free.positions, atol=1e-9)


def test_obstacle_radii_are_metres_kept_clear_and_followed(g_skill):
    """Radii in metres (2D: over the plane's scale); the detour; a followed plan keeps them."""
    free = plan_path(g_skill, START, GOAL, plane=PLANE)
    tops = free.positions[[60, 120]] + [0.0, 0.0, 0.08]         # cylinder tops on the path
    centres = tops * [1, 1, 0]
    radii = np.array([0.004, 0.006])                            # metres
    exact = PlanSettings(tool_radius=0.0, obstacle_clearance=0.0)     # the radii are clearances
    plan = plan_path(g_skill, START, GOAL, tops, exact, PLANE, obstacle_radii=radii)
    assert plan.avoidance == 'detour' and len(plan.t) == len(free.t)    # no obstacle_margin
    gaps = np.linalg.norm(plan.positions[:, None] - centres[None], axis=2).min(axis=0) - radii
    assert np.all(gaps >= 0.0) and np.all(gaps < 0.01 * np.ptp(free.positions, axis=0).max())
    np.testing.assert_allclose(plan.obstacle_radii, radii)
    assert np.linalg.norm(plan.positions[-1] - GOAL) < 1e-3
    # The same in demo units: the plane's 0.02 m per unit.
    core = g_skill.generalize(PLANE.to_plane(START), PLANE.to_plane(GOAL),
                              obstacles=PLANE.to_plane(tops), obstacle_radii=radii / 0.02,
                              dt=0.01)
    np.testing.assert_allclose(plan.positions, PLANE.from_plane(core.x), atol=1e-12)
    # The baseline on demand: the paper's points, its timing.
    paper = plan_path(g_skill, START, GOAL, tops, plane=PLANE, obstacle_radii=radii,
                      settings=PlanSettings(avoidance='paper', tool_radius=0.0,
                                            obstacle_clearance=0.0))
    assert paper.t[-1] == pytest.approx(1.5 * g_skill.tau)
    # An obstacle moves onto the remaining path while the plan runs: kept clear, continuous.
    followed = FollowedPlan(g_skill, plan, exact, PLANE)
    moved = tops.copy()
    moved[1] += [0.01, -0.01, 0.0]
    k = followed.update(0.5, obstacles=moved)
    after = followed.positions[k:]
    gaps = np.linalg.norm(after[:, None] - (moved * [1, 1, 0])[None], axis=2).min(axis=0)
    assert np.all(gaps >= radii)
    np.testing.assert_allclose(followed.obstacle_radii, radii)
    steps = np.linalg.norm(np.diff(followed.velocities, axis=0), axis=1)
    assert steps.max() <= 1.5 * np.linalg.norm(np.diff(plan.velocities, axis=0), axis=1).max()
    with pytest.raises(PlanningError, match='contains the plan'):
        followed.update(followed.t[k + 5], obstacles=[followed.positions[k + 6]],
                        obstacle_radii=[0.01])
    with pytest.raises(PlanningError, match='2 obstacles but 1 obstacle radii'):
        plan_path(g_skill, START, GOAL, tops, plane=PLANE, obstacle_radii=[0.01])
    with pytest.raises(PlanningError, match='finite and >= 0'):
        plan_path(g_skill, START, GOAL, tops, plane=PLANE, obstacle_radii=[0.01, -1.0])
    with pytest.raises(PlanningError, match='goal lies inside obstacle'):
        plan_path(g_skill, START, GOAL, [GOAL + [0.03, 0.0, 0.0]], plane=PLANE,
                  obstacle_radii=[0.04])
    with pytest.raises(ValueError, match='avoidance must be'):
        PlanSettings(avoidance='magic')


def test_obstacle_radii_become_the_clearance_the_plan_keeps(g_skill):
    # Issue 25: each obstacle's radius (as perceived) + the tool's + the safety margin, in
    # metres, on the plan (what the core is given, in the skill's units).
    obstacles = np.array([[0.78, 0.16, 0.08], [0.76, 0.2, 0.08]])
    plain = plan_path(g_skill, START, GOAL, obstacles, plane=PLANE)
    assert plain.obstacle_radii is None
    settings = PlanSettings(tool_radius=0.01, obstacle_clearance=0.004)
    sized = plan_path(g_skill, START, GOAL, obstacles, settings, PLANE,
                      obstacle_radii=[0.025, 0.0])
    np.testing.assert_allclose(sized.obstacle_radii, [0.039, 0.014])
    assert PlanSettings().tool_radius == PEN_RADIUS    # the simulation's pen, by default
    for radii, message in (([0.025], '2 obstacles but 1 obstacle radii'),
                           ([0.025, -0.01], 'finite and >= 0'),
                           ([0.025, math.nan], 'finite and >= 0'),
                           ('big', 'must be numbers')):
        with pytest.raises(PlanningError, match=message):
            plan_path(g_skill, START, GOAL, obstacles, plane=PLANE, obstacle_radii=radii)


@pytest.mark.parametrize('start, goal, obstacles, message', [
    ([math.nan, 0.2, 0.0], GOAL, (), 'start contains NaN or inf'),
    (START, [0.7, -math.inf, 0.0], (), 'goal contains NaN or inf'),
    (START, GOAL, [[0.7, 0.1, math.nan]], 'obstacles contains NaN'),
    (GOAL + [0.0, 0.0, 0.2], GOAL, (), r'start equals goal \(projected onto the task plane\)'),
    (START, [1.5, 0.0, 0.0], (), r"goal \(1.500, 0.000, 0.000\) .* out of the UR10's reach: "
                                 r'1.5\d\d m from the shoulder'),
    (START, [0.1, 0.05, 0.0], (), 'from the base axis, closer than 0.2 m'),
    (START, GOAL, [GOAL + [0.01, 0.0, 0.08]], r'lies on the goal: 10.0 mm from it'),
    # A static obstacle of 1e308 refused every request with "overflow encountered in divide".
    (START, GOAL, [[1e308, 0.0, 0.0]],
     r'obstacles has a coordinate of 1e\+308 m, beyond 100 m \(MAX_REQUEST_COORDINATE\)'),
    ([0.8, -150.0, 0.0], GOAL, (), 'start has a coordinate of -150 m'),
    ([1.05, -0.3, 0.0], [1.05, -0.15, 0.0], (),
     r"the plan leaves the UR10's reach at t = 0.27 s, \(1.107, -0.303, 0.000\): 1.155 m"),
])
def test_bad_requests_are_refused_with_the_reason(g_skill, start, goal, obstacles, message):
    with pytest.raises(PlanningError, match=message):
        plan_path(g_skill, start, goal, obstacles, plane=PLANE)


def test_core_refusals_and_wrong_dimensions_become_planning_errors(g_skill):
    # A 'U': it starts and ends at the same height, which the plain DMP cannot scale.
    s = np.linspace(0.0, 1.0, 100)
    u_skill = learn(Demonstration('U', np.column_stack([2.0 * s, -np.sin(np.pi * s)])))
    plan_path(u_skill, START, GOAL, plane=PLANE)    # ET-DMP can
    with pytest.raises(PlanningError, match='plain DMP cannot'):
        plan_path(u_skill, START, GOAL, plane=PLANE, settings=PlanSettings(method='dmp'))
    with pytest.raises(PlanningError, match='needs a task plane'):
        plan_path(g_skill, START, GOAL)
    line = learn(np.linspace(0.0, 1.0, 20))
    with pytest.raises(PlanningError, match='2 or 3 coordinates'):
        plan_path(line, START, GOAL, plane=PLANE)
    stir = learn(builtin_demo('stir'))
    with pytest.raises(PlanningError, match='below the table'):
        plan_path(stir, [0.7, 0.0, 0.1], [0.7, 0.0, -0.2])


def test_workspace_criterion_matches_the_ur10_model():
    workspace = Workspace()
    # The shoulder centre of the criterion is the URDF's shoulder_pan joint placement.
    model = UR10Model().model
    np.testing.assert_allclose(workspace.shoulder,
                               model.jointPlacements[1].translation, atol=1e-9)
    # The scene's tool position at its initial joints is reachable.
    tool = UR10Model(tool_offset=(0, 0, 0.16)).tool_position([0.0, -1.2, 1.9, -2.27, -1.57, 0])
    assert workspace.violation(tool) is None
    index, reason = workspace.violation([[0.5, 0, 0], [0.05, 0.05, 0.1], [1.3, 0.0, 0.1]])
    assert index == 1 and 'base axis' in reason
    assert workspace.violation([[0.5, 0.0, -0.02]])[1].startswith('below the table')
    with pytest.raises(ValueError, match='reach - margin > min_radius'):
        Workspace(reach=0.3, margin=0.2)


@pytest.mark.parametrize('kwargs, message', [
    ({'method': 'rrt'}, 'method must be one of'),
    ({'mode': 3}, 'mode must be 1 or 2'),
    ({'independent_axis': 3}, 'independent_axis'),
    ({'output_period': 0.0}, 'output_period must be > 0'),
    ({'duration': -1.0}, 'duration must be >= 0'),
    ({'goal_clearance': math.nan}, 'goal_clearance'),
    ({'orientation': (0, 0, 0, 0)}, 'non-zero quaternion'),
    ({'orientation': (0, 0, 1)}, '4 finite numbers'),
    ({'gains': ObstacleGains(gamma=-1.0)}, 'gamma must be finite and >= 0'),
    ({'tool_radius': -0.001}, 'tool_radius must be >= 0'),
    ({'obstacle_clearance': math.inf}, 'obstacle_clearance must be >= 0'),
])
def test_settings_refuse_bad_values(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PlanSettings(**kwargs)


def test_demo_placed_between_start_and_goal(g_skill):
    placed = place_demo(g_skill, START + [0, 0, 0.1], GOAL, PLANE)
    np.testing.assert_allclose(placed[[0, -1]], [START, GOAL], atol=1e-12)
    plan = plan_path(g_skill, START, GOAL, plane=PLANE)
    assert nrmse(placed, plan.positions) < 0.005
    with pytest.raises(PlanningError, match='start equals goal'):
        place_demo(g_skill, GOAL, GOAL, PLANE)


def test_a_followed_plan_moves_its_goal_without_a_jump():
    # The remainder of a plan re-planned at 1.6 s for a goal 40 mm away: unchanged before the
    # switch, continuous in position and velocity through it, at the new goal at the end.
    plane = TaskPlane.create([0.75, 0.15, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0], 0.003)
    skill = learn(builtin_demo('G'))
    settings = PlanSettings(duration=4.0)
    start, goal = np.array([0.70, 0.20, 0.0]), np.array([0.838, 0.1, 0.0])
    plan = plan_path(skill, start, goal, (), settings, plane)
    followed = FollowedPlan(skill, plan, settings, plane)
    new_goal = goal + [0.04, 0.0, 0.0]
    k = followed.update(1.6, goal=new_goal)
    assert followed.t[k - 1] == pytest.approx(1.6)
    np.testing.assert_array_equal(followed.positions[:k], plan.positions[:k])
    dt = settings.output_period
    np.testing.assert_allclose(np.diff(followed.t), dt, atol=1e-9)
    speed_step = np.linalg.norm(followed.velocities[k] - followed.velocities[k - 1])
    typical = np.linalg.norm(np.diff(plan.velocities, axis=0), axis=1).max()
    assert speed_step <= typical, (speed_step, typical)   # no larger than the plan's own steps
    assert np.linalg.norm(followed.positions[-1] - new_goal) < 1e-3
    np.testing.assert_allclose(followed.goal, new_goal)
    # A second move continues from the first; a bad one changes nothing.
    k2 = followed.update(2.4, goal=new_goal + [0.0, 0.02, 0.0])
    assert k2 > k and np.linalg.norm(followed.positions[-1] - new_goal - [0, 0.02, 0]) < 1e-3
    before = followed.positions.copy()
    with pytest.raises(PlanningError, match='reach'):
        followed.update(2.6, goal=[5.0, 0.0, 0.0])
    with pytest.raises(PlanningError):
        followed.update(2.6, goal=[np.nan, 0.0, 0.0])
    np.testing.assert_array_equal(followed.positions, before)


# -- orientation ----------------------------------------------------------------------

@pytest.fixture(scope='module')
def stir_skill():
    return learn(builtin_demo('stir'))


@pytest.fixture(scope='module')
def wipe_skill():
    return learn(builtin_demo('wipe'))


def degrees(p, q):
    return np.degrees(quat.angle_between(np.asarray(p), np.asarray(q)))


def test_a_skill_with_orientations_gives_every_pose_its_own(stir_skill, wipe_skill):
    # 3D: the core's orientations, in base_link as they are.
    mouth = np.array([0.70, -0.30, 0.20])
    start, goal = mouth + [-0.06, 0.04, 0.14], mouth + stir_skill.goal
    plan = plan_path(stir_skill, start, goal)
    core = stir_skill.generalize(start, goal, dt=0.01)
    assert plan.orientation.shape == (len(plan.t), 4)
    np.testing.assert_allclose(plan.orientation, core.q, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(plan.orientation, axis=1), 1.0, atol=1e-12)
    np.testing.assert_array_equal(plan.orientations, plan.orientation)
    # 2D on a vertical whiteboard: the plane's orientations composed with the plane's frame.
    s, g = WALL.from_plane(wipe_skill.start + [3.0, -2.0]), WALL.from_plane(wipe_skill.goal)
    plan = plan_path(wipe_skill, s, g, plane=WALL)
    core = wipe_skill.generalize(WALL.to_plane(s), WALL.to_plane(g), dt=0.01)
    np.testing.assert_allclose(plan.orientation, WALL.orientation_from_plane(core.q),
                               atol=1e-12)
    # On the table plane (its frame is base_link's) a start where the demo starts reproduces the
    # demonstrated orientations (the demo's are TOOL_DOWN composed with the sponge's yaw).
    plan = plan_path(wipe_skill, PLANE.from_plane(wipe_skill.start),
                     PLANE.from_plane(wipe_skill.goal), plane=PLANE)
    demo_q = builtin_demo('wipe').orientations
    assert degrees(plan.orientation[0], demo_q[0]) < 0.1
    assert degrees(plan.orientation[-1], demo_q[-1]) < 0.1
    # orientation_mode 'tool', and position-only skills: the one tool orientation.
    tool = plan_path(wipe_skill, PLANE.from_plane(wipe_skill.start),
                     PLANE.from_plane(wipe_skill.goal), plane=PLANE,
                     settings=PlanSettings(orientation_mode='tool'))
    assert tool.orientation == pytest.approx(TOOL_DOWN)
    np.testing.assert_allclose(tool.orientations, np.tile(TOOL_DOWN, (len(tool.t), 1)))


def test_a_goal_orientation_is_reached_and_none_is_all_zeros(stir_skill, wipe_skill):
    mouth = np.array([0.70, -0.30, 0.20])
    start, goal = mouth + [-0.06, 0.04, 0.14], mouth + stir_skill.goal
    turned = quat.multiply(quat.about_axis([0.0, 1.0, 0.0], 0.4), TOOL_DOWN)
    plan = plan_path(stir_skill, start, goal, goal_orientation=turned)
    assert degrees(plan.orientation[-1], turned) <= 0.1
    free = plan_path(stir_skill, start, goal)
    assert degrees(plan.orientation[0], free.orientation[0]) < 1e-6   # starts as without
    # 2D: the goal orientation is given in base_link, reached in base_link.
    s, g = WALL.from_plane(wipe_skill.start + [3.0, -2.0]), WALL.from_plane(wipe_skill.goal)
    wall_goal = WALL.orientation_from_plane(quat.multiply(quat.about_axis([0, 0, 1], 1.0),
                                                          TOOL_DOWN))
    plan = plan_path(wipe_skill, s, g, plane=WALL, goal_orientation=-wall_goal)
    assert degrees(plan.orientation[-1], wall_goal) <= 0.1
    # All zeros and the message default (0, 0, 0, 1) mean "none".
    for none in ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), None):
        np.testing.assert_array_equal(
            plan_path(stir_skill, start, goal, goal_orientation=none).orientation,
            free.orientation)
    # ... and the identity itself is (0, 0, 0, -1).
    identity = plan_path(stir_skill, start, goal, goal_orientation=(0.0, 0.0, 0.0, -1.0))
    assert degrees(identity.orientation[-1], (0.0, 0.0, 0.0, 1.0)) <= 0.1


@pytest.mark.parametrize('value, message', [
    ((np.nan, 0.0, 0.0, 1.0), 'NaN or inf'),
    ((0.0, 0.0, 0.0, np.inf), 'NaN or inf'),
    ((0.0, 0.0, 0.5, 0.5), 'not a unit quaternion'),
    ((0.0, 0.0, 1.0), '4 numbers'),
    # Refused as "overflow encountered in dot" before.
    ((1e308, 1e308, 0.0, 1.0),
     r'goal orientation \(1e\+308, 1e\+308, 0.000, 1.000\) is not a unit quaternion \(norm '
     r'1.414e\+308\)'),
    ((1.7e308, 1.7e308, 0.0, 1.0), r'is not a unit quaternion \(norm inf\)'),
])
def test_bad_goal_orientations_are_refused_with_the_reason(stir_skill, value, message):
    mouth = np.array([0.70, -0.30, 0.20])
    with pytest.raises(PlanningError, match=message):
        plan_path(stir_skill, mouth + [-0.06, 0.04, 0.14], mouth, goal_orientation=value)


def test_huge_quaternions_are_normalised_without_overflow(stir_skill):
    # tool_orientation (1e308, 1e308, 0, 1): its norm overflowed to inf, and the "normalised"
    # orientation was (0, 0, 0, 0). Demonstrated orientations alike (they are normalised).
    with np.errstate(over='raise', invalid='raise', divide='raise'):
        settings = PlanSettings(orientation=(1e308, 1e308, 0.0, 1.0))
        np.testing.assert_allclose(settings.orientation, [math.sqrt(0.5), math.sqrt(0.5), 0, 0],
                                   atol=1e-15)
        q = unit_quaternions([[1e308, 0.0, 0.0, 1e308], [0.0, 0.0, 0.0, 2.0]], 2, 'x', str)
        camera = quat.normalized([1e308, 1e308, 0.0, 1.0])   # was refused: its norm was inf
    np.testing.assert_allclose(q, [[math.sqrt(0.5), 0, 0, math.sqrt(0.5)], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(camera, [math.sqrt(0.5), math.sqrt(0.5), 0, 0], atol=1e-15)
    with pytest.raises(ValueError, match='non-zero'):
        PlanSettings(orientation=(0.0, 0.0, 1e-300, 0.0))


def test_a_goal_orientation_needs_a_skill_with_orientations(g_skill, stir_skill):
    with pytest.raises(PlanningError, match='the skill has no orientations'):
        plan_path(g_skill, START, GOAL, plane=PLANE, goal_orientation=TOOL_DOWN)
    assert plan_path(g_skill, START, GOAL, plane=PLANE,
                     goal_orientation=(0, 0, 0, 0)).orientation == pytest.approx(TOOL_DOWN)
    mouth = np.array([0.70, -0.30, 0.20])
    with pytest.raises(PlanningError, match="orientation_mode is 'tool'"):
        plan_path(stir_skill, mouth + [-0.06, 0.04, 0.14], mouth, goal_orientation=TOOL_DOWN,
                  settings=PlanSettings(orientation_mode='tool'))
    with pytest.raises(ValueError, match='orientation_mode must be one of'):
        PlanSettings(orientation_mode='goal')


def test_a_followed_plan_keeps_the_orientation_of_the_same_phase(stir_skill):
    mouth = np.array([0.70, -0.30, 0.20])
    start, goal = mouth + [-0.06, 0.04, 0.14], mouth + stir_skill.goal
    settings = PlanSettings()
    plan = plan_path(stir_skill, start, goal, (), settings)
    followed = FollowedPlan(stir_skill, plan, settings)
    k = followed.update(2.0, goal=goal + [0.03, 0.0, 0.0])
    assert followed.orientation.shape == (len(followed.t), 4)
    np.testing.assert_array_equal(followed.orientation[:k], plan.orientation[:k])
    n = min(len(plan.t), len(followed.t))
    np.testing.assert_allclose(followed.t[k:n], plan.t[k:n], atol=1e-9)
    np.testing.assert_array_equal(followed.orientation[k:n], plan.orientation[k:n])
    np.testing.assert_array_equal(followed.orientation[n:],
                                  np.tile(plan.orientation[-1], (len(followed.t) - n, 1)))


def _stepped_reference(skill, plan, settings, plane, moves):
    """Return the path of FollowedPlan.update as the online run's step() and run() give it."""
    space_in = (lambda p: plane.to_plane(p)) if plane is not None else (lambda p: p)
    space_out = (lambda p: plane.from_plane(p)) if plane is not None else (lambda p: p)
    run = skill.online(space_in(plan.start), space_in(plan.goal), space_in(plan.obstacles),
                       dt=settings.output_period, tau=settings.duration or None)
    t, x = plan.t.copy(), plan.positions.copy()
    for t_switch, goal, obstacles in moves:
        k = int(round(t_switch / run.dt))
        run.run(t[k])
        x0, _, _ = run.step(goal=space_in(goal),
                            obstacles=None if obstacles is None else space_in(obstacles))
        after = run.copy()
        _, xs, _, _ = run.run(t[-1] + run.tau)
        x = np.concatenate([x[:k + 1], space_out(np.vstack([x0[None], xs]))])
        t = np.concatenate([t[:k + 1], after.t + run.dt * np.arange(len(xs) + 1)])
        run = after
    return t, x


@pytest.mark.parametrize('name', ['G', 'stir'])
def test_a_followed_plan_is_the_online_run_stepped_and_run(name):
    # update() takes the run's state at the switch from the samples the path holds and
    # integrates the step that takes the new input with the rest in one call: the same path
    # as the online run stepped to the switch, stepped with the new goal and run to the end.
    skill = learn(builtin_demo(name))
    settings = PlanSettings(duration=4.0)
    if name == 'G':
        plane = TaskPlane.create([0.75, 0.15, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0], 0.003)
        start, goal = np.array([0.70, 0.20, 0.0]), np.array([0.838, 0.1, 0.0])
        obstacles = np.array([[0.76, 0.16, 0.0]])
        shift = np.array([0.04, 0.0, 0.0])
    else:
        plane = None
        start, goal = np.array([0.55, 0.25, 0.30]), np.array([0.70, 0.10, 0.22])
        obstacles = np.zeros((0, 3))
        shift = np.array([0.0, 0.02, 0.0])
    plan = plan_path(skill, start, goal, obstacles, settings, plane)
    moves = [(1.6, goal + shift, None), (1.9, goal + 2 * shift, obstacles + shift / 4),
             (2.5, goal + shift, None)]
    followed = FollowedPlan(skill, plan, settings, plane)
    for t_switch, new_goal, new_obstacles in moves:
        followed.update(t_switch, goal=new_goal, obstacles=new_obstacles)
    t, x = _stepped_reference(skill, plan, settings, plane, moves)
    assert followed.t.shape == t.shape
    np.testing.assert_allclose(followed.t, t, atol=1e-12)
    size = float(np.max(np.linalg.norm(plan.positions - plan.goal, axis=1)))
    assert np.max(np.abs(followed.positions - x)) <= 1e-9 * size

"""dmp_server's ROS-free parts beside planning: latest inputs, checks of goals and plans."""

import threading
import time

from etdmp_ros.dmp import builtin_demo, learn
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.robot import UR10Model
from etdmp_ros.skills.inputs import Latest, LatestInputs
from etdmp_ros.skills.plan_checks import ArmChecks, check_goal, check_usable
from etdmp_ros.skills.planning import plan_path, PlanSettings, Workspace
import numpy as np
import pytest

PLANE = TaskPlane.create([0.75, 0.15, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02)
HOME = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])


@pytest.fixture(scope='module')
def model():
    return UR10Model(tool_offset=[0.0, 0.0, 0.16])


def test_a_latest_value_is_used_while_fresh():
    latest = Latest()
    assert latest.fresh(0.0) is None
    latest.update(3)
    assert latest.fresh(0.0) == 3 and latest.fresh(10.0) == 3
    time.sleep(0.02)
    assert latest.fresh(0.01) is None and latest.age() >= 0.02


def test_latest_inputs_say_why_a_value_is_missing(model):
    inputs = LatestInputs(model)
    with pytest.raises(ValueError, match=r'tool position is unknown \(/joint_states: none'):
        inputs.tool_position('joint_states', 0.5)
    with pytest.raises(ValueError, match=r'no perceived goal yet on /etdmp/bottle'):
        inputs.perceived_goal('bottle', 1.0, np.zeros(3))
    inputs.keep('joint_states', HOME)
    np.testing.assert_allclose(inputs.tool_position('joint_states', 0.5),
                               model.tool_position(HOME))
    np.testing.assert_array_equal(inputs.joints(0.5), HOME)
    inputs.keep('tool_pose', np.array([0.8, 0.1, 0.2]))
    np.testing.assert_array_equal(inputs.tool_position('tool_pose', 0.5), [0.8, 0.1, 0.2])
    inputs.keep('marker', np.array([0.8, 0.1, 0.0]))
    np.testing.assert_allclose(inputs.perceived_goal('marker', 1.0, np.array([0, 0, 0.01])),
                               [0.8, 0.1, 0.01])
    time.sleep(0.02)
    with pytest.raises(ValueError, match=r'perceived goal is 0\.0 s old \(goal_max_age 0\.01 s\)'):
        inputs.perceived_goal('marker', 0.01, np.zeros(3))
    with pytest.raises(ValueError, match=r'the latest is 0\.0 s old \(tool_state_max_age 0\.01'):
        inputs.tool_position('tool_pose', 0.01)


def test_latest_obstacles_take_their_volumes_then_the_static_ones(model):
    inputs = LatestInputs(model)
    static = np.array([[0.5, -0.3, 0.0]])
    points, radii, stale, unsized = inputs.obstacles_with_radii(1.0, static)
    np.testing.assert_array_equal(points, static)
    assert radii.tolist() == [0.0] and not stale and unsized == 0
    inputs.keep('obstacles', np.array([[0.8, 0.1, 0.08], [0.9, 0.0, 0.08]]))
    inputs.keep('volumes', (np.array([[0.81, 0.1, 0.08]]), np.array([0.025])))
    points, radii, stale, unsized = inputs.obstacles_with_radii(1.0, static)
    np.testing.assert_array_equal(points, [[0.8, 0.1, 0.08], [0.9, 0.0, 0.08], [0.5, -0.3, 0.0]])
    np.testing.assert_array_equal(radii, [0.025, 0.0, 0.0])
    assert not stale and unsized == 1
    time.sleep(0.02)
    points, radii, stale, unsized = inputs.obstacles_with_radii(0.01, static)
    np.testing.assert_array_equal(points, static)
    assert stale and unsized == 0


def test_a_plan_waits_for_the_first_volumes_of_its_perceived_obstacles(model):
    inputs = LatestInputs(model)
    static = np.zeros((0, 3))
    inputs.keep('obstacles', np.array([[0.8, 0.1, 0.08]]))
    # None come: the wait ends at its bound and the obstacle is unsized.
    start = time.monotonic()
    _, radii, _, unsized = inputs.obstacles_with_radii(1.0, static, wait_for_volumes=0.2)
    assert 0.2 <= time.monotonic() - start < 0.5 and unsized == 1 and radii.tolist() == [0.0]
    # They come from another thread (the executor's) meanwhile: the plan has them.
    timer = threading.Timer(0.1, inputs.keep, ('volumes', (np.array([[0.8, 0.1, 0.08]]),
                                                           np.array([0.03]))))
    timer.start()
    start = time.monotonic()
    _, radii, _, unsized = inputs.obstacles_with_radii(1.0, static, wait_for_volumes=2.0)
    assert 0.05 < time.monotonic() - start < 1.0 and unsized == 0 and radii.tolist() == [0.03]
    # Once volumes were received, nothing waits (an obstacle without one is a point).
    inputs.keep('obstacles', np.array([[0.5, 0.5, 0.08]]))
    start = time.monotonic()
    assert inputs.obstacles_with_radii(1.0, static, wait_for_volumes=2.0)[3] == 1
    assert time.monotonic() - start < 0.1


def test_goal_checks_reach_and_the_task_plane():
    skill = learn(builtin_demo('G'))
    check_goal(np.array([0.8, 0.1, 0.19]), skill, Workspace(), PLANE, 'G')    # within 0.2 m
    with pytest.raises(ValueError, match="out of the UR10's reach"):
        check_goal(np.array([2.0, 0.1, 0.0]), skill, Workspace(), PLANE, 'G')
    with pytest.raises(ValueError, match=r'0\.210 m from the task plane.*2D skill \'G\''):
        check_goal(np.array([0.8, 0.1, 0.21]), skill, Workspace(), PLANE, 'G')
    check_goal(np.array([0.8, 0.1, 0.21]), learn(builtin_demo('stir')), Workspace(), PLANE, 's')
    check_usable(builtin_demo('G'), PlanSettings())
    with pytest.raises(ValueError, match='less than two output periods'):
        check_usable(builtin_demo('G'), PlanSettings(output_period=10.0))


def test_arm_checks_refuse_a_plan_too_fast_and_say_the_duration(model):
    skill = learn(builtin_demo('G'))
    start, goal = np.array([0.80, 0.20, 0.0]), np.array([0.74, 0.15, 0.0])
    checks = ArmChecks(model)
    slow = PlanSettings(duration=4.0)
    q0 = np.array([0.2, -1.2, 1.9, -2.27, -1.57, 0.2])
    checks.check(plan_path(skill, start, goal, (), slow, PLANE), skill, q0, np.zeros((0, 3)),
                 np.zeros(0), slow)
    fast = PlanSettings(duration=0.2)
    with pytest.raises(ValueError, match=r'the shortest feasible duration is about [\d.]+ s '
                                         r'\(parameter duration, now 0\.2 s\)'):
        checks.check(plan_path(skill, start, goal, (), fast, PLANE), skill, q0,
                     np.zeros((0, 3)), np.zeros(0), fast)
    # Neither check asked for: nothing is computed, nothing refused.
    checks.check(plan_path(skill, start, goal, (), fast, PLANE), skill, q0, np.zeros((0, 3)),
                 np.zeros(0), fast, timing=False, arm_clearance=None)

"""The decision to follow a moved goal or obstacle (etdmp_ros.skills.following), without ROS."""

from etdmp_ros.dmp import builtin_demo, learn
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.skills.following import (FOLLOW_AFTER_END, FOLLOW_CONFIRMATIONS,
                                        FOLLOW_MATCH_RADIUS, FOLLOW_OVERLAP, FollowedPlan,
                                        Following, goal_moved, merged_obstacles, MovedInput,
                                        obstacles_moved, sized_obstacles)
from etdmp_ros.skills.planning import plan_path, PlanSettings
import numpy as np
import pytest

THRESHOLD = 0.005
PLANE = TaskPlane.create([0.75, 0.15, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02)
START, GOAL = np.array([0.80, 0.20, 0.0]), np.array([0.74, 0.15, 0.0])


def test_goal_moved_is_a_distance_beyond_the_threshold():
    g = np.array([0.8, 0.1, 0.0])
    assert goal_moved(None, g, THRESHOLD)
    assert not goal_moved(g, g + [0.0049, 0.0, 0.0], THRESHOLD)
    o = np.zeros(3)
    assert not goal_moved(o, [0.003, 0.004, 0.0], THRESHOLD)     # exactly 5 mm: not beyond
    assert goal_moved(o, [0.003, 0.004, 0.0001], THRESHOLD)
    assert goal_moved(g, g + [0.0, 0.0, 0.0051], THRESHOLD)


def test_obstacles_moved_compares_unordered_sets():
    a = np.array([[0.8, 0.1, 0.0], [0.9, 0.2, 0.0]])
    assert obstacles_moved(None, a, THRESHOLD)
    assert obstacles_moved(None, np.zeros((0, 3)), THRESHOLD)
    assert not obstacles_moved(np.zeros((0, 3)), [], THRESHOLD)
    assert not obstacles_moved(a, a[::-1] + [0.004, 0.0, 0.0], THRESHOLD)   # order, noise
    assert obstacles_moved(a, a[::-1] + [[0.0, 0.0, 0.0], [0.006, 0.0, 0.0]], THRESHOLD)
    assert obstacles_moved(a, a[:1], THRESHOLD)                              # one gone
    assert obstacles_moved(a[:1], a, THRESHOLD)                              # one appeared
    # Both seen near the same used one: the other used one has none within the threshold.
    assert obstacles_moved(a, [a[0], a[0] + [0.001, 0, 0]], THRESHOLD)


def test_a_move_is_taken_at_the_third_message_that_agrees():
    assert FOLLOW_CONFIRMATIONS == 3
    g0, g1 = np.array([0.8, 0.1, 0.0]), np.array([0.8, 0.14, 0.0])
    watch = MovedInput(goal_moved)
    assert [watch.see(g0 + [1e-4, 0, 0], g0, THRESHOLD) for _ in range(5)] == [False] * 5
    assert watch.count == 5          # noise within the threshold keeps the candidate
    # The first two messages at the new place are not enough; the third is.
    assert [watch.see(g1, g0, THRESHOLD) for _ in range(3)] == [False, False, True]
    assert watch.count == 3
    np.testing.assert_array_equal(watch.candidate, g1)
    # Once the plan follows it (it is what the plan uses), it is not taken again.
    assert not watch.see(g1, g1, THRESHOLD)


def test_a_frame_in_between_restarts_the_count():
    g0, g1 = np.array([0.8, 0.1, 0.0]), np.array([0.8, 0.14, 0.0])
    watch = MovedInput(goal_moved)
    seen = [g0] * 3 + [0.5 * (g0 + g1), g1, g1, g1, g1]
    taken = [watch.see(g, g0, THRESHOLD) for g in seen]
    assert taken == [False] * 3 + [False, False, False, True, True]
    # Two messages are enough when asked so; a noisy one beyond the threshold restarts.
    watch = MovedInput(goal_moved, confirmations=2)
    assert [watch.see(g, g0, THRESHOLD) for g in (g1, g1 + [0.006, 0, 0], g1)] == \
        [False, False, False]
    with pytest.raises(ValueError, match='confirmations must be >= 1'):
        MovedInput(goal_moved, confirmations=0)


def test_a_refused_value_is_not_tried_again_until_another_is_seen():
    g0, g1 = np.array([0.8, 0.1, 0.0]), np.array([0.8, 0.14, 0.0])
    watch = MovedInput(goal_moved)
    assert [watch.see(g1, g0, THRESHOLD) for _ in range(3)] == [False, False, True]
    watch.refuse()
    np.testing.assert_array_equal(watch.refused, g1)
    assert not any(watch.see(g1 + [0.002, 0, 0], g0, THRESHOLD) for _ in range(5))
    g2 = g1 + [0.0, 0.01, 0.0]
    assert [watch.see(g2, g0, THRESHOLD) for _ in range(3)] == [False, False, True]
    watch.clear_refusal()
    assert watch.refused is None and watch.see(g1 + [0.002, 0, 0], g0, THRESHOLD) is False


def test_merged_obstacles_update_the_used_ones_with_their_radii():
    used = np.array([[0.8, 0.1, 0.0], [0.9, 0.2, 0.0]])
    used_radii = np.array([0.02, 0.03])
    # The first moved 10 mm (and is seen 25 mm wide), the second is hidden, a third appeared.
    seen = np.array([[0.5, 0.5, 0.0], [0.81, 0.1, 0.0]])
    merged, radii = merged_obstacles(used, used_radii, seen, [0.01, 0.025], THRESHOLD)
    np.testing.assert_allclose(merged, [[0.81, 0.1, 0.0], [0.9, 0.2, 0.0], [0.5, 0.5, 0.0]])
    np.testing.assert_allclose(radii, [0.025, 0.03, 0.01])
    # Moved less than the threshold: kept where it was, with its radius.
    merged, radii = merged_obstacles(used, used_radii, used + [0.004, 0, 0], [0.05, 0.05],
                                     THRESHOLD)
    np.testing.assert_array_equal(merged, used)
    np.testing.assert_array_equal(radii, used_radii)
    # Seen twice near the first (20 and 30 mm away): the nearest is it, the other no new one.
    seen = used[:1] + [[0.03, 0, 0], [0.0, 0.02, 0.0]]
    merged, radii = merged_obstacles(used, used_radii, seen, [0.011, 0.012], THRESHOLD)
    np.testing.assert_allclose(merged, [[0.8, 0.12, 0.0], [0.9, 0.2, 0.0]])
    np.testing.assert_allclose(radii, [0.012, 0.03])
    # Beyond FOLLOW_MATCH_RADIUS it is another obstacle, not this one moved.
    far = used[:1] + [FOLLOW_MATCH_RADIUS + 0.001, 0.0, 0.0]
    merged, radii = merged_obstacles(used, used_radii, far, [0.02], THRESHOLD)
    np.testing.assert_allclose(merged, np.vstack([used, far]))
    np.testing.assert_allclose(radii, [0.02, 0.03, 0.02])


def test_merged_obstacles_with_none_used_or_none_seen():
    seen = np.array([[0.5, 0.5, 0.0], [0.6, 0.5, 0.0]])
    merged, radii = merged_obstacles(np.zeros((0, 3)), [], seen, [0.01, 0.02], THRESHOLD)
    np.testing.assert_array_equal(merged, seen)
    np.testing.assert_array_equal(radii, [0.01, 0.02])
    merged, radii = merged_obstacles(seen, [0.01, 0.02], np.zeros((0, 3)), [], THRESHOLD)
    np.testing.assert_array_equal(merged, seen)
    np.testing.assert_array_equal(radii, [0.01, 0.02])
    merged, radii = merged_obstacles([], [], [], [], THRESHOLD)
    assert merged.shape == (0, 3) and radii.shape == (0,)


def test_sized_obstacles_take_the_nearest_volume_within_the_match_radius():
    seen = np.array([[0.8, 0.1, 0.0], [0.9, 0.2, 0.0], [0.5, 0.5, 0.0]])
    tops = np.array([[0.9, 0.21, 0.0], [0.8, 0.13, 0.0], [0.8, 0.11, 0.0],
                     [0.5, 0.5 + FOLLOW_MATCH_RADIUS + 0.001, 0.0]])
    radii, sized = sized_obstacles(seen, tops, [0.03, 0.04, 0.02, 0.05])
    np.testing.assert_array_equal(radii, [0.02, 0.03, 0.0])
    np.testing.assert_array_equal(sized, [True, True, False])
    radii, sized = sized_obstacles(seen, None, None)
    np.testing.assert_array_equal(radii, [0.0, 0.0, 0.0])
    assert not sized.any()
    radii, sized = sized_obstacles(np.zeros((0, 3)), tops, [0.03, 0.04, 0.02, 0.05])
    assert radii.shape == (0,) and sized.shape == (0,)


@pytest.fixture(scope='module')
def followed():
    """Return a function making a fresh Following of a planned G (4 s) with one obstacle."""
    skill = learn(builtin_demo('G'))
    settings = PlanSettings(duration=4.0)
    plan = plan_path(skill, START, GOAL, [[0.9, 0.3, 0.0]], settings, PLANE,
                     obstacle_radii=[0.02])

    def make(perceived_goal=True):
        return Following(FollowedPlan(skill, plan, settings, PLANE), skill, 123, perceived_goal)
    return make


def test_following_takes_the_goal_as_the_plan_uses_it(followed):
    f = followed()
    assert f.stamp == 123 and f.skill.dim == 2
    np.testing.assert_array_equal(f.start, f.plan.positions[0])
    # 10 mm above the task plane: the same goal once projected, never followed.
    assert not any(f.goal_to_follow(GOAL + [0.0, 0.0, 0.01], THRESHOLD) is not None
                   for _ in range(5))
    moved = GOAL + [0.0, 0.02, 0.003]
    taken = [f.goal_to_follow(moved, THRESHOLD) for _ in range(3)]
    assert taken[0] is None and taken[1] is None
    np.testing.assert_array_equal(taken[2], moved)       # as perceived; the plan projects it
    np.testing.assert_allclose(f.goal.candidate, GOAL + [0.0, 0.02, 0.0])
    # A request that gave its goal does not follow the perceived one.
    fixed = followed(perceived_goal=False)
    assert all(fixed.goal_to_follow(moved, THRESHOLD) is None for _ in range(5))


def test_following_takes_moved_obstacles_with_their_radii(followed):
    f = followed()
    np.testing.assert_allclose(f.plan.obstacle_sizes, [0.02])
    same = [f.obstacles_to_follow([[0.902, 0.3, 0.0]], [0.02], THRESHOLD) for _ in range(4)]
    assert same == [None] * 4
    seen, seen_radii = [[0.92, 0.3, 0.0], [0.6, 0.4, 0.0]], [0.025, 0.01]
    taken = [f.obstacles_to_follow(seen, seen_radii, THRESHOLD) for _ in range(3)]
    assert taken[:2] == [None, None]
    obstacles, radii = taken[2]
    np.testing.assert_allclose(obstacles, seen)
    np.testing.assert_allclose(radii, seen_radii)
    # Refused: the same set is not tried again, the goal's refusal is cleared.
    f.refused(goal=False, obstacles=True)
    np.testing.assert_allclose(f.obstacles.refused, seen)
    assert f.goal.refused is None
    assert f.obstacles_to_follow(seen, seen_radii, THRESHOLD) is None


def test_following_estimates_the_controller_on_the_path(followed):
    f = followed()
    p = f.plan
    k = p.index(1.5)
    assert f.controller_path_time(None, 2.0) == 2.0 and f.tau_c == 0.0
    # The tool at the pose of 1.5 s: found when the search window holds it.
    assert f.controller_path_time(p.positions[k], 2.0) == pytest.approx(p.t[k])
    assert f.tau_c == pytest.approx(1.5)
    # The controller cannot be ahead of the time since the stamp, nor go back.
    assert f.controller_path_time(p.positions[p.index(3.0)], 2.5) == pytest.approx(2.5)
    lo, hi = p.index(2.5), p.index(3.0) + 1
    nearest = p.t[lo + np.argmin(np.linalg.norm(p.positions[lo:hi] - p.positions[0], axis=1))]
    assert f.controller_path_time(p.positions[0], 3.0) == pytest.approx(nearest)
    assert 2.5 <= f.tau_c <= 3.0
    assert f.controller_path_time(p.positions[0], 2.0) == 2.0      # window empty: tau_now
    assert f.remainder_start(1.5) == p.index(1.5 - FOLLOW_OVERLAP)
    assert f.remainder_start(0.05) == 0
    assert FOLLOW_OVERLAP == 0.1 and FOLLOW_AFTER_END == 1.0
    assert not f.ended(p.duration + FOLLOW_AFTER_END)
    assert f.ended(p.duration + FOLLOW_AFTER_END + 0.01)

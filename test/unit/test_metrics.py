"""The closed loop's measuring functions (etdmp_ros.demo.metrics), without ROS."""

import math

from etdmp_ros.demo.metrics import (compute_metrics, contact_figures, cylinder_gap,
                                    executed_plan, fit_tracking_start, FOLLOW_CONFIRMATIONS,
                                    goal_seen_after_move, move_reference_nrmse, Run, switch_index,
                                    switch_speeds, system_figures)
from etdmp_ros.demo.scenario import Scenario
from etdmp_ros.geometry.task_plane import quadrant
from etdmp_ros.ros.events import Event, WALL_CLOCK
from etdmp_ros.skills import following
import numpy as np
import pytest


def test_cylinder_gap_is_the_distance_to_the_cylinder_surface():
    top = [[1.0, 0.0, 0.08]]            # a cylinder of radius 0.025 standing on the table
    points = [[1.1, 0.0, 0.0], [1.0, 0.0, 0.18], [1.0, 0.0, 0.05], [1.1, 0.0, 0.18],
              [1.01, 0.0, 0.079]]
    gap = cylinder_gap(points, top, 0.025)
    np.testing.assert_allclose(gap, [0.075, 0.1, -0.025, math.hypot(0.075, 0.1), -0.001],
                               atol=1e-12)
    assert cylinder_gap(points, np.zeros((0, 3)), 0.025)[0] == math.inf


def test_cylinder_gap_takes_a_radius_per_obstacle():
    tops = [[1.0, 0.0, 0.08], [0.5, 0.0, 0.08]]
    gap = cylinder_gap([[1.1, 0.0, 0.0], [0.6, 0.0, 0.0]], tops, [0.025, 0.06])
    np.testing.assert_allclose(gap, [0.075, 0.04], atol=1e-12)   # each to its nearest


def test_contacts_are_counted_from_the_ground_truth():
    # The simulation publishes its contacts at every tick while there are any, and once empty.
    rec = {'contacts': [(0, []), (8, [('wrist_2_link', 'obstacle_1', 0.003)]),
                        (16, [('wrist_2_link', 'obstacle_1', 0.004), ('tool', 'bottle', 0.001)]),
                        (24, [])]}
    figures = contact_figures(rec)
    assert figures == {'contacts': 2, 'contact_pairs': ['tool/bottle', 'wrist_2_link/obstacle_1'],
                       'contact_max_depth_mm': pytest.approx(4.0)}
    assert contact_figures({'contacts': [(0, [])]}) == {
        'contacts': 0, 'contact_pairs': [], 'contact_max_depth_mm': 0.0}
    # Not recorded at all: unknown, not zero.
    assert contact_figures({'contacts': []})['contacts'] is None
    assert contact_figures({})['contacts'] is None


def test_tracking_start_is_found_from_the_reference():
    t = np.arange(0.0, 3.0, 0.01)
    plan = np.stack([0.1 * np.sin(2 * t), 0.1 * np.cos(3 * t), 0 * t], axis=1)
    t0 = 12.34567
    stamps = np.arange(10.0, 16.0, 0.008)
    tau = np.clip(stamps - t0, 0.0, t[-1])
    reference = np.column_stack([stamps * 1e9] + [np.interp(tau, t, plan[:, i])
                                                  for i in range(3)])
    assert fit_tracking_start(reference, t, plan, t0 + 0.02) == pytest.approx(t0, abs=2e-4)


def test_quadrants():
    assert [quadrant(v) for v in ([1, 1], [-1, 1], [-1, -1], [1, -1])] == \
        ['I', 'II', 'III', 'IV']


def test_command_rate_is_taken_while_the_arm_moves():
    period = 8_000_000                                   # ns, 125 Hz
    call = 1_000_000_000
    t = call + period * np.arange(-50, 1200)             # commands from before the call on
    commands = np.zeros((len(t), 6))
    first = 110                                          # 0.48 s after the call: planning
    commands[first:first + 1000, 0] = 0.1                # 8 s of motion, then zeros
    rec = {'command_time': t, 'commands': commands, 'command_wall_time': t * 1e-9}
    end = int(t[first + 1060])
    figures = system_figures(_NoMonitor(), rec, call, end)
    assert figures['moving_commands_per_s'] == pytest.approx(125.0)
    assert figures['first_moving_command_after_call_s'] == pytest.approx(0.48)
    commands[first + 400:first + 425, 0] = 0.0          # a 0.2 s halt in the middle
    figures = system_figures(_NoMonitor(), rec, call, end)
    assert figures['moving_commands_per_s'] == pytest.approx(974 / (999 * 0.008))


def _event(wall_ns, node, kind, **values):
    """Return an event as read back from a recording (values as published: text)."""
    return Event(node, kind, 0, '', 0, {**values, WALL_CLOCK: str(wall_ns)})


class _NoMonitor:

    def window(self, start, end):
        return None


# ------------------------------------------------------------------ a goal that moves


PERIOD = 0.01


def _smooth(a, b, t, duration):
    """Return a minimum-jerk line from a to b over ``duration`` at ``t`` (n, 3)."""
    s = np.clip(np.asarray(t, dtype=float) / duration, 0.0, 1.0)[:, None]
    return a + (b - a) * (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5)


def _moved_plan(switch=2.0, duration=6.0):
    """Return (t, original, executed): the executed one heads for a goal 4 cm away from switch."""
    t = np.round(np.arange(0.0, duration + PERIOD / 2, PERIOD), 9)
    start, g0, g1 = np.array([0.75, 0.2, 0.0]), np.array([0.85, 0.1, 0.0]), \
        np.array([0.85, 0.14, 0.0])
    original = _smooth(start, g0, t, duration)
    shift = _smooth(np.zeros(3), g1 - g0, t - switch, duration - switch)
    return t, original, original + np.where(t[:, None] >= switch, shift, 0.0)


def _path_row(stamp, t, x, receipt_ns=0):
    return (receipt_ns, receipt_ns, stamp, stamp + np.round(t * 1e9).astype(np.int64), x)


def test_executed_plan_lays_each_remainder_over_the_plan():
    t, original, executed = _moved_plan()
    stamp = 5_000_000_000
    later = t >= 1.9      # the remainder published starts a little before the switch
    paths = [_path_row(stamp, t, original),                       # the plan itself
             _path_row(stamp + 7, t, original + 1.0),             # another plan: ignored
             _path_row(stamp, t[later], executed[later])]
    got_t, got_x, updates = executed_plan(t, original, stamp, paths)
    np.testing.assert_allclose(got_t, t, atol=1e-9)
    np.testing.assert_allclose(got_x, executed, atol=1e-15)
    assert updates == 1
    first = switch_index(original, got_x)
    assert got_t[first] == pytest.approx(2.0 + PERIOD)   # the shift starts from zero at 2.0 s
    assert switch_index(original, original) is None
    assert executed_plan(t, original, stamp, paths[:2])[2] == 0


def _tip_following(t0, plan_t, plan_x, stamps):
    tau = np.clip(stamps - t0, 0.0, plan_t[-1])
    return np.stack([np.interp(tau, plan_t, plan_x[:, i]) for i in range(3)], axis=1)


def test_switch_speed_ratio_sees_a_stop_and_go():
    t, _, executed = _moved_plan()
    t0 = 3.0
    stamps = np.arange(2.0, 11.0, 0.008)
    tip = _tip_following(t0, t, executed, stamps)
    figures = switch_speeds(stamps, tip, t0, t, executed, 2.0, t_from=1.9)
    assert figures['switch_speed_ratio_min'] == pytest.approx(1.0, abs=0.02)
    assert figures['switch_window_s'] == pytest.approx([1.9, 2.5])
    assert figures['switch_speed_samples'] >= 70
    assert 0.2 < figures['switch_tool_speed_min_fraction'] <= 1.02
    # The tool stops for 0.15 s after the switch (an approach again), then catches up.
    halt = (stamps - t0 >= 2.1) & (stamps - t0 < 2.25)
    stopped = tip.copy()
    stopped[halt] = tip[np.flatnonzero(halt)[0]]
    low = switch_speeds(stamps, stopped, t0, t, executed, 2.0, t_from=1.9)
    assert low['switch_speed_ratio_min'] < 0.05
    assert low['switch_tool_speed_min_fraction'] < 0.05


def test_switch_speed_ratio_leaves_out_a_plan_that_slows_itself():
    # The plan comes to rest 0.2 s after the switch: the tool does too, and that is no fault.
    t = np.round(np.arange(0.0, 3.0 + PERIOD / 2, PERIOD), 9)
    plan = _smooth(np.zeros(3), np.array([0.1, 0.0, 0.0]), t, 2.2)
    stamps = np.arange(0.0, 5.0, 0.008)
    tip = _tip_following(1.0, t, plan, stamps)
    figures = switch_speeds(stamps, tip, 1.0, t, plan, 1.6)
    assert figures['switch_speed_ratio_min'] > 0.9
    assert figures['switch_speed_samples'] < 62        # the samples of the plan at rest left out
    assert switch_speeds(stamps, tip, 1.0, t, plan, 2.5)['switch_speed_ratio_min'] is None


def _seen_rows(points, start_ns=1_000_000_000, period_ns=33_000_000):
    rows = [(start_ns + k * period_ns, 1e18 + k * period_ns, start_ns + k * period_ns - 2e7,
             *p) for k, p in enumerate(points)]
    return np.array(rows, dtype=float)


def test_goal_seen_after_move_confirms_as_dmp_server_does():
    scene = Scenario(None, 'G')
    g0, g1 = np.array([0.84, 0.10, 0.002]), np.array([0.84, 0.14, 0.002])
    placed = scene.plane.from_plane(scene.plane.to_plane(g0))
    seen = _seen_rows([g0 + [1e-4, 0, 0]] * 5 + [g1] * 5)
    assert goal_seen_after_move(scene, seen, placed, 0, 0.005) == (5, 7)
    # A frame in between (the marker seen half way) restarts the count.
    seen = _seen_rows([g0] * 5 + [0.5 * (g0 + g1), g1, g1, g1, g1])
    assert goal_seen_after_move(scene, seen, placed, 0, 0.005) == (5, 8)
    assert goal_seen_after_move(scene, _seen_rows([g0] * 6), placed, 0, 0.005) == (None, None)
    assert FOLLOW_CONFIRMATIONS == following.FOLLOW_CONFIRMATIONS


def _moved_run(follow=True, **followed):
    """
    Return a synthetic run of G whose marker moved 40 mm at 1.5 s of path time.

    ``followed``: more values of dmp_server's ``followed`` event.
    """
    scene = Scenario(None, 'G')
    t, original, moved = _moved_plan()
    executed = moved if follow else original
    stamp = call = 1_000_000_000
    t0 = 2.0
    stamps = np.round(np.arange(0.5, 10.0, 0.008), 6)
    tip = _tip_following(t0, t, executed, stamps)
    ref = (stamps >= t0) & (stamps <= t0 + t[-1])
    move_ns = int((t0 + 1.5) * 1e9)
    wall0 = 1_700_000_000_000_000_000           # the nodes' and the recorder's clock (ns)

    def wall(sim_s):
        return wall0 + int(round(sim_s * 1e9))

    g0, g1 = original[-1], moved[-1]
    seen_t = np.arange(1.0, 9.0, 1 / 30)
    seen = np.array([(s * 1e9, wall(s), s * 1e9 - 2e7, *(g1 if s > 3.55 else g0))
                     for s in seen_t])
    confirming = seen[np.flatnonzero(seen[:, 4] == g1[1])[2]]       # the 3rd new one
    paths = [_path_row(stamp, t, original, wall(1.0))]
    events = []
    if follow:
        later = t >= 1.9
        published = confirming[1] + 4e6
        paths.append((int(3.68e9), published, stamp,
                      stamp + np.round(t[later] * 1e9).astype(np.int64), executed[later]))
        events = [_event(int(published + 1e5), 'dmp_server', 'followed', goal='0.85 0.14 0.0',
                         from_path_time_s='2.0', controller_path_time_s='1.8',
                         poses=str(later.sum()), end_s='6.0', took_ms='4.1', update='1',
                         **followed),
                  _event(int(published + 6e6), 'controller', 'path_accepted',
                         poses=str(later.sum()), continued='false',
                         duration_s=str(t[later][-1] - t[later][0]))]
    rec = {'tip': np.column_stack([stamps * 1e9, tip]),
           'reference': np.column_stack([stamps[ref] * 1e9, tip[ref]]),
           'commands': np.zeros((len(stamps), 6)), 'command_time': stamps * 1e9,
           'command_wall_time': np.array([wall(s) for s in stamps]) * 1e-9,
           'status': [], 'paths': paths, 'goal_seen': seen, 'events': events}
    status = [(int(1.1e9), 'approaching'), (int(t0 * 1e9), 'tracking'),
              (int((t0 + 6) * 1e9), 'holding'), (int((t0 + 6.5) * 1e9), 'idle')]
    marker0, marker1 = np.array([*g0[:2], 0.002]), np.array([*g1[:2], 0.002])
    return Run(scene, 'etdmp', original[0], original[-1], (t, original, None),
               ('dmp', None, 'refused'), rec, status, call, stamp, int((t0 + 6.5) * 1e9),
               marker0, marker0, np.zeros((0, 3)), np.zeros((0, 3)),
               goal_move=(move_ns, marker0, marker1))


def test_a_moved_goal_is_measured_against_the_new_marker_and_the_executed_plan():
    run = _moved_run()
    m, extra = compute_metrics(run)
    assert m['goal_moved_by_mm'] == pytest.approx(40.0)
    assert m['goal_error_mm'] < 1e-6                  # the pen ended on the moved marker
    assert m['goal_error_vs_first_marker_mm'] == pytest.approx(40.0, abs=1e-6)
    assert m['approach_duration_s'] == pytest.approx(1.0, abs=2e-4)   # fitted on the executed
    assert m['tracking_max_mm'] < 1e-3
    assert m['plan_updates'] == 1 and extra['switch'] is not None
    assert m['switch_path_time_s'] == pytest.approx(2.01)
    assert m['switch_time_s'] == pytest.approx(1.0 + 2.01, abs=2e-4)
    assert m['switch_speed_ratio_min'] == pytest.approx(1.0, abs=0.03)
    assert m['nrmse_original_plan'] != m['nrmse_plan']
    assert 0.0 < m['nrmse_trace_own_end'] < m['nrmse_trace'] + 0.1
    # The move's own cost (the core's online ET-DMP at the same switch): a 4 cm move at a third
    # of the G costs shape however well it is followed.
    assert m['nrmse_move_reference'] > 0.1
    np.testing.assert_allclose(extra['executed'][1][-1], m['executed_plan_end'])
    follow = m['goal_follow']
    assert follow['goal_moved_at_path_time_s'] == pytest.approx(1.5, abs=2e-4)
    assert follow['dmp_server_ms'] == 4.1
    assert follow['dmp_server_recorded_ms'] == pytest.approx(4.0, abs=1e-3)
    assert follow['controller_accept_ms'] == pytest.approx(6.0, abs=1e-3)
    # From dmp_server's own time of publication when its event says it: the recorder may
    # receive the path after the controller accepted it.
    received = int(run.rec['paths'][1][1])       # the path's receipt here
    late = compute_metrics(_moved_run(published_wall_ns=str(received - 2_000_000)))[0]
    assert late['goal_follow']['controller_accept_ms'] == pytest.approx(8.0, abs=1e-3)
    # The first command after the controller's 'new path' line: the 8 ms grid of commands.
    assert 6.0 < follow['controller_first_command_ms'] <= 14.0 + 1e-6
    assert follow['end_to_end_ms'] == pytest.approx(
        follow['controller_first_command_ms'] + 4.1 - 0.1, abs=1e-3)
    assert follow['perception_latency_s'] == pytest.approx(3.5667 - 3.5, abs=1e-3)
    assert follow['confirmation_wait_ms'] == pytest.approx(2000 / 30, abs=1e-3)
    assert 'goal_follow' in m['definitions']


def test_a_moved_goal_received_late_by_the_recorder_keeps_the_chain():
    # A fresh clone: the recorder got the moved bottle 0.4 s late (batched), after the
    # controller had accepted the re-planned path; measured from that receipt, the chain found
    # no acceptance and every latency after dmp_server read None.
    on_time = compute_metrics(_moved_run())[0]['goal_follow']
    run = _moved_run()
    seen = run.rec['goal_seen']
    seen[seen[:, 0] > 3.55e9, 1] += 4e8
    follow = compute_metrics(run)[0]['goal_follow']
    assert follow['controller_accept_ms'] == pytest.approx(on_time['controller_accept_ms'])
    assert follow['controller_first_command_ms'] == on_time['controller_first_command_ms']
    # From dmp_server's own account of when it had the message (4.1 ms before its event).
    assert follow['end_to_end_ms'] == pytest.approx(
        follow['controller_first_command_ms'] + 4.1 - 0.1, abs=1e-3)
    assert follow['confirmation_wait_ms'] == pytest.approx(on_time['confirmation_wait_ms'])


def test_a_moved_goal_not_followed_fails_the_checks():
    m, _ = compute_metrics(_moved_run(follow=False))
    assert m['goal_error_mm'] == pytest.approx(40.0, abs=1e-6)
    # The nRMSE places the demonstration at the moved marker, where the trace did not go.
    assert m['nrmse_trace'] > m['nrmse_trace_own_end'] + 0.05
    assert m['plan_updates'] == 0 and m['switch_path_time_s'] is None
    assert m['nrmse_move_reference'] is None
    assert m['switch_speed_ratio_min'] is None
    assert m['goal_follow']['dmp_server_ms'] is None and m['goal_follow']['end_to_end_ms'] is None


def test_a_run_without_a_move_keeps_its_keys():
    run = _moved_run(follow=False)
    run.goal_move = None
    m, extra = compute_metrics(run)
    assert 'goal_moved_by_mm' not in m and 'goal_follow' not in m and 'switch' not in extra
    assert m['goal_error_mm'] < 1e-6                  # the marker as it was: the plan's end


def test_the_move_reference_is_online_etdmp_s_own_cost_of_the_move():
    """The core's online ET-DMP: a move at the start costs little, later ones more."""
    scene = Scenario(config_dir=None, skill='G')
    start, goal = np.array([0.775, 0.164, 0.0]), np.array([0.8385, 0.0997, 0.0])
    moved = goal + [0.0, 0.04, 0.0]
    costs = [move_reference_nrmse(scene, start, goal, moved, t, 4.0) for t in (0.0, 1.0, 1.8, 3.0)]
    assert costs[0] < 0.02 and np.all(np.diff(costs) > 0.0), costs
    # The demo's move (4 cm at ~45 % of the G): ~0.36 with no obstacle at all.
    assert 0.3 < costs[2] < 0.45, costs
    assert move_reference_nrmse(scene, start, goal, goal, 1.8, 4.0) < 0.01    # no move

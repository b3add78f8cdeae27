"""
A goal that moved while the pen wrote: the switch of plans, its speed, the follow latencies.

Definitions: :data:`._definitions.MOVE_DEFINITIONS`. The latencies come from the recording
alone: /etdmp/goal, /etdmp/path, the commands' receipt times and the nodes' events
(dmp_server's ``followed``, the controller's ``path_accepted``).
"""

import math

from etdmp_ros.demo.metrics._clearance import clearance_mm, obstacle_radii
from etdmp_ros.demo.metrics._definitions import SLOW_PLAN, SWITCH_WINDOW
from etdmp_ros.demo.metrics._trace import nrmse_over_tau
from etdmp_ros.dmp import learn
from etdmp_ros.ros import events as ev
from etdmp_ros.skills.following import FOLLOW_CONFIRMATIONS, FollowedPlan, goal_moved, MovedInput
from etdmp_ros.skills.planning import plan_path, PlanSettings
import numpy as np


def path_speed(t, x):
    """Return the speed (n,) of a sampled path (central differences)."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    if len(t) < 2:
        return np.zeros(len(t))
    return np.linalg.norm(np.gradient(x, t, axis=0), axis=1)


def switch_speeds(tip_t, tip_x, t0, plan_t, plan_x, t_switch, t_from=None,
                  window=SWITCH_WINDOW, slow=SLOW_PLAN):
    """
    Return the speed figures around a switch of plans (``switch_speed``).

    ``tip_t`` (s, simulated), ``tip_x``: the true pen tip; ``t0``: when path time 0 was;
    ``plan_t``, ``plan_x``: the executed plan; ``t_switch``: path time of the switch;
    ``t_from``: path time from which the window starts when earlier than the switch (the new
    path's publication). Return {'switch_speed_ratio_min', 'switch_tool_speed_min_fraction',
    'switch_plan_speed_m_s', 'switch_window_s', 'switch_speed_samples'}; the two minima are
    None when no sample is left.
    """
    tip_t, tip_x = np.asarray(tip_t, dtype=float), np.asarray(tip_x, dtype=float)
    start = t_switch if t_from is None else min(t_from, t_switch)
    plan_v = path_speed(plan_t, plan_x)
    v_switch = float(np.interp(t_switch, plan_t, plan_v))
    mid = 0.5 * (tip_t[1:] + tip_t[:-1]) - t0
    dt = np.diff(tip_t)
    v_tip = np.linalg.norm(np.diff(tip_x, axis=0), axis=1) / np.where(dt > 0, dt, np.inf)
    inside = (mid >= start) & (mid <= t_switch + window) & (dt > 0)
    v_plan = np.interp(mid[inside], plan_t, plan_v)
    kept = v_plan >= slow * v_switch
    if kept.any() and v_switch > 0.0:
        ratio = float(np.min(v_tip[inside][kept] / v_plan[kept]))
        fraction = float(np.min(v_tip[inside][kept]) / v_switch)
    else:
        ratio = fraction = None
    return {'switch_speed_ratio_min': ratio, 'switch_tool_speed_min_fraction': fraction,
            'switch_plan_speed_m_s': v_switch, 'switch_window_s': [float(start),
                                                                   float(t_switch + window)],
            'switch_speed_samples': int(kept.sum())}


def _placed(scene, points):
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    return scene.plane.from_plane(scene.plane.to_plane(points)) if scene.planar else points


def goal_seen_after_move(scene, goal_seen, plan_goal, since_ns, threshold,
                         confirmations=FOLLOW_CONFIRMATIONS):
    """
    Return the indices (first showing, confirming) of the /etdmp/goal rows that saw a move.

    ``goal_seen``: ``read_streams``'s rows (simulated ns at receipt, receipt ns, stamp ns, x, y,
    z), from ``since_ns`` (simulated) on; as dmp_server takes them: placed (projected onto the
    task plane), a candidate restarted by any message more than ``threshold`` from the previous
    one, confirmed when ``confirmations`` agree and lie more than ``threshold`` from
    ``plan_goal``. None for what did not happen.
    """
    rows = np.flatnonzero(goal_seen[:, 0] >= since_ns) if len(goal_seen) else []
    placed = _placed(scene, goal_seen[:, 3:6]) if len(goal_seen) else np.zeros((0, 3))
    first = None
    decision = MovedInput(goal_moved, confirmations)    # dmp_server's own (Following)
    for i in rows:
        if first is None and goal_moved(plan_goal, placed[i], threshold):
            first = int(i)
        if decision.see(placed[i], plan_goal, threshold):
            return first, int(i)
    return first, None


def perceived_goal_rows(run):
    """
    Return the perceived goal as dmp_server took it: /etdmp/goal's rows (``read_streams``).

    Stir with the perceived bottle: /etdmp/bottle's rows plus the skill's goal offset.
    """
    rec, scene = run.rec, run.scene
    if not getattr(scene, 'perceived_bottle', False):
        return rec.get('goal_seen', np.zeros((0, 6)))
    rows = np.array(rec.get('bottle_seen', np.zeros((0, 6))), dtype=float).reshape(-1, 6)
    rows[:, 3:6] += scene.goal_offset
    return rows


def follow_latencies(run, ex, t0):
    """
    Return the latencies of the first re-plan after the goal moved (``goal_follow``).

    Read from the recording alone: /etdmp/goal, /etdmp/path, the commands' receipt times and
    the nodes' events (dmp_server's ``followed`` of a moved goal, the controller's
    ``path_accepted``). A figure is None when its event is missing.
    """
    move_ns = int(run.goal_move[0])
    threshold = float(run.scene.server.get('follow_threshold', 0.005))
    seen = perceived_goal_rows(run)
    first, confirming = goal_seen_after_move(run.scene, seen, run.plan[1][-1], run.call_ns,
                                             threshold)
    out = dict.fromkeys((
        'perception_latency_s', 'perception_image_delay_s', 'confirmation_wait_ms',
        'dmp_server_ms', 'dmp_server_recorded_ms', 'controller_accept_ms',
        'controller_first_command_ms', 'end_to_end_ms', 'goal_change_to_first_command_s',
        'replanned_from_path_time_s', 'controller_path_time_estimate_s'))
    out['goal_moved_at_path_time_s'] = float(move_ns * 1e-9 - t0)
    out['updates'] = ex.updates
    if first is not None:
        out['perception_latency_s'] = float((seen[first, 0] - move_ns) * 1e-9)
        out['perception_image_delay_s'] = float((seen[first, 2] - move_ns) * 1e-9)
    if confirming is not None and first is not None:
        out['confirmation_wait_ms'] = float((seen[confirming, 1] - seen[first, 1]) * 1e-6)
    recorded = run.rec.get('events', [])
    after = seen[first, 1] - 1e9 if first is not None else -math.inf
    followed = [e for e in ev.of_kind(recorded, 'dmp_server', 'followed')
                if e.wall_ns > after and len(e.numbers('goal'))]
    if followed:
        out.update(_follow_chain(run, followed[0], seen[confirming, 1]
                                 if confirming is not None else None, move_ns))
    return out


def _follow_chain(run, followed, confirmed_ns, move_ns):
    """
    Return the latencies from dmp_server's ``followed`` event to the first command after it.

    ``confirmed_ns``: when the confirming /etdmp/goal was received here (None: not seen).
    """
    rec = run.rec
    took_ms, poses = followed.number('took_ms'), followed.integer('poses')
    # When dmp_server had the confirming message: its receipt here, or its own account if that
    # is earlier (this recorder once received the bottle 0.4 s late, batched, after the
    # controller had accepted the re-planned path: the chain then found no acceptance).
    own_ns = followed.wall_ns - took_ms * 1e6
    server_seen_ns = own_ns if confirmed_ns is None else min(confirmed_ns, own_ns)
    out = {'dmp_server_ms': took_ms,
           'replanned_from_path_time_s': followed.number('from_path_time_s'),
           'controller_path_time_estimate_s': followed.number('controller_path_time_s')}
    path = next((p for p in rec.get('paths', []) if int(p[2]) == int(run.plan_stamp_ns)
                 and len(p[3]) == poses and p[1] >= server_seen_ns - 1e9), None)
    if path is not None and confirmed_ns is not None:
        out['dmp_server_recorded_ms'] = float((path[1] - confirmed_ns) * 1e-6)
    accepted = [e for e in ev.of_kind(rec.get('events', []), 'controller', 'path_accepted')
                if e.wall_ns > server_seen_ns and e.integer('poses') == poses]
    if not accepted:
        return out
    accepted_ns = accepted[0].wall_ns
    wall = rec['command_wall_time'] * 1e9
    later = np.flatnonzero(wall > accepted_ns)
    # From dmp_server's publication (its event says when; one clock): the path's receipt
    # here is later than the controller's on a busy machine (accepted "-0.4 ms" after it).
    published_ns = followed.integer('published_wall_ns')
    if published_ns is None and path is not None:       # a recording from before
        published_ns = path[1]
    if published_ns is not None:
        out['controller_accept_ms'] = float((accepted_ns - published_ns) * 1e-6)
    if len(later):
        command_ns = wall[later[0]]
        out['end_to_end_ms'] = float((command_ns - server_seen_ns) * 1e-6)
        out['goal_change_to_first_command_s'] = float(
            (rec['command_time'][later[0]] - move_ns) * 1e-9)
        if published_ns is not None:
            out['controller_first_command_ms'] = float((command_ns - published_ns) * 1e-6)
    return out


def goal_move_figures(run, tr, ex):
    """Return the figures of a run whose goal marker moved (MOVE_DEFINITIONS)."""
    scene = run.scene
    _, before, after = run.goal_move
    radius = obstacle_radii(run)
    first_goal = _placed(scene, before)[0] if scene.planar else run.goal
    figures = {
        'moved_object': 'bottle' if getattr(scene, 'perceived_bottle', False) else 'goal marker',
        'goal_moved_by_mm': float(np.linalg.norm(np.asarray(after) - before) * 1e3),
        'goal_marker_before': np.asarray(before, dtype=float).tolist(),
        'goal_marker_after': np.asarray(after, dtype=float).tolist(),
        'goal_error_vs_first_marker_mm': float(np.linalg.norm(tr.final - first_goal) * 1e3),
        'nrmse_original_plan': nrmse_over_tau(run.plan[1], tr.tau, run.plan[0], scene),
        'nrmse_trace_own_end': nrmse_over_tau(tr.tip_x[tr.in_plan], tr.tau,
                                              tr.span[tr.in_plan], scene),
        'min_clearance_original_plan_mm': clearance_mm(run.plan[1], run.obstacles_truth,
                                                       radius),
        'original_plan_duration_s': float(run.plan[0][-1]),
        'executed_plan_end': ex.x[-1].tolist(),
        'plan_updates': ex.updates,
        'switch_path_time_s': None, 'switch_time_s': None, 'switch_point': None,
        'switch_speed_ratio_min': None, 'switch_tool_speed_min_fraction': None,
        'nrmse_move_reference': None,
    }
    seen = perceived_goal_rows(run)
    if len(seen):
        figures['perceived_goal_final'] = seen[-1, 3:6].tolist()
        figures['perceived_goal_final_error_mm'] = float(
            np.linalg.norm(seen[-1, 3:6] - after) * 1e3)
    if ex.switch is not None:
        t_switch = float(ex.t[ex.switch])
        published = [p[0] * 1e-9 - tr.t0 for p in run.rec.get('paths', [])
                     if int(p[2]) == int(run.plan_stamp_ns) and p[0] * 1e-9 - tr.t0 > 0.0]
        figures.update(switch_path_time_s=t_switch,
                       switch_time_s=float(tr.t0 + t_switch - run.call_ns * 1e-9),
                       switch_point=ex.x[ex.switch].tolist())
        figures.update(switch_speeds(tr.tip_t, tr.tip_x, tr.t0, ex.t, ex.x, t_switch,
                                     min(published) if published else None))
        figures['nrmse_move_reference'] = move_reference_nrmse(
            scene, ex.x[0], run.plan[1][-1], tr.goal, t_switch, tr.tau)
    figures['goal_follow'] = follow_latencies(run, ex, tr.t0)
    return figures


def move_reference_nrmse(scene, start, goal, moved_goal, t_switch, tau):
    """
    Return the nRMSE of the core's online ET-DMP for a goal moved at ``t_switch`` (no obstacles).

    The skill (learned from ``scene.demo`` as dmp_server learns it) is planned from ``start`` to
    ``goal`` in ``tau`` and followed (:class:`FollowedPlan`) with the goal moved to
    ``moved_goal`` from path time ``t_switch`` on; measured as ``nrmse_trace`` is, against the
    demonstration placed at ``moved_goal``. What the move costs by itself, without the system.
    """
    server = scene.server
    skill = learn(scene.demo, n_basis=int(server['n_basis']), formulation=server['formulation'])
    settings = PlanSettings(mode=int(server.get('mode', 1)),
                            independent_axis=int(server.get('independent_axis', 2)),
                            duration=float(tau))
    plane = scene.plane if scene.planar else None
    plan = plan_path(skill, np.asarray(start, float), np.asarray(goal, float), (), settings,
                     plane)
    followed = FollowedPlan(skill, plan, settings, plane)
    followed.update(float(t_switch), goal=np.asarray(moved_goal, dtype=float))
    return nrmse_over_tau(np.asarray(followed.positions), tau, np.asarray(followed.t), scene,
                          end=moved_goal)


def moved_bottle_mouths(run, tr, ex):
    """Where the mouth was at each trace and executed-plan point of a run whose bottle moved."""
    scene = run.scene
    move_ns, before, after = run.goal_move
    mouth0 = np.asarray(before, float) - scene.goal_offset
    mouth1 = np.asarray(after, float) - scene.goal_offset
    tip_t = tr.tip_t[(tr.tip_t >= run.call_ns * 1e-9) & (tr.tip_t <= run.end_ns * 1e-9 + 1e-9)]
    trace = np.where((tip_t >= move_ns * 1e-9)[:, None], mouth1, mouth0)
    plan = np.where((ex.t + tr.t0 >= move_ns * 1e-9)[:, None], mouth1, mouth0)
    return trace, plan

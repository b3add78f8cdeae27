"""
What a closed-loop run is measured by: computed from its recording, without ROS.

How the numbers are measured (``metrics.json`` repeats this under ``definitions``):

- nRMSE: SPEC §3.4, conventional variant (``etdmp_ros.dmp.nrmse``) against the demonstration,
  over the plan's ``tau`` only (its duration; a plan with obstacles runs 1.5 tau; its tail
  would be squeezed into the phase resampling, as in ``etdmp reproduce``). 2D skills are
  compared in the task plane (base_link points projected onto it), 3D skills in base_link.
  The executed trace is cut to the same span of the plan: from the moment the controller
  started tracking (found by fitting the controller's stamped reference to the plan, to a
  tenth of a millisecond) to that plus ``tau``; the approach before it is left out. A 3D skill
  planned in dmp_server's ``mode`` 2 (the taught stir) is first taken back to the
  demonstration's situation by mode 2's own transform (its turn about the independent axis and
  its per-block scales, from the path's start and end): the measure's Rodrigues alignment of
  the start direction alone counts that turn as a difference of shape (0.30 for a stir
  repeated 150 degrees round the bottle that is the recording turned exactly).
- tracking error: true pen tip minus the controller's reference at the same simulated stamps,
  while the plan is tracked.
- goal error: the pen tip at the end (after the hold) to the true goal marker projected onto
  the task plane (2D) or to the requested goal (stir).
- clearance: smallest distance from the pen tip's surface (radius
  :data:`~etdmp_ros.robot.PEN_TIP_RADIUS`, 3 mm) to an obstacle cylinder's surface (true
  positions from the simulation; cylinders of their radii, ``obstacle_radii`` or else
  ``obstacle.radius``, standing on the table up to their top point), over the whole executed
  motion; > 0: no contact of the tip. For a pen on the table it is the distance to the axis
  minus 25 mm minus 3 mm. (The pen's body, 9 mm, and the arm: ``contacts``.)
- orientation tracking (a skill with orientations, :func:`orientation_figures`): the true tool
  orientation, forward kinematics of the simulation's own ``/joint_states`` on the UR10 model
  with the scene's ``tool_offset`` (the simulation's ground truth publishes the tip's position
  only; the model's tip agrees with it to ``orientation_fk_vs_tip_max_mm``), against the plan's
  orientation at the same path time (geodesic between its poses; ``orientation_tracking_*``)
  and against the controller's reference at the same stamps (``..._vs_reference_*``), while
  the plan is tracked. ``orientation_plan_vs_demo_turned_max_deg``: the plan's orientations
  against the demonstration's at the same phase turned by the Euclidean transform's rotation
  (about the task plane's normal for 2D skills; ``R^T`` in 3D, mode 1), computed here from
  start and goal.
- contacts: the simulation's ground truth (``/ur10_sim/ground_truth/contacts``, published at
  every tick while the arm or the tool touches an obstacle, the bottle, the table or the
  floor): ``contacts`` counts the ticks with one over the whole recording (0: none; None: the
  topic was not recorded), ``contact_pairs`` names them (``part/item``),
  ``contact_max_depth_mm`` the deepest.
- commands: the largest ``|qd_j| / limit_j`` (limits: ``UR10Model.velocity_limits`` times the
  controller's ``velocity_scale``) and ``|qd_j[k] - qd_j[k-1]| * control_rate / a_j``
  (the controller's ``joint_acceleration_limits``) over every command received.

A run whose goal marker moved while the pen wrote (``Run.goal_move``, the demo's
``--move-goal``; dmp_server re-plans the remainder online and publishes it on /etdmp/path on the
plan's time base) is measured against what was executed (:func:`executed_plan`): the plan as
/generalize returned it with each later /etdmp/path of the same stamp laid over it from that
path's first pose on. The tracking start is fitted to that plan, the nRMSEs of the plan and of
the trace are the same measure as above on it, the trace's with the marker's final position
(projected) appended as its last point: the nRMSE takes a path relative to its last point, so
this places the demonstration at the new goal (``nrmse_trace_own_end``: without it). The goal
error is taken to the marker's final position (projected). Besides (:func:`goal_move_figures`):

- switch: the path time at which the executed plan first departs from the original one (by
  more than 1 nm): where dmp_server re-planned from.
- the move's own cost (``nrmse_move_reference``, :func:`move_reference_nrmse`): the same nRMSE
  of what online ET-DMP itself makes of this move, computed here with the core (no ROS, no
  obstacles): the skill planned from the run's start to the first goal, the goal moved to the
  final one at the switch. The part written before the switch was written for the old goal
  and stays as it is, so a move costs nRMSE however well the system follows (G moved by 4 cm
  at 45 %: ~0.37 with no obstacle at all, against ~0.0005 without the move).
- switch speed: over the window from the new path's publication (or the switch, if earlier) to
  the switch + :data:`SWITCH_WINDOW` s, the true tip's speed (finite differences of its 125 Hz
  samples) divided by the executed plan's speed at the same path time
  (``switch_speed_ratio_min``), and divided by the plan's speed at the switch
  (``switch_tool_speed_min_fraction``); samples where the plan itself is slower than
  :data:`SLOW_PLAN` of its speed at the switch are left out. No stop-and-go: both >= 0.2.
- latencies (``goal_follow``): the marker moved (simulated time of the parameter change) to
  the first /etdmp/goal showing it (more than dmp_server's ``follow_threshold`` from where it
  was) as this process received it; to the message that confirmed it
  (:data:`FOLLOW_CONFIRMATIONS`-th); dmp_server's own figure (its log line: from that message
  to the remainder published); the controller's take-over (its "path continued" or "new
  path" log line) and the first command after it (received here), the end-to-end figure from
  the confirming message (as this process received it, which dmp_server does at about the same
  time; a /rosout stamp can lag the event it reports by tens of milliseconds) to that command.
  Wall clock (the nodes' log stamps, this process's receipt times) except where said
  simulated.

:func:`system_figures` adds what the closed loop cost (CPU, rates) from a :class:`CpuMonitor`
window and the nodes' logs.
"""

from dataclasses import dataclass
import math
import re

from etdmp_ros.dmp import euclidean_transform, learn, nrmse
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.task_plane import quadrant
from etdmp_ros.robot import PEN_TIP_RADIUS, UR10Model
from etdmp_ros.skills.following import FOLLOW_CONFIRMATIONS, FollowedPlan, goal_moved, MovedInput
from etdmp_ros.skills.planning import plan_path, PlanSettings
import numpy as np

DEFINITIONS = {
    'nrmse': 'SPEC 3.4 conventional variant (etdmp_ros.dmp.nrmse) vs the demonstration, over '
             "the plan's tau (without the obstacle margin); 2D skills in the task plane, 3D in "
             'base_link; '
             'trace: true pen tip from the start of tracking (controller reference fitted to '
             "the plan) to that + tau; 3D mode 2: first taken back to the demonstration's "
             "situation by mode 2's transform (turn about the independent axis, block scales)",
    'tracking_error': 'true pen tip minus the controller reference at the same simulated '
                      'stamps, while tracking the plan',
    'goal_error': 'pen tip after the hold to the true goal marker projected onto the task '
                  'plane (2D) or to the requested goal (3D)',
    'min_clearance': 'smallest distance from the pen tip surface (radius 3 mm) to an obstacle '
                     'cylinder surface (true positions), over the executed motion; > 0: clear',
    'command_ratios': 'max |qd_j| / velocity limit_j and max |dqd_j| * control_rate / '
                      'acceleration limit_j over all joint-velocity commands received',
    'contacts': "the simulation's contacts (/ur10_sim/ground_truth/contacts: a link or the "
                'tool touching an obstacle, the bottle, the table or the floor; the tool tip '
                'writing on the table is none): ticks with one over the whole recording (None: '
                'not recorded), the pairs part/item, the deepest (mm)',
    'orientation_tracking': 'angle between the true tool orientation (forward kinematics of the '
                            "simulation's /joint_states) and the plan's at the same path time "
                            "(geodesic between poses), or the controller's reference at the "
                            'same stamps (_vs_reference_), while tracking; '
                            "plan_vs_demo_turned: the plan's orientations vs the demonstration's "
                            "at the same phase turned by the Euclidean transform's rotation",
    'quadrant': 'quadrant of start - goal in the task plane (I: +x +y, II: -x +y, ...); for '
                'the demonstration in its own coordinates',
    'moving_commands_per_s': 'non-zero joint-velocity commands per simulated second from the '
                             'first to the last of them (approach, plan, hold); the time from '
                             'the /generalize call to the first is '
                             'first_moving_command_after_call_s',
}
#: Added to ``definitions`` when the goal marker moved during the run.
MOVE_DEFINITIONS = {
    'executed_plan': 'the /generalize plan with each later /etdmp/path of the same stamp laid '
                     "over it from that path's first pose on (path time = pose stamp - plan "
                     'stamp); nrmse_plan, nrmse_trace, tracking, clearance are taken on it, '
                     'nrmse_original_plan on the plan as /generalize returned it',
    'nrmse_trace_moved': "nrmse_trace: the trace over tau with the marker's final position "
                         '(projected) appended as its last point, i.e. against the '
                         'demonstration placed at the new goal; nrmse_trace_own_end: without',
    'goal_error_moved': "goal_error_mm: pen tip after the hold to the marker's final position "
                        'projected onto the task plane; goal_error_vs_first_marker_mm: to '
                        'where it was when the plan was requested',
    'goal_moved_by_mm': 'distance between the marker before and after the move (true positions)',
    'nrmse_move_reference': "the nRMSE (as nrmse_trace) of the core's online ET-DMP "
                            '(etdmp_ros.skills.following.FollowedPlan, no ROS, no obstacles) '
                            "from the run's start to the first goal with the goal moved to the "
                            'final one at switch_path_time_s: what the move itself costs',
    'switch': 'switch_path_time_s: first path time at which the executed plan departs from the '
              'original plan (> 1 nm); switch_time_s: that, simulated s after the /generalize '
              'call',
    'switch_speed': 'over [min(new path published, switch), switch + 0.5 s] in path time: '
                    'switch_speed_ratio_min = min true tip speed / executed plan speed at the '
                    'same path time; switch_tool_speed_min_fraction = min tip speed / plan '
                    'speed at the switch; samples where the plan is slower than 0.2 of its '
                    'speed at the switch left out',
    'goal_follow': 'latencies of the first update: marker moved (simulated time of the '
                   'parameter change) -> first /etdmp/goal showing it (received here, '
                   'simulated s) -> the 3rd (confirming) one; dmp_server_ms: its own log figure '
                   '(confirming message -> remainder published); controller: path received '
                   'here -> its "path continued" / "new path" log line -> first command after '
                   'it; end_to_end_ms: the confirming message received here -> that first '
                   'command received here (wall clock)',
}
#: The end of the window of the switch speed check after the switch (s of path time).
SWITCH_WINDOW = 0.5
#: Plan speeds below this fraction of the plan's speed at the switch are the plan slowing down
#: itself: left out of the switch speed check.
SLOW_PLAN = 0.2


class MeasurementError(ValueError):
    """The run cannot be measured (e.g. the controller published no reference)."""


@dataclass
class Run:
    """
    Everything the demo measured in one run (inputs of :func:`compute_metrics`).

    ``scene``: the run's :class:`etdmp_ros.demo.scenario.Scenario`; ``rec``: the recorded streams,
    read back from the run's MCAP recording (:func:`etdmp_ros.demo.recording.read_streams`); times
    are simulated ns.
    """

    scene: object
    method: str
    start: np.ndarray                 # tool position when the plans were requested
    goal: np.ndarray                  # the goal as requested (perceived or explicit)
    plan: tuple                       # (t, positions, quaternions) executed
    other: tuple                      # (method, t, positions) or (method, None, reason)
    rec: dict                         # recording.read_streams(the run's demo.mcap)
    status: list                      # (sim ns, text) after the call
    call_ns: int
    plan_stamp_ns: int
    end_ns: int
    goal_truth: np.ndarray
    goal_seen: np.ndarray
    obstacles_truth: np.ndarray
    obstacles_seen: np.ndarray
    wall_time: float = 0.0
    #: (sim ns, marker before (3,), marker after (3,)) when the goal marker moved during the
    #: run (the demo's ``--move-goal``), else None.
    goal_move: tuple = None


def format_nrmse(value):
    """Format an nRMSE: three decimals, or two significant digits when it is that small."""
    return 'n/a' if value is None else (f'{value:.3f}' if value >= 0.01 else f'{value:.2g}')


# ------------------------------------------------------------------------------- geometry


def obstacle_radii(run):
    """Return the radius (m,) of each of the run's true obstacles (the scenario's)."""
    from etdmp_ros.robot import obstacle_radii_for
    scene = run.scene.scene
    radii = getattr(run.scene, 'obstacle_radii', None)
    if radii is None or len(radii) != len(np.reshape(run.obstacles_truth, (-1, 3))):
        radii = obstacle_radii_for(len(np.reshape(run.obstacles_truth, (-1, 3))),
                                   scene.get('obstacle_radii') or [], scene['obstacle.radius'])
    return np.asarray(radii, dtype=float)


def cylinder_gap(points, obstacles, radius):
    """
    Return the distance (n,) from points to the nearest upright cylinder's surface.

    Each obstacle point (m, 3) is the centre of a cylinder's top face; the cylinder of
    ``radius`` (one for all, or one per obstacle) stands on the table (z = 0) up to that
    point. Negative inside a cylinder.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    obstacles = np.asarray(obstacles, dtype=float).reshape(-1, 3)
    if not len(obstacles):
        return np.full(len(points), np.inf)
    radial = np.linalg.norm(points[:, None, :2] - obstacles[None, :, :2], axis=2) - radius
    above = points[:, None, 2] - obstacles[None, :, 2]
    outside = np.where(above > 0.0, np.hypot(np.maximum(radial, 0.0), above), radial)
    inside = np.where(above > 0.0, above, np.maximum(radial, above))
    gap = np.where((radial > 0.0) | (above > 0.0), outside, inside)
    return gap.min(axis=1)


def clearance_mm(points, obstacles, radius):
    """Return the smallest gap (mm) between the pen tip's surface at ``points`` and a cylinder."""
    return float((cylinder_gap(points, obstacles, radius).min() - PEN_TIP_RADIUS) * 1e3)


def fit_tracking_start(reference, plan_t, plan_x, rough_s, window=0.3):
    """
    Return the simulated time (s) at which the controller's reference started the plan.

    ``reference``: (n, 4) stamps (ns) and positions; the reference is ``plan(t - t0)`` while
    tracking. Searched around ``rough_s`` (±``window`` s) by least squares on a 0.1 ms grid.
    Raises MeasurementError when no reference lies inside the plan.
    """
    s = reference[:, 0] * 1e-9
    best = (math.inf, rough_s)
    for step, half in ((1e-3, window), (1e-4, 2e-3)):
        for t0 in best[1] + np.arange(-half, half + step / 2, step):
            inside = (s >= t0 + 0.05) & (s <= t0 + plan_t[-1] - 0.05)
            if inside.sum() < 10:
                continue
            tau = s[inside] - t0
            model = np.stack([np.interp(tau, plan_t, plan_x[:, i]) for i in range(3)], axis=1)
            cost = float(np.mean(np.sum((model - reference[inside, 1:]) ** 2, axis=1)))
            if cost < best[0]:
                best = (cost, float(t0))
    if not math.isfinite(best[0]):
        raise MeasurementError('the controller published no reference while tracking the plan')
    return best[1]


def nrmse_over_tau(points, tau, t, scene, end=None):
    """
    Return the nRMSE against the demonstration of ``points`` at times ``t`` up to ``tau``.

    ``end`` (3,): the goal to place the demonstration at, appended as the last point (the
    nRMSE takes a path relative to its last point); None: the points' own last one.
    """
    keep = t <= tau + 1e-9
    x = points[keep]
    if end is not None:
        x = np.vstack([x, np.reshape(end, (1, 3))])
    if scene.planar:
        x = scene.plane.to_plane(x)
    elif scene.server.get('mode') == 2:
        demo = scene.demo.positions
        placed = euclidean_transform(demo[0] - demo[-1], x[0] - x[-1], mode=2,
                                     independent_axis=scene.server['independent_axis'])
        x = (x - x[-1]) @ placed.R.T / placed.scale
    return float(nrmse(x, scene.demo.positions))


def tracking_errors(rec, t0, plan_duration):
    """Return |true tip - reference| (m) at the stamps both have while the plan is tracked."""
    ref = rec['reference']
    ref_by_stamp = {int(s): p for s, p in zip(ref[:, 0], ref[:, 1:])}
    pairs = [(x, ref_by_stamp[int(s)]) for s, x in zip(rec['tip'][:, 0], rec['tip'][:, 1:])
             if int(s) in ref_by_stamp and 0.0 <= s * 1e-9 - t0 <= plan_duration]
    return np.array([np.linalg.norm(a - b) for a, b in pairs]) if pairs else np.full(1, np.nan)


def start_direction(scene, start, goal):
    """
    Return (start - goal, demonstration start - goal, turn in rad between the two).

    2D skills: in the task plane, the turn signed; 3D: in base_link, the unsigned angle.
    """
    demo_rel = scene.demo.positions[0] - scene.demo.positions[-1]
    if scene.planar:
        start_rel = scene.plane.to_plane(start) - scene.plane.to_plane(goal)
        turn = math.atan2(demo_rel[0] * start_rel[1] - demo_rel[1] * start_rel[0],
                          demo_rel @ start_rel)
    else:
        start_rel = start - goal
        turn = math.acos(np.clip(demo_rel @ start_rel / np.linalg.norm(demo_rel)
                                 / np.linalg.norm(start_rel), -1.0, 1.0))
    return start_rel, demo_rel, turn


def matched_errors(seen, truth):
    """Return, per true point, the distance (mm) to the nearest perceived one."""
    if seen is None or truth is None or not len(truth):
        return []
    seen = np.asarray(seen).reshape(-1, 3)
    if not len(seen):
        return [None] * len(truth)
    return [float(np.min(np.linalg.norm(seen - p, axis=1)) * 1e3) for p in truth]


# -------------------------------------------------------------------------------- metrics


@dataclass
class _Trace:
    """The executed motion, cut as the metrics need it."""

    t0: float              # simulated s at which the controller started tracking the plan
    tau: float
    tip_t: np.ndarray
    tip_x: np.ndarray
    span: np.ndarray       # tip_t - t0
    in_plan: np.ndarray    # samples within the plan's duration from t0
    trace: np.ndarray      # pen tip from the call to the end
    final: np.ndarray      # pen tip at the end
    goal: np.ndarray       # the goal the pen is measured against


def executed_plan(plan_t, plan_x, stamp_ns, paths):
    """
    Return (t, positions, updates): the plan as executed, and how many re-plans changed it.

    ``plan_t``, ``plan_x``: the plan /generalize returned, stamped ``stamp_ns``; ``paths``: the
    recorded /etdmp/path messages (``read_streams``'s ``paths``). Each path with the same
    header stamp is a re-planned remainder on the plan's time base (path time = pose stamp -
    plan stamp): it replaces the plan from its first pose on.
    """
    t, x = np.asarray(plan_t, dtype=float), np.asarray(plan_x, dtype=float)
    updates = 0
    for _, _, header, stamps, positions in paths:
        if int(header) != int(stamp_ns) or not len(stamps):
            continue
        path_t = (np.asarray(stamps, dtype=np.int64) - int(stamp_ns)) * 1e-9
        keep = t < path_t[0] - 1e-6
        new_t = np.concatenate([t[keep], path_t])
        new_x = np.concatenate([x[keep], np.asarray(positions, dtype=float)])
        if len(new_t) != len(t) or not (np.array_equal(new_x, x) and np.allclose(new_t, t)):
            updates += 1
        t, x = new_t, new_x
    return t, x, updates


def switch_index(original_x, executed_x, tolerance=1e-9):
    """Return the index of the first pose where the executed plan departs (None: it never does)."""
    n = min(len(original_x), len(executed_x))
    apart = np.flatnonzero(np.linalg.norm(np.asarray(executed_x[:n]) - original_x[:n], axis=1)
                           > tolerance)
    if len(apart):
        return int(apart[0])
    return n if len(original_x) != len(executed_x) else None


def path_speed(t, x):
    """Return the speed (n,) of a sampled path (central differences)."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    if len(t) < 2:
        return np.zeros(len(t))
    return np.linalg.norm(np.gradient(x, t, axis=0), axis=1)


def switch_speeds(tip_t, tip_x, t0, plan_t, plan_x, t_switch, t_from=None,
                  window=SWITCH_WINDOW, slow=SLOW_PLAN):
    """
    Return the speed figures around a switch of plans (the module docstring defines them).

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


@dataclass
class _Executed:
    """The plan as executed (a moved goal: with its re-planned remainders) and the original."""

    t: np.ndarray
    x: np.ndarray
    updates: int = 0
    switch: int = None      # index of the first pose that departs from the original plan


def _executed(run):
    plan_t, plan_x, _ = run.plan
    if run.goal_move is None:
        return _Executed(np.asarray(plan_t), np.asarray(plan_x))
    t, x, updates = executed_plan(plan_t, plan_x, run.plan_stamp_ns, run.rec.get('paths', []))
    return _Executed(t, x, updates, switch_index(plan_x, x))


def _goal(run):
    """Return the goal the pen is measured against: the true marker projected (2D)."""
    scene = run.scene
    if not scene.planar:    # stir: the explicit goal, or the moved bottle's
        return run.goal if run.goal_move is None else np.asarray(run.goal_move[2], float)
    marker = run.goal_truth if run.goal_move is None else run.goal_move[2]
    return scene.plane.from_plane(scene.plane.to_plane(np.asarray(marker, dtype=float)))


def _trace(run, ex):
    scene, rec = run.scene, run.rec
    tip_t, tip_x = rec['tip'][:, 0] * 1e-9, rec['tip'][:, 1:]
    tracking = [ns for ns, text in run.status if text.split(':')[0] == 'tracking']
    rough = tracking[0] * 1e-9 if tracking else run.call_ns * 1e-9
    t0 = fit_tracking_start(rec['reference'], ex.t, ex.x, rough)
    span = tip_t - t0
    moving = tip_t >= run.call_ns * 1e-9
    trace = tip_x[moving & (tip_t <= run.end_ns * 1e-9 + 1e-9)]
    return _Trace(t0, float(scene.server['duration']) or float(scene.demo.duration), tip_t,
                  tip_x, span, (span >= -1e-6) & (span <= ex.t[-1] + 1e-6), trace,
                  trace[-1] if len(trace) else tip_x[-1], _goal(run))


def _dmp_plan(run):
    """Return (t, positions) of the plain-DMP plan of the run (executed or not), or None."""
    plan_t, plan_x, _ = run.plan
    other_method, other_t, other_x = run.other
    if run.method == 'dmp':
        return plan_t, plan_x
    return (other_t, other_x) if other_method == 'dmp' and other_t is not None else None


def _headline(run, tr, ex):
    scene, radius = run.scene, obstacle_radii(run)
    plan_t, plan_x = ex.t, ex.x
    dmp = _dmp_plan(run)
    errors = tracking_errors(run.rec, tr.t0, plan_t[-1])
    return {
        'skill': scene.skill,
        'method': run.method,
        'nrmse_plan': nrmse_over_tau(plan_x, tr.tau, plan_t, scene),
        'nrmse_trace': nrmse_over_tau(tr.tip_x[tr.in_plan], tr.tau, tr.span[tr.in_plan], scene,
                                      end=tr.goal if run.goal_move is not None else None),
        'nrmse_dmp_baseline': (nrmse_over_tau(dmp[1], tr.tau, dmp[0], scene)
                               if dmp is not None else None),
        'tracking_rms_mm': float(np.sqrt(np.mean(errors ** 2)) * 1e3),
        'tracking_max_mm': float(np.max(errors) * 1e3),
        'min_clearance_mm': (clearance_mm(tr.trace, run.obstacles_truth, radius)
                             if len(tr.trace) else None),
        'goal_error_mm': float(np.linalg.norm(tr.final - tr.goal) * 1e3),
        'duration_s': float((run.end_ns - run.call_ns) * 1e-9),
    }


def _plan_details(run, tr, ex):
    radius = obstacle_radii(run)
    plan_t, plan_x = ex.t, ex.x
    dmp = _dmp_plan(run)
    return {
        'plan_duration_s': float(plan_t[-1]),
        'tau_s': tr.tau,
        'approach_duration_s': float(tr.t0 - run.call_ns * 1e-9),
        'min_clearance_plan_mm': clearance_mm(plan_x, run.obstacles_truth, radius),
        'min_clearance_dmp_baseline_mm': (clearance_mm(dmp[1], run.obstacles_truth, radius)
                                          if dmp is not None else None),
        'goal_error_vs_plan_end_mm': float(np.linalg.norm(tr.final - plan_x[-1]) * 1e3),
    }


def _positions(run, tr):
    scene = run.scene
    start_rel, demo_rel, turn = start_direction(scene, run.start, run.goal)
    at_call = max(int(np.searchsorted(tr.tip_t, run.call_ns * 1e-9, 'right')) - 1, 0)
    return {
        'start': run.start.tolist(),
        'goal': run.goal.tolist(),
        'plan_end': run.plan[1][-1].tolist(),
        'tool_at_call': tr.tip_x[at_call].tolist(),
        'perceived_goal': None if run.goal_seen is None else run.goal_seen.tolist(),
        'true_goal_marker': None if run.goal_truth is None else run.goal_truth.tolist(),
        'goal_source': ('perceived marker' if scene.explicit_goal is None else
                        'perceived bottle' if getattr(scene, 'perceived_bottle', False)
                        else 'explicit'),
        'start_quadrant': quadrant(start_rel[:2]),
        'demo_quadrant': quadrant(demo_rel[:2]),
        'start_turn_deg': math.degrees(turn),
    }


def _perception(run):
    return {
        'perceived_goal_error_mm': (float(np.linalg.norm(run.goal_seen - run.goal_truth) * 1e3)
                                    if run.goal_seen is not None else None),
        'perceived_obstacle_errors_mm': matched_errors(run.obstacles_seen, run.obstacles_truth),
        'obstacles': np.asarray(run.obstacles_truth).tolist(),
    }


def command_ratios(scene, qd):
    """Return the commands' figures: counts and ratios to the limits the controller applies."""
    model = UR10Model(tool_offset=scene.scene['tool_offset'])
    v_lim = model.velocity_limits * float(scene.controller['velocity_scale'])
    a_lim = np.asarray(scene.controller['joint_acceleration_limits'], dtype=float)
    rate = float(scene.controller['control_rate'])
    dqd = np.abs(np.diff(qd, axis=0)) * rate if len(qd) > 1 else np.zeros((1, 6))
    return {
        'commands_received': int(len(qd)),
        'commands_nonzero': int(np.count_nonzero(np.any(qd != 0.0, axis=1))) if len(qd) else 0,
        'max_joint_velocity_ratio': float(np.max(np.abs(qd) / v_lim)) if len(qd) else 0.0,
        'max_joint_acceleration_ratio': float(np.max(dqd / a_lim)),
        'max_joint_velocity_rad_s': np.max(np.abs(qd), axis=0).tolist() if len(qd) else [],
        'joint_velocity_limits_rad_s': v_lim.tolist(),
        'joint_acceleration_limits_rad_s2': a_lim.tolist(),
    }


def bottle_clearances(scene, trace, plan_x, trace_mouths=None, plan_mouths=None):
    """
    Stirring: how close the pen tip came to the bottle's wall while inside it (mm).

    ``trace_mouths``, ``plan_mouths`` ((n, 3) or None): where the bottle's mouth was at each
    point (a bottle that moved); None: where the scene puts it.
    """
    r_b = float(scene.scene['bottle.radius'])
    out = {}
    for key, points, mouths in (('bottle_wall_clearance_mm', trace, trace_mouths),
                                ('bottle_wall_clearance_plan_mm', plan_x, plan_mouths)):
        mouths = np.broadcast_to(scene.bottle_mouth if mouths is None else mouths,
                                 points.shape)
        inside = points[:, 2] < mouths[:, 2]
        gap = r_b - np.linalg.norm(points[inside, :2] - mouths[inside, :2], axis=1) \
            - PEN_TIP_RADIUS
        out[key] = float(gap.min() * 1e3) if len(gap) else None
    return out


def _moved_bottle_mouths(run, tr, ex):
    """Where the mouth was at each trace and executed-plan point of a run whose bottle moved."""
    scene = run.scene
    move_ns, before, after = run.goal_move
    mouth0 = np.asarray(before, float) - scene.goal_offset
    mouth1 = np.asarray(after, float) - scene.goal_offset
    tip_t = tr.tip_t[(tr.tip_t >= run.call_ns * 1e-9) & (tr.tip_t <= run.end_ns * 1e-9 + 1e-9)]
    trace = np.where((tip_t >= move_ns * 1e-9)[:, None], mouth1, mouth0)
    plan = np.where((ex.t + tr.t0 >= move_ns * 1e-9)[:, None], mouth1, mouth0)
    return trace, plan


def _other_plan(run, tau):
    other_method, other_t, other_x = run.other
    out = {}
    if other_method != 'dmp' or other_t is None:
        out[f'nrmse_{other_method}_plan'] = (
            nrmse_over_tau(other_x, tau, other_t, run.scene) if other_t is not None else None)
    if other_t is None:
        out[f'{other_method}_error'] = other_x
    return out


#: dmp_server's log line when it re-planned a followed plan (etdmp_ros.nodes.dmp_server).
_FOLLOWING = re.compile(r'following: goal moved to \(([-\d.]+), ([-\d.]+), ([-\d.]+)\)'
                        r'(?: and obstacles moved to .*?)?: re-planned from path time ([-\d.]+) s '
                        r'\(the controller at about ([-\d.]+) s\), (\d+) poses to ([-\d.]+) s '
                        r'published in ([\d.]+) ms \(update (\d+)\)')
#: The controller's log line when it accepted a path (etdmp_ros.nodes.controller).
_NEW_PATH = re.compile(r'(?:new path|path continued): (\d+) poses over ([\d.]+) s')


def _node_lines(logs, node, pattern, after_ns=-math.inf):
    """Return [(stamp ns, match)] of ``node``'s /rosout lines matching ``pattern``."""
    found = []
    for stamp, name, text in logs:
        if name.split('.')[-1] == node and stamp > after_ns:
            match = pattern.search(text)
            if match:
                found.append((stamp, match))
    return found


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
    the nodes' /rosout lines (dmp_server's "following: ..." and the controller's "new path:
    ..."); the module docstring defines them. A figure is None when its event is missing.
    """
    rec, scene = run.rec, run.scene
    move_ns = int(run.goal_move[0])
    threshold = float(scene.server.get('follow_threshold', 0.005))
    seen = perceived_goal_rows(run)
    first, confirming = goal_seen_after_move(scene, seen, run.plan[1][-1], run.call_ns,
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
    logs = rec.get('logs', [])
    after = seen[first, 1] - 1e9 if first is not None else -math.inf
    following = _node_lines(logs, 'dmp_server', _FOLLOWING, after)
    if not following:
        return out
    stamp, match = following[0]
    took_ms, poses = float(match.group(8)), int(match.group(6))
    # When dmp_server had the confirming message: its receipt here (a /rosout stamp can come
    # tens of milliseconds after the event it reports), else its own log line's account.
    server_seen_ns = (seen[confirming, 1] if confirming is not None
                      else stamp - took_ms * 1e6)
    out.update(dmp_server_ms=took_ms, replanned_from_path_time_s=float(match.group(4)),
               controller_path_time_estimate_s=float(match.group(5)))
    path = next((p for p in rec.get('paths', []) if int(p[2]) == int(run.plan_stamp_ns)
                 and len(p[3]) == poses and p[1] >= server_seen_ns - 1e9), None)
    if path is not None and confirming is not None:
        out['dmp_server_recorded_ms'] = float((path[1] - seen[confirming, 1]) * 1e-6)
    accepted = [(ns, m) for ns, m in _node_lines(logs, 'controller', _NEW_PATH, server_seen_ns)
                if int(m.group(1)) == poses]
    if not accepted:
        return out
    accepted_ns = accepted[0][0]
    wall = rec['command_wall_time'] * 1e9
    later = np.flatnonzero(wall > accepted_ns)
    if path is not None:
        out['controller_accept_ms'] = float((accepted_ns - path[1]) * 1e-6)
    if len(later):
        command_ns = wall[later[0]]
        out['end_to_end_ms'] = float((command_ns - server_seen_ns) * 1e-6)
        out['goal_change_to_first_command_s'] = float(
            (rec['command_time'][later[0]] - move_ns) * 1e-9)
        if path is not None:
            out['controller_first_command_ms'] = float((command_ns - path[1]) * 1e-6)
    return out


def goal_move_figures(run, tr, ex):
    """Return the figures of a run whose goal marker moved (the module docstring)."""
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


def _geodesic(t, q, at):
    """Return the orientations (len(at), 4) at times ``at`` of quaternions ``q`` at ``t``."""
    q = quat.continuous(np.asarray(q, dtype=float))
    at = np.clip(at, t[0], t[-1])
    i = np.clip(np.searchsorted(t, at, 'right') - 1, 0, len(t) - 2)
    s = ((at - t[i]) / (t[i + 1] - t[i]))[:, None]
    step = quat.log_map(quat.multiply(q[i + 1], quat.conjugate(q[i])))
    return quat.multiply(quat.exp_map(s * step), q[i])


def _angles_deg(p, q):
    return np.degrees(quat.angle_between(np.asarray(p), np.asarray(q)))


def demo_turned(scene, start, goal, plan_t, tau):
    """
    Return the demonstration's orientations at the plan's phase turned by ET-DMP's rotation.

    ``plan_t`` (n,) path times; ``tau`` the plan's duration without margin. Base_link (n, 4);
    None for a position-only demonstration, orientation_mode tool, or a transform that mirrors.
    """
    demo = scene.demo
    if demo.orientations is None or scene.server.get('orientation_mode') == 'tool':
        return None     # the plan keeps the tool's orientation: nothing turned to compare with
    if scene.planar:
        plane = scene.plane
        s, g = plane.to_plane(np.asarray(start)), plane.to_plane(np.asarray(goal))
    else:
        s, g = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    mode = 1 if scene.planar else scene.server.get('mode', 1)
    transform = euclidean_transform(demo.positions[0] - demo.positions[-1], s - g, mode,
                                    scene.server.get('independent_axis', 2))
    turn = np.eye(3)
    r_t = np.asarray(transform.R, dtype=float).T
    turn[:len(r_t), :len(r_t)] = r_t
    if np.linalg.det(turn) < 0.0:
        return None
    q_demo = _geodesic(demo.t, demo.orientations,
                       np.asarray(plan_t) * demo.duration / tau)
    turned = quat.multiply(quat.from_matrix(turn), q_demo)
    return plane.orientation_from_plane(turned) if scene.planar else turned


def orientation_figures(run, tr):
    """Return the orientation tracking figures of a run (the module docstring), or {}."""
    plan_t, plan_x, plan_q = run.plan
    joints = run.rec.get('joints')
    if run.scene.demo.orientations is None or plan_q is None or joints is None or \
            not len(joints):
        return {}
    plan_t, plan_q = np.asarray(plan_t), np.asarray(plan_q)
    stamps = joints[:, 0]
    span = stamps * 1e-9 - tr.t0
    inside = (span >= 0.0) & (span <= plan_t[-1])
    if not inside.any():
        return {}
    model = UR10Model(tool_offset=run.scene.scene['tool_offset'])
    poses = [model.frame_pose(q) for q in joints[inside, 1:]]
    true_q = quat.from_matrix(np.array([rot for _, rot in poses]))
    vs_plan = _angles_deg(true_q, _geodesic(plan_t, plan_q, span[inside]))
    figures = {'orientation_tracking_rms_deg': float(np.sqrt(np.mean(vs_plan ** 2))),
               'orientation_tracking_max_deg': float(vs_plan.max()),
               'orientation_samples': int(inside.sum()),
               'orientation_plan_turn_deg': float(_angles_deg(plan_q[0], plan_q).max())}
    ref = run.rec['reference'][:, 0].astype(np.int64)
    ref_q = run.rec.get('reference_q')
    order = {int(k): i for i, k in enumerate(ref)}
    pairs = [(j, order[int(k)]) for j, k in enumerate(stamps[inside]) if int(k) in order]
    if pairs and ref_q is not None:
        a, b = np.array(pairs).T
        vs_ref = _angles_deg(true_q[a], ref_q[b])
        figures.update({'orientation_tracking_vs_reference_rms_deg':
                        float(np.sqrt(np.mean(vs_ref ** 2))),
                        'orientation_tracking_vs_reference_max_deg': float(vs_ref.max())})
    tip = {int(k): x for k, x in zip(run.rec['tip'][:, 0], run.rec['tip'][:, 1:])}
    gaps = [np.linalg.norm(p - tip[int(k)]) for (p, _), k in zip(poses, stamps[inside])
            if int(k) in tip]
    if gaps:
        figures['orientation_fk_vs_tip_max_mm'] = float(np.max(gaps) * 1e3)
    turned = demo_turned(run.scene, plan_x[0], plan_x[-1], plan_t, tr.tau) \
        if run.goal_move is None and run.method == 'etdmp' else None
    if turned is not None:
        keep = plan_t <= tr.tau + 1e-9
        figures['orientation_plan_vs_demo_turned_max_deg'] = float(
            _angles_deg(plan_q[keep], turned[keep]).max())
    return figures


def contact_figures(rec):
    """Return the contact figures of the recorded streams (module docstring)."""
    messages = rec.get('contacts', [])
    if not messages:
        return {'contacts': None, 'contact_pairs': [], 'contact_max_depth_mm': None}
    touching = [found for _, found in messages if found]
    depths = [depth for found in touching for _, _, depth in found]
    return {'contacts': len(touching),
            'contact_pairs': sorted({f'{part}/{item}' for found in touching
                                     for part, item, _ in found}),
            'contact_max_depth_mm': float(max(depths) * 1e3) if depths else 0.0}


def compute_metrics(run):
    """
    Return (metrics, extra) of a run (the module docstring defines them).

    ``extra``: what the figures need besides, ``{'t0', 'tau', 'trace', 'goal', 'executed'}``
    (``executed``: (t, positions) of the plan as executed; with a moved goal also ``switch``,
    the index of its first re-planned pose or None). Raises MeasurementError when the run
    tracked nothing that could be measured.
    """
    ex = _executed(run)
    tr = _trace(run, ex)
    metrics = {**_headline(run, tr, ex), **_plan_details(run, tr, ex), **_positions(run, tr),
               **_perception(run), **command_ratios(run.scene, run.rec['commands']),
               **contact_figures(run.rec),
               'plan_stamp_minus_sim_time_s': float((run.plan_stamp_ns - run.call_ns) * 1e-9),
               'controller_status': [text for _, text in run.status],
               'wall_time_s': float(run.wall_time),
               'definitions': DEFINITIONS}
    if not run.scene.planar:
        mouths = (_moved_bottle_mouths(run, tr, ex) if run.goal_move is not None
                  and getattr(run.scene, 'perceived_bottle', False) else (None, None))
        metrics.update(bottle_clearances(run.scene, tr.trace, ex.x, *mouths))
    metrics.update(orientation_figures(run, tr))
    metrics.update(_other_plan(run, tr.tau))
    extra = {'t0': tr.t0, 'tau': tr.tau, 'trace': tr.trace, 'goal': tr.goal,
             'executed': (ex.t, ex.x)}
    if run.goal_move is not None:
        metrics.update(goal_move_figures(run, tr, ex))
        metrics['definitions'] = {**DEFINITIONS, **MOVE_DEFINITIONS}
        extra['switch'] = ex.switch
    return metrics, extra


# -------------------------------------------------------------------------- system budget


#: The controller's log line at the end of a tracked path (etdmp_ros.nodes.controller).
_TRACKED = re.compile(r'path tracked: error RMS ([\d.]+) mm, max ([\d.]+) mm; (\d+) control '
                      r'steps in (\d+) periods \((\d+) joint states received, largest gap '
                      r'([\d.]+) ms(?: at t = ([\d.]+) s)?\)')
#: The camera process's log line when it stops (etdmp_ros.nodes._sim_camera).
_CAMERA_STOPPED = re.compile(r'camera stopped: (\d+) frames published, (\d+) skipped')
#: ur10_sim's warning about a stalled simulation loop.
_STALL = re.compile(r'simulation loop stalled: (\d+) ms between two ticks at t = ([\d.]+) s')
#: ur10_sim's log line when it stops.
_SIM_STOPPED = re.compile(r'(\d+) more than \d+ periods after the previous one, largest '
                          r'wall-clock gap between two ([\d.]+) ms; camera frames published '
                          r'(\d+), dropped (\d+); waited for a late command (\d+) times '
                          r'\((\d+) ms\), (\d+) in vain')


def _cpu_figures(monitor, call_ns, end_ns):
    window = monitor.window(call_ns * 1e-9, end_ns * 1e-9) if end_ns else None
    if window is None:
        return {}
    return {'cpu_cores': window['cpu'],
            'cpu_cores_total': window['total'],
            'cpu_cores_nodes_but_sim': sum(v for k, v in window['cpu'].items()
                                           if k != 'ur10_sim'),
            'real_time_factor': window['real_time_factor'],
            'min_real_time_factor_1s': window['min_real_time_factor_1s']}


def _command_figures(rec, call_ns, end_ns):
    figures = {}
    t = rec['command_time']
    inside = (t >= call_ns) & (t <= (end_ns or 0))
    moving = inside & np.any(rec['commands'] != 0.0, axis=1) if len(t) else inside
    moving_t = t[moving]
    if len(moving_t) >= 2:
        # While the arm moves: from the first non-zero command to the last. The time before
        # the first (planning, the path check, numba loading a kernel) is a latency, reported
        # apart; zero commands in between (a halt) count against the rate.
        span = (moving_t[-1] - moving_t[0]) * 1e-9
        figures['moving_commands_per_s'] = float((len(moving_t) - 1) / span) if span > 0 else 0.0
        figures['first_moving_command_after_call_s'] = float((moving_t[0] - call_ns) * 1e-9)
    periods = np.diff(rec['command_wall_time'][inside]) * 1e3
    if len(periods):
        figures['command_period_ms'] = {'p50': float(np.median(periods)),
                                        'p99': float(np.percentile(periods, 99)),
                                        'max': float(periods.max())}
    return figures


def _controller_figures(log):
    found = _TRACKED.findall(log)
    if not found:
        return {}
    rms, peak, steps, periods, received, gap, gap_at = found[-1]
    return {'controller': {'tracking_rms_mm': float(rms), 'tracking_max_mm': float(peak),
                           'steps': int(steps), 'periods': int(periods),
                           'joint_states_received': int(received),
                           'largest_joint_state_gap_ms': float(gap),
                           'largest_joint_state_gap_at_s': float(gap_at or 'nan')}}


def _simulation_figures(log, call_ns, end_ns):
    stalls = _STALL.findall(log)
    figures = {'simulation_stalls': [(float(t), float(ms)) for ms, t in stalls
                                     if call_ns * 1e-9 <= float(t) <= (end_ns or 0) * 1e-9]}
    found = _SIM_STOPPED.findall(log)
    if found:
        late, gap, frames, dropped, waits, waited, in_vain = found[-1]
        figures['simulation'] = {'late_ticks': int(late), 'largest_tick_gap_ms': float(gap),
                                 'frames': int(frames), 'frames_dropped': int(dropped),
                                 'command_waits': int(waits), 'command_wait_ms': int(waited),
                                 'command_waits_in_vain': int(in_vain)}
        camera = _CAMERA_STOPPED.findall(log)
        if camera:   # snapshots the camera process skipped because it was still rendering
            figures['simulation']['frames_rendered'] = int(camera[-1][0])
            figures['simulation']['frames_dropped'] += int(camera[-1][1])
    return figures


def system_figures(monitor, rec, call_ns, end_ns, nodes):
    """
    Return what the closed loop cost and how well it kept time from the call to the end.

    CPU per process (CPU-s per simulated s, from /proc), the real-time factor, the moving
    commands per simulated second and the wall-clock period between commands as this process
    received them, and what the controller and the simulation logged about their loops.
    ``monitor``: a started and stopped :class:`etdmp_ros.demo.cpu_monitor.CpuMonitor`; ``nodes``:
    anything with ``log(node)`` returning a node's output.
    """
    return {**_cpu_figures(monitor, call_ns, end_ns), **_command_figures(rec, call_ns, end_ns),
            **_controller_figures(nodes.log('controller')),
            **_simulation_figures(nodes.log('ur10_sim'), call_ns, end_ns)}

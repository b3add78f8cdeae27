"""
The executed motion against the plan: when tracking started, the trace, the plan as executed.

Definitions: ``nrmse``, ``tracking_error``, ``executed_plan`` (:mod:`._definitions`).
"""

from dataclasses import dataclass
import math

from etdmp_ros.demo.metrics._run import MeasurementError
from etdmp_ros.dmp import euclidean_transform, nrmse
import numpy as np


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


@dataclass
class Trace:
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


@dataclass
class Executed:
    """The plan as executed (a moved goal: with its re-planned remainders) and the original."""

    t: np.ndarray
    x: np.ndarray
    updates: int = 0
    switch: int = None      # index of the first pose that departs from the original plan


def plan_as_executed(run):
    """Return the run's plan as executed (:class:`Executed`)."""
    plan_t, plan_x, _ = run.plan
    if run.goal_move is None:
        return Executed(np.asarray(plan_t), np.asarray(plan_x))
    t, x, updates = executed_plan(plan_t, plan_x, run.plan_stamp_ns, run.rec.get('paths', []))
    return Executed(t, x, updates, switch_index(plan_x, x))


def measured_goal(run):
    """Return the goal the pen is measured against: the true marker projected (2D)."""
    scene = run.scene
    if not scene.planar:    # stir: the explicit goal, or the moved bottle's
        return run.goal if run.goal_move is None else np.asarray(run.goal_move[2], float)
    marker = run.goal_truth if run.goal_move is None else run.goal_move[2]
    return scene.plane.from_plane(scene.plane.to_plane(np.asarray(marker, dtype=float)))


def cut_trace(run, ex):
    """Return the run's executed motion cut as the metrics need it (:class:`Trace`)."""
    scene, rec = run.scene, run.rec
    tip_t, tip_x = rec['tip'][:, 0] * 1e-9, rec['tip'][:, 1:]
    tracking = [ns for ns, text in run.status if text.split(':')[0] == 'tracking']
    rough = tracking[0] * 1e-9 if tracking else run.call_ns * 1e-9
    t0 = fit_tracking_start(rec['reference'], ex.t, ex.x, rough)
    span = tip_t - t0
    moving = tip_t >= run.call_ns * 1e-9
    trace = tip_x[moving & (tip_t <= run.end_ns * 1e-9 + 1e-9)]
    return Trace(t0, float(scene.server['duration']) or float(scene.demo.duration), tip_t,
                 tip_x, span, (span >= -1e-6) & (span <= ex.t[-1] + 1e-6), trace,
                 trace[-1] if len(trace) else tip_x[-1], measured_goal(run))

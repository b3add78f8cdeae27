"""
Three ways to handle a goal that jumps mid-movement, compared (docs/design.md#online-goal).

(a) the online ET-DMP (:class:`OnlineRun`) told the new goal, (b) a fresh ET-DMP re-planned from
rest at the switch, (c) the plain DMP's goal change; :func:`goal_jump_case` gives the scenario.
"""

import math
from typing import NamedTuple

import numpy as np

from ._online_gains import OnlineGains
from ._similarity import nrmse


#: The three ways :func:`compare_goal_jump` compares, in its order, with their labels.
GOAL_JUMP_WAYS = {'online': '(a) online ET-DMP', 'replan': '(b) re-plan from rest',
                  'dmp': '(c) plain DMP goal change'}


class GoalJump(NamedTuple):
    """
    One way of handling a goal jump (:func:`compare_goal_jump`).

    ``t``, ``x``, ``v``, ``a``: the executed movement from the start until ``end_time`` (its
    own nominal end: tau, or for the re-plan the switch plus tau). ``velocity_step`` and
    ``acceleration_step``: the largest change over one sample, in the samples just after the
    switch, beyond what the same movement without a goal change did over that sample (units/s
    and units/s^2); the acceleration is the one the samples imply, ``(v_(k+1) - v_k) / dt``, so
    a velocity jump counts as the impulse it is. ``final_distance``: ``|x - g_new|`` at
    ``end_time``. ``shape_nrmse``: the conventional nRMSE (:func:`nrmse`, Eq. 15-16) of the part
    after the switch against the same phases of the demonstration placed at the new goal (the
    ET-DMP from the start to the new goal). ``shape_error``: the RMS distance between the two,
    by phase and without nRMSE's alignment, divided by the size of the placed demonstration.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    velocity_step: float
    acceleration_step: float
    final_distance: float
    shape_nrmse: float
    shape_error: float
    end_time: float


#: Samples after a switch in which :func:`compare_goal_jump` looks for the largest step.
STEP_WINDOW = 3


def _step_excess(series, nominal, k):
    """Largest |change over one sample - the nominal change| over the STEP_WINDOW samples."""
    ds = np.diff(series[k:k + STEP_WINDOW + 1], axis=0)
    dn = np.diff(nominal[k:k + STEP_WINDOW + 1], axis=0)
    return float(np.max(np.linalg.norm(ds - dn, axis=1)))


def _by_phase(y, n):
    """Resample (m, d) samples to n by linear interpolation in the sample index."""
    src, dst = np.linspace(0.0, 1.0, len(y)), np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(dst, src, y[:, i]) for i in range(y.shape[1])], axis=1)


def compare_goal_jump(skill, start, goal, new_goal, switch=0.4, dt=None, tau=None, mode=1,
                      online=None):
    """
    Compare three ways to handle a goal that jumps at ``switch`` of the movement's duration.

    (a) ``'online'``: the online ET-DMP (:class:`OnlineRun`, gains ``online``) told the new
    goal; (b) ``'replan'``: a fresh ET-DMP from the position at the switch, at rest, to the new
    goal; (c) ``'dmp'``: the plain DMP's goal change (the goal of Eq. 1 replaced at once, no
    filter). Returns ``(results, reference)``: a dict of :class:`GoalJump` keyed as
    :data:`GOAL_JUMP_WAYS`, and the demonstration placed at the new goal (the
    :class:`Trajectory` of the ET-DMP from ``start`` to ``new_goal``).
    """
    online = OnlineGains() if online is None else online
    base = skill.generalize(start, goal, method='etdmp', mode=mode, dt=dt, tau=tau)
    plain = skill.generalize(start, goal, method='dmp', mode=mode, dt=dt, tau=tau)
    reference = skill.generalize(start, new_goal, method='etdmp', mode=mode, dt=dt, tau=tau)
    dt = base.t[1] - base.t[0]
    n = len(base.t) - 1                     # samples to tau
    k = int(round(switch * n))
    ref_rest = reference.x[k:]
    ref_size = float(np.max(np.linalg.norm(reference.x - reference.x[-1], axis=1)))
    results = {}
    for way in GOAL_JUMP_WAYS:
        if way == 'replan':
            fresh = skill.generalize(base.x[k], new_goal, method='etdmp', mode=mode, dt=dt,
                                     tau=tau)
            x, v, a = (np.concatenate([getattr(base, name)[:k + 1], getattr(fresh, name)[1:]])
                       for name in ('x', 'v', 'a'))
            nominal = base
        else:
            method = 'etdmp' if way == 'online' else 'dmp'
            gains = online if way == 'online' else OnlineGains(alpha_goal=math.inf)
            run = skill.online(start, goal, method=method, mode=mode, dt=dt, tau=tau,
                               online=gains)
            samples = [(run.x, run.v, run.a)]
            for i in range(n):
                samples.append(run.step(goal=new_goal if i == k else None))
            x, v, a = (np.array(column) for column in zip(*samples))
            nominal = base if way == 'online' else plain
        t = np.arange(len(x)) * dt
        implied, implied_nominal = np.diff(v, axis=0) / dt, np.diff(nominal.v, axis=0) / dt
        rest = _by_phase(x[k:], len(ref_rest))
        error = np.sqrt(np.mean(np.sum((rest - ref_rest) ** 2, axis=1))) / ref_size
        results[way] = GoalJump(
            t, x, v, a, _step_excess(v, nominal.v, k),
            _step_excess(implied, implied_nominal, k - 1),
            float(np.linalg.norm(x[-1] - new_goal)), float(nrmse(x[k:], ref_rest)),
            float(error), float(t[-1]))
    return results, reference


def goal_jump_case(skill, turn=np.radians(25.0), distance=1.2, jump=0.3):
    """
    Return ``(start, goal, new_goal)``: the goal-jump scenario of docs/design.md#online-goal.

    The goal is the demonstration's; the start is the demonstration's start turned about the
    goal by ``turn`` (about z in 3D) and moved to ``distance`` times its distance; the new goal
    lies ``jump`` times ``|start - goal|`` from the goal, perpendicular to ``start - goal`` (in
    the x-y plane). 2D and 3D skills only.
    """
    if skill.dim not in (2, 3):
        raise ValueError(f'the goal-jump scenario needs a 2D or 3D skill, got d={skill.dim}')
    c, s = np.cos(turn), np.sin(turn)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])[:skill.dim, :skill.dim]
    goal = skill.goal.copy()
    offset = distance * rotation @ (skill.start - skill.goal)
    side = np.zeros(skill.dim)
    side[:2] = -offset[1], offset[0]
    side /= np.linalg.norm(side)
    return goal + offset, goal, goal + jump * np.linalg.norm(offset) * side

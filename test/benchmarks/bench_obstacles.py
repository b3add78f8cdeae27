"""
Obstacle benchmark: ways to avoid obstacles with a size, compared in one run on held-out shapes.

A script, not a pytest test. ``make bench-obstacles`` runs it in ``.venv-bench/`` (where
movement-primitives is installed: its Hoffmann term is checked against ours); it also runs in
``.venv/``::

    .venv/bin/python test/benchmarks/bench_obstacles.py [--quick] [--json PATH] [--no-docs]

Shapes (none of them the built-in demonstrations the defaults were chosen on): the 30 LASA
handwriting shapes (demonstration 0), the Z as the teaching page draws it, 8 random 2D scribbles,
and in 3D the helix, the figure eight, 8 random 3D scribbles (``test/support/shapes.py``). Each is
learned once; for each of 3 starts (other quadrants/octants, 0.8-1.25 times the demonstrated
distance) and 1, 2 and 3 obstacles, the obstacles are drawn on and near the obstacle-free ET-DMP
plan (``shapes.obstacles_on_path``: radius 3-15 % of the plan's size, centre on the plan at 15-85 %
of its arc length, moved sideways by up to one radius; start and goal kept clear). A second set
of the same radii lies beside the plan, each at least its radius plus 3 % of the size from it
("far": it must change nothing).

Methods, all in ET-DMP's virtual situation (obstacles transformed, Eq. 23), same skill and
integrator (exact zero-order-hold steps of the linear part, 4 sub-steps per output sample; the
coupling term held over a sub-step):

- ``paper``: the package's Eq. 22-27 point-obstacle coupling (``avoidance='paper'``, its
  default gains; radii unknown to it), margin 0.5 tau;
- ``hoffmann``: Hoffmann et al. 2009's steering angle as movement-primitives'
  ``CouplingTermObstacleAvoidance2D/3D`` computes it (gamma 1000, beta 20/pi, the velocity
  ``dx/dt``, summed over obstacles, no safe region), point obstacles;
- ``ginesi-static``: Ginesi et al. 2019's volumetric potential ``U = A exp(-eta C) / C`` on the
  superquadric isopotential ``C = sum_i ((x_i - c_i) / r)^2 - 1`` (a ball of the obstacle's
  radius), ``A = 10, eta = 1`` (their demo);
- ``ginesi-dynamic``: Ginesi et al. 2021's dynamic potential
  ``U = lambda (-cos theta)^beta |v| / C^eta`` for ``theta > pi/2`` (``cos theta`` between
  ``grad C`` and ``v``), ``lambda = 10, beta = 2, eta = 0.5`` (their demo);
- ``cbf``: a control-barrier-function safety filter on the DMP's acceleration (design (b) of
  the issue): the smallest change along ``(x - c)/|x - c|`` that keeps
  ``ddh + 2 w dh + w^2 h >= 0`` for ``h = |x - c| - r``, w = 4 sqrt(K)/tau;
- ``detour``: the package's default (``avoidance='detour'``, docs/design.md#obstacles-with-a-
  size).

The potentials' gains are for Ginesi's K = 1050 and shapes of size ~1: they are applied to the
movement normalised by its size and K (``lambda = L (K / 1050) phi(x / L, v / L)``). Each
coupling method's gain is then scaled by the factor (0.25, 1, 4, 16) that does best (fewest
collisions, then smallest median shape deviation) on a tuning set of the built-in letters G, P,
R, W and the stir, which is not part of the evaluation; the factor is printed.

Metrics per case: collision (any sample closer to a centre than its radius), shape deviation
(RMS distance between the plan and the obstacle-free plan, both resampled to 500 points by arc
length, over the plan's size), goal error (|x(end) - g| over the size), far change (largest
|x - x_free| over the size with the far obstacles), peak acceleration over the obstacle-free
plan's, time per plan. "rim push" is a reference, not a method: every sample inside an obstacle
moved radially to its rim (the least any method can change the shape; not smooth).

Unless ``--no-docs``, a run of every method writes the table over all cases, the detour's 2D
and 3D rows and the check of Hoffmann's term into docs/design.md (block ``obstacles``) with the
command, date, machine and code version (``_results.publish``).
"""

import argparse
from dataclasses import replace
import json
import os
from pathlib import Path
import sys
import time

from etdmp_ros.dmp import builtin_demo, GeneralizationError, learn, ObstacleGains
from etdmp_ros.dmp._integrate import discretize
import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / 'test'))
sys.path.insert(0, str(REPO / 'test' / 'benchmarks'))
from _results import add_option, command, publish  # noqa: E402, I100
from support import drawings, shapes  # noqa: E402, I100  (test helpers)

N_OUT = 1000            # output steps per tau
SUBSTEPS = 4
RESAMPLE = 500
STARTS_2D = ((70.0, 0.8), (160.0, 1.0), (250.0, 1.25))
OBSTACLE_COUNTS = (1, 2, 3)
SCALES = (0.25, 1.0, 4.0, 16.0)
COUPLED = ('paper', 'hoffmann', 'ginesi-static', 'ginesi-dynamic', 'cbf')
METHODS = COUPLED + ('detour',)
GINESI_K = 1050.0


# --------------------------------------------------------------------------------- shapes

def evaluation_shapes(quick=False):
    """Return (group, name, positions, t) of the held-out shapes."""
    out = []
    names = shapes.lasa_names()
    for name in names[::6] if quick else names:
        rec = shapes.lasa(name)
        out.append(('2D', rec.name, rec.positions, rec.t))
    z = drawings.letter_z()
    out.append(('2D', 'drawn Z', z * np.array([1.0, -1.0]), np.arange(len(z)) / 60.0))
    for seed in range(2 if quick else 8):
        rec = shapes.scribble(seed, 2)
        out.append(('2D', rec.name, rec.positions, rec.t))
    for rec in (shapes.helix(), shapes.figure_eight_3d()):
        out.append(('3D', rec.name, rec.positions, rec.t))
    for seed in range(2 if quick else 8):
        rec = shapes.scribble(100 + seed, 3)
        out.append(('3D', rec.name, rec.positions, rec.t))
    return out


def tuning_shapes():
    """Return the built-in demonstrations the coupling gains are tuned on."""
    out = []
    for name in ('G', 'P', 'R', 'W', 'stir'):
        demo = builtin_demo(name)
        out.append(('3D' if demo.dim == 3 else '2D', 'builtin ' + name, demo.positions, demo.t))
    return out


def _rotation(d, angle, rng):
    if d == 2:
        c, s = np.cos(angle), np.sin(angle)
        return np.array([[c, -s], [s, c]])
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def make_cases(shape_list, seed=0):
    """Learn each shape; draw starts and obstacles; return the cases (dicts)."""
    rng = np.random.default_rng(seed)
    cases = []
    for group, name, positions, t in shape_list:
        skill = learn(positions, t=t)
        d = skill.dim
        dt = skill.tau / N_OUT
        goal = skill.goal.copy()
        for angle, factor in STARTS_2D:
            R = _rotation(d, np.radians(angle), rng)
            start = goal + factor * R @ (skill.start - skill.goal)
            free = skill.generalize(start, goal, dt=dt)
            for count in OBSTACLE_COUNTS:
                try:
                    centres, radii = shapes.obstacles_on_path(free.x, rng, count,
                                                              keep_clear=(start, goal))
                    far, far_radii = shapes.obstacles_on_path(free.x, rng, count, far=True,
                                                              keep_clear=(start, goal))
                except ValueError:
                    continue
                cases.append({'group': group, 'name': name, 'skill': skill, 'start': start,
                              'goal': goal, 'dt': dt, 'centres': centres, 'radii': radii,
                              'far': far, 'far_radii': far_radii, 'count': count})
    return cases


# ------------------------------------------------------------------------------ couplings

def _as3(a):
    if a.shape[-1] == 3:
        return a
    return np.concatenate([a, np.zeros(a.shape[:-1] + (1,))], axis=-1)


def hoffmann(x, xd, centres, radii, scale, size, K):
    """Steering angle (Hoffmann et al. 2009) as movement-primitives computes it, summed."""
    gamma, beta = 1000.0 * scale, 20.0 / np.pi
    d = x.shape[-1]
    to_obs = centres - x[:, None]                                       # (B, m, d)
    r = np.cross(_as3(to_obs), _as3(xd)[:, None])                       # (B, m, 3)
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    r_hat = np.where(rn > 0.0, r / np.maximum(rn, 1e-300), 0.0)
    turned = np.cross(r_hat, _as3(xd)[:, None])[..., :d]                # R(pi/2) yd
    cos = np.einsum('bmi,bi->bm', to_obs, xd) / (
        np.linalg.norm(to_obs, axis=-1) * np.linalg.norm(xd, axis=-1)[:, None] + 1e-10)
    theta = np.arccos(np.clip(cos, -1.0, 1.0))
    return np.sum(gamma * turned * (theta * np.exp(-beta * theta))[..., None], axis=1)


def _isopotential(x, centres, radii):
    w = (x[:, None] - centres) / radii[..., None]
    C = np.sum(w * w, axis=-1) - 1.0
    grad = 2.0 * w / radii[..., None]
    return C, grad


def ginesi_static(x, v, centres, radii, scale, size, K):
    """-grad of U = A exp(-eta C) / C, in the size-normalised movement (Ginesi et al. 2019)."""
    A, eta = 10.0 * scale, 1.0
    y, cy, ry = x / size[:, None], centres / size[:, None, None], radii / size[:, None]
    C, grad = _isopotential(y, cy, ry)
    C = np.maximum(C, 1e-6)           # inside the obstacle: the potential is undefined
    phi = (A * np.exp(-eta * C) * (eta / C + 1.0 / C ** 2))[..., None] * grad
    return size[:, None] * K / GINESI_K * np.sum(phi, axis=1)


def ginesi_dynamic(x, v, centres, radii, scale, size, K):
    """-grad of U = lambda (-cos theta)^beta |v| / C^eta for theta > pi/2 (Ginesi et al. 2021)."""
    lam, beta, eta = 10.0 * scale, 2.0, 0.5
    y, cy, ry = x / size[:, None], centres / size[:, None, None], radii / size[:, None]
    vy = v / size[:, None]
    C, grad = _isopotential(y, cy, ry)
    C = np.maximum(C, 1e-6)
    speed = np.linalg.norm(vy, axis=-1)[:, None]                        # (B, 1)
    gnorm = np.linalg.norm(grad, axis=-1)                               # (B, m)
    gv = np.einsum('bmi,bi->bm', grad, vy)
    cos = gv / np.maximum(gnorm * speed, 1e-300)
    # grad_x cos: H v / (|grad||v|) - cos H grad / |grad|^2, with the Hessian H = 2 I / r^2.
    hess = (2.0 / ry ** 2)[..., None]
    dcos = (hess * vy[:, None] / np.maximum(gnorm * speed, 1e-300)[..., None]
            - (cos / np.maximum(gnorm ** 2, 1e-300))[..., None] * hess * grad)
    active = (cos < 0.0) & (speed > 0.0)
    base = lam * speed * np.where(active, (-cos) ** (beta - 1.0), 0.0) * C ** (-eta)
    # grad U = base [ -beta grad cos - eta (-cos) grad C / C ]
    gradU = base[..., None] * (-beta * dcos + (eta * cos / C)[..., None] * grad)
    phi = np.sum(np.where(active[..., None], -gradU, 0.0), axis=1)
    return size[:, None] * K / GINESI_K * phi


def cbf(x, v, centres, radii, scale, size, K, tau, nominal):
    """Return the smallest radial change of the acceleration that keeps the barrier condition."""
    w = 4.0 * np.sqrt(K) / tau * scale
    xd = v / tau
    acc = nominal / tau ** 2                                             # d2x/dt2 nominal
    extra = np.zeros_like(x)
    for j in range(centres.shape[1]):
        rel = x - centres[:, j]
        dist = np.linalg.norm(rel, axis=-1)
        n = rel / np.maximum(dist, 1e-300)[:, None]
        h = dist - radii[:, j]
        hd = np.sum(n * xd, axis=-1)
        tangential = (np.sum(xd * xd, axis=-1) - hd ** 2) / np.maximum(dist, 1e-300)
        need = -2.0 * w * hd - w * w * h - tangential
        have = np.sum(n * (acc + extra), axis=-1)
        extra += np.maximum(need - have, 0.0)[:, None] * n
    return extra * tau ** 2


def coupled_rollout(skill, starts, goal, centres, radii, method, scale, dt, margin):
    """Roll out B starts with a coupling term, in the virtual situation; return x, v, a real."""
    B, d = starts.shape
    tau = skill.tau
    n_out = int(round(tau * (1.0 + margin) / dt)) + 1
    goals = np.broadcast_to(goal, (B, d))
    transform, x, A, M = skill._placement(starts, goals, 'etdmp', 1, 2)
    R = transform.R
    cv = np.einsum('bij,bmj->bmi', R, centres - goal) + goal
    s_mid, f_mid, s_out, f_out = skill._forcing_table(tau, dt, n_out, SUBSTEPS)
    phi, gam = discretize(skill.K, skill.D, tau, dt / SUBSTEPS)
    size = np.max(np.linalg.norm(skill.demo - skill.goal, axis=1)) * \
        np.linalg.norm(starts - goal, axis=1) / np.linalg.norm(skill.start - skill.goal)
    X, V, Acc = (np.empty((B, n_out, d)) for _ in range(3))
    v = np.zeros((B, d))
    K, D = skill.K, skill.D

    def coupling(x, v, j):
        if method == 'hoffmann':
            return hoffmann(x, v / tau, cv, radii, scale, size, K)
        if method == 'ginesi-static':
            return ginesi_static(x, v, cv, radii, scale, size, K)
        if method == 'ginesi-dynamic':
            return ginesi_dynamic(x, v, cv, radii, scale, size, K)
        nominal = K * (goals - x) - D * v + A * s_mid[j] + M * f_mid[j]
        return cbf(x, v, cv, radii, scale, size, K, tau, nominal)

    for i in range(n_out):
        lam = coupling(x, v, min(i * SUBSTEPS, len(s_mid) - 1)) if i < n_out - 1 else 0.0
        X[:, i], V[:, i] = x, v / tau
        Acc[:, i] = (K * (goals - x) - D * v + A * s_out[i] + M * f_out[i] + lam) / tau ** 2
        if i == n_out - 1:
            break
        for j in range(i * SUBSTEPS, (i + 1) * SUBSTEPS):
            lam = coupling(x, v, j)
            u = K * goals + A * s_mid[j] + M * f_mid[j] + lam
            x, v = (phi[0, 0] * x + phi[0, 1] * v + gam[0] * u,
                    phi[1, 0] * x + phi[1, 1] * v + gam[1] * u)
            if not np.all(np.isfinite(x)):
                x = np.nan_to_num(x, nan=1e9, posinf=1e9, neginf=-1e9)
                v = np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0)
    g = goals[:, None]
    return (X - g) @ R + g, V @ R, Acc @ R


# -------------------------------------------------------------------------------- metrics

def shape_deviation(x, free, size):
    """RMS distance of the two plans resampled by arc length, over the size."""
    return shapes.shape_deviation(x, free, size, RESAMPLE)


def penetration(x, centres, radii):
    """Return the deepest sample inside an obstacle, as a fraction of its radius (0: none)."""
    dist = np.linalg.norm(x[:, None] - centres[None], axis=2)
    return float(np.max(np.maximum(radii - dist, 0.0) / radii))


def rim_push(x, centres, radii):
    """Move every sample inside an obstacle radially to its rim (a reference)."""
    y = x.copy()
    for c, r in zip(centres, radii):
        rel = y - c
        dist = np.linalg.norm(rel, axis=1)
        inside = dist < r
        y[inside] = c + rel[inside] / np.maximum(dist[inside], 1e-300)[:, None] * r
    return y


# ---------------------------------------------------------------------------------- runs

def _margin(method):
    return 0.0 if method == 'detour' else 0.5


def _obstacles(case, far):
    return (case['far'], case['far_radii']) if far else (case['centres'], case['radii'])


def run_core(case, method, scale, far=False):
    """Plan with the package's own avoidance; return (x, a, seconds, refusal)."""
    centres, radii = _obstacles(case, far)
    kwargs = {'obstacles': centres, 'dt': case['dt'], 'avoidance': method}
    if method == 'detour':
        kwargs['obstacle_radii'] = radii
    elif scale != 1.0:
        gains = ObstacleGains()
        kwargs['gains'] = replace(gains, gamma=gains.gamma * scale, gamma2=gains.gamma2 * scale)
    t0 = time.perf_counter()
    try:
        traj = case['skill'].generalize(case['start'], case['goal'], **kwargs)
    except GeneralizationError as err:
        return None, None, time.perf_counter() - t0, str(err)
    return traj.x, traj.a, time.perf_counter() - t0, None


def run_group(cases, method, scale, far=False):
    """Return per-case (x, a, seconds, refusal) of one method."""
    if method in ('paper', 'detour'):
        return [run_core(case, method, scale, far) for case in cases]
    # The coupling terms of this script: one batch per skill (padded to its most obstacles).
    by_skill = {}
    for i, case in enumerate(cases):
        by_skill.setdefault(id(case['skill']), []).append(i)
    results = [None] * len(cases)
    for idx in by_skill.values():
        group = [cases[i] for i in idx]
        skill = group[0]['skill']
        m = max(c['count'] for c in group)
        centres = np.full((len(group), m, skill.dim), 1e6)
        radii = np.ones((len(group), m))
        for b, case in enumerate(group):
            c, r = _obstacles(case, far)
            centres[b, :len(c)], radii[b, :len(r)] = c, r
        starts = np.array([c['start'] for c in group])
        t0 = time.perf_counter()
        with np.errstate(all='ignore'):
            X, _, Acc = coupled_rollout(skill, starts, group[0]['goal'], centres, radii, method,
                                        scale, group[0]['dt'], _margin(method))
        each = (time.perf_counter() - t0) / len(group)
        for b, i in enumerate(idx):
            results[i] = (X[b], Acc[b], each, None)
    return results


def _free(case, margin):
    free = case['skill'].generalize(case['start'], case['goal'], dt=case['dt'], margin=margin)
    return free, float(np.max(np.linalg.norm(free.x - case['goal'], axis=1)))


def _row(case, seconds, refused):
    return {'group': case['group'], 'name': case['name'], 'count': case['count'],
            'seconds': seconds, 'refused': refused}


def evaluate(cases, method, scale, far=True):
    """Return the per-case metrics of ``method`` at gain ``scale`` (``far``: also far ones)."""
    near = run_group(cases, method, scale)
    far_runs = run_group(cases, method, scale, far=True) if far else [None] * len(cases)
    rows = []
    for case, (x, a, seconds, refused), far_run in zip(cases, near, far_runs):
        free, size = _free(case, _margin(method))
        row = _row(case, seconds, refused)
        if refused is None and np.all(np.isfinite(x)):
            row.update(
                collision=penetration(x, case['centres'], case['radii']) > 0.0,
                deviation=shape_deviation(x, free.x, size),
                goal=float(np.linalg.norm(x[-1] - case['goal']) / size),
                acc=float(np.max(np.linalg.norm(a, axis=1))
                          / np.max(np.linalg.norm(free.a, axis=1))))
        elif refused is None:
            row.update(collision=True, deviation=np.inf, goal=np.inf, acc=np.inf)
        row['far'] = np.nan
        if far_run is not None:
            xf, refused_far = far_run[0], far_run[3]
            row['far'] = (float(np.max(np.linalg.norm(xf - free.x, axis=1)) / size)
                          if refused_far is None and np.all(np.isfinite(xf)) else np.inf)
        rows.append(row)
    return rows


def reference_rows(cases, kind):
    """
    Return rows that are not methods: ``kind`` "rim push" or "free".

    ``rim push``: every sample inside an obstacle moved radially to its rim, the least any
    method could change the shape (not smooth). ``free``: the obstacle-free plan to tau, whose
    goal error (and in ``far`` at 1.5 tau) says what the DMP itself does there.
    """
    rows = []
    for case in cases:
        free, size = _free(case, 0.0)
        row = _row(case, np.nan, None)
        row.update(collision=False, acc=np.nan, far=np.nan)
        if kind == 'rim push':
            pushed = rim_push(free.x, case['centres'], case['radii'])
            row.update(deviation=shape_deviation(pushed, free.x, size), goal=0.0)
        else:
            late, _ = _free(case, 0.5)
            row.update(deviation=0.0, goal=float(np.linalg.norm(free.x[-1] - case['goal']) / size),
                       far=float(np.linalg.norm(late.x[-1] - case['goal']) / size),
                       collision=penetration(free.x, case['centres'], case['radii']) > 0.0)
        rows.append(row)
    return rows


def summary(rows, group=None):
    """Aggregate per-case rows (of a group, or all)."""
    rows = [r for r in rows if group is None or r['group'] == group]
    done = [r for r in rows if r['refused'] is None]

    def pick(key, rows=done):
        return np.array([r[key] for r in rows], dtype=float)

    def q(a, p):
        a = a[~np.isnan(a)]
        return float(np.percentile(a, p)) if len(a) else np.nan

    return {'cases': len(rows), 'refused': len(rows) - len(done),
            'collisions': int(sum(bool(r['collision']) for r in done)),
            'dev_median': q(pick('deviation'), 50), 'dev_p90': q(pick('deviation'), 90),
            'goal_median': q(pick('goal'), 50), 'goal_max': q(pick('goal'), 100),
            'far_median': q(pick('far', rows), 50), 'far_max': q(pick('far', rows), 100),
            'acc_median': q(pick('acc'), 50), 'acc_p90': q(pick('acc'), 90),
            'ms': q(pick('seconds', rows), 50) * 1e3}


def tune(cases, method):
    """Return the gain scale that does best on the tuning cases."""
    scores = {scale: summary(evaluate(cases, method, scale, far=False)) for scale in SCALES}
    return min(SCALES, key=lambda k: (scores[k]['collisions'] + scores[k]['refused'],
                                      scores[k]['dev_median']))


def check_hoffmann_against_movement_primitives():
    """Compare our Hoffmann term with movement-primitives' on random states (or say why not)."""
    try:
        from movement_primitives.dmp._coupling_terms import (
            obstacle_avoidance_acceleration_2d, obstacle_avoidance_acceleration_3d)
    except ImportError as err:
        return f'movement-primitives not importable ({err}): the Hoffmann term is not checked'
    rng = np.random.default_rng(1)
    worst = 0.0
    for d, theirs in ((2, obstacle_avoidance_acceleration_2d),
                      (3, obstacle_avoidance_acceleration_3d)):
        for _ in range(200):
            y, yd, o = rng.normal(size=d), rng.normal(size=d), rng.normal(size=d)
            ours = hoffmann(y[None], yd[None], o[None, None], np.ones((1, 1)), 1.0, 1.0, 1.0)[0]
            ref = theirs(y, yd, o)
            worst = max(worst, float(np.max(np.abs(ours - ref)) / max(np.abs(ref).max(), 1e-9)))
    return ('Hoffmann term checked against movement-primitives 0.9.1 '
            'obstacle_avoidance_acceleration_2d/_3d on 400 random states: largest relative '
            f'difference {worst:.2e}')


LABELS = {'paper': 'paper Eq. 22-27 (avoidance="paper")', 'hoffmann': 'Hoffmann 2009 steering',
          'ginesi-static': 'Ginesi 2019 static volumetric',
          'ginesi-dynamic': 'Ginesi 2021 dynamic volumetric', 'cbf': 'CBF safety filter',
          'detour': '**detour (default)**', 'rim push': 'rim push (reference, not smooth)',
          'free': 'obstacle-free plan (reference)'}


def table(results, groups):
    """Return the markdown table of every method (and reference) per group."""
    lines = ['| method | gain | group | cases | refused | collisions | shape dev. median | p90 '
             '| goal err. median | max | far change median | max | peak acc. ratio median '
             '| p90 | ms/plan |',
             '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|']
    for (method, scale), rows in results.items():
        for group in groups:
            s = summary(rows, group)
            if not s['cases']:
                continue
            cells = [LABELS[method], '' if scale is None else f'x{scale:g}', group or 'all',
                     s['cases'], s['refused'], s['collisions'], f"{s['dev_median']:.4f}",
                     f"{s['dev_p90']:.4f}", f"{s['goal_median']:.1e}", f"{s['goal_max']:.1e}",
                     f"{s['far_median']:.1e}", f"{s['far_max']:.1e}", f"{s['acc_median']:.2f}",
                     f"{s['acc_p90']:.2f}", f"{s['ms']:.2f}"]
            lines.append('| ' + ' | '.join(str(c) for c in cells) + ' |')
    return '\n'.join(lines)


NOTES = """\
- shape dev.: RMS distance between the plan and the obstacle-free plan, both resampled to 500
  points by arc length, over the plan's size (its largest distance from the goal); goal err.:
  |x(end) - g| over the size, at the plan's end (tau for the detour, 1.5 tau for the others);
  far change: the largest |x - x_free| over the size with the obstacles beside the plan (0:
  bit-identical); peak acc. ratio: the plan's largest acceleration over the obstacle-free
  plan's; ms/plan: the core's generalize (paper, detour) or this script's numpy loop per start
  of a batch (the others: not comparable).
- obstacle-free plan: goal err. at tau, and in the far column at 1.5 tau (every plan comes
  to rest at its goal by tau and stays there: make bench-rest), so the goal errors of the
  methods that need 1.5 tau are their own; collisions: the cases whose obstacle-free plan
  enters an obstacle (all of them, by construction)."""


def main(argv=None):
    """Run the benchmark; print the table."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='a few shapes only (smoke run)')
    parser.add_argument('--json', metavar='PATH', help='also write the per-case rows to PATH')
    parser.add_argument('--methods', default=','.join(METHODS),
                        help=f'comma-separated subset of {",".join(METHODS)}')
    add_option(parser)
    args = parser.parse_args(argv)
    methods = [m for m in args.methods.split(',') if m]
    load = os.getloadavg()[0]
    wall = time.perf_counter()
    tuning = make_cases(tuning_shapes(), seed=1)
    cases = make_cases(evaluation_shapes(args.quick), seed=0)
    print('# Obstacles with a size: avoidance methods on held-out shapes\n')
    print(f'{len(cases)} cases ({sum(c["group"] == "2D" for c in cases)} 2D, '
          f'{sum(c["group"] == "3D" for c in cases)} 3D) on '
          f'{len({c["name"] for c in cases})} shapes; coupling gains tuned on {len(tuning)} '
          'cases of the built-in demonstrations', flush=True)
    results = {}
    for method in methods:
        scales = [1.0]
        if method in COUPLED:
            best = tune(tuning, method)
            scales = [1.0, best] if method == 'paper' and best != 1.0 else [best]
        for scale in scales:
            results[(method, scale)] = evaluate(cases, method, scale)
            print(f'- {method} x{scale:g} done ({time.perf_counter() - wall:.0f} s)', flush=True)
    results[('rim push', None)] = reference_rows(cases, 'rim push')
    results[('free', None)] = reference_rows(cases, 'free')
    print()
    print(table(results, ('2D', '3D', None)))
    checked = check_hoffmann_against_movement_primitives()
    print('\n' + checked)
    print('\n' + NOTES)
    seconds = time.perf_counter() - wall
    print(f'\nwall time {seconds:.0f} s')
    if not args.no_docs and set(methods) == set(METHODS):
        groups = {g: sum(c['group'] == g for c in cases) for g in ('2D', '3D')}
        head = (f'{len(cases)} cases ({groups["2D"]} 2D, {groups["3D"]} 3D) on '
                f'{len({c["name"] for c in cases})} shapes; the detour in each group:')
        detour = {key: rows for key, rows in results.items() if key[0] == 'detour'}
        publish('obstacles', f'{table(results, (None,))}\n\n{head}\n\n'
                f'{table(detour, ("2D", "3D"))}\n\n{checked}. Wall time {seconds:.0f} s.',
                command('obstacles', argv), page='docs/design.md', load=load)
    if args.json:
        out = {f'{m} x{s}': rows for (m, s), rows in results.items()}
        Path(args.json).write_text(json.dumps(out, indent=1, default=float) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""
Core benchmark: etdmp_ros.dmp side by side with movement-primitives and pydmps.

A script, not a pytest test (its name does not start with ``test_``, so pytest never collects it).
It runs in its own environment, ``.venv-bench/`` at the repository root, so the peer libraries
never enter the project's ``.venv/``::

    make bench-core

or by hand, from the repository root::

    python3 -m venv .venv-bench
    .venv-bench/bin/pip install -r requirements.txt -r test/benchmarks/requirements-bench.txt
    .venv-bench/bin/pip install --no-deps -e .
    .venv-bench/bin/python test/benchmarks/bench_core.py [--json PATH] [--quick]

Workload (same for every library): the letter G demonstration (``../shared/data/pbdlib_2Dletters/
G_00.csv``, 200 samples over tau = 1 s; the built-in ``builtin_demo("G")`` when the data set is
absent), K = 156.25, D = 25, 100 basis functions, rollouts of 1000 steps (dt = 1 ms over tau = 1 s)
from a start in another quadrant than the demo's (paper Table 2), 0 or 2 point obstacles placed
near the ET-DMP path, and a batch of 256 starts around the goal. Each row reports the median and
the 90th percentile of wall-clock time (``time.perf_counter``) after warm-up calls; the first
(cold) call of ours, which includes numba compilation or cache loading, is printed separately.
The script prints a markdown table with ratios (fastest peer / ours) and exits 0 whatever the
outcome, unless ``--strict`` is given (then 1 when a target is missed).

Online section (ours only, no peer has it; docs/design.md#online-goal): the cost of one
``OnlineRun.step`` on the same workload (G, dt = 1 ms, tau = 1 s), p50 and p99 over every step of
several runs, for a step with a goal that stands still, a step with a new goal every step and a
step with phase stopping (``actual`` given and lagging); target <= 2 ms. Then the comparison of
three ways to handle a goal that jumps at 40 % of the movement (``compare_goal_jump``) for the
built-in G, W and stir.

Orientation section (docs/orientation.md): on the built-in stir (with orientations), learn and
generalize with orientation vs position only, and vs movement-primitives' ``CartesianDMP`` (Ude et
al. 2014) on the same demonstration: time and orientation reproduction error, the error at the end
of a goal-orientation rollout, and ET-DMP's turned orientation against the reproduction turned by
the transform. Without movement-primitives its column shows n/a and a line says why.
"""

import argparse
import gc
import importlib.metadata
import json
import os
from pathlib import Path
import platform
import sys
import time

from _results import _cpu_model, add_option, command, printed, publish
from etdmp_ros.dmp import (builtin_demo, clearance, compare_goal_jump, goal_jump_case,
                           GOAL_JUMP_WAYS, learn, nrmse)
import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[2]
DEMO_CSV = REPO_ROOT.parent / 'shared' / 'data' / 'pbdlib_2Dletters' / 'G_00.csv'

K = 156.25
D = 25.0
N_BASIS = 100
ALPHA = 4.0
TAU = 1.0
N_STEPS = 1000
DT = TAU / N_STEPS
# Paper Table 2, letter G, quadrant II start (the demo starts in quadrant I).
TABLE2_START = np.array([-3.40, 3.10])
TABLE2_GOAL = np.array([0.11, -0.51])
N_BATCH = 256
OBSTACLE_FRACTIONS = (0.3, 0.6)
OBSTACLE_OFFSET = 0.02   # sideways offset from the path, as a fraction of |start - goal|
OBSTACLE_RADIUS = 0.05   # radius of the same obstacles for the detour, same unit

PEERS = ('movement-primitives', 'pydmps')
ONLINE_LIMIT_MS = 2.0
ONLINE_SKILLS = ('G', 'W', 'stir')


# --------------------------------------------------------------------------------------------
# Timing

def _stats(samples):
    ms = np.asarray(samples) * 1e3
    return {'median_ms': float(np.median(ms)), 'p90_ms': float(np.percentile(ms, 90)),
            'n': int(ms.size)}


def _time(fn, repeats, warmup=2):
    """Median and p90 of ``repeats`` timed calls of ``fn`` after ``warmup`` untimed ones."""
    for _ in range(warmup):
        fn()
    gc.collect()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return _stats(samples)


def _cold(fn):
    t0 = time.perf_counter()
    result = fn()
    return (time.perf_counter() - t0) * 1e3, result


# --------------------------------------------------------------------------------------------
# Workload

def _load_demo(use_builtin=False):
    """Positions (T, 2), timestamps (T,) over tau, start, goal and where the demo came from."""
    if DEMO_CSV.is_file() and not use_builtin:
        positions = np.loadtxt(DEMO_CSV, delimiter=',', skiprows=1)
        t = np.linspace(0.0, TAU, len(positions))
        return positions, t, TABLE2_START, TABLE2_GOAL, str(DEMO_CSV)
    demo = builtin_demo('G')
    positions = np.array(demo.positions, dtype=float)
    t = np.array(demo.t, dtype=float)
    t = (t - t[0]) * (TAU / (t[-1] - t[0]))
    # The built-in G has its own units: keep Table 2's start direction, scaled to this demo.
    goal = positions[-1].copy()
    direction = (TABLE2_START - TABLE2_GOAL) / np.linalg.norm(TABLE2_START - TABLE2_GOAL)
    start = goal + np.linalg.norm(positions[0] - goal) * direction
    why = 'forced by --builtin-demo' if use_builtin else f'{DEMO_CSV} not found'
    return positions, t, start, goal, f'builtin_demo("G") ({why}; time rescaled to tau = 1 s)'


def _obstacles_near(path, start, goal):
    """
    Two obstacles beside ``path`` at 30 % and 60 % of its samples, slightly off the path.

    Exactly on the path the velocity is parallel to ``o - x`` (a degenerate case of the coupling);
    a small sideways offset keeps the benchmark on the ordinary code path of every library.
    """
    offset = OBSTACLE_OFFSET * np.linalg.norm(start - goal)
    obstacles = []
    for fraction in OBSTACLE_FRACTIONS:
        i = int(round(fraction * (len(path) - 1)))
        tangent = path[min(i + 1, len(path) - 1)] - path[max(i - 1, 0)]
        normal = np.array([-tangent[1], tangent[0]]) / max(np.linalg.norm(tangent), 1e-12)
        obstacles.append(path[i] + offset * normal)
    return np.array(obstacles)


def _batch_starts(start, goal, n):
    """``n`` starts around ``goal`` in every direction, at 0.5-1.5 times |start - goal|."""
    rng = np.random.default_rng(0)
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    radius = np.linalg.norm(start - goal) * rng.uniform(0.5, 1.5, n)
    return goal + radius[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])


def _sanity(path, goal, demo, obstacles=None):
    """Numbers that show a rollout is sane: final distance to goal, shape error, clearance."""
    path = np.asarray(path)
    result = {'finite': bool(np.isfinite(path).all()),
              'final_dist': float(np.linalg.norm(path[-1] - goal))}
    try:
        result['nrmse'] = float(nrmse(path, demo))
    except ValueError as error:   # e.g. a diverged rollout
        result['nrmse'] = f'n/a ({error})'
    if obstacles is not None and len(obstacles):
        result['clearance'] = float(clearance(path, obstacles))
    return result


# --------------------------------------------------------------------------------------------
# Ours

class _Ours:
    """etdmp_ros.dmp: ``learn`` and ``Skill.generalize`` (one call per rollout or batch)."""

    name = 'ours'

    def __init__(self, positions, t):
        self.positions, self.t = positions, t
        self.skill = None

    def learn(self):
        self.skill = learn(self.positions, t=self.t, n_basis=N_BASIS, K=K, D=D, alpha=ALPHA)
        return self.skill

    def rollout(self, start, goal, obstacles=(), method='etdmp', radii=None):
        return self.skill.generalize(start, goal, obstacles=obstacles, method=method,
                                     dt=DT, tau=TAU, obstacle_radii=radii).x

    def batch(self, starts, goal, method='etdmp', obstacles=(), radii=None):
        return self.skill.generalize(starts, goal, method=method, dt=DT, tau=TAU,
                                     obstacles=obstacles, obstacle_radii=radii).x


# --------------------------------------------------------------------------------------------
# movement-primitives (dfki-ric)

class _SummedCoupling:
    """Sum of movement-primitives coupling terms (its obstacle term takes one obstacle)."""

    def __init__(self, terms):
        self.terms = terms

    def coupling(self, y, yd):
        cd = np.zeros_like(y)
        cdd = np.zeros_like(y)
        for term in self.terms:
            d, dd = term.coupling(y, yd)
            cd += d
            cdd += dd
        return cd, cdd


class _MovementPrimitives:
    """
    movement-primitives ``DMP``: ``imitate`` and ``open_loop`` (its default RK4 Cython step).

    Its transformation system is ``tau^2 ydd = alpha_y (beta_y (g - y) - tau yd) + f + C_t``, so
    alpha_y = D = 25 and beta_y = K / D = 6.25 give the same K and D as ours.
    """

    name = 'movement-primitives'

    def __init__(self, positions, t):
        from movement_primitives.dmp import CouplingTermObstacleAvoidance2D, DMP
        self._dmp_class = DMP
        self._coupling_class = CouplingTermObstacleAvoidance2D
        self.positions, self.t = positions, t
        self.dmp = None

    def learn(self):
        dmp = self._dmp_class(n_dims=2, execution_time=TAU, dt=DT, n_weights_per_dim=N_BASIS,
                              int_dt=DT, alpha_y=D, beta_y=K / D)
        dmp.imitate(self.t, self.positions)
        self.dmp = dmp
        return dmp

    def rollout(self, start, goal, obstacles=()):
        self.dmp.configure(start_y=start, goal_y=goal)
        coupling = None
        if len(obstacles):
            # Its own default gains (Hoffmann's gamma = 1000, beta = 20/pi).
            coupling = _SummedCoupling([
                self._coupling_class(np.asarray(o, dtype=float), fast=True) for o in obstacles])
        return self.dmp.open_loop(coupling_term=coupling)[1]

    def batch(self, starts, goal):
        return np.stack([self.rollout(s, goal) for s in starts])


# --------------------------------------------------------------------------------------------
# pydmps (studywolf)

class _PyDMPs:
    """
    pydmps ``DMPs_discrete``: ``imitate_path`` and ``rollout`` / ``step`` (Euler, dt = 1 ms).

    ``ddy = ay (by (g - y) - dy) + f`` at tau = 1: ay = D = 25, by = K / D = 6.25; its canonical
    gain ax is set to ours (4). pydmps has no coupling-term class: its own example
    (``examples/avoid_obstacles.py``) computes Hoffmann's steering term in numpy at every step and
    passes it as ``step(external_force=...)``; ``_steering`` below does the same computation.
    """

    name = 'pydmps'
    _R_HALF_PI = np.array([[0.0, -1.0], [1.0, 0.0]])
    # The example's gains. Its term is not normalised (it grows with |o - y| |dy|^2), so
    # Hoffmann's gamma = 1000 makes this workload's rollouts diverge.
    GAMMA = 100.0
    BETA = 20.0 / np.pi

    def __init__(self, positions, t):
        import pydmps.dmp_discrete
        self._dmp_class = pydmps.dmp_discrete.DMPs_discrete
        self.positions = positions
        self.dmp = None

    def learn(self):
        dmp = self._dmp_class(n_dmps=2, n_bfs=N_BASIS, dt=DT, ay=np.full(2, D),
                              by=np.full(2, K / D), ax=ALPHA)
        dmp.imitate_path(y_des=self.positions.T.copy())
        self.dmp = dmp
        return dmp

    def _steering(self, y, dy, goal, obstacles):
        """Hoffmann et al. (2009) steering acceleration, as in pydmps' obstacle example."""
        gamma, beta = self.GAMMA, self.BETA
        p = np.zeros(2)
        for obstacle in obstacles:
            to_obstacle = obstacle - y
            if np.linalg.norm(dy) * np.linalg.norm(to_obstacle) <= 1e-5:
                continue
            heading = -np.arctan2(dy[1], dy[0])
            c, s = np.cos(heading), np.sin(heading)
            relative = np.array([[c, -s], [s, c]]) @ to_obstacle
            phi = np.arctan2(relative[1], relative[0])
            dphi = gamma * phi * np.exp(-beta * abs(phi))
            rotation = self._R_HALF_PI @ np.outer(to_obstacle, dy)
            push = -np.nan_to_num(rotation @ dy * dphi)
            # Obstacles farther away than the goal are ignored (the example's safe region).
            if np.linalg.norm(relative) <= np.linalg.norm(goal - y):
                p += push
        return p

    def rollout(self, start, goal, obstacles=()):
        dmp = self.dmp
        dmp.y0 = np.array(start, dtype=float)
        dmp.goal = np.array(goal, dtype=float)
        if not len(obstacles):
            return dmp.rollout()[0]
        obstacles = np.asarray(obstacles, dtype=float)
        dmp.reset_state()
        y_track = np.empty((dmp.timesteps, 2))
        for i in range(dmp.timesteps):
            force = self._steering(dmp.y, dmp.dy, dmp.goal, obstacles)
            y_track[i] = dmp.step(external_force=force)[0]
        return y_track

    def batch(self, starts, goal):
        return np.stack([self.rollout(s, goal) for s in starts])


# --------------------------------------------------------------------------------------------
# Online ET-DMP

def _online_steps(skill, start, goal, runs, kind):
    """
    Wall-clock time of every ``OnlineRun.step`` of ``runs`` runs of N_STEPS steps.

    ``kind``: 'still' (the goal stands still), 'goal' (a new goal at every step, on a circle of
    10 % of |start - goal| about the goal) or 'actual' (phase stopping: the measured position
    lags the plan by 1 % of |start - goal|). The first run is a warm-up and is not counted.
    """
    samples = []
    radius = 0.1 * np.linalg.norm(start - goal)
    for r in range(runs + 1):
        run = skill.online(start, goal, dt=DT, tau=TAU)
        times = []
        for i in range(N_STEPS):
            kwargs = {}
            if kind == 'goal':
                angle = 2.0 * np.pi * i / N_STEPS
                kwargs['goal'] = goal + radius * np.array([np.cos(angle) - 1.0, np.sin(angle)])
            elif kind == 'actual':
                kwargs['actual'] = run.x + np.array([radius * 0.1, 0.0])
            t0 = time.perf_counter()
            run.step(**kwargs)
            times.append(time.perf_counter() - t0)
        if r:
            samples.extend(times)
    ms = np.asarray(samples) * 1e3
    return {'p50_ms': float(np.percentile(ms, 50)), 'p99_ms': float(np.percentile(ms, 99)),
            'max_ms': float(ms.max()), 'n': int(ms.size)}


def _online_table(rows):
    lines = ['| online step (ours; G, dt = 1 ms) | p50 (ms) | p99 (ms) | max (ms) | target '
             '| pass/fail |', '|---|---|---|---|---|---|']
    for r in rows:
        s = r['stats']
        lines.append(f"| {r['name']} | {s['p50_ms']:.3f} | {s['p99_ms']:.3f} "
                     f"| {s['max_ms']:.3f} | p50 and p99 <= {ONLINE_LIMIT_MS:g} ms "
                     f"| {'pass' if r['pass'] else 'FAIL'} |")
    return '\n'.join(lines)


def goal_jump_rows(names=ONLINE_SKILLS):
    """Run the goal-jump comparison (docs/design.md#online-goal) for the built-in ``names``."""
    rows = []
    for name in names:
        skill = learn(builtin_demo(name))
        start, goal, new_goal = goal_jump_case(skill)
        results, reference = compare_goal_jump(skill, start, goal, new_goal)
        top_speed = float(np.max(np.linalg.norm(reference.v, axis=1)))
        top_acc = float(np.max(np.linalg.norm(reference.a, axis=1)))
        for way, r in results.items():
            rows.append({'skill': name, 'way': way, 'size': skill.size,
                         'velocity_step': r.velocity_step, 'top_speed': top_speed,
                         'acceleration_step': r.acceleration_step, 'top_acceleration': top_acc,
                         'final_distance': r.final_distance, 'shape_nrmse': r.shape_nrmse,
                         'shape_error': r.shape_error, 'end_time': r.end_time})
    return rows


def goal_jump_table(rows):
    """Markdown table of :func:`goal_jump_rows`; steps relative to the top speed/acceleration."""
    lines = ['| skill | way | velocity step | acceleration step | final distance '
             '| nRMSE of the rest | distance to placed demo (RMS) | end |',
             '|---|---|---|---|---|---|---|---|']
    for r in rows:
        dv, da = r['velocity_step'], r['acceleration_step']
        lines.append(
            f"| {r['skill']} | {GOAL_JUMP_WAYS[r['way']]} "
            f"| {dv:.3g} ({dv / r['top_speed']:.1%}) "
            f"| {da:.3g} ({da / r['top_acceleration']:.1%})"
            f" | {r['final_distance'] / r['size']:.2e} L | {r['shape_nrmse']:.3f} "
            f"| {r['shape_error']:.3f} | {r['end_time']:.2f} s |")
    return '\n'.join(lines)


GOAL_JUMP_NOTES = """\
Goal jump at 40 % of the movement (compare_goal_jump, goal_jump_case: start = the demo's turned by
25 degrees about the goal and 1.2 times as far; the goal jumps sideways by 30 % of |start - goal|).
Steps: the largest change over one sample in the 3 samples after the switch beyond the unperturbed
movement's change, in units/s and units/s^2 (in brackets: relative to the top speed and
acceleration of the demo placed at the new goal); the acceleration is (v_k+1 - v_k) / dt, so (b)'s
velocity jump shows as the impulse it is. Final distance: |x - g_new| at each way's own nominal end
(tau; for (b) the switch + tau), in units of the demo's size L. nRMSE of the rest: conventional
nRMSE (Eq. 15-16) of the samples after the switch against the same phases of the demo placed at the
new goal (the ET-DMP from the start to the new goal); distance to placed demo: the RMS distance
between the two by phase, without nRMSE's alignment, over the placed demo's size."""


# --------------------------------------------------------------------------------------------
# Orientation (docs/orientation.md)

ORIENTATION_SKILL = 'stir'
ORIENTATION_STEPS = 1000
#: The goal orientation of the "goal" rows: the demo's goal turned 60 degrees about x.
ORIENTATION_GOAL_TURN = np.radians(60.0)


def _wxyz(q):
    """ROS order (x, y, z, w) to pytransform3d's (w, x, y, z)."""
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def _xyzw(q):
    """Pytransform3d's (w, x, y, z) to ROS order (x, y, z, w)."""
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def _orientation_error_deg(q, reference):
    """Max and RMS rotation angle (deg) between quaternions q and reference (n, 4), by sample."""
    from etdmp_ros.geometry.quaternion import angle_between
    angle = np.degrees(angle_between(q, reference))
    return float(angle.max()), float(np.sqrt(np.mean(angle ** 2)))


class _MPCartesian:
    """movement-primitives ``CartesianDMP`` (Ude et al. 2014's quaternion DMP) on the same demo."""

    name = 'movement-primitives CartesianDMP'

    def __init__(self, t, positions, q, dt):
        from movement_primitives.dmp import CartesianDMP
        self._class = CartesianDMP
        self.t, self.dt = t, dt
        self.y = np.hstack([positions, _wxyz(q)])
        self.dmp = None

    def learn(self):
        dmp = self._class(execution_time=float(self.t[-1]), dt=self.dt, n_weights_per_dim=N_BASIS,
                          int_dt=self.dt, alpha_y=D, beta_y=K / D)
        dmp.imitate(self.t, self.y)
        self.dmp = dmp
        return dmp

    def rollout(self, goal_q=None):
        goal = self.y[-1].copy()
        if goal_q is not None:
            goal[3:] = _wxyz(goal_q)
        self.dmp.configure(start_y=self.y[0], goal_y=goal)
        return _xyzw(self.dmp.open_loop()[1][:, 3:])


def orientation_section(repeats, batch_repeats):
    """
    Learn + generalize with orientation vs position only, and vs movement-primitives.

    Workload: the built-in stir (500 samples over 5 s, with orientations), rollouts of
    ORIENTATION_STEPS steps over its 5 s; ET-DMP from a start turned 90 degrees about z and 1.2
    times as far; the goal-orientation rows ask for the demo's goal turned 60 degrees about x.
    Returns (rows, errors, note): timing rows for :func:`_table`, orientation errors (deg), and a
    line saying why movement-primitives is missing, if it is.
    """
    from etdmp_ros.geometry.quaternion import about_axis, from_matrix, multiply
    demo = builtin_demo(ORIENTATION_SKILL)
    t, x, q = np.array(demo.t), np.array(demo.positions), np.array(demo.orientations)
    tau = float(t[-1])
    dt = tau / ORIENTATION_STEPS
    i_d = x[0] - x[-1]
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    start, goal = x[-1] + 1.2 * turn @ i_d, x[-1]
    goal_q = multiply(about_axis([1.0, 0.0, 0.0], ORIENTATION_GOAL_TURN), q[-1])
    starts = _batch_starts_3d(start, goal, N_BATCH)
    note = None
    try:
        peer = _MPCartesian(t, x, q, dt)
    except ImportError as error:
        peer, note = None, (f'movement-primitives: NOT AVAILABLE ({error}); its '
                            'CartesianDMP column shows n/a')

    def ours_learn(with_q):
        return learn(x, q if with_q else None, t=t, n_basis=N_BASIS, K=K, D=D, alpha=ALPHA)

    position_only, oriented = ours_learn(False), ours_learn(True)
    rows = [{'name': f'learn ({ORIENTATION_SKILL}, {len(t)} samples; ours: with orientation)',
             'limit_ms': None, 'ours': _time(lambda: ours_learn(True), repeats),
             'peers': {'movement-primitives': peer and _time(peer.learn, repeats)}},
            {'name': f'learn ({ORIENTATION_SKILL}; ours: position only)', 'limit_ms': None,
             'ours': _time(lambda: ours_learn(False), repeats), 'peers': {}}]
    if peer is not None:
        peer.learn()
    peer_rollout = peer and _time(peer.rollout, repeats)
    peer_goal = peer and _time(lambda: peer.rollout(goal_q), repeats)
    for label, skill, kwargs, peer_stat in (
            ('position only', position_only, {}, None),
            ('with orientation', oriented, {}, peer_rollout),
            ('with a goal orientation', oriented, {'goal_orientation': goal_q}, peer_goal)):
        rows.append({'name': f'rollout {ORIENTATION_STEPS} steps ({ORIENTATION_SKILL}, ours: '
                             f'ET-DMP {label})', 'limit_ms': None,
                     'ours': _time(lambda s=skill, k=kwargs: s.generalize(
                         start, goal, dt=dt, tau=tau, **k), repeats),
                     'peers': {'movement-primitives': peer_stat}})
    for label, skill in (('position only', position_only), ('with orientation', oriented)):
        rows.append({'name': f'batch {N_BATCH} starts x {ORIENTATION_STEPS} steps '
                             f'({ORIENTATION_SKILL}, ours: {label})', 'limit_ms': None,
                     'ours': _time(lambda s=skill: s.generalize(starts, goal, dt=dt, tau=tau),
                                   max(batch_repeats, 5)),
                     'peers': {}})
    for row in rows:
        row['peers'] = {k: v for k, v in row['peers'].items() if v}
        _evaluate(row)

    # Orientation errors (deg): reproduction against the demo (by phase: same sample times),
    # the end of a goal-orientation rollout against that goal, and ET-DMP's turned path
    # against the reproduction turned by the transform.
    times = np.linspace(0.0, tau, ORIENTATION_STEPS + 1)
    demo_q = _resample_quaternions(t, q, times)
    rep = oriented.generalize(x[0], x[-1], method='dmp', dt=dt, tau=tau)
    reached = oriented.generalize(x[0], x[-1], method='dmp', dt=dt, tau=tau,
                                  goal_orientation=goal_q)
    et = oriented.generalize(start, goal, dt=dt, tau=tau)
    turned = multiply(from_matrix(et.rotation.T), rep.q)
    errors = {'ours': {'reproduction_max_deg': _orientation_error_deg(rep.q, demo_q)[0],
                       'reproduction_rms_deg': _orientation_error_deg(rep.q, demo_q)[1],
                       'goal_end_deg': _orientation_error_deg(reached.q[-1:], goal_q[None])[0],
                       'etdmp_turned_residual_deg': _orientation_error_deg(et.q, turned)[0]}}
    if peer is not None:
        peer_q = peer.rollout()
        peer_goal_q = peer.rollout(goal_q)
        n = min(len(peer_q), len(demo_q))
        errors['movement-primitives CartesianDMP'] = {
            'reproduction_max_deg': _orientation_error_deg(peer_q[:n], demo_q[:n])[0],
            'reproduction_rms_deg': _orientation_error_deg(peer_q[:n], demo_q[:n])[1],
            'goal_end_deg': _orientation_error_deg(peer_goal_q[-1:], goal_q[None])[0],
            'etdmp_turned_residual_deg': None}
    return rows, errors, note


def _batch_starts_3d(start, goal, n):
    """``n`` starts around ``goal`` in every direction, at 0.5-1.5 times |start - goal|."""
    rng = np.random.default_rng(0)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = np.linalg.norm(start - goal) * rng.uniform(0.5, 1.5, n)
    return goal + radius[:, None] * direction


def _resample_quaternions(t, q, times):
    """Quaternions (n, 4) at ``times`` by normalised linear interpolation (sign-continuous q)."""
    out = np.column_stack([np.interp(times, t, q[:, i]) for i in range(4)])
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def orientation_tables(rows, errors, note):
    """Markdown tables of :func:`orientation_section`."""
    lines = ['| row | ours (ms) | movement-primitives CartesianDMP (ms) | ratio (peer / ours) |',
             '|---|---|---|---|']
    for r in rows:
        ratio = 'n/a' if r['ratio'] is None else f"{r['ratio']:.1f}x"
        lines.append(f"| {r['name']} | {_cell(r['ours'])} "
                     f"| {_cell(r['peers'].get('movement-primitives'))} | {ratio} |")
    lines += ['', '| orientation error (deg) | reproduction max | reproduction RMS '
              '| goal orientation, at the end | ET-DMP turned vs reproduction turned |',
              '|---|---|---|---|---|']
    for lib, e in errors.items():
        cells = ['n/a' if e[k] is None else f'{e[k]:.3g}' for k in
                 ('reproduction_max_deg', 'reproduction_rms_deg', 'goal_end_deg',
                  'etdmp_turned_residual_deg')]
        lines.append(f"| {lib} | {' | '.join(cells)} |")
    if 'movement-primitives CartesianDMP' not in errors:
        lines.append(f"| movement-primitives CartesianDMP | n/a ({note or 'not run'}) "
                     '| n/a | n/a | n/a |')
    if note:
        lines.append('\n' + note)
    return '\n'.join(lines)


ORIENTATION_NOTES = """\
Orientation workload: built-in stir (500 samples over 5 s, tilted circling stirrer), K = 156.25,
D = 25, 100 basis functions, 1000 steps of 5 ms over tau = 5 s. ours: learn(positions,
orientations) (the quaternion DMP on e = 2 log(q q_g^-1), docs/orientation.md) vs learn(positions);
generalize from a start turned 90 degrees about z (ET-DMP, mode 1) without / with a goal
orientation (the demo's goal turned 60 degrees about x); a batch of 256 starts around the goal.
movement-primitives CartesianDMP (Ude et al. 2014, alpha_y = 25, beta_y = 6.25, 100 weights per
dimension, dt = int_dt = 5 ms): imitate; open_loop from the demo's start pose to its goal pose (or
to the goal orientation); it has no Euclidean transform, so its rollout rows are reproductions
(same step count) and its batch rows are not run. Errors: rotation angle per sample against the
demo resampled at the rollout's times (by phase, same duration), the goal error at the last
sample (t = tau), and the residual of ET-DMP's orientation against the reproduction turned by the
transform (the method's claim: round-off)."""


# --------------------------------------------------------------------------------------------
# Report

def _version(dist):
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        if dist == 'etdmp_ros':   # run from a source tree (PYTHONPATH) rather than installed
            import etdmp_ros
            return getattr(etdmp_ros, '__version__', 'source tree')
        return 'not installed'


def _environment():
    env = {
        'python': platform.python_version(),
        'platform': platform.platform(),
        'cpu': _cpu_model(),
        'cpu_count': os.cpu_count(),
        'cpus_usable': (len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity')
                        else None),
        'versions': {d: _version(d) for d in ('etdmp_ros', 'numpy', 'numba', 'scipy',
                                              'movement-primitives', 'pytransform3d',
                                              'pydmps')},
    }
    for var in ('OPENBLAS_CORETYPE', 'OPENBLAS_L2_SIZE', 'OMP_NUM_THREADS',
                'NUMBA_NUM_THREADS'):
        if var in os.environ:
            env[var] = os.environ[var]
    return env


def _cell(stat):
    if stat is None:
        return 'n/a'
    return f"{stat['median_ms']:.3f} (p90 {stat['p90_ms']:.3f})"


def _evaluate(row):
    peers = [row['peers'][p]['median_ms'] for p in PEERS if row['peers'].get(p)]
    ours = row['ours']['median_ms']
    row['fastest_peer_ms'] = min(peers) if peers else None
    row['ratio'] = (min(peers) / ours) if peers else None
    ok = row['ratio'] is None or row['ratio'] >= 1.0
    if row['limit_ms'] is not None:
        ok = ok and ours <= row['limit_ms']
    row['pass'] = bool(ok)
    return row


def _table(rows):
    lines = ['| row | ours (ms) | movement-primitives (ms) | pydmps (ms) '
             '| ratio (fastest peer / ours) | target | pass/fail |',
             '|---|---|---|---|---|---|---|']
    for r in rows:
        ratio = 'n/a' if r['ratio'] is None else f"{r['ratio']:.1f}x"
        target = '>= fastest peer'
        if r['limit_ms'] is not None:
            target = f"<= {r['limit_ms']:g} ms and {target}"
        lines.append(f"| {r['name']} | {_cell(r['ours'])} "
                     f"| {_cell(r['peers'].get('movement-primitives'))} "
                     f"| {_cell(r['peers'].get('pydmps'))} | {ratio} | {target} "
                     f"| {'pass' if r['pass'] else 'FAIL'} |")
    return '\n'.join(lines)


def _readme_table(rows):
    """Return the README's speed rows: ours (ET-DMP) against the peers, medians in ms."""
    def ms(stat):
        if stat is None:
            return 'n/a'
        value = stat['median_ms']
        return f'{value:.0f} ms' if value >= 10 else f'{value:.2g} ms'
    names = (('(ours: etdmp; peers: loop of 256)', '(theirs: a loop of 256)'),
             (' (ours: etdmp, detour)', ', the detour (theirs: points)'),
             ('2 obstacles (ours: etdmp)', '2 point obstacles'), (' (ours: etdmp)', ''))
    lines = ['| 2D, medians | ours | movement-primitives | pydmps |', '|---|---|---|---|']
    for r in rows:
        if 'ours: dmp' in r['name']:
            continue                                 # the plain DMP's rows: docs/benchmarks.md
        name = r['name']
        for old, new in names:
            name = name.replace(old, new)
        lines.append(f"| {name} | {ms(r['ours'])} | {ms(r['peers'].get('movement-primitives'))}"
                     f" | {ms(r['peers'].get('pydmps'))} |")
    return '\n'.join(lines)


def _print_sanity(sanity):
    print('\nReproduction sanity (every rollout that was timed; final_dist = |x(tau) - g|, '
          'nrmse = conventional nRMSE against the demo, docs/design.md; clearance = min distance '
          'to an obstacle):')
    for case, per_lib in sanity.items():
        print(f'- {case}')
        for lib, values in per_lib.items():
            text = ', '.join(f'{k}={v:.4g}' if isinstance(v, float) else f'{k}={v}'
                             for k, v in values.items())
            print(f'    {lib:20s} {text}')


NOTES = """\
Parameters (same workload for every library; where a peer cannot match, it says so):
- ours: K = 156.25, D = 25, n_basis = 100, alpha = 4, tau = 1 s, generalize(dt = 1 ms):
  1001 samples = 1000 steps. Obstacle coupling = paper Eq. 24 + Eq. 26 (default ObstacleGains);
  the detour row: the same two obstacles with a radius (docs/design.md#obstacles-with-a-size;
  the peers' columns there are their point-obstacle rollouts, for scale).
- movement-primitives: alpha_y = 25, beta_y = 6.25 (same K and D), 100 weights per dim,
  execution_time = 1, dt = int_dt = 1 ms (1000 RK4 Cython steps, its default step function).
  Cannot match: canonical alpha_z is fixed so that z(tau) = 0.01 (alpha_z = 4.61 vs ours 4),
  basis widths fixed by overlap 0.8, forcing term not scaled by (g - y0) (its formulation).
  Obstacles: one CouplingTermObstacleAvoidance2D(fast=True, its default gamma = 1000,
  beta = 20/pi) per obstacle, summed (the class takes a single obstacle), passed to
  open_loop(coupling_term=...).
- pydmps: DMPs_discrete(ay = 25, by = 6.25 (same K and D), n_bfs = 100, ax = 4, dt = 1 ms):
  1000 Euler steps. Cannot match: basis widths are its fixed heuristic; imitate_path resamples
  the demo to 1000 points. Obstacles: no coupling class; its example's Hoffmann steering term
  (examples/avoid_obstacles.py, with its gamma = 100, beta = 20/pi: the term is not normalised
  and diverges here with gamma = 1000) computed in numpy each step and passed as
  step(external_force=...). Neither peer has the paper's Eq. 26 distance term (gamma2, k);
  ours has it. With obstacles the peers' final_dist is at t = tau: their detour may not have
  converged yet (same computation either way).
- Batch of 256 starts: ours in ONE batched generalize call; each peer in a Python loop of 256
  rollouts (neither has a batched rollout). Learning happens once, outside the timing.
- learn row: ours = learn(); movement-primitives = DMP(...) + imitate(); pydmps =
  DMPs_discrete(...) + imitate_path(). Rollout rows include setting start/goal (and building
  the coupling terms) on every call. pass = median of ours meets the target."""


# --------------------------------------------------------------------------------------------
# Main

def _parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--json', metavar='PATH', help='also write all results to PATH')
    parser.add_argument('--repeats', type=int, default=30,
                        help='timed calls per single-rollout/learn row (default 30)')
    parser.add_argument('--batch-repeats', type=int, default=5,
                        help='timed calls per batch row (default 5)')
    parser.add_argument('--quick', action='store_true',
                        help='smoke run: 5 repeats, 1 batch repeat (numbers are noisier)')
    parser.add_argument('--builtin-demo', action='store_true',
                        help='use builtin_demo("G") even when the data set is present')
    parser.add_argument('--strict', action='store_true',
                        help='exit 1 when a target is missed (default: always exit 0)')
    add_option(parser)
    args = parser.parse_args(argv)
    if args.quick:
        args.repeats, args.batch_repeats = 5, 1
    return args


def _make_peers(positions, t):
    peers, missing = {}, {}
    for cls in (_MovementPrimitives, _PyDMPs):
        try:
            peers[cls.name] = cls(positions, t)
        except ImportError as error:
            missing[cls.name] = str(error)
    return peers, missing


def main(argv=None):
    """Run the benchmark, print the report; return the exit status."""
    args = _parse_args(argv)
    load = os.getloadavg()[0]
    wall0 = time.perf_counter()
    env = _environment()
    positions, t, start, goal, demo_source = _load_demo(args.builtin_demo)

    # Cold calls of ours first, in a fresh process: numba compiles (or loads its cache) here.
    ours = _Ours(positions, t)
    cold = {}
    cold['learn'], _ = _cold(ours.learn)
    for method in ('etdmp', 'dmp'):
        cold[f'rollout {method}, 0 obstacles'], free_path = _cold(
            lambda m=method: ours.rollout(start, goal, method=m))
        if method == 'etdmp':
            obstacles = _obstacles_near(free_path, start, goal)
        cold[f'rollout {method}, 2 obstacles'], _ = _cold(
            lambda m=method: ours.rollout(start, goal, obstacles, method=m))
    radii = np.full(len(obstacles), OBSTACLE_RADIUS * np.linalg.norm(start - goal))
    cold['rollout etdmp, 2 obstacles with radii'], _ = _cold(
        lambda: ours.rollout(start, goal, obstacles, radii=radii))
    starts = _batch_starts(start, goal, N_BATCH)
    for method in ('etdmp', 'dmp'):
        cold[f'batch {method}'], _ = _cold(lambda m=method: ours.batch(starts, goal, method=m))

    peers, missing = _make_peers(positions, t)
    rows, sanity = [], {}

    # Learning.
    row = {'name': f'learn (2D, {len(positions)} samples, {N_BASIS} basis)', 'limit_ms': None,
           'ours': _time(ours.learn, args.repeats),
           'peers': {name: _time(p.learn, args.repeats) for name, p in peers.items()}}
    rows.append(_evaluate(row))

    # Each library reproducing its own demo (demo start -> demo goal): shows it learned it right.
    case = 'reproduction (demo start -> demo goal, no obstacles)'
    sanity[case] = {name: _sanity(p.rollout(positions[0], positions[-1]), positions[-1],
                                  positions) for name, p in peers.items()}
    for method in ('etdmp', 'dmp'):
        sanity[case][f'ours ({method})'] = _sanity(
            ours.rollout(positions[0], positions[-1], method=method), positions[-1], positions)

    # Single rollouts, 0 and 2 obstacles.
    for n_obs, limit in ((0, 1.0), (2, 5.0)):
        obs = obstacles if n_obs else np.empty((0, 2))
        peer_stats, case = {}, f'rollout, {n_obs} obstacles'
        sanity[case] = {}
        for name, p in peers.items():
            peer_stats[name] = _time(lambda p=p: p.rollout(start, goal, obs), args.repeats)
            sanity[case][name] = _sanity(p.rollout(start, goal, obs), goal, positions, obs)
        for method in ('etdmp', 'dmp'):
            stat = _time(lambda m=method: ours.rollout(start, goal, obs, method=m), args.repeats)
            sanity[case][f'ours ({method})'] = _sanity(
                ours.rollout(start, goal, obs, method=method), goal, positions, obs)
            rows.append(_evaluate({
                'name': f'rollout {N_STEPS} steps, {n_obs} obstacles (ours: {method})',
                'limit_ms': limit, 'ours': stat, 'peers': peer_stats}))
            if n_obs and method == 'etdmp':
                # Obstacles with a size: the default detour (docs/design.md#obstacles-with-a-size).
                stat = _time(lambda: ours.rollout(start, goal, obs, radii=radii), args.repeats)
                sanity[case]['ours (etdmp, detour)'] = _sanity(
                    ours.rollout(start, goal, obs, radii=radii), goal, positions, obs)
                rows.append(_evaluate({
                    'name': f'rollout {N_STEPS} steps, {n_obs} obstacles of radius '
                            f'{OBSTACLE_RADIUS:g} x the start-goal distance (ours: etdmp, detour)',
                    'limit_ms': 1.0, 'ours': stat, 'peers': peer_stats}))

    # Batch of starts: ours batched, peers looped.
    peer_stats, case = {}, f'batch of {N_BATCH} starts, 0 obstacles (worst over the batch)'
    sanity[case] = {}
    for name, p in peers.items():
        peer_stats[name] = _time(lambda p=p: p.batch(starts, goal), args.batch_repeats, warmup=0)
        finals = [p.rollout(s, goal)[-1] for s in starts[:16]]
        sanity[case][f'{name} (first 16)'] = {
            'finite': bool(np.isfinite(finals).all()),
            'final_dist': float(np.max(np.linalg.norm(np.array(finals) - goal, axis=1)))}
    for method in ('etdmp', 'dmp'):
        stat = _time(lambda m=method: ours.batch(starts, goal, method=m),
                     max(args.batch_repeats, 20 if not args.quick else 3))
        x = ours.batch(starts, goal, method=method)
        sanity[case][f'ours ({method})'] = {
            'finite': bool(np.isfinite(x).all()),
            'final_dist': float(np.max(np.linalg.norm(x[:, -1] - goal, axis=1))),
            'shape': str(x.shape)}
        rows.append(_evaluate({
            'name': f'batch {N_BATCH} starts x {N_STEPS} steps, 0 obstacles (ours: {method}; '
                    f'peers: loop of {N_BATCH})',
            'limit_ms': 10.0, 'ours': stat, 'peers': peer_stats}))
    # The batch's cost per system beside a single rollout's, in this process.
    single = _time(lambda: ours.rollout(start, goal), args.repeats)
    batch = next(r for r in rows if r['name'].startswith(f'batch {N_BATCH}'))['ours']
    per_system = (f"batch of {N_BATCH}: {batch['median_ms']:.2f} ms = "
                  f"{batch['median_ms'] / N_BATCH * 1e3:.1f} us per system; a single rollout "
                  f"(its Python call included): {single['median_ms'] * 1e3:.1f} us (ET-DMP, "
                  f'{N_STEPS} steps, medians)')
    clear = starts[np.all(np.linalg.norm(starts[:, None] - obstacles[None], axis=2)
                          > 1.1 * radii, axis=1)]
    detour_batch = _time(lambda: ours.batch(clear, goal, obstacles=obstacles, radii=radii),
                         max(args.batch_repeats, 3))
    per_system += (f'; with the 2 obstacles of radius {OBSTACLE_RADIUS:g} x the start-goal '
                   f'distance (detour, the {len(clear)} starts outside them): '
                   f"{detour_batch['median_ms']:.2f} ms")

    # Print.
    print('# etdmp_ros core benchmark\n')
    print(f"python {env['python']} | numpy {env['versions']['numpy']} | numba "
          f"{env['versions']['numba']} | {env['cpu']} | os.cpu_count() = {env['cpu_count']} "
          f"(usable {env['cpus_usable']})")
    print('versions: ' + ', '.join(f'{k} {v}' for k, v in env['versions'].items()))
    for var in ('OPENBLAS_CORETYPE', 'OPENBLAS_L2_SIZE', 'OMP_NUM_THREADS', 'NUMBA_NUM_THREADS'):
        if var in env:
            print(f'{var}={env[var]}')
    for name, error in missing.items():
        print(f'{name}: NOT AVAILABLE ({error}); its column shows n/a')
    print(f'demo: {demo_source}; start {start.tolist()}, goal {goal.tolist()}; '
          f'obstacles {np.round(obstacles, 3).tolist()}')
    print(f'timing: median and p90 of {args.repeats} calls per row '
          f'({args.batch_repeats} for the peer batch rows), after warm-up\n')
    print(_table(rows))
    print('\n' + per_system)
    print('\nFirst (cold) call of ours in this process, ms (numba compile or cache load): '
          + ', '.join(f'{k} {v:.1f}' for k, v in cold.items()))
    _print_sanity(sanity)
    print('\n' + NOTES)

    # Online: the cost of one step, and the goal-jump comparison.
    online_skill = learn(positions, t=t, n_basis=N_BASIS, K=K, D=D, alpha=ALPHA)
    online_runs = 1 if args.quick else 5
    online_rows = []
    for kind, label in (('still', 'step, goal standing still'),
                        ('goal', 'step with a goal change (new goal every step)'),
                        ('actual', 'step with phase stopping (actual given, lagging)')):
        stats = _online_steps(online_skill, start, goal, online_runs, kind)
        online_rows.append({'name': label, 'stats': stats,
                            'pass': bool(stats['p99_ms'] <= ONLINE_LIMIT_MS)})
    jump_rows = goal_jump_rows()
    print('\n## Online ET-DMP\n')
    with printed() as online:
        print(_online_table(online_rows))
        print(f'\n({online_runs} runs of {N_STEPS} steps per row after one warm-up run.)\n')
        print(goal_jump_table(jump_rows))
    print('\n' + GOAL_JUMP_NOTES)

    # Orientation: learn + generalize with and without it, and movement-primitives' CartesianDMP.
    ori_rows, ori_errors, ori_note = orientation_section(args.repeats, args.batch_repeats)
    print('\n## Orientation\n')
    orientation = orientation_tables(ori_rows, ori_errors, ori_note)
    print(orientation)
    print('\n' + ORIENTATION_NOTES)

    failed = [r['name'] for r in rows + online_rows if not r['pass']]
    wall = time.perf_counter() - wall0
    missed = ('; missed: ' + '; '.join(failed)) if failed else ''
    total = len(rows) + len(online_rows)
    print(f'\n{total - len(failed)} of {total} rows meet their target{missed} '
          f'(wall time {wall:.0f} s)')
    if not args.no_docs:
        timing = (f'Medians (p90) of {args.repeats} calls per row ({args.batch_repeats} for the '
                  'peer batch rows) after warm-up; demo: '
                  + demo_source.replace(str(REPO_ROOT.parent), '..') + '.')
        run = command('core', argv)
        publish('core', f'{_table(rows)}\n\n{per_system}\n\n{timing}', run, load=load)
        publish('core-online', online.getvalue(), run, load=load)
        publish('core-orientation', orientation, run, load=load)
        publish('readme-speed', _readme_table(rows), run, page='README.md', load=load)

    if args.json:
        result = {'environment': env, 'demo': demo_source, 'start': start.tolist(),
                  'goal': goal.tolist(), 'obstacles': obstacles.tolist(),
                  'missing_peers': missing, 'rows': rows, 'cold_ms': cold,
                  'sanity': sanity, 'online': online_rows, 'goal_jump': jump_rows,
                  'repeats': args.repeats,
                  'batch_repeats': args.batch_repeats, 'wall_s': wall}
        result['orientation'] = {'rows': ori_rows, 'errors': ori_errors, 'note': ori_note}
        Path(args.json).write_text(json.dumps(result, indent=2, default=_json_default) + '\n')
        print(f'results written to {args.json}')
    return 1 if (args.strict and failed) else 0


def _json_default(value):
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f'not JSON serializable: {type(value)}')


if __name__ == '__main__':
    sys.exit(main())

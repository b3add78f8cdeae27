"""
Experiment logic behind the ``etdmp`` command line, callable without argparse.

Two experiments, both on top of the public core :mod:`etdmp_ros.dmp`:

- :func:`compare_methods`: one generalization request (start, goal, obstacles) served by both DMP
  and ET-DMP, with the similarity (nRMSE, docs/design.md "Similarity measure"), the final
  distance to the goal and the obstacle clearance of each.
- :func:`reproduce`: the paper's 2D letter simulation (Table 2, Figs. 5, 7, 8, 13) for ANY letters
  directory and table in the format of ``pbdlib_2Dletters/table2.json``.

Notation as in the paper: the demonstration goes from ``x0_D`` to ``g_D``; a request from ``x0_C``
to ``g_C``. The *relative quadrant* of a start is the quadrant of ``I_C = x0_C - g_C`` (Table 2);
the demonstration's own quadrant is that of ``I_D = x0_D - g_D``. Quadrants are half-open angular
sectors of ``atan2(I_y, I_x)``: I = [0, 90) deg, II = [90, 180), III = [180, 270), IV = [270, 360),
so a start exactly on an axis belongs to the sector that begins there.

Nothing here prints, plots or touches ROS; the CLI and :mod:`etdmp_ros.apps.plotting` do that.
"""

from dataclasses import dataclass, field
import json
import math
from pathlib import Path

from etdmp_ros.dmp import (clearance, DemonstrationError, GeneralizationError, learn, load_demo,
                           METHODS, OBSTACLE_MARGIN, similarity)
from etdmp_ros.geometry.task_plane import quadrant as task_plane_quadrant, QUADRANTS
import numpy as np

# Where the obstacles of the Figs. 7-8 runs sit on the obstacle-free ET-DMP path, as fractions of
# its arc length: on the path is where they disturb the most (paper: "limited to the vicinity of
# expected trajectory"). Arc length rather than time, because letters are drawn fast at first and
# slowly at the end, so time fractions would crowd the obstacles into the first strokes.
ONE_OBSTACLE_FRACTIONS = (0.5,)
TWO_OBSTACLE_FRACTIONS = (0.35, 0.65)

QUADRANT_CONVENTION = (
    'quadrant of (start - goal); half-open sectors of atan2: I [0,90), II [90,180), '
    'III [180,270), IV [270,360) degrees')
NRMSE_DEFINITION = {
    'paper': 'Eq. 16 as printed: sqrt(sum_k (mean_i diff_ik^2)^2)',
    'conventional': 'sqrt(sum_k mean_i diff_ik^2)',
    'common': 'both paths relative to their own goal, generated rotated so its start direction '
              "matches the demo's, resampled by phase, each divided by its max |coordinate| "
              '(SPEC 3.4)',
}


class ReproductionError(ValueError):
    """A letters directory or table cannot be used (missing file, malformed table, ...)."""


def quadrant(relative):
    """Return the quadrant of ``relative`` (:func:`etdmp_ros.geometry.task_plane.quadrant`)."""
    try:
        return task_plane_quadrant(relative)
    except ValueError as exc:
        raise ReproductionError(str(exc)) from None


def _finite_or_none(value):
    value = float(value)
    return value if math.isfinite(value) else None


def _similarity_dict(x, demo):
    sim = similarity(x, demo)
    return {'paper': _finite_or_none(sim.paper), 'conventional': _finite_or_none(sim.conventional)}


# --------------------------------------------------------------------------------------------
# One request, both methods


@dataclass
class MethodResult:
    """Outcome of one method on one request: the trajectory and its metrics, or the error."""

    method: str
    trajectory: object = None
    error: str = ''
    nrmse: dict = field(default_factory=dict)
    final_distance_to_goal: float = None
    distance_to_goal_at_tau: float = None
    min_clearance: float = None

    @property
    def ok(self):
        """Whether the method produced a trajectory."""
        return self.trajectory is not None

    def metrics(self):
        """Return the JSON-ready metrics, or just the ``error`` when the method failed."""
        if not self.ok:
            return {'error': self.error}
        out = {'nrmse': self.nrmse, 'final_distance_to_goal': self.final_distance_to_goal,
               'distance_to_goal_at_tau': self.distance_to_goal_at_tau}
        if self.min_clearance is not None:
            out['min_clearance'] = self.min_clearance
        return out


def _evaluate(skill, method, start, goal, obstacles, **kwargs):
    try:
        traj = skill.generalize(start, goal, obstacles=obstacles, method=method, **kwargs)
    except GeneralizationError as exc:
        return MethodResult(method, error=str(exc))
    result = MethodResult(method, trajectory=traj)
    # Compare shapes over the demo's duration only: a margin tail would be squeezed into the
    # phase-resampling of the similarity and distort it.
    n_tau = int(np.searchsorted(traj.t, skill.tau * (1.0 + 1e-9), side='right'))
    n_tau = max(n_tau, 2)
    goal = np.asarray(goal, float)
    result.nrmse = _similarity_dict(traj.x[:n_tau], skill.demo)
    result.final_distance_to_goal = float(np.linalg.norm(traj.x[-1] - goal))
    result.distance_to_goal_at_tau = float(np.linalg.norm(traj.x[n_tau - 1] - goal))
    if len(obstacles):
        result.min_clearance = float(clearance(traj.x, obstacles))
    return result


def compare_methods(skill, start, goal, obstacles=(), *, mode=1, dt=None, margin=None,
                    gains=None):
    """
    Generalize ``skill`` from ``start`` to ``goal`` with ET-DMP and DMP; return both results.

    Returns ``{"etdmp": MethodResult, "dmp": MethodResult}``. A method that rejects the request
    (GeneralizationError, e.g. the plain-DMP baseline on a demo with ``g - x0`` ~ 0 in some
    dimension) is reported in its result's ``error`` instead of raising, so the other method can
    still be shown; input errors common to both (wrong dimension, start = goal) surface there too.
    """
    obstacles = np.asarray(obstacles, dtype=float)
    if obstacles.size == 0:
        obstacles = np.zeros((0, skill.dim))
    return {m: _evaluate(skill, m, start, goal, obstacles, mode=mode, dt=dt, margin=margin,
                         gains=gains)
            for m in METHODS}


# --------------------------------------------------------------------------------------------
# The letters table (paper Table 2)


@dataclass(frozen=True)
class LetterSpec:
    """Goal and start positions of one letter (one row block of Table 2)."""

    goal: np.ndarray
    starts: np.ndarray
    table_quadrants: tuple = None


@dataclass(frozen=True)
class LetterTable:
    """A table in the format of ``pbdlib_2Dletters/table2.json``."""

    K: float
    D: float
    tau: float
    n_basis: int
    letters: dict
    units: str = ''
    path: str = ''


def _vector(value, what, dim=2):
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ReproductionError(f'{what} is not a list of numbers: {value!r}') from None
    if arr.shape != (dim,) or not np.all(np.isfinite(arr)):
        raise ReproductionError(f'{what} must be {dim} finite numbers, got {value!r}')
    return arr


def parse_table(data, path=''):
    """Validate a decoded table (dict) and return a :class:`LetterTable`."""
    if not isinstance(data, dict):
        raise ReproductionError('the table must be a JSON object')
    params = data.get('dmp_parameters')
    if not isinstance(params, dict):
        raise ReproductionError("the table has no 'dmp_parameters' object {K, D, tau, n_basis}")
    try:
        K, D, tau = (float(params[k]) for k in ('K', 'D', 'tau'))
        n_basis = int(params['n_basis'])
    except KeyError as exc:
        raise ReproductionError(f'dmp_parameters lacks {exc.args[0]!r}') from None
    except (TypeError, ValueError):
        raise ReproductionError(f'dmp_parameters must be numbers, got {params!r}') from None
    if not (K > 0 and D > 0 and tau > 0 and n_basis > 0) or not all(
            math.isfinite(v) for v in (K, D, tau)):
        raise ReproductionError(f'dmp_parameters must be positive and finite, got {params!r}')
    letters = data.get('letters')
    if not isinstance(letters, dict) or not letters:
        raise ReproductionError("the table has no non-empty 'letters' object")
    order = data.get('quadrant_order')
    if order is not None:
        if not isinstance(order, list) or any(q not in QUADRANTS for q in order):
            raise ReproductionError(
                f"quadrant_order must be a list of {'/'.join(QUADRANTS)}, got {order!r}")
    specs = {}
    for name, entry in letters.items():
        if not isinstance(entry, dict) or 'goal' not in entry or 'starts' not in entry:
            raise ReproductionError(f"letter {name!r} needs 'goal' and 'starts'")
        goal = _vector(entry['goal'], f'goal of letter {name!r}')
        if not isinstance(entry['starts'], list) or not entry['starts']:
            raise ReproductionError(f'letter {name!r} needs a non-empty list of starts')
        starts = np.array([_vector(s, f'start {i} of letter {name!r}')
                           for i, s in enumerate(entry['starts'])])
        if order is not None and len(order) != len(starts):
            raise ReproductionError(
                f'quadrant_order has {len(order)} entries but letter {name!r} has '
                f'{len(starts)} starts')
        specs[str(name)] = LetterSpec(goal, starts, tuple(order) if order is not None else None)
    return LetterTable(K=K, D=D, tau=tau, n_basis=n_basis, letters=specs,
                       units=str(data.get('units', '')), path=str(path))


def load_table(path):
    """Read and validate a letters table (JSON) from ``path``."""
    try:
        with open(path, encoding='utf-8') as f:
            data = json.load(f)
    except OSError as exc:
        raise ReproductionError(f'cannot read table {path}: {exc.strerror or exc}') from None
    except json.JSONDecodeError as exc:
        raise ReproductionError(f'table {path} is not valid JSON: {exc}') from None
    return parse_table(data, path)


# --------------------------------------------------------------------------------------------
# The reproduction (paper Figs. 5, 7, 8, 13)


@dataclass
class StartRun:
    """Both methods generalized from one start of one letter."""

    index: int
    start: np.ndarray
    quadrant: str
    table_quadrant: str
    results: dict

    def metrics(self, demo_quadrant):
        """Return the JSON-ready record of this start."""
        rec = {'index': self.index, 'start': self.start.tolist(), 'quadrant': self.quadrant}
        if self.table_quadrant is not None:
            rec['table_quadrant'] = self.table_quadrant
        rec['same_quadrant_as_demo'] = self.quadrant == demo_quadrant
        rec['nrmse'] = {m: (r.nrmse if r.ok else None) for m, r in self.results.items()}
        rec['final_distance_to_goal'] = {
            m: (r.final_distance_to_goal if r.ok else None) for m, r in self.results.items()}
        errors = {m: r.error for m, r in self.results.items() if not r.ok}
        if errors:
            rec['errors'] = errors
        return rec


@dataclass
class ObstacleRun:
    """ET-DMP with obstacles placed on its own obstacle-free path (paper Figs. 7-8)."""

    start_index: int
    start: np.ndarray
    fractions: tuple
    obstacles: np.ndarray
    with_obstacles: MethodResult
    without_obstacles: MethodResult

    def metrics(self):
        """Return the JSON-ready record of this run."""
        free, obst = self.without_obstacles, self.with_obstacles
        rec = {'start_index': self.start_index, 'start': self.start.tolist(),
               'method': 'etdmp', 'arc_length_fractions': list(self.fractions),
               'obstacles': self.obstacles.tolist()}
        if not obst.ok:
            rec['error'] = obst.error
            return rec
        rec['min_clearance'] = {
            'with_obstacles': obst.min_clearance,
            'without_obstacles': float(clearance(free.trajectory.x, self.obstacles))}
        rec['nrmse'] = {'with_obstacles': obst.nrmse, 'without_obstacles': free.nrmse}
        rec['final_distance_to_goal'] = {'with_obstacles': obst.final_distance_to_goal,
                                         'without_obstacles': free.final_distance_to_goal}
        rec['distance_to_goal_at_tau'] = {'with_obstacles': obst.distance_to_goal_at_tau,
                                          'without_obstacles': free.distance_to_goal_at_tau}
        rec['rollout_duration'] = float(free.trajectory.t[-1])
        return rec


@dataclass
class LetterRun:
    """Everything computed for one letter."""

    name: str
    demo_file: Path
    demo: np.ndarray
    goal: np.ndarray
    demo_quadrant: str
    starts: list
    obstacle_runs: list

    @property
    def demo_at_goal(self):
        """Return the demo translated so that its last sample is the requested goal."""
        return self.demo - self.demo[-1] + self.goal


@dataclass
class Reproduction:
    """Result of :func:`reproduce`: per-letter runs plus the settings that produced them."""

    table: LetterTable
    letters_dir: Path
    formulation: str
    letters: list

    def summary(self):
        """Return aggregate numbers over all letters and starts (JSON-ready)."""
        runs = [s for letter in self.letters for s in letter.starts]
        demo_q = {id(s): letter.demo_quadrant for letter in self.letters for s in letter.starts}
        out = {'letters': len(self.letters), 'starts': len(runs)}
        for variant in ('conventional', 'paper'):
            out[f'mean_nrmse_{variant}'] = {
                m: _mean([s.results[m].nrmse[variant] for s in runs if s.results[m].ok])
                for m in METHODS}
        outside = [s for s in runs if s.quadrant != demo_q[id(s)]]
        both = [s for s in outside if s.results['etdmp'].ok and s.results['dmp'].ok]
        out['starts_outside_demo_quadrant'] = len(outside)
        out['etdmp_better_outside_demo_quadrant'] = sum(
            s.results['etdmp'].nrmse['conventional'] < s.results['dmp'].nrmse['conventional']
            for s in both)
        all_both = [s for s in runs if s.results['etdmp'].ok and s.results['dmp'].ok]
        out['etdmp_better_all_starts'] = sum(
            s.results['etdmp'].nrmse['conventional'] < s.results['dmp'].nrmse['conventional']
            for s in all_both)
        out['comparison_variant'] = 'conventional'
        out['failures'] = {m: sum(not s.results[m].ok for s in runs) for m in METHODS}
        out['max_final_distance_to_goal'] = {
            m: _max([s.results[m].final_distance_to_goal for s in runs if s.results[m].ok])
            for m in METHODS}
        out['quadrant_mismatches'] = [
            {'letter': letter.name, 'index': s.index, 'start': s.start.tolist(),
             'table_quadrant': s.table_quadrant, 'quadrant': s.quadrant}
            for letter in self.letters for s in letter.starts
            if s.table_quadrant is not None and s.table_quadrant != s.quadrant]
        obst = [o.metrics() for letter in self.letters for o in letter.obstacle_runs]
        out['obstacle_runs'] = len(obst)
        out['min_obstacle_clearance'] = _min([o['min_clearance']['with_obstacles']
                                              for o in obst if 'min_clearance' in o])
        return out

    def metrics(self):
        """Return the whole ``metrics.json`` document."""
        t = self.table
        return {
            'parameters': {
                'K': t.K, 'D': t.D, 'tau': t.tau, 'n_basis': t.n_basis,
                'formulation': self.formulation, 'dt': t.tau / (len(self.letters[0].demo) - 1)
                if self.letters else None,
                'obstacle_gains': 'core defaults (etdmp_ros.dmp.ObstacleGains())',
                'obstacle_arc_length_fractions': {'one': list(ONE_OBSTACLE_FRACTIONS),
                                                  'two': list(TWO_OBSTACLE_FRACTIONS)},
                'obstacle_margin': OBSTACLE_MARGIN,
            },
            'sources': {'letters_dir': str(self.letters_dir), 'table': t.path, 'units': t.units},
            'quadrant_convention': QUADRANT_CONVENTION,
            'nrmse_definition': NRMSE_DEFINITION,
            'letters': {
                letter.name: {
                    'demo_file': str(letter.demo_file),
                    'demo_samples': len(letter.demo),
                    'demo_start': letter.demo[0].tolist(),
                    'demo_goal': letter.demo[-1].tolist(),
                    'demo_quadrant': letter.demo_quadrant,
                    'goal': letter.goal.tolist(),
                    'starts': [s.metrics(letter.demo_quadrant) for s in letter.starts],
                    'obstacle_runs': [o.metrics() for o in letter.obstacle_runs],
                }
                for letter in self.letters
            },
            'summary': self.summary(),
        }


def _mean(values):
    return float(np.mean(values)) if values else None


def _max(values):
    return float(np.max(values)) if values else None


def _min(values):
    return float(np.min(values)) if values else None


def _load_letter(letters_dir, name, table, formulation):
    path = Path(letters_dir) / f'{name}_00.csv'
    try:
        demo = load_demo(path)
    except DemonstrationError as exc:   # its message names the file and what is wrong
        raise ReproductionError(f'letter {name!r}: {exc}') from None
    positions = np.asarray(demo.positions, dtype=float)
    if positions.ndim != 2 or positions.shape[1] != 2:
        raise ReproductionError(f'{path}: letters must be 2D (x, y), got shape {positions.shape}')
    # The table's tau fixes the duration; the CSV carries no time (README: uniform over tau).
    try:
        skill = learn(positions, dt=table.tau / (len(positions) - 1), n_basis=table.n_basis,
                      K=table.K, D=table.D, formulation=formulation)
    except ValueError as exc:
        raise ReproductionError(f'{path}: cannot learn letter {name!r}: {exc}') from None
    return path, skill


def points_along(x, fractions):
    """Return the points of path ``x`` (n, d) at the given fractions of its arc length."""
    x = np.asarray(x, dtype=float)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
    targets = np.asarray(fractions, dtype=float) * arc[-1]
    return np.stack([np.interp(targets, arc, x[:, k]) for k in range(x.shape[1])], axis=1)


def _obstacle_run(skill, spec, start_index, fractions):
    start = spec.starts[start_index]
    free = _evaluate(skill, 'etdmp', start, spec.goal, np.zeros((0, 2)), margin=OBSTACLE_MARGIN)
    if not free.ok:
        return None
    obstacles = points_along(free.trajectory.x, fractions)
    with_obst = _evaluate(skill, 'etdmp', start, spec.goal, obstacles, margin=OBSTACLE_MARGIN)
    return ObstacleRun(start_index, start, tuple(fractions), obstacles, with_obst, free)


def reproduce(letters_dir, table, formulation='ijspeert', obstacles=True):
    """
    Run the paper's 2D letter simulation for every letter and start of ``table``.

    ``table`` is a :class:`LetterTable` or a path to one; the demonstration of letter ``L`` is
    ``letters_dir/L_00.csv`` (header ``x,y``, samples uniform over the table's tau). Each start is
    generalized with ET-DMP and DMP; with ``obstacles``, ET-DMP is also run with one and with two
    obstacles placed on its own obstacle-free path, from the first start outside the demo's
    quadrant (or the first start if there is none). Raises :class:`ReproductionError` on bad input.
    """
    if not isinstance(table, LetterTable):
        table = load_table(table)
    letters_dir = Path(letters_dir)
    if not letters_dir.is_dir():
        raise ReproductionError(f'letters directory {letters_dir} does not exist')
    runs = []
    for name, spec in table.letters.items():
        path, skill = _load_letter(letters_dir, name, table, formulation)
        demo = np.asarray(skill.demo, dtype=float)
        try:
            demo_q = quadrant(demo[0] - demo[-1])
        except ReproductionError:
            raise ReproductionError(
                f'{path}: the demonstration starts at its goal; no quadrant, no ET-DMP') from None
        starts = []
        for i, start in enumerate(spec.starts):
            try:
                q = quadrant(start - spec.goal)
            except ReproductionError as exc:
                raise ReproductionError(f'letter {name!r}, start {i}: {exc}') from None
            results = compare_methods(skill, start, spec.goal)
            table_q = spec.table_quadrants[i] if spec.table_quadrants else None
            starts.append(StartRun(i, start, q, table_q, results))
        obstacle_runs = []
        if obstacles:
            outside = [s.index for s in starts if s.quadrant != demo_q]
            chosen = outside[0] if outside else 0
            for fractions in (ONE_OBSTACLE_FRACTIONS, TWO_OBSTACLE_FRACTIONS):
                run = _obstacle_run(skill, spec, chosen, fractions)
                if run is not None:
                    obstacle_runs.append(run)
        runs.append(LetterRun(name, path, demo, spec.goal, demo_q, starts, obstacle_runs))
    return Reproduction(table, letters_dir, formulation, runs)


def _fmt(value, width=9, digits=4):
    return f"{'fail':>{width}}" if value is None else f'{value:{width}.{digits}f}'


def format_report(rep):
    """Return the compact human-readable table of a :class:`Reproduction`."""
    lines = [
        'nRMSE: conventional variant (paper Eq. 16 variant in metrics.json); '
        '|x_T-g|: final distance to the goal',
        f"{'letter':<7}{'demo q':<7}{'#':>2}  {'start':<18}{'quad':<5}"
        f"{'ET-DMP':>9}{'DMP':>9}  {'|x_T-g| ET':>10}{'DMP':>9}",
    ]
    for letter in rep.letters:
        for s in letter.starts:
            et, dmp = s.results['etdmp'], s.results['dmp']
            q = s.quadrant + ('*' if s.table_quadrant not in (None, s.quadrant) else '')
            start = '(' + ', '.join(f'{c:.2f}' for c in s.start) + ')'
            lines.append(
                f'{letter.name:<7}{letter.demo_quadrant:<7}{s.index:>2}  {start:<18}{q:<5}'
                f"{_fmt(et.nrmse.get('conventional'))}{_fmt(dmp.nrmse.get('conventional'))}  "
                f'{_fmt(et.final_distance_to_goal, 10)}{_fmt(dmp.final_distance_to_goal)}')
    mism = [(letter.name, s) for letter in rep.letters for s in letter.starts
            if s.table_quadrant not in (None, s.quadrant)]
    for name, s in mism:
        lines.append(f'* letter {name} start {s.index}: the table says quadrant '
                     f'{s.table_quadrant}, start - goal lies in {s.quadrant} (used here)')
    for letter in rep.letters:
        for o in letter.obstacle_runs:
            m = o.metrics()
            if 'error' in m:
                lines.append(f"obstacles {letter.name} start {o.start_index}: {m['error']}")
                continue
            lines.append(
                f'obstacles {letter.name:<3} start {o.start_index} x{len(o.obstacles)}: '
                f"min clearance {m['min_clearance']['with_obstacles']:.3f} "
                f"(without avoidance {m['min_clearance']['without_obstacles']:.3f}), nRMSE "
                f"{m['nrmse']['with_obstacles']['conventional']:.4f} "
                f"(free {m['nrmse']['without_obstacles']['conventional']:.4f}), |x_T-g| "
                f"{m['distance_to_goal_at_tau']['with_obstacles']:.4f} at tau, "
                f"{m['final_distance_to_goal']['with_obstacles']:.4f} at "
                f"{m['rollout_duration']:.3g} s")
    s = rep.summary()
    lines.append(
        f"mean nRMSE (conventional): ET-DMP {_fmt(s['mean_nrmse_conventional']['etdmp'], 0)}, "
        f"DMP {_fmt(s['mean_nrmse_conventional']['dmp'], 0)}; ET-DMP better than DMP for "
        f"{s['etdmp_better_outside_demo_quadrant']}/{s['starts_outside_demo_quadrant']} starts "
        f"outside the demo's quadrant ({s['etdmp_better_all_starts']}/{s['starts']} overall)")
    return '\n'.join(lines)


def write_metrics(rep, path):
    """Write ``metrics.json`` for ``rep`` (strict JSON: no NaN/inf) and return its path."""
    path = Path(path)
    text = json.dumps(rep.metrics(), indent=2, allow_nan=False)
    path.write_text(text + '\n', encoding='utf-8')
    return path

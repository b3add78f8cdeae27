"""
Rest benchmark: every plan comes to rest at its goal, position and orientation.

A script, not a pytest test; it needs no peer library. Run from the repository root::

    make bench-rest                                    # this code
    make bench-rest BENCH_ARGS="--before 7b7c223"      # and the code of a revision, side by side
    .venv/bin/python test/benchmarks/bench_rest.py [--quick] [--before REV] [--json PATH]
        [--no-docs]

The recordings (none of them built in; docs/design.md#coming-to-rest): the LASA handwriting
data set (30 shapes x 7 recordings, ``test/support/shapes.py``) as recorded (they start nearly at
rest and most end moving) and each of them cut while moving (``ends_moving``), starting moving
(``starts_moving``), halting abruptly (``abrupt_stop``) and sampled unevenly (``uneven``);
strokes drawn as the teaching page sends them (``test/drawings.py``, resampled as the page's
node does): a Z at rest at its corners, the Z lifted while moving, a circle and a spiral drawn
at speed; the pbdlib letters when ``../shared/data`` has them; 3D shapes with a tool that turns
with the stroke (``helix``, ``figure_eight_3d``) and their moving-end variants.

For every recording, both formulations (Ijspeert, Hoffmann) and both methods (ET-DMP, the plain
DMP; a plain DMP that refuses a start is counted, not measured), from its own start and from
starts in the other quadrants (2D: its start direction turned by 90, 180 and 270 degrees, at
1.5, 0.6 and 1.2 times the distance) or octants (3D: the 8 diagonal directions), rolled out to
2 tau (``margin=1``), with ``size`` the plan's largest distance from its goal up to tau:

- ``after tau``: the plan's farthest distance from the goal after tau / size (target <= 0.5 %);
- ``at 2 tau``: its distance at 2 tau / size (<= 0.1 %) and its speed there, sizes per tau
  (<= 1 %);
- ``reproduction``: nRMSE (conventional) of the plain DMP from the recording's own start
  against the recording, sample by sample on the clock the skill learned (the re-timed time of
  each recorded sample; the recording's own clock before the change), and by sample index as
  ``nrmse(plan, recording)`` pairs them;
- orientation (the 3D shapes and the LASA shapes with a turning tool): with a goal orientation
  30-180 degrees from the demonstration's last, about three axes, the angle from the plan's
  last orientation to it at tau (``margin=0``) and at 2 tau, and the angular speed there
  (target: within 0.1 degree, at rest);
- with two point obstacles on the path (``OBSTACLE_MARGIN``, 1.5 tau) and online
  (``Skill.online(...).run(2 tau)``): the distance and speed at the end.

Medians and worst cases; with ``--before REV`` the same figures of the code at git revision REV
(its ``etdmp_ros`` exported to a temporary directory and imported in a subprocess) next to them.
The table goes into docs/design.md (block ``rest``) unless ``--no-docs`` is given.
"""

import argparse
import json
import math
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time
import warnings

from etdmp_ros.dmp import GeneralizationError, learn, nrmse, OBSTACLE_MARGIN
from etdmp_ros.geometry import quaternion as quat
import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE.parent))        # test/: shapes.py, drawings.py

from support import drawings  # noqa: E402, I100
from support import shapes  # noqa: E402

PBDLIB = REPO.parent / 'shared' / 'data' / 'pbdlib_2Dletters'
FORMULATIONS = ('ijspeert', 'hoffmann')
METHODS = ('etdmp', 'dmp')
#: Other starts in 2D: the start direction turned by these angles (degrees), at these distances.
TURNS_2D = ((90.0, 1.5), (180.0, 0.6), (270.0, 1.2))
#: Goal orientations: the demonstration's last turned by these angles (degrees) about 3 axes.
GOAL_TURNS = (30.0, 90.0, 150.0, 179.0, 180.0)
GOAL_AXES = ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (1.0, 2.0, -2.0))
TARGETS = {'after': 0.005, 'at_2tau': 0.001, 'speed': 0.01, 'angle_deg': 0.1}


# --------------------------------------------------------------------------------- recordings

def _drawn(name, points, period_ms=16.7):
    """Return a stroke as the teaching page sends it and its node resamples it (pixels, s)."""
    from etdmp_ros.skills.teaching import parse_drawing, resampled
    drawing = parse_drawing({'name': 'bench', 'strokes': [drawings.stroke(points, period_ms)]})
    positions, t = resampled(drawing)
    return shapes.Recording(f'drawn/{name}', positions, t)


def drawn_strokes():
    """Return strokes drawn on the teaching page (at rest at the ends, or not)."""
    z = drawings.letter_z()
    circle_a = np.linspace(0.0, 1.8 * np.pi, 90)
    spiral_a = np.linspace(0.0, 4.0 * np.pi, 150) ** 1.3
    spiral_r = 30.0 + 10.0 * spiral_a
    return [
        _drawn('Z', z),
        _drawn('Z lifted while moving', z[:-12]),
        _drawn('circle at speed', np.c_[320 + 120 * np.cos(circle_a),
                                        240 + 120 * np.sin(circle_a)]),
        _drawn('spiral speeding up', np.c_[320 + spiral_r * np.cos(spiral_a) / 3.0,
                                           240 + spiral_r * np.sin(spiral_a) / 3.0]),
    ]


def variants(rec):
    """Return the recording and the ways it goes wrong (test/support/shapes.py)."""
    return [('as recorded', rec), ('ends moving', shapes.ends_moving(rec)),
            ('starts moving', shapes.starts_moving(rec)), ('abrupt stop', shapes.abrupt_stop(rec)),
            ('uneven', shapes.uneven(rec))]


def recordings(quick=False):
    """Yield (family, Recording) for every recording of the set."""
    for name in shapes.lasa_names():
        for demo in ((0,) if quick else range(7)):
            for kind, rec in variants(shapes.lasa(name, demo)):
                yield f'LASA {kind}', rec
    for rec in drawn_strokes():
        yield 'drawn strokes', rec
    if PBDLIB.is_dir():
        for path in sorted(PBDLIB.glob('*_*.csv'))[::4 if quick else 1]:
            y = np.loadtxt(path, delimiter=',', skiprows=1)
            yield 'pbdlib letters', shapes.Recording(path.stem, y, np.linspace(0.0, 1.0, len(y)))
    for shape in (shapes.helix(), shapes.figure_eight_3d()):
        for kind, rec in variants(shape):
            yield '3D shapes', rec


def oriented_recordings(quick=False):
    """Yield Recordings with orientations: 3D shapes and LASA shapes with a turning tool."""
    for shape in (shapes.helix(), shapes.figure_eight_3d()):
        for _, rec in variants(shape):
            yield rec
    for name in shapes.lasa_names()[::3 if quick else 1]:
        for _, rec in variants(shapes.with_turning_tool(shapes.lasa(name, 0))):
            yield rec


# ------------------------------------------------------------------------------------ figures

def starts_for(rec):
    """Return the recording's own start and starts in other quadrants / octants (B, d)."""
    start, goal = rec.positions[0], rec.positions[-1]
    offset = start - goal
    if len(offset) == 2:
        out = [start]
        for angle, scale in TURNS_2D:
            c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
            out.append(goal + scale * np.array([[c, -s], [s, c]]) @ offset)
        return np.array(out)
    norm = np.linalg.norm(offset)
    signs = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)])
    return np.vstack([start, goal + norm * signs / math.sqrt(3.0)])


def rest_figures(tr, goal, tau):
    """Return (after, at_2tau, speed) of plans (B, n, d) rolled out to 2 tau, in their sizes."""
    x = tr.x if tr.x.ndim == 3 else tr.x[None]
    v = tr.v if tr.v.ndim == 3 else tr.v[None]
    k = int(round((len(tr.t) - 1) / 2))         # the sample at tau (margin = 1)
    dist = np.linalg.norm(x - goal, axis=2)
    size = dist[:, :k + 1].max(axis=1)
    return (dist[:, k:].max(axis=1) / size, dist[:, -1] / size,
            np.linalg.norm(v[:, -1], axis=1) * tau / size)


def _on_learned_clock(skill, rec, tr):
    """Return the plan at the learned time of each recorded sample (the recording's own before)."""
    retiming = getattr(skill, 'retiming', None)
    times = rec.t if retiming is None else retiming.times
    return np.stack([np.interp(times, tr.t, tr.x[:, i]) for i in range(tr.x.shape[1])], axis=1)


def position_figures(quick):
    """Return {family: {metric: [values]}} for the recordings' positions."""
    out = {}
    for family, rec in recordings(quick):
        row = out.setdefault(family, {'recordings': 0, 'refused': 0})
        row['recordings'] += 1
        for formulation in FORMULATIONS:
            skill = learn(rec.positions, t=rec.t, formulation=formulation)
            rep = skill.generalize(rec.positions[0], rec.positions[-1], method='dmp')
            row.setdefault('rep_clock', []).append(nrmse(_on_learned_clock(skill, rec, rep),
                                                         rec.positions))
            row.setdefault('rep_index', []).append(nrmse(rep.x, rec.positions))
            starts, goal = starts_for(rec), rec.positions[-1]
            for method in METHODS:
                try:
                    tr = skill.generalize(starts, goal, method=method, margin=1.0)
                except GeneralizationError:
                    row['refused'] += 1     # the plain DMP's division by ~0 (a closed shape)
                    continue
                for key, values in zip(('after', 'at_2tau', 'speed'),
                                       rest_figures(tr, goal, skill.tau)):
                    row.setdefault(key, []).extend(values.tolist())
                    row.setdefault(key + '_own', []).append(float(values[0]))
    return out


def _turned(q, axis, degrees):
    axis = np.asarray(axis, dtype=float)
    return quat.multiply(quat.about_axis(axis / np.linalg.norm(axis), math.radians(degrees)), q)


def orientation_figures(quick):
    """Return {metric: [values]} of goal orientations reached (degrees, degrees per tau)."""
    out = {'angle_tau': [], 'angle_2tau': [], 'omega_2tau': [], 'recordings': 0}
    for rec in oriented_recordings(quick):
        out['recordings'] += 1
        skill = learn(rec.positions, rec.orientations, t=rec.t)
        starts = starts_for(rec)[:2]
        goal = rec.positions[-1]
        last = rec.orientations[-1]
        for axis in GOAL_AXES:
            for degrees in GOAL_TURNS:
                q_goal = _turned(last, axis, degrees)
                for margin, key in ((0.0, 'angle_tau'), (1.0, 'angle_2tau')):
                    tr = skill.generalize(starts, goal, goal_orientation=q_goal, margin=margin)
                    angle = np.degrees(quat.angle_between(tr.q[:, -1], q_goal[None]))
                    out[key].extend(angle.tolist())
                    if margin:
                        out['omega_2tau'].extend(
                            (np.degrees(np.linalg.norm(tr.omega[:, -1], axis=1))
                             * skill.tau).tolist())
    return out


def _obstacles_on(path, goal, size):
    """Two points on the path at 30 % and 60 % of its length, 2 % of the size to its side."""
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(steps)]
    points = []
    for fraction in (0.3, 0.6):
        k = int(np.searchsorted(arc, fraction * arc[-1]))
        tangent = path[min(k + 1, len(path) - 1)] - path[max(k - 1, 0)]
        side = np.zeros_like(tangent)
        side[0], side[1] = -tangent[1], tangent[0]
        side /= max(np.linalg.norm(side), 1e-12)
        points.append(path[k] + 0.02 * size * side)
    return np.array(points)


def obstacle_and_online_figures(quick):
    """Return {metric: [values]}: obstacles (1.5 tau) and online (2 tau) end figures."""
    out = {'obstacles_end': [], 'obstacles_speed': [], 'obstacles_later': [], 'online_end': [],
           'online_speed': [], 'recordings': 0}
    chosen = [rec for family, rec in recordings(True)
              if family in ('LASA ends moving', 'LASA abrupt stop', 'drawn strokes', '3D shapes')]
    for rec in chosen[::2 if quick else 1]:
        out['recordings'] += 1
        for formulation in FORMULATIONS:
            skill = learn(rec.positions, t=rec.t, formulation=formulation)
            start, goal = starts_for(rec)[1], rec.positions[-1]
            free = skill.generalize(start, goal)
            size = np.max(np.linalg.norm(free.x - goal, axis=1))
            obstacles = _obstacles_on(free.x, goal, size)
            # To 2.5 tau; the plan's own end is at 1.5 tau (OBSTACLE_MARGIN).
            tr = skill.generalize(start, goal, obstacles=obstacles, margin=1.5)
            k = int(round((len(tr.t) - 1) * (1.0 + OBSTACLE_MARGIN) / 2.5))
            out['obstacles_end'].append(float(np.linalg.norm(tr.x[k] - goal) / size))
            out['obstacles_speed'].append(float(np.linalg.norm(tr.v[k]) * skill.tau / size))
            out['obstacles_later'].append(float(np.max(np.linalg.norm(tr.x[k:] - goal, axis=1))
                                                / size))
            run = skill.online(start, goal)
            _, x, v, _ = run.run(2.0 * skill.tau)
            out['online_end'].append(float(np.linalg.norm(x[-1] - goal) / size))
            out['online_speed'].append(float(np.linalg.norm(v[-1]) * skill.tau / size))
    return out


#: The remedies (docs/design.md#coming-to-rest) that ``--ablation`` turns off one by one.
REMEDIES = ('gate', 'hoffmann', 'retime', 'end')
#: The configurations of the ablation table, by the remedies they keep.
ABLATION = (('none (as before)', ()), ('gate', ('gate',)),
            ('gate, Hoffmann', ('gate', 'hoffmann')),
            ('gate, Hoffmann, re-timed ends', ('gate', 'hoffmann', 'retime')),
            ('gate, Hoffmann, end condition', ('gate', 'hoffmann', 'end')),
            ('all four (this code)', REMEDIES))


def keep_only(remedies):
    """Turn off the remedies not in ``remedies`` in this process (for the ablation table)."""
    from etdmp_ros.dmp import _forcing_term, _retime, _skill
    if 'gate' not in remedies:
        _forcing_term.gate = lambda s, alpha, width=None: np.ones(np.shape(s))
    if 'hoffmann' not in remedies:      # Hoffmann's own term, K s (gated if the gate is kept)
        gate = _forcing_term.gate

        def own(self, s):
            return np.asarray(s) * gate(s, self.alpha)
        _forcing_term.ForcingTerm.phase_term = own
    if 'retime' not in remedies:
        _skill.come_to_rest = lambda t, y, q: (t, y, q, _retime.Retiming(0.0, 0.0, t))
    if 'end' not in remedies:
        fit = _forcing_term.ForcingTerm.fit
        _forcing_term.ForcingTerm.fit = lambda self, s, f, regularization=1e-8, end=None: fit(
            self, s, f, regularization)


def measure(quick):
    """Return every figure of this code (JSON-ready)."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        t0 = time.perf_counter()
        figures = {'positions': position_figures(quick),
                   'orientation': orientation_figures(quick),
                   'obstacles_online': obstacle_and_online_figures(quick)}
        figures['seconds'] = time.perf_counter() - t0
    return figures


# ------------------------------------------------------------------------------------- report

def _median_worst(values, scale=1.0):
    if not values:
        return 'n/a'
    a = np.asarray(values, dtype=float) * scale
    return f'{np.median(a):.3g} / {np.max(a):.3g}'


def _cell(now, before, key, scale):
    text = _median_worst(now.get(key, []), scale)
    if before is not None:
        text = f'{_median_worst(before.get(key, []), scale)} → {text}'
    return text


def report(now, before=None):
    """Return the markdown tables (median / worst; ``before → after`` with a before)."""
    lines = ['| recordings | n | after tau, % of size (≤ 0.5) | at 2 tau, % (≤ 0.1) | '
             'speed at 2 tau, % of size per tau (≤ 1) | reproduction nRMSE, learned clock | '
             'by index |', '|---|---|---|---|---|---|---|']
    old = before['positions'] if before else {}
    for family, row in now['positions'].items():
        prev = old.get(family) if before else None
        n = f"{row['recordings']}" + (f" ({row['refused']} plain-DMP refusals)"
                                      if row['refused'] else '')
        lines.append(f"| {family} | {n} | {_cell(row, prev, 'after', 100)} | "
                     f"{_cell(row, prev, 'at_2tau', 100)} | {_cell(row, prev, 'speed', 100)} | "
                     f"{_cell(row, prev, 'rep_clock', 1)} | {_cell(row, prev, 'rep_index', 1)} |")
    o, ob = now['orientation'], before['orientation'] if before else None
    lines += ['', '| orientation (goal 30-180 degrees away) | n | angle at tau, degrees (≤ 0.1) | '
              'at 2 tau | angular speed at 2 tau, degrees per tau |', '|---|---|---|---|---|',
              f"| 3D shapes and LASA with a turning tool, all variants | {o['recordings']} | "
              f"{_cell(o, ob, 'angle_tau', 1)} | {_cell(o, ob, 'angle_2tau', 1)} | "
              f"{_cell(o, ob, 'omega_2tau', 1)} |"]
    p, pb = now['obstacles_online'], before['obstacles_online'] if before else None
    lines += ['', '| moving ends, other start | n | distance at the end, % of size | '
              'speed there, % of size per tau | farthest after the end, to 2.5 tau |',
              '|---|---|---|---|---|',
              f"| two obstacles on the path, at 1.5 tau | {2 * p['recordings']} | "
              f"{_cell(p, pb, 'obstacles_end', 100)} | {_cell(p, pb, 'obstacles_speed', 100)} | "
              f"{_cell(p, pb, 'obstacles_later', 100)} |",
              f"| online (`Skill.online`), at 2 tau | {2 * p['recordings']} | "
              f"{_cell(p, pb, 'online_end', 100)} | {_cell(p, pb, 'online_speed', 100)} | |"]
    return '\n'.join(lines)


def missed(now):
    """List the targets not met; empty when every figure is within its target."""
    out = []
    for family, row in now['positions'].items():
        for key in ('after', 'at_2tau', 'speed'):
            worst = max(row.get(key, [0.0]))
            if worst > TARGETS[key]:
                out.append(f'{family}: worst {key} {100 * worst:.3g} % > {100 * TARGETS[key]:g} %')
    worst = max(now['orientation']['angle_tau'] or [0.0])
    if worst > TARGETS['angle_deg']:
        out.append(f'orientation: worst angle at tau {worst:.3g} deg > 0.1 deg')
    return out


def ablation(quick):
    """Return the ablation table: each configuration measured in a subprocess of its own."""
    lines = ['| remedies kept | after tau, % of size: LASA as recorded | ends moving | '
             'abrupt stop | 3D shapes | reproduction nRMSE, LASA as recorded | orientation '
             'at tau, degrees |', '|---|---|---|---|---|---|---|']
    for label, kept in ABLATION:
        with tempfile.TemporaryDirectory(prefix='bench_rest_') as tmp:
            out = Path(tmp) / 'figures.json'
            subprocess.run([sys.executable, __file__, '--measure-only', str(out), '--keep',
                            ','.join(kept)] + (['--quick'] if quick else []), check=True)
            f = json.loads(out.read_text())
        rows = f['positions']
        cells = [_median_worst(rows[family]['after'], 100) for family in
                 ('LASA as recorded', 'LASA ends moving', 'LASA abrupt stop', '3D shapes')]
        lines.append(f"| {label} | {' | '.join(cells)} | "
                     f"{_median_worst(rows['LASA as recorded']['rep_clock'])} | "
                     f"{_median_worst(f['orientation']['angle_tau'])} |")
    return '\n'.join(lines)


def _before(revision, quick):
    """Measure the code of git ``revision`` in a subprocess; return its figures."""
    with tempfile.TemporaryDirectory(prefix='bench_rest_') as tmp:
        archive = subprocess.run(['git', 'archive', revision, 'etdmp_ros'], cwd=REPO,
                                 capture_output=True, check=True).stdout
        subprocess.run(['tar', '-x', '-C', tmp], input=archive, check=True)
        out = Path(tmp) / 'figures.json'
        env = dict(os.environ, PYTHONPATH=tmp + os.pathsep + os.environ.get('PYTHONPATH', ''))
        cmd = [sys.executable, __file__, '--measure-only', str(out)]
        cmd += ['--quick'] if quick else []
        subprocess.run(cmd, env=env, check=True)
        return json.loads(out.read_text())


def main(argv=None):
    """Run the benchmark; print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--quick', action='store_true', help='one LASA recording per shape')
    parser.add_argument('--before', metavar='REV', help='also measure the code of git REV')
    parser.add_argument('--json', type=Path, help='also write the figures here')
    parser.add_argument('--no-docs', action='store_true',
                        help='only print the tables; do not write them into docs/design.md')
    parser.add_argument('--ablation', action='store_true',
                        help='also: what each remedy contributes (a quick run per configuration)')
    parser.add_argument('--measure-only', type=Path, help=argparse.SUPPRESS)
    parser.add_argument('--keep', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.measure_only:
        if args.keep is not None:
            keep_only(set(filter(None, args.keep.split(','))))
        args.measure_only.write_text(json.dumps(measure(args.quick)))
        return 0
    load = os.getloadavg()[0]
    before = _before(args.before, args.quick) if args.before else None
    now = measure(args.quick)
    table = report(now, before)
    print(table)
    print(f"\nload {load:.1f} at the start; {now['seconds']:.0f} s for this code"
          + (f", {before['seconds']:.0f} s for {args.before}" if before else ''))
    for line in missed(now) or ['every target met']:
        print(line)
    remedies = None
    if args.ablation:
        remedies = ablation(True)     # the quick set: one run per configuration
        print(f'\nWhat each remedy contributes (median / worst):\n\n{remedies}')
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({'now': now, 'before': before}))
    if not args.no_docs:
        from _results import command, publish   # test/benchmarks/_results.py
        publish('rest', table, command('rest', argv), page='docs/design.md', load=load)
        if remedies is not None:
            publish('rest-ablation', remedies, command('rest', argv) + ' (its quick set)',
                    page='docs/design.md', load=load)
    return 0


if __name__ == '__main__':
    sys.exit(main())

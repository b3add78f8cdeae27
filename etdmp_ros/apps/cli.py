r"""
``etdmp``: offline command line for ET-DMPs (no ROS needed).

Subcommands::

    etdmp generalize --skill G --start 5.8 4.25 --goal 0.11 -0.51 [--obstacle X Y]... \
                     [--plot out.png] [--json out.json]
    etdmp reproduce --letters-dir DIR [--table DIR/table2.json] --out OUT [--no-plots]
    etdmp demos [--plot demos.png]

Exit codes: 0 success, 2 bad input (unknown skill, wrong coordinates, start = goal, unreadable or
malformed file, ...) with a one-line message on stderr, 1 when the environment cannot do the job
(matplotlib missing for a plot, output not writable).
"""

import argparse
import json
import math
from pathlib import Path
import sys

from etdmp_ros.apps.reproduce import (compare_methods, format_report, reproduce, ReproductionError,
                                      write_metrics)
from etdmp_ros.dmp import (builtin_demo, builtin_demo_names, DemonstrationError,
                           GeneralizationError, learn, load_demo, METHOD_LABELS, METHODS,
                           OBSTACLE_MARGIN)
import numpy as np

PROG = 'etdmp'


class UsageError(ValueError):
    """Bad command-line input, reported as one line on stderr with exit code 2."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (not usage + message) and do not exit."""

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


def _build_parser():
    parser = _Parser(prog=PROG, description='Euclidean-transformation DMPs, offline: '
                     "generalize a skill, reproduce the paper's letter experiments, list demos.")
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    sub.required = True

    gen = sub.add_parser(
        'generalize', help='generalize one skill from a start to a goal (DMP vs ET-DMP)',
        description='Learn a skill (built-in or from a file), generalize it from --start to '
                    '--goal with ET-DMP and DMP, print nRMSE / final distance / clearance, and '
                    "optionally plot and save the selected method's trajectory as JSON.")
    src = gen.add_mutually_exclusive_group(required=True)
    src.add_argument('--skill', help="built-in demonstration name (see 'etdmp demos')")
    src.add_argument('--demo', metavar='FILE', help='demonstration file (.csv, .npy, .npz)')
    gen.add_argument('--start', nargs='+', type=float, required=True, metavar='C',
                     help="start position, 2 or 3 coordinates (the skill's dimension)")
    gen.add_argument('--goal', nargs='+', type=float, required=True, metavar='C',
                     help='goal position, 2 or 3 coordinates')
    gen.add_argument('--obstacle', nargs='+', type=float, action='append', default=[],
                     metavar='C', help='an obstacle point (repeat for several)')
    gen.add_argument('--method', choices=('etdmp', 'dmp'), default='etdmp',
                     help='method whose trajectory goes to --json and is drawn thicker '
                          '(both are computed and reported; default etdmp)')
    gen.add_argument('--mode', type=int, choices=(1, 2), default=1,
                     help='3D transform mode: 1 Rodrigues, 2 planar + independent z (default 1)')
    gen.add_argument('--formulation', choices=('ijspeert', 'hoffmann'), default='ijspeert',
                     help='DMP formulation (default ijspeert)')
    gen.add_argument('--dt', type=float, default=None,
                     help="output sample period in seconds (default: the demo's)")
    gen.add_argument('--margin', type=float, default=None,
                     help='extra rollout time after tau, as a fraction of tau (default 0, or '
                          f'{OBSTACLE_MARGIN:g} with obstacles: a detour arrives later)')
    gen.add_argument('--plot', metavar='PNG', help='write a figure (needs matplotlib)')
    gen.add_argument('--json', metavar='FILE', help='write t, x, v, a and the metrics as JSON')
    gen.set_defaults(func=_cmd_generalize)

    rep = sub.add_parser(
        'reproduce', help="reproduce the paper's 2D letter experiments (Figs. 5, 7-8, 13)",
        description='For every letter and start of a Table-2-style JSON table, generalize the '
                    "letter's demonstration <DIR>/<L>_00.csv with DMP and ET-DMP (and ET-DMP "
                    'with obstacles); write metrics.json and the figures into --out.')
    rep.add_argument('--letters-dir', required=True, metavar='DIR',
                     help='directory with <L>_00.csv files (header x,y, uniform over tau)')
    rep.add_argument('--table', metavar='JSON',
                     help='table of goals and starts (default: DIR/table2.json)')
    rep.add_argument('--out', required=True, metavar='DIR', help='output directory')
    rep.add_argument('--no-plots', action='store_true',
                     help='write metrics.json only (matplotlib not needed)')
    rep.add_argument('--formulation', choices=('ijspeert', 'hoffmann'), default='ijspeert',
                     help="DMP formulation (default ijspeert, the paper's)")
    rep.set_defaults(func=_cmd_reproduce)

    dem = sub.add_parser('demos', help='list (and plot) the built-in demonstrations',
                         description='List the built-in demonstrations: name, dimension, '
                                     'number of samples, duration.')
    dem.add_argument('--list', action='store_true', help='list them (the default action)')
    dem.add_argument('--plot', metavar='PNG', help='also plot them all (needs matplotlib)')
    dem.set_defaults(func=_cmd_demos)
    return parser


# --------------------------------------------------------------------------------------------
# generalize


def _point(values, dim, what):
    if len(values) != dim:
        raise UsageError(f'{what} needs {dim} coordinates for a {dim}D skill, got {len(values)}')
    arr = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise UsageError(f'{what} must be finite, got {values}')
    return arr


def _load_skill(args):
    if args.skill is not None:
        names = builtin_demo_names()
        if args.skill not in names:
            raise UsageError(f"unknown skill {args.skill!r}; built-in skills: {', '.join(names)}")
        demo = builtin_demo(args.skill)
    else:
        try:
            demo = load_demo(args.demo)
        except DemonstrationError as exc:   # its message names the file and what is wrong
            raise UsageError(str(exc)) from None
    try:
        return demo, learn(demo, formulation=args.formulation)
    except ValueError as exc:
        raise UsageError(f'cannot learn {demo.name!r}: {exc}') from None


def _output_path(value, option):
    """Check an output file's folder exists now, before any long computation."""
    if value is None:
        return None
    path = Path(value)
    if not path.parent.is_dir():
        raise UsageError(f'{option} {path}: folder {path.parent} does not exist')
    if path.is_dir():
        raise UsageError(f'{option} {path} is a directory, expected a file name')
    return path


def _fmt(value, spec='.4f'):
    return 'n/a' if value is None else format(value, spec)


def _cmd_generalize(args):
    if args.dt is not None and not (math.isfinite(args.dt) and args.dt > 0):
        raise UsageError(f'--dt must be a positive number, got {args.dt}')
    if args.margin is not None and not (math.isfinite(args.margin) and args.margin >= 0):
        raise UsageError(f'--margin must be >= 0, got {args.margin}')
    json_path = _output_path(args.json, '--json')
    plot_path = _output_path(args.plot, '--plot')
    if plot_path:
        from etdmp_ros.apps.plotting import require_matplotlib
        require_matplotlib()
    demo, skill = _load_skill(args)
    start = _point(args.start, skill.dim, '--start')
    goal = _point(args.goal, skill.dim, '--goal')
    obstacles = np.array([_point(o, skill.dim, '--obstacle') for o in args.obstacle]).reshape(
        -1, skill.dim)
    if np.linalg.norm(start - goal) == 0.0:
        raise UsageError('--start equals --goal: there is no movement to generalize')
    results = compare_methods(skill, start, goal, obstacles, mode=args.mode, dt=args.dt,
                              margin=args.margin)
    chosen = results[args.method]
    if not chosen.ok:
        raise UsageError(f'{METHOD_LABELS[args.method]} cannot serve this request: '
                         f'{chosen.error}')

    _print_comparison(args, demo.name, skill, start, goal, obstacles, results)
    if json_path:
        _write_json(json_path, args, demo.name, start, goal, obstacles, results)
    if plot_path:
        from etdmp_ros.apps.plotting import plot_generalization
        paths = {m: (r.trajectory.x if r.ok else None) for m, r in results.items()}
        n_obs = len(obstacles)
        title = f'{demo.name}: ET-DMP vs DMP' + (
            f", {n_obs} obstacle{'s' if n_obs > 1 else ''}" if n_obs else '')
        path = plot_generalization(plot_path, demo=skill.demo, start=start, goal=goal,
                                   paths=paths, obstacles=obstacles, title=title,
                                   selected=args.method)
        print(f'wrote {path}')
    return 0


def _print_comparison(args, name, skill, start, goal, obstacles, results):
    """Print the request and every method's figures, the selected one marked."""
    print(f'skill {name}: {skill.dim}D, {len(skill.demo)} samples, tau = {skill.tau:.3g} s, '
          f'{args.formulation}')
    print(f'start {start.tolist()} -> goal {goal.tolist()}, {len(obstacles)} obstacle(s)')
    print(f"{'method':<9}{'nRMSE conv':>11}{'nRMSE paper':>12}{'|x_T - g|':>11}"
          f"{'clearance':>11}")
    for method in METHODS:
        r = results[method]
        mark = '*' if method == args.method else ' '
        label = f'{METHOD_LABELS[method]}{mark}'
        if not r.ok:
            print(f'{label:<9}failed: {r.error}')
            continue
        print(f"{label:<9}{_fmt(r.nrmse['conventional']):>11}{_fmt(r.nrmse['paper']):>12}"
              f"{_fmt(r.final_distance_to_goal):>11}{_fmt(r.min_clearance, '.3f'):>11}")
    print('(* = selected method; nRMSE vs the demonstration, docs/design.md)')


def _write_json(json_path, args, name, start, goal, obstacles, results):
    """Write the selected method's trajectory and every method's metrics as JSON."""
    chosen = results[args.method]
    traj = chosen.trajectory
    doc = {
        'skill': name, 'method': args.method, 'mode': args.mode,
        'formulation': args.formulation, 'start': start.tolist(), 'goal': goal.tolist(),
        'obstacles': obstacles.tolist(),
        't': np.asarray(traj.t).tolist(), 'x': np.asarray(traj.x).tolist(),
        'v': np.asarray(traj.v).tolist(), 'a': np.asarray(traj.a).tolist(),
        'rotation': np.asarray(traj.rotation).tolist(),
        'virtual_start': np.asarray(traj.virtual_start).tolist(),
        'metrics': {m: r.metrics() for m, r in results.items()},
    }
    json_path.write_text(json.dumps(doc, allow_nan=False) + '\n', encoding='utf-8')
    print(f'wrote {json_path}')


# --------------------------------------------------------------------------------------------
# reproduce


def _cmd_reproduce(args):
    letters_dir = Path(args.letters_dir)
    if not letters_dir.is_dir():
        raise UsageError(f'--letters-dir {letters_dir} is not a directory')
    table = Path(args.table) if args.table else letters_dir / 'table2.json'
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f'--out {out} exists and is not a directory')
    if not args.no_plots:
        from etdmp_ros.apps.plotting import require_matplotlib
        require_matplotlib()
    rep = reproduce(letters_dir, table, formulation=args.formulation)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_metrics(rep, out / 'metrics.json')]
    if not args.no_plots:
        from etdmp_ros.apps.plotting import write_reproduction_figures
        written += write_reproduction_figures(rep, out)
    print(format_report(rep))
    for path in written:
        print(f'wrote {path}')
    return 0


# --------------------------------------------------------------------------------------------
# demos


def _cmd_demos(args):
    plot_path = _output_path(args.plot, '--plot')
    if plot_path:
        from etdmp_ros.apps.plotting import require_matplotlib
        require_matplotlib()
    demos = [builtin_demo(name) for name in builtin_demo_names()]
    print(f"{'name':<8}{'dim':>4}{'samples':>9}{'duration [s]':>14}")
    for d in demos:
        x, t = np.asarray(d.positions), np.asarray(d.t)
        print(f'{d.name:<8}{x.shape[1]:>4}{len(x):>9}{t[-1] - t[0]:>14.3f}')
    if plot_path:
        from etdmp_ros.apps.plotting import plot_demos
        print(f'wrote {plot_demos(plot_path, [(d.name, d.positions) for d in demos])}')
    return 0


# --------------------------------------------------------------------------------------------


def main(argv=None):
    """Run the ``etdmp`` command line with ``argv`` (default ``sys.argv[1:]``); return the code."""
    from etdmp_ros.apps.plotting import PlottingUnavailable
    user_errors = (UsageError, ReproductionError, DemonstrationError, GeneralizationError)
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
        return args.func(args)
    except SystemExit as exc:
        # --help / --version exit through argparse; report their code instead of exiting.
        return exc.code if isinstance(exc.code, int) else 0
    except PlottingUnavailable as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return 1
    except user_errors as exc:
        # Bad user input only; any other exception is a bug and keeps its traceback.
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:
        # Input files are checked where they are read (-> 2); what is left is writing output.
        where = f' {exc.filename}' if exc.filename else ''
        print(f'{PROG}: error: cannot write{where}: {exc.strerror or exc}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())

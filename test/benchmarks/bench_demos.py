"""
The demo's figures for every built-in skill, ET-DMP and the plain DMP: what `make demo` shows.

A script, not a pytest test (``make bench-demos``). From the repository root::

    MUJOCO_GL=egl .venv/bin/python test/benchmarks/bench_demos.py [--skills G W] [--no-docs]

Each run is one ``make demo SKILL=<skill> METHOD=<method>`` (``etdmp_ros.demo.run.run_demo``:
the four nodes as separate processes on a DDS domain of their own, the camera, perception,
``/generalize``, the controller, the MuJoCo UR10), without pictures. The figures come from each
run's ``metrics.json`` (``etdmp_ros.demo.metrics``: the executed pen trace against the
demonstration, the tracking error, the goal error, the clearance from the pen's surface to the
true obstacle cylinders, the simulation's contacts, the joint velocity and acceleration as a
share of their limits). It prints a markdown table and, unless ``--no-docs``, writes it into
docs/demo.md (block ``demo-skills``) and the README's short results table (block ``readme``),
with the command, date, machine and code version (``_results.publish``).
"""

import argparse
import json
import os
from pathlib import Path
import sys
import tempfile

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / 'test' / 'benchmarks'))
os.environ.setdefault('MUJOCO_GL', 'egl')

from _results import publish  # noqa: E402
from etdmp_ros.demo import run as demo  # noqa: E402
from etdmp_ros.dmp import METHOD_LABELS  # noqa: E402
from etdmp_ros.ros.processes import isolated_environment  # noqa: E402

SKILLS = ('G', 'P', 'R', 'W', 'wipe', 'stir')
METHODS = ('etdmp', 'dmp')
COMMAND = 'make bench-demos'


def run_once(skill, method, out):
    """Run the demo once; return its metrics (or {'failed': reason})."""
    options = demo.Options(skill=skill, method=method, out=out, animation=False,
                           pictures=False, quiet=True)
    env = isolated_environment()
    os.environ.update(env)
    try:
        metrics, _ = demo.run_demo(options, env)
    except demo.DemoError as err:
        saved = Path(out) / 'metrics.json'
        metrics = json.loads(saved.read_text()) if saved.exists() else {}
        metrics['failed'] = str(err).splitlines()[0].split(' (files written')[0]
    return metrics


def _f(value, digits=3):
    """Format a figure: ``digits`` significant digits when small, else ``digits`` decimals."""
    if value is None:
        return '-'
    if digits == 2:                             # millimetres: hundredths are the resolution
        return f'{value:.2f}'
    if abs(value) >= 100:
        return f'{value:.0f}'
    return f'{value:.{digits}g}' if abs(value) < 0.01 else f'{value:.{digits}f}'.rstrip('0') \
        .rstrip('.')


def full_table(results):
    """Return docs/demo.md's table: one row per skill and executed method."""
    head = ('| skill | executed | nRMSE plan | nRMSE trace | nRMSE other plan | tracking RMS / '
            'max (mm) | goal error (mm) | min clearance (mm) | contacts | max velocity / '
            'acceleration (% of limits) | motion (s) |')
    lines = [head, '|' + '---|' * 11]
    for (skill, method), m in results.items():
        if 'failed' in m:
            lines.append(f'| {skill} | {method} | failed: {m["failed"]} |' + ' |' * 9)
            continue
        other = m.get('nrmse_dmp_baseline') if method == 'etdmp' else m.get('nrmse_etdmp_plan')
        lines.append(
            f'| {skill} | {METHOD_LABELS[method]} | {_f(m["nrmse_plan"])} | '
            f'{_f(m["nrmse_trace"])} | {_f(other)} | {_f(m["tracking_rms_mm"])} / '
            f'{_f(m["tracking_max_mm"], 2)} | {_f(m["goal_error_mm"], 2)} | '
            f'{_f(m["min_clearance_mm"], 1)} | {m.get("contacts", "-")} | '
            f'{100 * m["max_joint_velocity_ratio"]:.0f} / '
            f'{100 * m["max_joint_acceleration_ratio"]:.0f} | {m["duration_s"]:.1f} |')
    return '\n'.join(lines)


def readme_table(results):
    """Return the README's short table: ET-DMP against the plain DMP, per skill."""
    lines = ['| skill, start in another quadrant | nRMSE, ET-DMP | nRMSE, DMP | executed '
             '(ET-DMP): tracking max, goal error | contacts |', '|---|---|---|---|---|']
    for skill in dict.fromkeys(s for s, _ in results):
        et, plain = results.get((skill, 'etdmp'), {}), results.get((skill, 'dmp'), {})
        if 'failed' in et or not et:
            continue
        label = {'G': 'G, two obstacles on its path', 'stir': 'stir (3D)'}.get(skill, skill)
        plain_nrmse = plain.get('nrmse_trace') if plain and 'failed' not in plain else \
            et.get('nrmse_dmp_baseline')
        lines.append(f'| {label} | {_f(et["nrmse_trace"])} | {_f(plain_nrmse)} | '
                     f'{_f(et["tracking_max_mm"], 2)} mm, {_f(et["goal_error_mm"], 2)} mm | '
                     f'{et.get("contacts", "-")} |')
    return '\n'.join(lines)


def main(argv=None):
    """Run the demos, print the tables, write them into the docs."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--skills', nargs='+', default=list(SKILLS), choices=SKILLS)
    parser.add_argument('--methods', nargs='+', default=list(METHODS), choices=METHODS)
    parser.add_argument('--no-docs', action='store_true', help='only print the tables')
    args = parser.parse_args(argv)
    load = 0.0     # the highest 1-minute load average seen at the start of a run
    results = {}
    with tempfile.TemporaryDirectory(prefix='bench_demos_') as tmp:
        for skill in args.skills:
            for method in args.methods:
                print(f'{skill} with {method} ...', flush=True)
                load = max(load, os.getloadavg()[0])
                results[skill, method] = run_once(skill, method, Path(tmp) / f'{skill}_{method}')
    full, short = full_table(results), readme_table(results)
    print(f'\n{full}\n\n{short}')
    failed = [key for key, m in results.items() if 'failed' in m]
    if failed:
        print(f'\nfailed runs: {failed}')
    if not args.no_docs and not failed and args.skills == list(SKILLS):
        publish('demo-skills', full, COMMAND, page='docs/demo.md', load=load)
        publish('readme', short, COMMAND, page='README.md', load=load)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())

"""
Two-hosts benchmark: the closed loop across a UDP link, against one host; the link cut mid-letter.

A script, not a pytest test. Run as root from the repository root (``make bench-two-hosts``)::

    MUJOCO_GL=egl .venv/bin/python test/benchmarks/bench_two_hosts.py [--runs 3] [--cuts 10]
        [--splits robot workstation] [--json out/bench_two_hosts.json] [--no-docs]

Each run is the demo's letter G (``etdmp_ros.demo.run.run_demo``, no pictures) driven by
``test/support/two_hosts.py run``, as the tests run it: on one host (the nodes as ``make demo``
starts them, the package's Fast DDS profile with shared memory), and on two hosts, two network
namespaces joined by a veth pair, UDP only, the demo's recorder on the workstation, with the
controller on the robot's PC (``robot``, the default split, ``etdmp_ros.ros.system.HOSTS``) and on
the workstation (``workstation``: its velocity stream crosses the link). Runs of the cases are
interleaved, so that the machine's drifting load falls on all alike.

- the controller's control steps per control period while tracking and the largest gap between
  joint states at the controller (its own count, logged at the end of the path);
- the tracking error max (the true pen tip against the controller's reference, the demo's
  metrics);
- camera frames per simulated second that perception processed (its /etdmp/obstacles, one a
  frame) and that reached the recorder (camera_info), over the motion;
- ``/generalize`` round trips (not executed, 20 calls after one warm-up) from a process on each
  host: on two hosts the robot's side crosses the link both ways;
- the workstation's UDP datagrams dropped at a full receive buffer (UdpRcvbufErrors) and the
  datagrams reassembled from IP fragments;
- link down (``--cuts`` runs with the controller on the workstation, whose velocity stream
  then crosses the link): the link down for 0.5 s at 40 % of a letter; in robot time, from the
  last command that reached the simulation, its watchdog's zero command (both times from its
  log) and the arm at rest (every joint below 1e-3 rad/s, the joint states' stamps), and, wall
  clock from the link's return, a plan of a skill taught before the cut and the first moving
  command of the next /generalize at the robot. (With the controller on the robot's PC the
  letter goes on and ends at the goal, where the demo's next plan could not start:
  docs/two_hosts.md has that case.)

It prints, per case, the median and the worst run of each figure with its target and whether
every run met it. Timing depends on the machine and on what else runs on it (the load average
is printed before and after). Unless ``--no-docs``, the tables go into docs/two_hosts.md (block
``two-hosts``) with the command, date, machine and code version (``_results.publish``).
"""

import argparse
import json
import os
from pathlib import Path
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[2]
#: Where the files of a failed run are kept (the runs themselves write to a temporary folder).
FAILED_RUNS = REPO / 'out' / 'bench_two_hosts_failed'
sys.path.insert(0, str(REPO / 'test'))
sys.path.insert(0, str(REPO / 'test' / 'benchmarks'))
os.environ.setdefault('MUJOCO_GL', 'egl')

from _results import add_option, command, publish  # noqa: E402
from etdmp_ros.ros import system  # noqa: E402
from support import two_hosts  # noqa: E402

PERIOD_MS = 8.0       # 125 Hz
WATCHDOG = system.node('ur10_sim').parameter('watchdog_timeout').default
#: (key, label, target text, check(value, one_host) -> bool or None, worst: max or min).
G_ROWS = (
    ('steps_share', 'control steps / control periods while tracking', '>= 99 %',
     lambda v, base: v >= 0.99, min),
    ('largest_gap_ms', 'largest joint-state gap at the controller (ms)', '<= 4 periods (32 ms)',
     lambda v, base: v <= 4 * PERIOD_MS, max),
    ('tracking_max_mm', 'tracking max (mm)', '<= 0.5', lambda v, base: v <= 0.5, max),
    ('camera_hz', 'camera frames at perception (per simulated s)', '>= 29',
     lambda v, base: v >= 29.0, min),
    ('camera_received_hz', 'camera frames at the recorder (per simulated s)', '', None, min),
    ('generalize_p50_ms', '/generalize p50 from the workstation (ms)', '<= 1.5 x one host',
     lambda v, base: None if base is None else v <= 1.5 * base, max),
    ('generalize_robot_p50_ms', '/generalize p50 from the robot side, across (ms)',
     '<= 1.5 x one host', lambda v, base: None if base is None else v <= 1.5 * base, max),
    ('rcvbuf_errors', 'UDP datagrams dropped at a full receive buffer (workstation)', '0',
     lambda v, base: v == 0, max),
    ('reassembled', 'UDP datagrams reassembled from fragments (workstation)', '', None, max),
    ('cpu_total', 'CPU of the closed loop (cores)', '', None, max),
)
LINK_ROWS = (
    ('braked_after_last_command_s', 'zero command in force after the last command (robot s)',
     f'<= {WATCHDOG:g} (+ a 2 ms physics step)', lambda v, base: v <= WATCHDOG + 0.002 + 1e-9,
     max),
    ('zero_velocity_after_last_command_s',
     'all joints < 1e-3 rad/s after the last command (robot s)', '<= 0.1',
     lambda v, base: v <= 0.1, max),
    ('zero_velocity_after_s', '... after the cut as the robot side heard it (robot s)', '',
     None, max),
    ('stayed_stopped', 'at rest until the link was back', 'yes', lambda v, base: v, min),
    ('planned_again_after_s', 'taught skill planned again after the return (s)', '<= 2',
     lambda v, base: v <= 2.0, max),
    ('moving_again_after_s', 'next /generalize moving at the robot after the return (s)',
     '<= 2', lambda v, base: v <= 2.0, max),
)


def _p50(values):
    return statistics.median(values) if values else None


def g_figures(result, split):
    """Return the flat figures of one G run from two_hosts.json."""
    m = result['metrics'] or {}
    controller = m.get('system', {}).get('controller', {})
    latency = m.get('before_plans') or {}
    camera = result.get('camera', {})
    counters = result.get('counters', {})
    return {
        'failed': result['error'],
        'steps_share': (controller['steps'] / controller['periods']
                        if controller.get('periods') else None),
        'largest_gap_ms': controller.get('largest_joint_state_gap_ms'),
        'tracking_max_mm': m.get('tracking_max_mm'),
        'camera_hz': camera.get('perception'),
        'camera_received_hz': camera.get('received'),
        'generalize_p50_ms': _p50(latency.get('one host' if split == 'one host'
                                              else 'workstation', [])),
        'generalize_robot_p50_ms': _p50(latency.get('robot', [])),
        'rcvbuf_errors': counters.get('UdpRcvbufErrors'),
        'reassembled': counters.get('IpReasmOKs'),
        'cpu_total': m.get('system', {}).get('cpu_cores_total'),
    }


def link_figures(result):
    """Return the flat figures of one link-down run from two_hosts.json."""
    link = result.get('link') or {}
    out = {key: link.get(key) for key, *_ in LINK_ROWS}
    out['failed'] = result['error']
    out['status_after_cut'] = link.get('status_after_cut')
    return out


def run_once(out, split, extra):
    """Run the driver once (``split``: 'one host' or the host of the controller)."""
    argv = [sys.executable, two_hosts.THIS, 'run', '--out', out, *extra]
    log = Path(out).with_suffix('.log')
    if split == 'one host':
        with open(log, 'w') as stream:
            subprocess.run(argv, stdout=stream, stderr=subprocess.STDOUT,
                           timeout=two_hosts.RUN_TIMEOUT)
    else:
        robot = system.HOSTS['robot'] if split == 'robot' else ('ur10_sim',)
        with two_hosts.TwoHosts(robot) as hosts, open(log, 'w') as stream:
            subprocess.run(hosts.wrap(two_hosts.WORKSTATION, [*argv, *hosts.arguments()]),
                           stdout=stream, stderr=subprocess.STDOUT,
                           timeout=two_hosts.RUN_TIMEOUT)
    path = Path(out) / two_hosts.RESULT
    result = (json.loads(path.read_text()) if path.exists()
              else {'metrics': None, 'error': 'no result'})
    if result['error']:
        kept = FAILED_RUNS / Path(out).name
        shutil.rmtree(kept, ignore_errors=True)
        shutil.copytree(out, kept)
        shutil.copy(log, kept / 'driver.log')
        result['error'] += f' (logs kept in {kept})'
    return result


def _cell(key, value):
    if value is None:
        return '-'
    if isinstance(value, bool):
        return 'yes' if value else 'no'
    if key == 'steps_share':
        return f'{100 * value:.1f} %'
    if isinstance(value, float):
        return f'{value:.3f}' if abs(value) < 10 else f'{value:.1f}'
    return str(value)


def table(title, runs, rows, base=None):
    """
    Return a markdown table: the median and worst run of each figure, its target, met.

    A target is met when every run meets it (a run without the figure, e.g. a failed one,
    does not); ``base``: the one-host figures' medians, for the targets relative to them.
    """
    lines = [f'| {title} ({len(runs)} runs) | median | worst | target | met |',
             '|---|---|---|---|---|']
    for key, label, target, check, worst in rows:
        values = [r.get(key) for r in runs]
        present = [v for v in values if v is not None]
        if not present:
            continue
        met = ''
        if check is not None:
            reference = (base or {}).get(key)
            verdicts = [None if v is None else check(v, reference) for v in values]
            if any(v is not None for v in verdicts):
                met = 'yes' if all(verdicts) else 'NO'
                met += f' ({sum(bool(v) for v in verdicts)}/{len(values)})'
        median = (statistics.median(present) if not isinstance(present[0], bool)
                  else sum(present) > len(present) / 2)
        lines.append(f'| {label} | {_cell(key, median)} | {_cell(key, worst(present))} | '
                     f'{target} | {met} |')
    failed = [r['failed'] for r in runs if r.get('failed')]
    if failed:
        lines.append(f'| runs failed | {len(failed)} | {failed[0].splitlines()[0][:90]} | 0 | '
                     'NO |')
    return '\n'.join(lines)


def medians(runs):
    """Return {figure: median over the runs that have it}."""
    keys = {k for r in runs for k in r}
    out = {}
    for key in keys:
        values = [r[key] for r in runs if isinstance(r.get(key), (int, float))
                  and not isinstance(r.get(key), bool)]
        if values:
            out[key] = statistics.median(values)
    return out


def main(argv=None):
    """Run the benchmark; print the tables; return 0 (1 when two hosts cannot be made)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--runs', type=int, default=3, help='G runs per case (default 3)')
    parser.add_argument('--cuts', type=int, default=10,
                        help='link-down runs with the controller on the workstation (10)')
    parser.add_argument('--splits', nargs='+', default=['robot', 'workstation'],
                        choices=('robot', 'workstation'),
                        help='where the controller runs in the two-host G runs')
    parser.add_argument('--calls', type=int, default=20, help='/generalize calls per caller')
    parser.add_argument('--json', type=Path, help="also write every run's figures here")
    add_option(parser)
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    why = two_hosts.unavailable()
    if why:
        print(f'bench_two_hosts: two hosts cannot be made here: {why}', file=sys.stderr)
        return 1
    print(f'bench_two_hosts: {os.cpu_count()} cores, load average before '
          f'{os.getloadavg()[0]:.2f}; {args.runs} G runs per case, {args.cuts} link cuts',
          flush=True)
    cases = ['one host', *args.splits]
    g = {case: [] for case in cases}
    links = {'workstation': []}
    with tempfile.TemporaryDirectory(prefix='bench_two_hosts_') as tmp:
        for run in range(max(args.runs, args.cuts)):
            for case in cases if run < args.runs else ():
                started = time.monotonic()
                out = Path(tmp) / f'G_{case.replace(" ", "_")}_{run}'
                figures = g_figures(run_once(out, case, ['--latency', str(args.calls)]), case)
                g[case].append(figures)
                print(f'  G, {case if case == "one host" else "controller on the " + case} '
                      f'run {run + 1}: {_cell("steps_share", figures["steps_share"])} steps, '
                      f'gap {_cell("x", figures["largest_gap_ms"])} ms, tracking max '
                      f'{_cell("x", figures["tracking_max_mm"])} mm, camera '
                      f'{_cell("x", figures["camera_hz"])} Hz, /generalize p50 '
                      f'{_cell("x", figures["generalize_p50_ms"])} / '
                      f'{_cell("x", figures["generalize_robot_p50_ms"])} ms '
                      f'({time.monotonic() - started:.0f} s)'
                      + (f' FAILED: {figures["failed"].splitlines()[0]}'
                         if figures['failed'] else ''), flush=True)
            for split in links if run < args.cuts else ():
                started = time.monotonic()
                out = Path(tmp) / f'cut_{split}_{run}'
                figures = link_figures(run_once(out, split, ['--cut', '0.5', '--cut-at', '0.4']))
                links[split].append(figures)
                print(f'  link down, controller on the {split}, run {run + 1}: braked '
                      f'{_cell("x", figures["braked_after_last_command_s"])} s, at rest '
                      f'{_cell("x", figures["zero_velocity_after_last_command_s"])} s after the '
                      'last command; moving '
                      f'again {_cell("x", figures["moving_again_after_s"])} s after the return; '
                      f'{figures["status_after_cut"]} ({time.monotonic() - started:.0f} s)'
                      + (f' FAILED: {figures["failed"].splitlines()[0]}'
                         if figures['failed'] else ''), flush=True)
    base = medians(g['one host'])
    base['generalize_robot_p50_ms'] = base.get('generalize_p50_ms')
    tables = []
    for case in cases:
        title = ('G on one host' if case == 'one host'
                 else f'G across two hosts, controller on the {case}')
        tables.append(table(title, g[case], G_ROWS, None if case == 'one host' else base))
    for split in links:
        if links[split]:
            tables.append(table(f'link down 0.5 s, controller on the {split}', links[split],
                                LINK_ROWS))
    print('\n' + '\n\n'.join(tables) + '\n')
    print(f'load average after: {os.getloadavg()[0]:.2f}', flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({'G': g, 'link down': links}, indent=1,
                                        default=str) + '\n')
    if not args.no_docs:
        publish('two-hosts', '\n\n'.join(tables), command('two-hosts', argv),
                page='docs/two_hosts.md', load=load)
    return 0


if __name__ == '__main__':
    sys.exit(main())

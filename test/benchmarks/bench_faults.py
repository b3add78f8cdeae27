"""
Faults benchmark: restarts in one domain, with a crash's leftovers; nodes killed.

A script, not a pytest test. Run from the repository root after ``make ros-tools`` (the ros2
CLI and launch in .venv/; ``make bench-faults``)::

    MUJOCO_GL=egl .venv/bin/python test/benchmarks/bench_faults.py [--cycles 10]
        [--load idle busy] [--end ctrl-c kill] [--kill-runs 1] [--domain-id N]
        [--install PATH] [--json out/bench_faults.json] [--no-docs]

It builds the package with colcon into a temporary folder (or uses ``--install``), then, for
each load (``busy``: one more process busy-looping on a core, another user of the machine)
and each way a run ends:

- **restart cycles**: ``--cycles`` times in one ROS domain, as a user works: ``ros2 launch
  etdmp_ros etdmp.launch.py``, ``ros2 service call /generalize nav_msgs/srv/GetPlan "{}"`` (the
  arm writes the G to the perceived goal), then Ctrl-C to the launch (``--end ctrl-c``) or
  SIGKILL to the launch and every node (``--end kill``, a crash: the next launch finds the
  Fast DDS files the killed processes left in /dev/shm). Before the first cycle one launch is
  killed while the arm writes, so the first launch finds such files too (``--no-leftovers``:
  not). Per cycle, from the launch's output: the largest wall-clock gap between two ticks of
  the simulation after start-up (its ``simulation loop stalled`` warnings with t >= 1 s of
  simulated time; target <= 50 ms), the controller's stale-input reports (target 0), whether
  the path was tracked (its ``path tracked`` summary, no halt; target every cycle), and how
  many stale files the nodes removed as they started;
- **nodes killed** (``--kill-runs`` sequences, each on a new system, :mod:`fault_rig` as
  test_faults.py runs it): dmp_server and perception killed while the arm writes (the letter
  must complete), the controller (the simulation's watchdog must bring the arm to rest within
  0.1 s of robot time after the kill), the simulation (the controller must stop and say why within
  its 1 s simulation_stall_timeout); each node restarted alone before the next.

It prints the machine's load average before and after (the figures depend on what else runs),
medians and worst cases, and the targets. ``--json`` writes every figure. Unless ``--no-docs``,
the tables go into docs/reliability.md (block ``faults``) with the command, date, machine and
code version (``_results.publish``).
"""

import argparse
import json
import os
from pathlib import Path
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parents[2]
#: Where the launch output of a cycle that missed a target is kept.
FAILED_RUNS = REPO / 'out' / 'bench_faults_failed'
#: The node logs of the kill sequences.
KILL_LOGS = REPO / 'out' / 'bench_faults_kills'
sys.path.insert(0, str(REPO / 'test'))
sys.path.insert(0, str(REPO / 'test' / 'benchmarks'))
os.environ.setdefault('MUJOCO_GL', 'egl')

from _results import add_option, command, publish  # noqa: E402
from conftest import busy_core  # noqa: E402
from etdmp_ros.ros import fastdds_files, system  # noqa: E402
from etdmp_ros.ros.processes import isolated_environment  # noqa: E402
from support import fault_rig, ros2_cli  # noqa: E402

#: Simulated time (s) after which the simulation counts as started (its first tick waits for
#: the camera process and the first subscribers).
STARTED = 1.0
STALL_TARGET = 0.050
#: What each node logs when it is ready (as test_ros2_cli waits for them).
READY = {'ur10_sim': 'UR10 workcell ready', 'perception': 'perception ready',
         'dmp_server': 'serving /generalize', 'controller': 'following '}
STARTUP = 240.0
_STALL = re.compile(r'\[ur10_sim\]: simulation loop stalled: (\d+) ms between two ticks at '
                    r't = ([\d.]+) s')
_TRACKED = re.compile(r'\[controller\]: path tracked: error RMS ([\d.]+) mm, max ([\d.]+) mm')
_REMOVED = re.compile(r'removed (\d+) Fast DDS shared-memory files')


def build(tmp):
    """Build the package with colcon into ``tmp``; return the install prefix."""
    colcon = Path(sys.executable).with_name('colcon')
    result = subprocess.run(
        [str(colcon), '--log-base', str(tmp / 'log'), 'build', '--paths', str(REPO),
         '--merge-install', '--build-base', str(tmp / 'build'),
         '--install-base', str(tmp / 'install')],
        cwd=tmp, env=dict(os.environ, COLCON_HOME=str(tmp / 'colcon_home')),
        capture_output=True, text=True, timeout=600)
    if result.returncode:
        raise SystemExit(f'colcon build failed:\n{result.stdout}\n{result.stderr}')
    return tmp / 'install'


def wait_for(predicate, timeout, what, process):
    """Poll ``predicate``; raise RuntimeError naming ``what`` on timeout or exit."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if process.returncode is not None:
            raise RuntimeError(f'{what}: ros2 launch exited ({process.returncode})')
        if time.monotonic() > deadline:
            raise RuntimeError(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(0.2)


def launch(ros2, name):
    """Start ``ros2 launch etdmp_ros etdmp.launch.py``; return it once every node serves."""
    process = ros2.start('ros2 launch etdmp_ros etdmp.launch.py', name)
    for node, line in READY.items():
        wait_for(lambda: f'[{node}]: {line}' in process.log(), STARTUP, f'{node} ready',
                 process)
    wait_for(lambda: 'goal marker at' in process.log(), STARTUP, 'a perceived goal', process)
    return process


def write(ros2, process):
    """Call /generalize from the tool to the perceived goal; wait for the end of the path."""
    before = len(process.log())
    ros2.run('ros2 service call /generalize nav_msgs/srv/GetPlan "{}"', timeout=120)

    def ended():
        text = process.log()[before:]
        moving = text.find('[controller]: status: approaching')
        text = text[moving:] if moving >= 0 else ''
        return ('[controller]: path tracked' in text or 'status: stale-input' in text
                or 'status: unreachable' in text or 'status: halted' in text)
    wait_for(ended, 120, 'the end of the path', process)
    time.sleep(1.5)         # the simulation's last stall warning comes a second later


def kill_group(process):
    """SIGKILL ``ros2 launch`` and every node it started (a crash of the whole terminal)."""
    os.killpg(process.pid, signal.SIGKILL)
    process.process.wait()      # not Background.wait(): it would remove what they left
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:      # the nodes: gone once their group is empty
        try:
            os.killpg(process.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)


def figures(text):
    """Return the figures of one launch's output (see the module docstring)."""
    stalls = [float(ms) for ms, t in _STALL.findall(text) if float(t) >= STARTED]
    tracked = _TRACKED.search(text)
    return {'largest_gap_ms': max(stalls, default=0.0),
            # The controller's status before its first joint state is stale-input too
            # ("never received"): the start, not a fault.
            'stale_input': text.count('[controller]: status: stale-input')
            - text.count('[controller]: status: stale-input: joint states on joint_states are '
                         'stale (never received)'),
            'tracked': bool(tracked) and 'status: unreachable' not in text,
            'tracking_max_mm': float(tracked.group(2)) if tracked else None,
            'removed_files': sum(int(n) for n in _REMOVED.findall(text)),
            'stalls_over_1s': [ms for ms in stalls if ms >= 1000.0]}


def cycles(ros2, count, end, leftovers):  # noqa: C901 - one loop, read top to bottom
    """Run ``count`` launch + /generalize + end cycles in one domain; return their figures."""
    if leftovers:
        process = launch(ros2, 'leftovers')
        ros2.run('ros2 service call /generalize nav_msgs/srv/GetPlan "{}"', timeout=120)
        time.sleep(2.0)             # the arm writes: every node sends and receives
        kill_group(process)
        print(f'  a launch killed while the arm wrote: {len(fastdds_files.stale())} groups of '
              'stale Fast DDS files in /dev/shm', flush=True)
    runs = []
    for i in range(count):
        started = time.monotonic()
        process = launch(ros2, f'cycle_{i}')
        try:
            write(ros2, process)
        finally:
            if end == 'kill':
                kill_group(process)
            else:
                process.stop(60.0, group=True)
        run = figures(process.log())
        run['wall_s'] = time.monotonic() - started
        runs.append(run)
        if (run['largest_gap_ms'] > STALL_TARGET * 1e3 or run['stale_input']
                or not run['tracked']):
            FAILED_RUNS.mkdir(parents=True, exist_ok=True)
            kept = FAILED_RUNS / f'{ros2.home.name}_cycle_{i + 1}.log'
            kept.write_text(process.log())
            run['log'] = str(kept)
        print(f'  cycle {i + 1}: largest tick gap {run["largest_gap_ms"]:.0f} ms, stale-input '
              f'{run["stale_input"]}, tracked {run["tracked"]} (max '
              f'{run["tracking_max_mm"]} mm), stale files removed at start '
              f'{run["removed_files"]}, {run["wall_s"]:.0f} s', flush=True)
    return runs


def kill_sequence(install, env, tmp):
    """Run the four kills of test_faults on a new system; return their figures."""
    sys_ = fault_rig.System(install, env, tmp)
    watch = None
    out = {}
    try:
        watch = fault_rig.Watch(int(env['ROS_DOMAIN_ID']))
        fault_rig.ready(sys_, watch, fault_rig.STARTUP)
        for name in ('dmp_server', 'perception'):
            f = fault_rig.kill_while_writing(sys_, watch, name)
            out[name] = {k: f[k] for k in ('completed', 'stale_input', 'largest_gap_s')}
            fault_rig.restart(sys_, watch, name)
        f = fault_rig.kill_controller(sys_, watch)
        out['controller'] = {k: f[k] for k in ('braking_s', 'standstill_s', 'moved_again',
                                               'largest_gap_s')}
        fault_rig.restart(sys_, watch, 'controller')
        f = fault_rig.kill_simulation(sys_, watch)
        out['ur10_sim'] = {'said_after_s': f['said_after_s'], 'status': f['status'],
                           'zero_command': f['last_command'] is not None
                           and bool((f['last_command'] == 0.0).all())}
        fault_rig.restart(sys_, watch, 'ur10_sim')
    finally:
        if watch is not None:
            watch.close()
        sys_.stop()
        fastdds_files.clean()
    return out


def _median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else float('nan')


def summary(load, end, runs):
    """Return the table of one set of cycles."""
    gaps = [r['largest_gap_ms'] for r in runs]
    tracked = sum(r['tracked'] for r in runs)
    stale = sum(r['stale_input'] for r in runs)
    return '\n'.join([
        f'### {len(runs)} cycles, {load}, ended by {end}',
        '| figure | median | worst | target | met |', '|---|---|---|---|---|',
        f'| largest tick gap after start-up (ms) | {_median(gaps):.0f} | {max(gaps):.0f} | '
        f'<= {STALL_TARGET * 1e3:.0f} | {"yes" if max(gaps) <= STALL_TARGET * 1e3 else "NO"} |',
        f'| stalls of 1 s or more | | {sum(len(r["stalls_over_1s"]) for r in runs)} | 0 | '
        f'{"yes" if not any(r["stalls_over_1s"] for r in runs) else "NO"} |',
        f'| stale-input reports | | {stale} | 0 | {"yes" if stale == 0 else "NO"} |',
        f'| paths tracked | | {tracked} of {len(runs)} | all | '
        f'{"yes" if tracked == len(runs) else "NO"} |',
        f'| stale files removed as the nodes started | '
        f'{_median([r["removed_files"] for r in runs]):.0f} | '
        f'{max(r["removed_files"] for r in runs)} | | |'])


def kill_summary(results):
    """Return the table of the kill sequences."""
    watchdog = system.node('ur10_sim').parameter('watchdog_timeout').default
    stall = system.node('controller').parameter('simulation_stall_timeout').default
    rows = ['### nodes killed while the arm writes', '| node killed | what happened | target |'
            ' met |', '|---|---|---|---|']
    for name in ('dmp_server', 'perception'):
        done = [r[name]['completed'] and not r[name]['stale_input'] for r in results]
        gap = max(r[name]['largest_gap_s'] for r in results) * 1e3
        rows.append(f'| {name} | letter completed {sum(done)} of {len(done)}, largest tick gap '
                    f'{gap:.0f} ms | completes | {"yes" if all(done) else "NO"} |')
    braking = [r['controller']['braking_s'] for r in results]
    still = [r['controller']['standstill_s'] for r in results]
    ok = all(b is not None and b <= watchdog + 0.008 and t is not None and t <= 0.1
             for b, t in zip(braking, still))
    rows.append(f'| controller | watchdog braking {_median(braking) * 1e3:.0f} ms (worst '
                f'{max(b or 0 for b in braking) * 1e3:.0f}), at rest '
                f'{_median(still) * 1e3:.0f} ms (worst {max(t or 0 for t in still) * 1e3:.0f}) '
                f'of robot time after the kill | braking {watchdog:g} s after the last command, '
                f'at rest within 0.1 s | {"yes" if ok else "NO"} |')
    said = [r['ur10_sim']['said_after_s'] for r in results]
    ok = all(s <= stall + 0.5 and r['ur10_sim']['zero_command']
             and r['ur10_sim']['status'].startswith('stale-input')
             for s, r in zip(said, results))
    rows.append(f'| ur10_sim | the controller sent zero and said why after '
                f'{_median(said):.2f} s (worst {max(said):.2f}): '
                f'"{results[-1]["ur10_sim"]["status"][:60]}..." | within {stall:g} s | '
                f'{"yes" if ok else "NO"} |')
    return '\n'.join(rows)


def main(argv=None):
    """Run the benchmark; print its tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--cycles', type=int, default=10)
    parser.add_argument('--load', nargs='+', default=['idle', 'busy'], choices=('idle', 'busy'))
    parser.add_argument('--end', nargs='+', default=['ctrl-c'], choices=('ctrl-c', 'kill'))
    parser.add_argument('--no-leftovers', dest='leftovers', action='store_false')
    parser.add_argument('--kill-runs', type=int, default=1)
    parser.add_argument('--domain-id', type=int, default=None)
    parser.add_argument('--install', type=Path, default=None)
    parser.add_argument('--json', type=Path, default=None)
    add_option(parser)
    args = parser.parse_args(argv)
    if ros2_cli.missing():
        raise SystemExit(ros2_cli.missing())
    load_before = os.getloadavg()[0]
    print(f'load average before: {os.getloadavg()}', flush=True)
    results = {'load_before': os.getloadavg(), 'cycles': {}, 'kills': {}}
    tables = []
    with tempfile.TemporaryDirectory(prefix='bench_faults_') as tmp:
        tmp = Path(tmp)
        install = args.install or build(tmp)
        env = isolated_environment(args.domain_id)
        os.environ.update(env)
        for load in args.load:
            for end in args.end:
                print(f'{args.cycles} cycles, {load}, ended by {end}:', flush=True)
                ros2 = ros2_cli.Ros2(install, int(env['ROS_DOMAIN_ID']),
                                     tmp / f'ros2_{load}_{end}')
                with busy_core(load == 'busy'):
                    runs = cycles(ros2, args.cycles, end, args.leftovers)
                ros2.stop_daemon()
                results['cycles'][f'{load}/{end}'] = runs
                tables.append(summary(load, end, runs))
                print(tables[-1], flush=True)
            kills = []
            for i in range(args.kill_runs):
                print(f'nodes killed, {load}, sequence {i + 1}:', flush=True)
                try:
                    with busy_core(load == 'busy'):
                        kills.append(kill_sequence(install,
                                                   dict(env, ROS_HOME=str(tmp / 'home')),
                                                   KILL_LOGS / f'{load}_{i}'))
                except (AssertionError, RuntimeError) as err:    # a target missed: say so
                    print(f'  FAILED: {err} (logs: {KILL_LOGS / f"{load}_{i}"})', flush=True)
                    results.setdefault('kill_failures', []).append(f'{load} {i}: {err}')
                    continue
                print(f'  {kills[-1]}', flush=True)
            if kills:
                results['kills'][load] = kills
                tables.append(f'{kill_summary(kills)}\n(load: {load})')
                print(tables[-1], flush=True)
    for failure in results.get('kill_failures', []):
        tables.append(f'kill sequence FAILED ({failure})')
    results['load_after'] = os.getloadavg()
    print(f'\nload average after: {os.getloadavg()}\n')
    print('\n\n'.join(tables))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2, default=str) + '\n')
    if not args.no_docs:
        # Bold titles, not headings, inside the page's own section.
        text = re.sub(r'^### (.*)$', r'**\1**\n', '\n\n'.join(tables), flags=re.M)
        publish('faults', text, command('faults', argv), page='docs/reliability.md',
                load=load_before)
    return 0


if __name__ == '__main__':
    sys.exit(main())

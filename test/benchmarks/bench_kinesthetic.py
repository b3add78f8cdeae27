"""
Kinesthetic teaching benchmark: record a stir by hand, learn it, repeat it.

A script, not a pytest test; it needs no peer library. Run from the repository root::

    MUJOCO_GL=egl .venv/bin/python test/benchmarks/bench_kinesthetic.py [--runs 3]
        [--out out/bench_kinesthetic] [--json out/bench_kinesthetic.json] [--no-docs]

or ``make bench-kinesthetic BENCH_ARGS="..."``.

Each run does what ``make kinesthetic`` and then ``make demo SKILL=stir DEMO_FILE=<bag>`` do
(:func:`etdmp_ros.demo.kinesthetic.record`, :func:`etdmp_ros.demo.run.run_demo` with
``demo_file``; the nodes as processes on a DDS domain of their own) and reports:

- the recording: joint states recorded, the learned path against the simulation's true tool
  tip at the same stamps (the same forward kinematics), its trimmed duration against the
  script's motion by the same rule, and the wall time of the recording;
- the repeat from 150 degrees round the bottle: the trace's nRMSE against the recorded tool
  path (the issue's target: <= 0.05), the goal error, the tracking error and the largest joint
  velocity and acceleration fractions, and the demo's wall time.

Medians over the runs, with the smallest and largest value. Unless ``--no-docs``, the table goes
into docs/teach.md (block ``kinesthetic``) with the command, date, machine and code version
(``_results.publish``).
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import sys
import time

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / 'test' / 'benchmarks'))

from _results import add_option, command, publish  # noqa: E402
from etdmp_ros.demo import kinesthetic, run as demo  # noqa: E402
from etdmp_ros.demo.scenario import Scenario  # noqa: E402
from etdmp_ros.dmp import load_demo  # noqa: E402
from etdmp_ros.robot import UR10Model  # noqa: E402
from etdmp_ros.ros.processes import DISCOVERY_VARIABLES, isolated_environment  # noqa: E402
from etdmp_ros.skills.library import load_demonstration  # noqa: E402
from etdmp_ros.skills.recorded import _motion_span  # noqa: E402
from etdmp_ros.skills.recordings import read_messages  # noqa: E402
from geometry_msgs.msg import PointStamped  # noqa: E402
import numpy as np  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402

#: (name, unit, where in a run's figures, target) of the printed rows.
ROWS = (('joint states recorded', '', 'joint_states', ''),
        ('learned path vs true tool tip, max', 'mm', 'fk_vs_truth_mm', ''),
        ('trimmed duration - script motion', 's', 'trim_vs_script_s', ''),
        ('recording, wall clock', 's', 'record_s', ''),
        ('repeat: trace nRMSE vs the recording', '', 'nrmse_trace', '<= 0.05'),
        ('repeat: goal error', 'mm', 'goal_error_mm', '<= 5'),
        ('repeat: tracking error max', 'mm', 'tracking_max_mm', ''),
        ('repeat: joint velocity / limit, max', '', 'max_joint_velocity_ratio', '<= 1'),
        ('repeat: joint acceleration / limit, max', '', 'max_joint_acceleration_ratio', '<= 1'),
        ('repeat: demo wall clock', 's', 'demo_s', ''))


def recording_figures(path, scenario):
    """Return the recording's figures: the learned path against the true tool tip, the trim."""
    model = UR10Model(tool_offset=scenario.scene['tool_offset'])
    recorded = load_demonstration(path, scenario.plane, kinematics=model)
    truth = {}
    for _, _, _, data in read_messages(path, [kinesthetic.TOOL_TIP]):
        msg = deserialize_message(data, PointStamped)
        truth[msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] = [
            msg.point.x, msg.point.y, msg.point.z]
    stamps = np.array(list(truth))
    points = np.array(list(truth.values()))
    t0 = stamps[np.argmin(np.linalg.norm(points - recorded.positions[0], axis=1))]
    at = t0 + np.round(recorded.t * 1e9).astype(np.int64)
    matched = [k for k, s in enumerate(at) if int(s) in truth]
    gap = np.linalg.norm(recorded.positions[matched]
                         - np.array([truth[int(at[k])] for k in matched]), axis=1)
    script = load_demo(path.parent / f'{path.stem}_script.csv')
    first, last = _motion_span(script.positions)
    return {'fk_vs_truth_mm': float(gap.max() * 1e3), 'matched': len(matched),
            'trim_vs_script_s': float(recorded.duration - (script.t[last] - script.t[first]))}


def one_run(out, env):
    """Record, learn and repeat once; return the run's figures."""
    started = time.monotonic()
    path, counts = kinesthetic.record(out / 'recording', env, progress=lambda *_: None)
    figures = {'joint_states': counts[kinesthetic.JOINT_STATES],
               'record_s': time.monotonic() - started}
    figures.update(recording_figures(path, Scenario(None, 'stir')))
    started = time.monotonic()
    options = demo.Options(skill='stir', out=out / 'demo', animation=False, quiet=True,
                           demo_file=path)
    metrics, _ = demo.run_demo(options, env)
    figures['demo_s'] = time.monotonic() - started
    for key in ('nrmse_trace', 'goal_error_mm', 'tracking_max_mm', 'max_joint_velocity_ratio',
                'max_joint_acceleration_ratio'):
        figures[key] = metrics[key]
    return figures


def main(argv=None):
    """Run the benchmark; return the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--runs', type=int, default=3, help='runs (default 3)')
    parser.add_argument('--out', type=Path, default=Path('out/bench_kinesthetic'))
    parser.add_argument('--json', type=Path, default=None, help='also write the figures here')
    add_option(parser)
    args = parser.parse_args(argv)
    env = isolated_environment()
    os.environ.update(env)
    for name in DISCOVERY_VARIABLES:
        os.environ.pop(name, None)
    load = os.getloadavg()[0]
    runs = []
    for i in range(args.runs):
        runs.append(one_run(args.out / f'run{i + 1}', env))
        print(f'run {i + 1}: nRMSE {runs[-1]["nrmse_trace"]:.5f}, goal error '
              f'{runs[-1]["goal_error_mm"]:.2f} mm ({runs[-1]["record_s"]:.0f} s + '
              f'{runs[-1]["demo_s"]:.0f} s)', flush=True)
    table = [f'| kinesthetic teaching ({args.runs} runs) | median | min | max | target |',
             '|---|---|---|---|---|']
    for label, unit, key, target in ROWS:
        values = [r[key] for r in runs]
        table.append(f'| {label}{f" ({unit})" if unit else ""} | '
                     f'{statistics.median(values):.4g} | {min(values):.4g} | '
                     f'{max(values):.4g} | {target} |')
    print('\n' + '\n'.join(table))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(runs, indent=2) + '\n')
    missed = [r['nrmse_trace'] for r in runs if r['nrmse_trace'] > 0.05]
    print('\ntarget missed' if missed else '\ntarget met in every run')
    if not args.no_docs:
        publish('kinesthetic', '\n'.join(table), command('kinesthetic', argv),
                page='docs/teach.md', load=load)
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""
Flood benchmark: what 13 000 joint states a second for other joints cost the process reading them.

A script, not a pytest test (``make bench-flood``)::

    .venv/bin/python test/benchmarks/bench_flood.py [--runs 3] [--rate 13000] [--seconds 5]
        [--no-docs]

A publisher process sends serialized JointStates naming joints ``a, b, c`` at ``--rate``
(``support.flood``, the program test/nodes/test_adversarial_controller.py floods the controller
with, its sending thread at SCHED_FIFO 20 as there); a reader process, set up as
the controller is (the UDP-only Fast DDS profile, its thread at SCHED_FIFO 50 where allowed),
takes them with a best-effort subscription of depth 1000 and refuses each with
``joint_state_from_cdr``, one of two ways:

- **executor**: the subscription's callback, one message per dispatch of the executor every
  node spins with (:func:`etdmp_ros.ros.spin.make_executor`): the controller before;
- **batches**: :class:`etdmp_ros.ros.batches.TopicBatches` with the controller's
  ``min_interval`` at 125 Hz (1 ms): what it does now.

Per run, from the reader: messages refused, CPU time over the flood divided by its wall time
(cores, every thread of the process: Fast DDS's reception included). Medians over ``--runs``.
Unless ``--no-docs``, the table goes into docs/controller.md (block ``flood``).
"""

import argparse
import os
from pathlib import Path
import statistics
import subprocess
import sys

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / 'test'))

from _results import add_option, command, printed, publish  # noqa: E402
from etdmp_ros.ros.processes import isolated_environment  # noqa: E402
from support.flood import FLOOD, FLOOD_PRIORITY  # noqa: E402

READER = """
import sys, time
from etdmp_ros.ros.spin import dds_settings, make_executor, set_realtime_priority
with dds_settings(shared_memory=False):
    import rclpy
    rclpy.init()
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from etdmp_ros.ros.batches import TopicBatches
from etdmp_ros.ros.conversions import joint_state_from_cdr
mode, seconds = sys.argv[1], float(sys.argv[2])
set_realtime_priority(50)
node = rclpy.create_node('flood_reader')
qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
seen = [0, None]
def refuse(data):
    try:
        joint_state_from_cdr(data)
    except ValueError:
        pass
    seen[0] += 1
    if seen[1] is None:
        seen[1] = (time.monotonic(), time.process_time())
executor = make_executor()
if mode == 'executor':
    node.create_subscription(JointState, 'joint_states', refuse, qos, raw=True)
    executor.add_node(node)
else:
    batches = TopicBatches(node, JointState, 'joint_states', qos,
                           lambda batch: [refuse(d) for d in batch], 0.001, 1000)
    batches.start(50)
print('ready', flush=True)
end = time.monotonic() + seconds + 30
while time.monotonic() < end and (seen[1] is None or time.monotonic() < seen[1][0] + seconds):
    if mode == 'executor':
        executor.spin_once(timeout_sec=0.01)
    else:
        time.sleep(0.01)
wall, cpu = time.monotonic() - seen[1][0], time.process_time() - seen[1][1]
print(seen[0], cpu / wall, flush=True)
"""


def run_once(mode, rate, seconds):
    """Return (messages refused, reader cores, publisher rate) of one flood."""
    env = dict(os.environ, **isolated_environment())
    reader = subprocess.Popen([sys.executable, '-c', READER, mode, str(seconds)], env=env,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert reader.stdout.readline().strip() == 'ready'
        sent = subprocess.run([sys.executable, '-c', FLOOD, str(seconds + 1.0), str(rate),
                               str(FLOOD_PRIORITY)],
                              env=env, capture_output=True, text=True, timeout=120, check=True)
        out, _ = reader.communicate(timeout=120)
    finally:
        reader.kill()
    count, cores = out.split()[-2:]
    return int(count), float(cores), float(sent.stdout.split()[-1])


def main(argv=None):
    """Run the benchmark; print (and publish) the table; return 0."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--runs', type=int, default=3, help='floods per way (default 3)')
    parser.add_argument('--rate', type=float, default=13000.0, help='joint states a second')
    parser.add_argument('--seconds', type=float, default=5.0, help='seconds a flood lasts')
    add_option(parser)
    args = parser.parse_args(argv)
    rows = {}
    for mode in ('executor', 'batches'):
        rows[mode] = [run_once(mode, args.rate, args.seconds) for _ in range(args.runs)]
    with printed() as kept:
        print('| reading | joint states refused a second | reader CPU (cores) |\n|---|---|---|')
        for mode, runs in rows.items():
            rate = statistics.median(count / args.seconds for count, _, _ in runs)
            cores = statistics.median(cores for _, cores, _ in runs)
            print(f'| {mode} | {rate:.0f} | {cores:.2f} |')
        sent = statistics.median(r[2] for runs in rows.values() for r in runs)
        print(f'\nMedians of {args.runs} floods of {args.seconds:g} s each way; the publisher '
              f'sent {sent:.0f} a second.')
    if not args.no_docs:
        publish('flood', kept.getvalue(), command('flood', argv), page='docs/controller.md')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

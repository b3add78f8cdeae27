"""
ur10_sim benchmark: real-time factor and CPU per part (physics, render, publish).

A script, not a pytest test. Run from the repository root::

    MUJOCO_GL=egl .venv/bin/python test/benchmarks/bench_sim.py [--seconds 5] [--no-subscriber]

It builds the real node (``etdmp_ros.nodes.ur10_sim.UR10SimNode``, shipped parameter files) in
this process and, for camera 15/30 Hz x control 125/500 Hz:

1. runs it UNPACED (real_time_factor 0) for ``--seconds`` of simulated time: the maximum
   real-time factor (simulated s / wall s) and the CPU it needs per simulated second, split into
   physics, render (+ depth conversion) and publish (state: joint states, clock, /tf, ground truth;
   images: Image + CameraInfo messages). CPU is process CPU (``time.process_time``), so
   llvmpipe's render threads and the DDS transport threads are counted;
2. runs it PACED at real_time_factor 1 in its simulation thread, as ``ros2 run`` does: the
   achieved real-time factor and the CPU share of the node (cores), its camera process (which
   renders there) included.

A subscriber process receives the camera and joint-state topics, like perception and the
controller would (``--no-subscriber`` to leave it out); its delivered rates are printed. Target
(issue 3): real-time factor >= 1.0 at 30 Hz camera + 125 Hz control while the simulation uses
at most one of the two cores. Finally it times sensor_msgs/Image creation (three ways) and
publishing for 640x480 rgb8 and 16UC1. Timing is noisy while other work runs on the machine.
"""

import argparse
import array
import os
import statistics
import subprocess
import sys
import textwrap
import time

os.environ.setdefault('MUJOCO_GL', 'egl')
# An isolated DDS domain for this run: other tests and nodes on the machine cannot interfere.
os.environ.setdefault('ROS_DOMAIN_ID', str(150 + os.getpid() % 50))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from _results import add_option, command, printed, publish  # noqa: E402
from etdmp_ros.demo.cpu_monitor import process_cpu_seconds, tree_cpu_seconds  # noqa: E402
from etdmp_ros.nodes.ur10_sim import UR10SimNode  # noqa: E402
from etdmp_ros.ros.conversions import image_msg  # noqa: E402
from etdmp_ros.ros.topics import COLOR as COLOR_TOPIC, DEPTH as DEPTH_TOPIC  # noqa: E402
import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import Image  # noqa: E402

SUBSCRIBER = textwrap.dedent("""
    import sys, time, rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import Image, JointState
    rclpy.init()
    node = Node('bench_sim_subscriber')
    counts = {'color': 0, 'depth': 0, 'joints': 0}
    def counter(key):
        def count(msg):
            counts[key] += 1
        return count
    node.create_subscription(Image, sys.argv[1], counter('color'), 2)
    node.create_subscription(Image, sys.argv[2], counter('depth'), 2)
    node.create_subscription(JointState, '/joint_states', counter('joints'), 50)
    start = None
    while True:
        line = sys.stdin.readline().strip()
        if line == 'start':
            for key in counts:
                counts[key] = 0
            start = time.monotonic(); cpu = time.process_time()
            import threading
            threading.Thread(target=rclpy.spin, args=(node,), daemon=True).start()
        elif line == 'reset':
            for key in counts:
                counts[key] = 0
            start = time.monotonic(); cpu = time.process_time()
        elif line == 'report':
            wall = time.monotonic() - start
            print(' '.join(f'{k}={v / wall:.1f}' for k, v in counts.items()),
                  f'cpu={(time.process_time() - cpu) / wall:.2f}', flush=True)
        elif line in ('quit', ''):
            break
""")


class Subscriber:
    """A separate process subscribing to camera and joint states (a stand-in for perception)."""

    def __init__(self):
        self.process = subprocess.Popen([sys.executable, '-c', SUBSCRIBER, COLOR_TOPIC,
                                         DEPTH_TOPIC], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True)
        self._send('start')

    def _send(self, line):
        self.process.stdin.write(line + '\n')
        self.process.stdin.flush()

    def reset(self):
        """Restart counting."""
        self._send('reset')

    def report(self):
        """Return the received rates and the subscriber's CPU since reset."""
        self._send('report')
        return self.process.stdout.readline().strip()

    def close(self):
        """End the process."""
        self._send('quit')
        self.process.wait(timeout=10)


def make_node(camera_rate, control_rate, rtf):
    """Return the ur10_sim node with the shipped parameters and these overrides."""
    return UR10SimNode(parameter_overrides=[
        Parameter('camera_rate', value=float(camera_rate)),
        Parameter('control_rate', value=float(control_rate)),
        Parameter('real_time_factor', value=float(rtf)),
        Parameter('watchdog_timeout', value=0.0)])


def unpaced(camera_rate, control_rate, seconds, subscribed):
    """Run unpaced; return (max real-time factor, CPU s per simulated s, per-part CPU)."""
    node = make_node(camera_rate, control_rate, 0.0)
    node.sim.set_velocity_command([0.05, -0.05, 0.05, 0.1, 0.1, 0.1])
    node.run_for(0.5)                                  # warm up: GL context, first frames
    # The image publishers exist from the first frame on; until the subscriber has matched
    # them nothing is rendered (unpaced, 0.5 s of simulated time pass in milliseconds).
    deadline = time.monotonic() + 10.0
    while subscribed and node.stats['render'] == 0.0 and time.monotonic() < deadline:
        time.sleep(0.05)
        node.run_for(0.1)
    for key in node.stats:
        node.stats[key] = 0 if key in ('ticks', 'frames') else 0.0
    wall, cpu = time.perf_counter(), time.process_time()
    node.run_for(seconds)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    stats = dict(node.stats)
    node.stop()
    node.destroy_node()
    return seconds / wall, cpu / seconds, {k: v / seconds for k, v in stats.items()}


def paced(camera_rate, control_rate, seconds):
    """Run the node's own thread at real-time factor 1; return (achieved RTF, CPU cores)."""
    node = make_node(camera_rate, control_rate, 1.0)
    node.start()
    time.sleep(2.0)    # the camera process starts up

    def cpu_now():     # this process and the node's camera process (not the subscriber's)
        camera = node._camera.process.pid if node._camera is not None else None
        return process_cpu_seconds(os.getpid()) + (tree_cpu_seconds(camera) if camera else 0.0)

    sim0, wall, cpu = node.sim.time, time.perf_counter(), cpu_now()
    time.sleep(seconds)
    sim1, wall = node.sim.time, time.perf_counter() - wall
    cpu = cpu_now() - cpu
    node.stop()
    node.destroy_node()
    return (sim1 - sim0) / wall, cpu / wall


def time_call(function, n):
    """Return the median wall time of ``function()`` in ms over ``n`` calls."""
    samples = []
    for _ in range(n):
        start = time.perf_counter()
        function()
        samples.append((time.perf_counter() - start) * 1e3)
    return statistics.median(samples)


def image_messages(n=50):
    """Time Image creation three ways and publishing, for rgb8 and 16UC1 640x480."""
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    depth = rng.integers(0, 3000, (480, 640), dtype=np.uint16)
    node = rclpy.create_node('bench_image_publisher')
    publisher = node.create_publisher(Image, COLOR_TOPIC, 2)
    rows = []
    for name, image, encoding in (('rgb8', rgb, 'rgb8'), ('16UC1', depth, '16UC1')):
        def via_bytes():
            msg = Image()
            msg.data = image.tobytes()
            return msg

        def via_bytes_checked():   # what ROS_PYTHON_CHECK_FIELDS=1 does to every message
            msg = Image(check_fields=True)
            msg.data = image.tobytes()
            return msg

        def via_frombytes():
            msg = Image(check_fields=True)
            data = array.array('B')
            data.frombytes(image.reshape(-1).view(np.uint8))
            msg.data = data
            return msg

        msg = image_msg(image, encoding)
        rows.append((name, time_call(via_bytes, n), time_call(via_bytes_checked, 3),
                     time_call(via_frombytes, n),
                     time_call(lambda: image_msg(image, encoding), n),
                     time_call(lambda: publisher.publish(msg), n)))
    node.destroy_node()
    return rows


def main():
    """Run the benchmark and print its tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seconds', type=float, default=5.0,
                        help='simulated seconds per configuration (default 5)')
    parser.add_argument('--no-subscriber', action='store_true',
                        help='no subscriber process (publishing then costs less)')
    add_option(parser)
    args = parser.parse_args()
    load = os.getloadavg()[0]
    rclpy.init(args=['--ros-args', '--log-level', 'warn'])
    subscriber = None if args.no_subscriber else Subscriber()
    time.sleep(1.0)
    print(f'ur10_sim benchmark: {os.cpu_count()} cores, {args.seconds:g} s simulated per row, '
          f'subscriber: {"no" if subscriber is None else "yes"}, load average before: '
          f'{os.getloadavg()[0]:.2f} (other work on the machine slows the paced rows)\n')
    with printed() as tables:
        print('Unpaced (as fast as possible); CPU in ms per simulated second '
              '(1000 = one core busy at real time):\n')
        print('| camera Hz | control Hz | max RTF | CPU/sim s | physics | render | publish images'
              ' | publish state | of which /tf |')
        print('|---|---|---|---|---|---|---|---|---|')
        results = {}
        for camera_rate in (15, 30):
            for control_rate in (125, 500):
                rtf, cpu, parts = unpaced(camera_rate, control_rate, args.seconds,
                                          subscriber is not None)
                results[camera_rate, control_rate] = rtf, cpu
                print(f'| {camera_rate} | {control_rate} | {rtf:.1f} | {cpu * 1e3:.0f} | '
                      f'{parts["physics"] * 1e3:.0f} | {parts["render"] * 1e3:.0f} | '
                      f'{parts["publish_images"] * 1e3:.0f} | '
                      f'{parts["publish_state"] * 1e3:.0f} | {parts["publish_tf"] * 1e3:.0f} |')
        print('\nPaced at real-time factor 1 (the node as it runs):\n')
        print('| camera Hz | control Hz | achieved RTF | CPU (cores) | subscriber received (Hz), '
              'its CPU (cores) |')
        print('|---|---|---|---|---|')
        paced_results = {}
        for camera_rate, control_rate in ((30, 125), (30, 500), (15, 125)):
            if subscriber:
                subscriber.reset()
            rtf, cores = paced(camera_rate, control_rate, args.seconds)
            received = subscriber.report() if subscriber else '-'
            paced_results[camera_rate, control_rate] = rtf, cores
            print(f'| {camera_rate} | {control_rate} | {rtf:.3f} | {cores:.2f} | {received} |')
    print('\nsensor_msgs/Image 640x480, median ms: creation via msg.data = arr.tobytes() '
          '(without / with rclpy field checks, ROS_PYTHON_CHECK_FIELDS=1), via '
          'array.array.frombytes (what image_msg does; checks on), image_msg() with its '
          'validation; publish (serialization + DDS, subscriber present):\n')
    print('| encoding | tobytes | tobytes, checked | frombytes, checked | image_msg | publish |')
    print('|---|---|---|---|---|---|')
    for name, t_bytes, t_checked, t_from, t_msg, t_pub in image_messages():
        print(f'| {name} | {t_bytes:.2f} | {t_checked:.1f} | {t_from:.2f} | {t_msg:.2f} | '
              f'{t_pub:.2f} |')
    rtf, cores = paced_results[30, 125]
    ok = results[30, 125][0] >= 1.0 and rtf >= 0.98 and cores <= 1.0
    target = (f'Target 30 Hz camera + 125 Hz control: max RTF {results[30, 125][0]:.1f} (>= 1), '
              f'paced RTF {rtf:.3f} using {cores:.2f} of {os.cpu_count()} cores (<= 1): '
              f'{"met" if ok else "NOT met"}')
    print(f'\n{target} (load average now {os.getloadavg()[0]:.2f})')
    if not args.no_docs:
        publish('sim', f'{tables.getvalue().strip()}\n\n{target}; {args.seconds:g} s simulated '
                f'per row, subscriber: {"no" if subscriber is None else "yes"}.', command('sim'),
                load=load)
    if subscriber:
        subscriber.close()
    rclpy.shutdown()


if __name__ == '__main__':
    main()

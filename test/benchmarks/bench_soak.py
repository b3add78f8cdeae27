#!/usr/bin/env python3
"""
Soak of the whole system: /generalize hammered while the arm tracks, junk on its input.

The four nodes start as ``make demo`` starts them (letter G, its scene; dmp_server with
``execute`` false, so the requests plan without moving the arm). The arm tracks one long path
published on /etdmp/path: the letter forward and back, over and over, for ``--seconds``. Meanwhile

- ``--clients`` clients (4) each call /generalize ``--rate`` times a second (20), from the
  tool's current position to the perceived goal, without waiting for the answers;
- a junk publisher sends ``--junk-rate`` (1000) joint states a second on /joint_states naming
  joints the robot does not have.

It prints: requests sent, answered with a plan, refused (an empty plan: dmp_server logs why),
never answered; answer latency p50 / p99 / max; the controller's states over the run (no
stale-input, no unreachable), how far the tool ended from the path's end and its tracking
summary; the largest resident memory of every node. Run from the repository with the venv:
``.venv/bin/python test/benchmarks/bench_soak.py`` (or ``make bench-soak``). Unless
``--no-docs``, the table goes into docs/reliability.md (block ``soak``) with the command, date,
machine and code version (``_results.publish``).
"""

import argparse
import os
from pathlib import Path
import statistics
import sys
import tempfile
import threading
import time

REPO = Path(__file__).resolve().parents[2]
os.environ.setdefault('MUJOCO_GL', 'egl')
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'test' / 'benchmarks'))

from _results import add_option, command, printed, publish  # noqa: E402
from etdmp_ros.demo.scenario import Scenario  # noqa: E402
from etdmp_ros.ros.background import BackgroundNode  # noqa: E402
from etdmp_ros.ros.conversions import path_to_numpy, point_to_numpy, serialize_path  # noqa: E402
from etdmp_ros.ros.processes import isolated_environment, SystemProcesses  # noqa: E402
from geometry_msgs.msg import PointStamped  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
import numpy as np  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STARTUP = 120.0


class Observer(BackgroundNode):
    """Status, tool tip, the path publisher and one /generalize client."""

    def __init__(self, domain):
        super().__init__('soak_observer', domain)
        self.lock = threading.Lock()
        self.status = []
        self.tip = None
        n = self.node
        n.create_subscription(String, 'etdmp/controller/status', self._on_status, LATCHED)
        n.create_subscription(PointStamped, 'ur10_sim/ground_truth/tool_tip', self._on_tip, 10)
        self.path_pub = n.create_publisher(PathMsg, 'etdmp/path', LATCHED)
        self.generalize = n.create_client(GetPlan, 'generalize')
        self.start()

    def _on_status(self, msg):
        with self.lock:
            self.status.append((time.monotonic(), msg.data))

    def _on_tip(self, msg):
        with self.lock:
            self.tip = point_to_numpy(msg.point)

    def state(self):
        with self.lock:
            return self.status[-1][1].split(':')[0] if self.status else None

    def plan(self, timeout=10.0):
        """Return (t, positions, quaternions) of one /generalize answer (empty if refused)."""
        future = self.generalize.call_async(GetPlan.Request())
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        if not future.done():
            return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 4))
        return path_to_numpy(future.result().plan)


class Client(BackgroundNode):
    """Calls /generalize ``rate`` times a second without waiting; records every answer."""

    def __init__(self, domain, index, rate):
        super().__init__(f'soak_client_{index}', domain)
        self.rate = rate
        # A client that has many calls outstanding must keep as many responses (rclpy's default
        # depth of 10 drops the rest in this client, unseen).
        self.client = self.node.create_client(GetPlan, 'generalize',
                                              qos_profile=QoSProfile(depth=1000))
        self.lock = threading.Lock()
        self.sent = []              # send times
        self.answers = []           # (latency s, poses)
        self.start()

    def _answer(self, sent):
        def done(future):
            poses = len(future.result().plan.poses) if future.result() is not None else -1
            with self.lock:
                self.answers.append((time.monotonic() - sent, poses))
        return done

    def run(self, seconds, stop):
        start = time.monotonic()
        k = 0
        while not stop.is_set() and time.monotonic() < start + seconds:
            now = time.monotonic()
            future = self.client.call_async(GetPlan.Request())
            future.add_done_callback(self._answer(now))
            with self.lock:
                self.sent.append(now)
            k += 1
            time.sleep(max(0.0, start + k / self.rate - time.monotonic()))


class Junk(BackgroundNode):
    """Publishes joint states of joints the robot does not have."""

    def __init__(self, domain):
        super().__init__('soak_junk', domain)
        self.pub = self.node.create_publisher(JointState, 'joint_states', 10)
        self.sent = 0
        self.start()

    def run(self, rate, stop):
        msg = JointState(name=['a', 'b', 'c'], position=[0.0, 1.0, 2.0])
        start = time.monotonic()
        while not stop.is_set():
            self.pub.publish(msg)
            self.sent += 1
            time.sleep(max(0.0, start + self.sent / rate - time.monotonic()))


def wait_until(predicate, timeout, what, nodes):
    deadline = time.monotonic() + timeout
    while not predicate():
        nodes.check_alive()
        if time.monotonic() > deadline:
            raise SystemExit(f'timed out waiting for {what}')
        time.sleep(0.05)


def back_and_forth(t, positions, seconds):
    """Return (t, positions) of the plan forward, then backward, ... for at least ``seconds``."""
    out_t, out_p = [t], [positions]
    while out_t[-1][-1] < seconds:
        base = out_t[-1][-1]
        pieces = positions[::-1] if len(out_t) % 2 else positions
        out_t.append(base + t[1:])
        out_p.append(pieces[1:])
    return np.concatenate(out_t), np.concatenate(out_p)


def rss_mb(pid):
    try:
        with open(f'/proc/{pid}/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--clients', type=int, default=4)
    parser.add_argument('--rate', type=float, default=20.0, help='requests/s per client')
    parser.add_argument('--junk-rate', type=float, default=1000.0)
    add_option(parser)
    args = parser.parse_args()
    load = os.getloadavg()[0]

    domain = os.getpid() % 100 + 1
    env = isolated_environment(domain)
    os.environ.update(env)
    out = Path(tempfile.mkdtemp(prefix='bench_soak_'))
    scenario = Scenario(None, 'G', parameters={'dmp_server': {'execute': False}})
    nodes = SystemProcesses(scenario.param_files, out / 'logs', env)
    observer = Observer(domain)
    clients, junk, stop = [], None, threading.Event()
    peak = {}
    try:
        wait_until(lambda: observer.generalize.service_is_ready() and observer.state() == 'idle'
                   and observer.tip is not None, STARTUP, 'the system', nodes)
        for _ in range(100):
            t, positions, quaternions = observer.plan()
            if len(positions):
                break
            time.sleep(0.5)
        else:
            raise SystemExit('dmp_server gave no plan: ' + nodes.last_error('dmp_server'))
        path_t, path_p = back_and_forth(t, positions, args.seconds)
        print(f'the arm tracks {len(path_t)} poses over {path_t[-1]:.1f} s (the letter G '
              f'forward and back); {args.clients} clients x {args.rate:g} requests/s; junk '
              f'joint states at {args.junk_rate:g}/s', flush=True)
        clients = [Client(domain, i, args.rate) for i in range(args.clients)]
        junk = Junk(domain)
        wait_until(lambda: all(c.client.service_is_ready() for c in clients), 30, 'clients',
                   nodes)
        n_status = len(observer.status)
        observer.path_pub.publish(serialize_path(path_p, path_t, orientation=quaternions[0]))
        wait_until(lambda: observer.state() == 'tracking', 30, 'tracking', nodes)
        threads = [threading.Thread(target=c.run, args=(args.seconds, stop)) for c in clients]
        threads.append(threading.Thread(target=junk.run, args=(args.junk_rate, stop)))
        for thread in threads:
            thread.start()
        end = time.monotonic() + args.seconds + 60.0
        moving = ('approaching', 'tracking', 'holding')
        while time.monotonic() < end and observer.state() in moving:
            nodes.check_alive()
            for name, process in nodes.processes.items():
                peak[name] = max(peak.get(name, 0.0), rss_mb(process.pid))
            time.sleep(0.2)
        stop.set()
        for thread in threads:
            thread.join()
        sent = sum(len(c.sent) for c in clients)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and sum(len(c.answers) for c in clients) < sent:
            time.sleep(0.1)
        answers = [a for c in clients for a in c.answers]
        latencies = sorted(a[0] for a in answers)
        planned = sum(1 for a in answers if a[1] > 0)
        with observer.lock:
            states = [s for _, s in observer.status[n_status:]]
            tip = observer.tip.copy()
        log = nodes.log('controller')
        tracked = [line.split('path tracked: ')[1] for line in log.splitlines()
                   if 'path tracked: ' in line]
        refusals = [line for line in nodes.log('dmp_server').splitlines() if '[ERROR]' in line]
        print()
        with printed() as kept:
            print('| figure | value |')
            print('|---|---|')
            print(f'| requests sent | {sent} |')
            print(f'| answered with a plan | {planned} |')
            print(f'| refused (empty plan, ERROR line) | {len(answers) - planned} |')
            print(f'| never answered | {sent - len(answers)} |')
            if latencies:
                p99 = latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))]
                print(f'| answer latency p50 / p99 / max (ms) | '
                      f'{1e3 * statistics.median(latencies):.0f} / {1e3 * p99:.0f} / '
                      f'{1e3 * latencies[-1]:.0f} |')
            print(f'| junk joint states sent | {junk.sent} |')
            order = ' -> '.join(dict.fromkeys(s.split(':')[0] for s in states))
            print(f'| controller states | {order} |')
            bad = sum(s.startswith(('stale-input', 'unreachable', 'halted')) for s in states)
            print(f'| stale-input / unreachable / halted | {bad} |')
            print(f'| tool to the path end (mm) | {1e3 * np.linalg.norm(tip - path_p[-1]):.2f} |')
            print(f'| tracking | {tracked[-1] if tracked else "-"} |')
            print('| peak RSS (MB) | ' + ', '.join(f'{k} {v:.0f}' for k, v in peak.items()) + ' |')
        if not args.no_docs:
            setting = (f'A {path_t[-1]:.0f} s path; {args.clients} clients x {args.rate:g} '
                       f'requests/s; junk joint states at {args.junk_rate:g}/s.')
            publish('soak', f'{kept.getvalue()}\n{setting}', command('soak'),
                    page='docs/reliability.md', load=load)
        if refusals:
            print(f'\nlast refusal: {refusals[-1]}')
        print(f'\nlogs in {out / "logs"}')
    finally:
        stop.set()
        for node in clients + [junk, observer]:
            if node is not None:
                node.close()
        nodes.stop()
        served = [line.split('/generalize answered ')[1] for line in
                  nodes.log('dmp_server').splitlines() if '/generalize answered ' in line]
        if served:    # its own count, at exit: answers lost on the way show as a difference
            print(f'dmp_server at exit: /generalize answered {served[-1]}')


if __name__ == '__main__':
    main()

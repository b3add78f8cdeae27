"""
Two computers on one machine, for the tests and the benchmark (no test module).

:class:`TwoHosts` makes two network namespaces, the robot's PC and the workstation, joined by a
veth pair with a private /30 (:data:`ADDRESSES`; it exists only inside the two namespaces),
each with its own loopback. Their names carry this process's id and a counter, so parallel runs
cannot meet; :meth:`TwoHosts.close` kills what still runs inside them and removes them, also
after a failure. Making namespaces needs root (CAP_SYS_ADMIN, CAP_NET_ADMIN) and ``ip``
(iproute2): :func:`unavailable` says why not where they are missing, and the tests skip with it.

The middleware is limited to UDP, as between two real machines: the package's Fast DDS profile
without its shared-memory transport (:func:`udp_only_profile`; the UDP transport as the package
configures it). The namespaces share ``/dev/shm``, and on one machine nothing else would keep
the two sides from meeting there (docs/two_hosts.md). Discovery is docs/two_hosts.md's recipe for
a network that does not carry multicast: ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (the default;
multicast is routed to each namespace's loopback only, so the nodes of one host find each other
by it) and ``ROS_STATIC_PEERS`` naming the other host's address. Not ``LOCALHOST``: with it,
rmw_fastrtps (Jazzy) adds a shared-memory and a UDP transport of its own to every participant,
whatever the profile says.

The demo runs as a user runs it on the workstation, in a process of its own there (``python
test/support/two_hosts.py run ...``, :func:`run`): the demo's machinery
(:func:`etdmp_ros.demo.run.run_demo`, its recorder, scenario and metrics), each node started on its
host (``ip netns exec``; the demo's ``command``), the figures written to ``two_hosts.json`` in the
output folder. A process of its own, because Fast DDS lists the network interfaces once per
process: a participant made in a second namespace of the same process offers the first one's
addresses, and is never reached. For the same reason what the arm does while the link is down is
recorded on the robot's side by a process there (``python test/support/two_hosts.py observe FILE``,
:func:`observe`).

- :func:`link_down_mid_letter`: the demo's ``before_plans`` hook that takes the link down for
  0.5 s while a letter is written, then waits for the controller and plans again;
- :func:`generalize_latency`: a ``before_plans`` hook timing ``/generalize`` from each host;
- :func:`camera_figures`: the frames perception processed per simulated second.
"""

import argparse
import contextlib
import itertools
import json
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from xml.etree import ElementTree

from etdmp_ros.ros import fastdds_files, system
from etdmp_ros.ros.paths import config_path

ROBOT, WORKSTATION = 'robot', 'workstation'
HOST_NAMES = (ROBOT, WORKSTATION)
#: The link's addresses: a /30 that exists only inside the two namespaces.
ADDRESSES = {ROBOT: '10.23.0.1', WORKSTATION: '10.23.0.2'}
PREFIX_LENGTH = 30
#: The ends of the veth pair, one in each namespace.
INTERFACES = {ROBOT: 'etdmp0', WORKSTATION: 'etdmp1'}
THIS = Path(__file__).resolve()
#: The demo's output (etdmp_ros.demo) and this harness's figures beside it.
RESULT = 'two_hosts.json'
_COUNTER = itertools.count()
#: Joint speeds below this count as stopped (rad/s: 1 mm/s at a metre from the axis).
STOPPED = 1e-3
#: Wall-clock time the run may take beyond start-up and the letters (s).
RUN_TIMEOUT = 300.0


def udp_only_profile(path, source=None):
    """
    Write the package's Fast DDS profile (config/fastdds.xml) without shared memory to ``path``.

    The UDPv4 transport stays as the package configures it. ``source``: the profile to start
    from (default: the package's). Return ``path``.
    """
    tree = ElementTree.parse(source or config_path('fastdds.xml'))
    root = tree.getroot()
    ns = {'p': root.tag.split('}')[0].strip('{')}
    shm = {d.find('p:transport_id', ns).text
           for d in root.iterfind('p:transport_descriptors/p:transport_descriptor', ns)
           if d.find('p:type', ns).text == 'SHM'}
    for transports in root.iterfind('.//p:userTransports', ns):
        for entry in list(transports):
            if entry.text in shm:
                transports.remove(entry)
    ElementTree.register_namespace('', ns['p'])
    tree.write(path, xml_declaration=True, encoding='UTF-8')
    return Path(path)


def _ip(*args, check=True):
    return subprocess.run(['ip', *args], capture_output=True, text=True, check=check,
                          timeout=10)


def unavailable():
    """Return why two namespaces cannot be made here ('' when they can)."""
    if shutil.which('ip') is None:
        return 'ip (iproute2) is not installed'
    if os.geteuid() != 0:
        return 'not root: network namespaces and a veth pair need CAP_SYS_ADMIN and CAP_NET_ADMIN'
    name = f'etdmp-probe-{os.getpid()}'
    made = _ip('netns', 'add', name, check=False)
    if made.returncode != 0:
        return f'ip netns add is not permitted here: {made.stderr.strip()}'
    _ip('netns', 'del', name, check=False)
    return ''


class TwoHosts:
    """The robot's PC and the workstation as two network namespaces joined by one link."""

    def __init__(self, robot_nodes=None, profile=None, names=None):
        """
        Make the namespaces and the link (or use ``names``, made by another process).

        ``robot_nodes``: the nodes on the robot's PC, default :data:`etdmp_ros.ros.system.HOSTS`
        ``robot``; every other node runs on the workstation. ``profile``: the Fast DDS profile
        of every process (default: :func:`udp_only_profile`, written here).
        """
        self.robot_nodes = tuple(system.HOSTS[ROBOT] if robot_nodes is None else robot_nodes)
        self._dir = tempfile.TemporaryDirectory(prefix='etdmp_two_hosts_')
        self.profile = Path(profile) if profile else udp_only_profile(
            Path(self._dir.name) / 'fastdds_udp.xml')
        self.owner = names is None
        if names is None:
            tag = f'etdmp-{os.getpid()}-{next(_COUNTER)}'
            names = (f'{tag}-r', f'{tag}-w')
        self.names = dict(zip(HOST_NAMES, names))
        self._made = []
        if self.owner:
            try:
                self._make()
            except BaseException:
                self.close()
                raise

    def _make(self):
        robot, work = self.names[ROBOT], self.names[WORKSTATION]
        for name in (robot, work):
            _ip('netns', 'add', name)
            self._made.append(name)
            # Multicast stays on the host (a network that does not carry it): the nodes of
            # one host find each other by it, the other host only as a static peer.
            _ip('-n', name, 'link', 'set', 'lo', 'up', 'multicast', 'on')
            _ip('-n', name, 'route', 'add', '224.0.0.0/4', 'dev', 'lo')
        _ip('-n', robot, 'link', 'add', INTERFACES[ROBOT], 'type', 'veth', 'peer', 'name',
            INTERFACES[WORKSTATION], 'netns', work)
        for host in HOST_NAMES:
            _ip('-n', self.names[host], 'addr', 'add', f'{ADDRESSES[host]}/{PREFIX_LENGTH}',
                'dev', INTERFACES[host])
            _ip('-n', self.names[host], 'link', 'set', INTERFACES[host], 'up')
        self.wait_for_carrier()

    def wait_for_carrier(self, timeout=5.0):
        """
        Wait until both ends of the link have carrier (the kernel may report it late).

        Fast DDS lists a host's addresses when a process's first participant starts, leaving
        out interfaces without carrier: a node started before would offer only its loopback,
        and the other host could discover it but never reach it.
        """
        deadline = time.monotonic() + timeout
        while True:
            states = [_ip('-n', self.names[h], '-o', 'link', 'show', 'dev', INTERFACES[h]).stdout
                      for h in HOST_NAMES]
            if all('NO-CARRIER' not in s and 'state UP' in s for s in states):
                return
            if time.monotonic() > deadline:
                raise RuntimeError(f'the link has no carrier after {timeout:g} s: {states}')
            time.sleep(0.02)

    # ------------------------------------------------------------------------------ placing
    def host_of(self, node):
        """Return the host a node runs on."""
        return ROBOT if node in self.robot_nodes else WORKSTATION

    def environment(self, host):
        """Return the variables of a process on ``host``: discovery and the Fast DDS profile."""
        other = WORKSTATION if host == ROBOT else ROBOT
        return {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET',
                'ROS_STATIC_PEERS': ADDRESSES[other],
                'FASTRTPS_DEFAULT_PROFILES_FILE': str(self.profile)}

    def wrap(self, host, argv):
        """Return ``argv`` run on ``host`` (inside its namespace, with its environment)."""
        variables = [f'{k}={v}' for k, v in self.environment(host).items()]
        return ['ip', 'netns', 'exec', self.names[host], 'env', *variables, *map(str, argv)]

    def command(self, inner):
        """Return a demo command that runs ``inner(node, param_files)``'s argv on its host."""
        def command(node, param_files):
            return self.wrap(self.host_of(node), inner(node, param_files))
        return command

    def arguments(self):
        """Return the command-line arguments of :func:`run` that name these hosts."""
        return ['--names', *[self.names[h] for h in HOST_NAMES], '--profile', str(self.profile),
                '--robot-nodes', ','.join(self.robot_nodes)]

    # --------------------------------------------------------------------------------- faults
    def link(self, up):
        """Take the link up or down (the robot's end; the workstation's loses its carrier)."""
        _ip('-n', self.names[ROBOT], 'link', 'set', INTERFACES[ROBOT], 'up' if up else 'down')

    def cut(self, seconds):
        """Take the link down for ``seconds`` (wall clock); return (down, up) monotonic s."""
        self.link(False)
        down = time.monotonic()
        try:
            time.sleep(seconds)
        finally:
            self.link(True)
        return down, time.monotonic()

    def counters(self, host):
        """Return the kernel's IP and UDP counters in ``host``'s namespace (``nstat``)."""
        out = subprocess.run(['ip', 'netns', 'exec', self.names[host], 'nstat', '-az',
                              '--json'], capture_output=True, text=True, timeout=10).stdout
        try:
            return json.loads(out)['kernel']
        except (ValueError, KeyError):
            return {}

    # ------------------------------------------------------------------------------ cleanup
    def pids(self):
        """Return the ids of the processes inside either namespace (never this one)."""
        found = []
        for name in self._made:
            out = _ip('netns', 'pids', name, check=False).stdout.split()
            found += [int(p) for p in out if p.isdigit() and int(p) != os.getpid()]
        return found

    def close(self):
        """Kill what still runs inside (all of it started here), remove the namespaces."""
        killed = self.pids()
        for pid in killed:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + 5.0
        while self.pids() and time.monotonic() < deadline:
            time.sleep(0.05)
        if killed:      # their Fast DDS files (/dev/shm is shared): as a next start removes them
            fastdds_files.clean()
        for name in reversed(self._made):
            _ip('netns', 'del', name, check=False)
        self._made = []
        self._dir.cleanup()

    def __enter__(self):
        """Return self."""
        return self

    def __exit__(self, *exc):
        """Close."""
        self.close()


# ------------------------------------------------------------------------- the robot's side


def observe(path):
    """
    Record /joint_states and the commands as they reach the robot's side until SIGINT.

    Writes ``path`` (.json): ``states`` [receipt monotonic s, stamp ns, largest joint speed
    rad/s], ``commands`` [receipt monotonic s, latest joint-state stamp ns then, largest
    |command| rad/s]. CLOCK_MONOTONIC is the machine's, shared by every namespace.
    """
    from etdmp_ros.ros.spin import rate_qos
    from etdmp_ros.ros.background import BackgroundNode
    from etdmp_ros.ros.conversions import joint_state_from_cdr
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    lock = threading.Lock()
    states, commands, latest = [], [], [0]
    node = BackgroundNode('etdmp_robot_observer')

    def on_state(raw):
        stamp, _, velocities = joint_state_from_cdr(raw)
        speed = float(max(abs(v) for v in velocities)) if velocities is not None else None
        with lock:
            latest[0] = max(latest[0], stamp)
            states.append((time.monotonic(), stamp, speed))

    def on_command(raw):
        data = deserialize_message(raw, Float64MultiArray).data
        with lock:
            commands.append((time.monotonic(), latest[0],
                             float(max((abs(v) for v in data), default=0.0))))

    node.node.create_subscription(JointState, 'joint_states', on_state, rate_qos(125.0),
                                  raw=True)
    node.node.create_subscription(Float64MultiArray, 'forward_velocity_controller/commands',
                                  on_command, rate_qos(125.0), raw=True)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    node.start()
    print('observing', flush=True)
    stop.wait()
    node.close()
    with lock:
        Path(path).write_text(json.dumps({'states': states, 'commands': commands}))


def stop_figures(observed, down, up):
    """
    Return how the arm stopped after the link went down at monotonic ``down`` (up at ``up``).

    ``observed``: what :func:`observe` wrote. In robot time, from the cut (the latest joint
    state the robot's side published before the link went down: the cut came within one
    control period after it): ``speed_at_cut`` (largest joint speed, rad/s),
    ``last_command_after_s`` (the last command to arrive; negative: before the cut),
    ``braked_after_s`` (the first joint state whose speed is below half the speed at the cut:
    a zero command in force, which the joint servos follow within milliseconds),
    ``zero_velocity_after_s`` (every joint speed below :data:`STOPPED`; None: not while the
    link was down), ``stayed_stopped`` (until the link was back), ``robot_time_down_s``.
    """
    states, commands = observed['states'], observed['commands']
    before = [stamp for t, stamp, _ in states if t <= down]
    if not before:
        return {'observed': False}
    cut = before[-1]
    during = [(stamp, speed) for t, stamp, speed in states if stamp >= cut and t <= up]
    last = max((stamp for t, stamp, _ in commands if t <= up), default=None)
    stopped = next((stamp for stamp, speed in during if speed is not None and speed < STOPPED),
                   None)
    at_cut = during[0][1] if during else None
    braked = next((stamp for stamp, speed in during
                   if at_cut and speed is not None and speed < 0.5 * at_cut), None)
    after = [speed for stamp, speed in during if stopped is not None and stamp >= stopped]
    return {'observed': True, 'cut_stamp_ns': cut,
            'speed_at_cut': at_cut,
            'last_command_after_s': None if last is None else (last - cut) * 1e-9,
            'braked_after_s': None if braked is None else (braked - cut) * 1e-9,
            'zero_velocity_after_s': None if stopped is None else (stopped - cut) * 1e-9,
            'stayed_stopped': bool(after) and max(after) < STOPPED,
            'robot_time_down_s': (during[-1][0] - cut) * 1e-9 if during else 0.0}


def watchdog_figures(recorded_events, observed, cut_ns):
    """
    Return when the simulation braked after the cut, in its own time (its ``braked`` events).

    The first brake among ``recorded_events`` (the run's recording's, etdmp_ros.ros.events) at
    or after the cut (``cut_ns``, stamp): ``last_command_s``, ``braked_after_last_command_s``
    (the watchdog: its timeout, to a physics step) and ``zero_velocity_after_last_command_s``
    (every joint speed in ``observed`` below :data:`STOPPED`, from the joint states' stamps).
    Empty if it did not brake.
    """
    from etdmp_ros.ros.events import of_kind
    for event in of_kind(recorded_events, 'ur10_sim', 'braked'):
        last, braked = event.number('last_command_s'), event.number('braked_s')
        if braked * 1e9 >= cut_ns:
            break
    else:
        return {}
    rest = next((stamp for _, stamp, speed in observed['states']
                 if stamp >= braked * 1e9 and speed is not None and speed < STOPPED), None)
    return {'last_command_s': last, 'braked_after_last_command_s': braked - last,
            'zero_velocity_after_last_command_s': None if rest is None
            else rest * 1e-9 - last}


def first_command_after(observed, wall):
    """Return the monotonic time of the first moving command to reach the robot after ``wall``."""
    return next((t for t, _, speed in observed['commands'] if t > wall and speed > 0.0), None)


# ------------------------------------------------------------------------------ the hooks


def _wait(predicate, timeout, what, nodes):
    deadline = time.monotonic() + timeout
    while not predicate():
        nodes.check_alive()
        if time.monotonic() > deadline:
            raise RuntimeError(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(0.005)


#: The skill taught before the link goes down (:func:`teach_stroke`), planned after its return.
TAUGHT = 'stroke_before_the_cut'


def teach_stroke(recorder, nodes, name=TAUGHT, timeout=10.0):
    """
    Teach dmp_server a skill as a user's tool would: a Path on /etdmp/demonstrations.

    A quarter circle of 0.1 m radius on the table, 100 poses over 2 s, named ``name``
    (dmp_server's ``teach_skill_name``). Waits for dmp_server's report in its log; raises
    RuntimeError if it did not learn it.
    """
    import numpy as np
    from etdmp_ros.ros.conversions import path_from_numpy
    from nav_msgs.msg import Path as PathMessage
    recorder.set_server_parameters(teach_skill_name=name)
    publisher = recorder.node.create_publisher(PathMessage, '/etdmp/demonstrations', 10)
    deadline = time.monotonic() + timeout
    while publisher.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            raise RuntimeError('dmp_server does not subscribe /etdmp/demonstrations')
        time.sleep(0.05)
    angle = np.linspace(0.0, np.pi / 2, 100)
    positions = np.column_stack([0.80 + 0.1 * np.cos(angle), 0.05 + 0.1 * np.sin(angle),
                                 np.zeros_like(angle)])
    seen = len(nodes.log('dmp_server'))
    publisher.publish(path_from_numpy(positions, np.linspace(0.0, 2.0, 100)))

    def report():
        return [line for line in nodes.log('dmp_server')[seen:].splitlines()
                if f'skill {name!r}' in line]
    while not report():
        if time.monotonic() > deadline:
            raise RuntimeError(f'dmp_server did not report learning {name!r}')
        time.sleep(0.05)
    if 'learned skill' not in report()[0]:
        raise RuntimeError(report()[0])
    recorder.node.destroy_publisher(publisher)


def link_down_mid_letter(hosts, seconds=0.5, at=0.4, timeout=30.0):
    """
    Return a demo ``before_plans`` hook: a letter whose link goes down for ``seconds`` mid-way.

    It teaches dmp_server a skill (:func:`teach_stroke`), asks ``/generalize`` for the
    demo's skill (executed), takes the link down at ``at`` of the letter's duration after
    tracking began, brings it back after ``seconds`` (wall clock), waits until the controller
    has stopped tracking, then asks ``/generalize`` again (not executed) until dmp_server plans
    the taught skill; the demo's own plans follow. Returns ``statuses`` (the controller's,
    from that plan on), ``status_after_cut`` (its first status after the cut), ``link_down_s``,
    ``planned_again_after_s`` (wall clock, from the link's return to a plan of the taught
    skill), ``taught_plan_poses``, ``down`` and ``up`` (monotonic s), ``watchdog_braked``
    (ur10_sim logged its command watchdog's brake), ``node_pids``.
    """
    from etdmp_ros.demo import run as demo

    def before_plans(recorder, nodes, scenario, progress):
        teach_stroke(recorder, nodes)
        progress(f'taught dmp_server the skill {TAUGHT!r}')
        recorder.set_server_parameters(method='etdmp', execute=True)
        seen = len(recorder.state())
        _, plan_t, _, _, reason = demo._generalize(recorder, scenario.request_goal)
        if not len(plan_t):
            raise RuntimeError(f'/generalize refused the first letter: {reason}')
        tau = float(scenario.server['duration']) or float(scenario.demo.duration)

        def tracking_since():
            return next((ns for ns, text in recorder.state(seen)
                         if text.startswith('tracking')), None)
        _wait(lambda: tracking_since() is not None, timeout, 'tracking', nodes)
        cut_ns = tracking_since() + int(at * tau * 1e9)
        _wait(lambda: recorder.sim_ns >= cut_ns, timeout, f'{at:g} of the letter', nodes)
        n_status, sim_log = len(recorder.state()), len(nodes.log('ur10_sim'))
        down, up = hosts.cut(seconds)
        progress(f'the link was down for {up - down:.3f} s at {at:.0%} of the letter')

        def settled():      # not moving any more, whatever the reason
            words = [text.split(':')[0] for _, text in recorder.state(n_status)]
            return bool(words) and words[-1] in ('idle', *demo.STATUS_FAILURES)
        _wait(settled, timeout, 'the controller to stop tracking', nodes)
        # The recorder's simulated time (the pen tip's stamps, from the robot's side) runs
        # again: the demo's plans are timed by it.
        since = recorder.sim_ns
        _wait(lambda: recorder.sim_ns > since + int(0.1e9), timeout, 'the pen tip', nodes)
        recorder.set_server_parameters(method='etdmp', execute=False, skill=TAUGHT)
        while True:
            _, plan_t, _, _, reason = demo._generalize(recorder, scenario.request_goal,
                                                       attempts=1)
            if len(plan_t):
                planned = time.monotonic()
                break
            if time.monotonic() > up + timeout:
                raise RuntimeError(f'no plan of {TAUGHT!r} within {timeout:g} s of the '
                                   f"link's return: {reason}")
            time.sleep(0.05)
        recorder.set_server_parameters(skill=scenario.skill)
        after_cut = [text for _, text in recorder.state(n_status)]
        return {'statuses': [text for _, text in recorder.state(seen)],
                'status_after_cut': after_cut[0] if after_cut else None,
                'link_down_s': up - down, 'planned_again_after_s': planned - up,
                'taught_plan_poses': len(plan_t),
                'down': down, 'up': up, 'requested_again': time.monotonic(),
                'watchdog_braked': 'braking to zero' in nodes.log('ur10_sim')[sim_log:],
                'node_pids': {n: p.pid for n, p in nodes.processes.items()}}
    return before_plans


def generalize_latency(callers, calls=20):
    """
    Return a demo ``before_plans`` hook timing ``/generalize`` (not executed) from each caller.

    ``callers``: {name: argv prefix} of the processes that call (``python test/support/two_hosts.py
    call`` is appended): each calls ``calls`` times and prints the round trips. Returns {name:
    [ms, ...]}.
    """
    def before_plans(recorder, nodes, scenario, progress):
        recorder.set_server_parameters(method='etdmp', execute=False)
        times = {}
        for name, prefix in callers.items():
            out = subprocess.run([*prefix, sys.executable, str(THIS), 'call', '--calls',
                                  str(calls)], capture_output=True, text=True, timeout=120)
            if out.returncode != 0:
                raise RuntimeError(f'the /generalize caller on {name} failed:\n{out.stderr}')
            times[name] = json.loads(out.stdout.strip().splitlines()[-1])
            progress(f'/generalize from {name}: p50 '
                     f'{sorted(times[name])[len(times[name]) // 2]:.1f} ms')
        return times
    return before_plans


def call(calls):
    """Call /generalize ``calls`` times (the tool's position to the perceived goal); print ms."""
    from etdmp_ros.ros.background import BackgroundNode
    from nav_msgs.srv import GetPlan
    node = BackgroundNode('etdmp_generalize_caller').start()
    client = node.node.create_client(GetPlan, 'generalize')
    try:
        if not client.wait_for_service(timeout_sec=30.0):
            raise SystemExit('/generalize is not offered')
        times = []
        for _ in range(calls + 1):          # the first one warms up
            started = time.perf_counter()
            future = client.call_async(GetPlan.Request())
            while not future.done():
                if time.perf_counter() - started > 30.0:
                    raise SystemExit('/generalize did not answer within 30 s')
                time.sleep(0.0005)
            if not future.result().plan.poses:
                raise SystemExit('/generalize refused the request')
            times.append((time.perf_counter() - started) * 1e3)
        print(json.dumps(times[1:]), flush=True)
    finally:
        node.close()


# ------------------------------------------------------------------------------ figures


def camera_figures(bag_path, start_ns, end_ns):
    """
    Return camera frames per simulated second over [start_ns, end_ns], from the recording.

    ``perception``: frames perception processed (its /etdmp/obstacles, one per frame, stamped
    with the frame's stamp); ``received``: camera_info as the demo's recorder received it;
    ``largest_gap_ms``: the largest gap between two frames perception processed.
    """
    from etdmp_ros.skills import recordings as bag
    from etdmp_ros.ros.conversions import header_stamp_ns
    stamps = {'/etdmp/obstacles': set(), '/camera/camera/color/camera_info': set()}
    for topic, _, _, data in bag.read_messages(bag_path, tuple(stamps)):
        stamp = header_stamp_ns(data)
        if start_ns <= stamp <= end_ns:
            stamps[topic].add(stamp)
    span = (end_ns - start_ns) * 1e-9
    processed = sorted(stamps['/etdmp/obstacles'])
    gaps = [(b - a) * 1e-6 for a, b in zip(processed, processed[1:])]
    return {'perception': len(processed) / span,
            'received': len(stamps['/camera/camera/color/camera_info']) / span,
            'largest_gap_ms': max(gaps, default=None), 'window_s': span}


# ----------------------------------------------------------------------------- the driver


def run(args):
    """
    Run the demo with its nodes on two hosts; write ``<out>/two_hosts.json``.

    Runs on the workstation (``hosts.wrap(WORKSTATION, ...)``). The JSON holds ``metrics``
    (the demo's; None if it failed), ``error``, ``camera`` (:func:`camera_figures` over the
    motion), ``link`` (``--cut``: the hook's figures, :func:`stop_figures` and
    ``moving_again_after_s``: from the link's return to the first moving command at the robot
    for the demo's plan), ``counters`` (the workstation's UDP/IP counters during the run).
    """
    from etdmp_ros.demo import run as demo
    from etdmp_ros.ros.processes import installed_command, isolated_environment, module_argv
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.names:
        hosts = TwoHosts(args.robot_nodes.split(','), args.profile, names=args.names)
        command = hosts.command(installed_command(args.install) if args.install
                                else module_argv)
    else:       # one host, as `make demo` runs it (the benchmark's comparison)
        hosts = None
        command = installed_command(args.install) if args.install else module_argv
    env = isolated_environment(args.domain, base=dict(os.environ))
    env['ROS_HOME'] = str(out / 'ros_home')       # logs and taught skills stay in the run's folder
    if hosts is not None:
        env.update(hosts.environment(WORKSTATION))
    os.environ.update(env)
    observer, observed_path = None, out / 'robot_side.json'
    if hosts is not None and args.cut:
        observer = subprocess.Popen(hosts.wrap(ROBOT, [sys.executable, THIS, 'observe',
                                                       observed_path]),
                                    stdout=subprocess.PIPE, text=True)
        observer.stdout.readline()      # 'observing': subscribed before the nodes start
    hook = None
    if args.cut:
        hook = link_down_mid_letter(hosts, args.cut, args.cut_at)
    elif args.latency:
        callers = {'one host': []} if hosts is None else {
            'workstation': hosts.wrap(WORKSTATION, []), 'robot': hosts.wrap(ROBOT, [])}
        hook = generalize_latency(callers, args.latency)
    options = demo.Options(skill=args.skill, out=out, animation=False, pictures=False,
                           quiet=False,
                           config_dir=Path(args.install) / 'share' / 'etdmp_ros' / 'config'
                           if args.install else None,
                           command=command, before_plans=hook)
    result = {'metrics': None, 'error': None}
    before = hosts.counters(WORKSTATION) if hosts is not None else {}
    try:
        result['metrics'], _ = demo.run_demo(options, env)
    except (demo.DemoError, RuntimeError) as err:
        result['error'] = str(err)
    finally:
        if observer is not None:
            observer.send_signal(signal.SIGINT)
            observer.wait(timeout=30)
    if hosts is not None:
        after = hosts.counters(WORKSTATION)
        result['counters'] = {k: after[k] - before.get(k, 0) for k in after
                              if k.startswith(('Udp', 'IpReasm', 'IpFrag'))}
    m = result['metrics']
    if m is not None:
        result['camera'] = camera_figures(out / demo.BAG_NAME, *_motion_window(out, m))
    if observer is not None and observed_path.exists() and m is not None:
        observed = json.loads(observed_path.read_text())
        link = dict(m['before_plans'])
        link.update(stop_figures(observed, link['down'], link['up']))
        if link.get('cut_stamp_ns') is not None:
            # The observer hears the joint states a little late on a busy machine, so its
            # cut is a little early: the simulation's own times are exact.
            from etdmp_ros.demo.recording import read_streams
            link.update(watchdog_figures(read_streams(out / demo.BAG_NAME)['events'], observed,
                                         link['cut_stamp_ns'] - int(0.05e9)))
        moving = first_command_after(observed, link['requested_again'])
        link['moving_again_after_s'] = None if moving is None else moving - link['up']
        result['link'] = link
    (out / RESULT).write_text(json.dumps(result, indent=1, default=float) + '\n')
    return 0 if result['error'] is None else 1


def _motion_window(out, metrics):
    """Return the simulated ns from the demo's /generalize call to the controller's idle."""
    import numpy as np
    call = float(np.load(out / 'recording.npz')['tracking_start']) - metrics['approach_duration_s']
    return int(call * 1e9), int((call + metrics['duration_s']) * 1e9)


def main(argv=None):
    """Run one of the harness's commands (see the module docstring)."""
    parser = argparse.ArgumentParser(prog='test/support/two_hosts.py')
    sub = parser.add_subparsers(dest='what', required=True)
    p = sub.add_parser('run', help='the demo with its nodes on two hosts')
    p.add_argument('--out', required=True)
    p.add_argument('--names', nargs=2, metavar=('ROBOT', 'WORKSTATION'),
                   help='the two network namespaces (default: one host)')
    p.add_argument('--profile', help='Fast DDS profile file of every process')
    p.add_argument('--robot-nodes', default=','.join(system.HOSTS[ROBOT]))
    p.add_argument('--install', help='colcon install whose executables run (default: python -m)')
    p.add_argument('--domain', type=int, default=None)
    p.add_argument('--skill', default='G')
    p.add_argument('--cut', type=float, default=0.0, help='take the link down this long (s)')
    p.add_argument('--cut-at', type=float, default=0.4, help='... at this part of the letter')
    p.add_argument('--latency', type=int, default=0, help='time this many /generalize calls')
    p = sub.add_parser('observe', help='record the arm on the robot side until SIGINT')
    p.add_argument('path')
    p = sub.add_parser('call', help='time /generalize calls')
    p.add_argument('--calls', type=int, default=20)
    args = parser.parse_args(argv)
    if args.what == 'run' and args.cut and not args.names:
        parser.error('--cut needs two hosts (--names)')
    os.environ.setdefault('MUJOCO_GL', 'egl')
    if args.what == 'observe':
        return observe(args.path) or 0
    if args.what == 'call':
        return call(args.calls) or 0
    return run(args)


if __name__ == '__main__':
    sys.exit(main())

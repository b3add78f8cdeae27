"""
The controller node as a user runs it: installed executables in their own processes, rclpy here.

``ur10_sim`` (camera off) and ``controller`` start from the colcon install with the shipped
parameter files; this process publishes a nav_msgs/Path on /etdmp/path, as ``ros2 topic pub``
would (no dmp_server needed), and records /joint_states, the commands, the controller's reference
and status. The true tool tip is the forward kinematics of the simulated joints (/joint_states);
the controller's reference is checked to be the plan at its nominal speed, so a slowed-down
reference cannot hide a lag. Timing thresholds leave room for a loaded 2-core machine.
"""

import os
import signal
import threading
import time

from conftest import isolate_dds, NodeProcess
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.nodes.controller import InputWatch
from etdmp_ros.robot import PoseTrajectory, UR10Model
from etdmp_ros.ros.background import BackgroundNode
from etdmp_ros.ros.conversions import (joint_state_from_cdr, joint_state_msg, ns_to_stamp,
                                       path_from_cdr, path_from_numpy, serialize_path, stamp_to_ns)
from etdmp_ros.ros.spin import normal_scheduling, RECEPTION_PRIORITY, set_realtime_priority
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
import numpy as np
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import SetBool
from support import threads
from support.controller_plans import g_plan, path_time_offset, Q_INITIAL, stir_plan, TOOL_OFFSET
from support.waiting import wait_for


LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STARTUP = 60.0
#: Reader history of the recorded topics (a few seconds at 500 Hz).
DEPTH = 5000
#: Zero commands the controller sends on exit (etdmp_ros.nodes.controller.EXIT_ZEROS).
EXIT_ZEROS = 3


class Client(BackgroundNode):
    """rclpy in this process (own context, spinning in a thread): records what it hears."""

    def __init__(self, domain):
        super().__init__('controller_test_client', domain)
        self.lock = threading.Lock()
        self.joints = {}            # stamp (ns) -> (q, receipt)
        self.references = {}        # stamp (ns) -> position
        self.commands = []          # (receipt, qd)
        self.status = []            # (receipt, text)
        n = self.node
        self.path_pub = n.create_publisher(Path, '/etdmp/path', LATCHED)
        self.joint_pub = n.create_publisher(JointState, '/joint_states', 10)
        # Joint states and references: shallow queues keep this client current (a deep backlog
        # would still hold the end of a path when its records are read). Commands: a deep queue,
        # since the acceleration check needs every one (consecutive ones are a period apart).
        n.create_subscription(JointState, '/joint_states', self._on_joints, 100, raw=True)
        n.create_subscription(PoseStamped, '/etdmp/controller/reference', self._on_reference,
                              100)
        n.create_subscription(Float64MultiArray, '/forward_velocity_controller/commands',
                              self._on_command, DEPTH)
        # Every status, also when this process is starved for a while: the controller sends
        # each once (on a change) and its publisher keeps only the last, so a depth-1 reader
        # here lost 'holding' (0.5 s long) once under a flood on a slower machine.
        n.create_subscription(String, '/etdmp/controller/status', self._on_status,
                              QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.pause = n.create_client(SetBool, '/controller/pause')
        self.parameters = n.create_client(SetParameters, '/controller/set_parameters')
        self.start()

    def _on_joints(self, data):
        # Read from the bytes, joint states of other joints skipped (a flood of them is cheap).
        now = time.monotonic()
        try:
            stamp, q, _ = joint_state_from_cdr(data)
        except ValueError:
            return
        with self.lock:
            self.joints[stamp] = (q, now)

    def _on_reference(self, msg):
        p = msg.pose.position
        with self.lock:
            self.references[stamp_to_ns(msg.header.stamp)] = np.array([p.x, p.y, p.z])

    def _on_command(self, msg):
        now = time.monotonic()
        with self.lock:
            self.commands.append((now, np.array(msg.data)))

    def _on_status(self, msg):
        with self.lock:
            self.status.append((time.monotonic(), msg.data))

    def state(self):
        """Return the latest status word (before any ': reason')."""
        with self.lock:
            return self.status[-1][1].split(':')[0] if self.status else None

    def wait_for(self, predicate, timeout, what, processes=()):
        """Wait until ``predicate()``; fail saying ``what`` (the last statuses, the logs)."""
        return wait_for(predicate, timeout, what, processes, period=0.01,
                        details=lambda: f'status {self.status[-5:]}')

    def latest_q(self):
        """Return the newest joint positions."""
        with self.lock:
            return self.joints[max(self.joints)][0].copy()

    def publish_path(self, path, stamp=0, orientation=None):
        """Publish a PoseTrajectory (positions, its times) as a nav_msgs/Path."""
        first = quat.from_matrix(path.rotations[0]) if orientation is None else orientation
        if np.allclose(path.rotations, path.rotations[0]):
            self.path_pub.publish(serialize_path(path.positions, path.t, stamp=stamp,
                                                 orientation=first))
            return
        msg = Path()
        msg.header.frame_id = 'base_link'
        for t, p, r in zip(path.t, path.positions, path.rotations):
            pose = PoseStamped()
            pose.header.stamp = ns_to_stamp(stamp + round(t * 1e9))
            pose.header.frame_id = 'base_link'
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = map(float, p)
            o = pose.pose.orientation
            o.x, o.y, o.z, o.w = map(float, quat.from_matrix(r))
            msg.poses.append(pose)
        self.path_pub.publish(msg)

    def set_parameter(self, name, value):
        """Set one bool or double parameter of /controller (as `ros2 param set`)."""
        assert self.parameters.wait_for_service(timeout_sec=10)
        if isinstance(value, bool):
            v = ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
        else:
            v = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(value))
        future = self.parameters.call_async(
            SetParameters.Request(parameters=[ParameterMsg(name=name, value=v)]))
        wait_for(future.done, 10.0, f'the answer to setting {name}')
        return future.result().results[0]

    def call_pause(self, paused):
        """Call /controller/pause; return the response."""
        assert self.pause.wait_for_service(timeout_sec=10)
        future = self.pause.call_async(SetBool.Request(data=paused))
        wait_for(future.done, 10.0, 'the answer of /controller/pause', period=0.005)
        return future.result()


class Rig:
    """ur10_sim + controller at one control rate, and the client."""

    def __init__(self, install, tmp, rate, sim=True):
        self._patch = pytest.MonkeyPatch()
        env = isolate_dds(self._patch)
        self.domain = int(env['ROS_DOMAIN_ID'])
        self.rate = rate
        self.processes = []
        self.client = None
        try:
            self._start(install, env, tmp, sim)
        except BaseException:
            # Nobody else would stop them: a failed start must not leave the nodes running.
            self.close()
            raise

    def _start(self, install, env, tmp, sim):
        rate = self.rate
        if sim:
            self.processes.append(NodeProcess(install, env, tmp, 'ur10_sim',
                                              {'camera_rate': 0.0, 'control_rate': rate}))
        # A faster approach than the default 0.1 m/s keeps the test short. On the simulation's
        # clock as the system runs it; without the simulation this process is a robot on the
        # wall clock (a real driver's).
        self.controller = NodeProcess(install, env, tmp, 'controller',
                                      {'control_rate': rate, 'approach_speed': 0.25,
                                       'use_sim_time': sim})
        self.processes.append(self.controller)
        self.client = Client(self.domain)
        self.ur10 = UR10Model(TOOL_OFFSET)
        if sim:
            self.client.wait_for(lambda: self.client.state() == 'idle', STARTUP,
                                 'the controller to see joint states', self.processes)
            # The latched status can arrive before the other topics are matched: wait for their
            # publishers, and for commands to arrive (the controller has matched this client's
            # readers, announced together), or the first path's references are missed.
            node = self.client.node
            self.client.wait_for(
                lambda: all(node.count_publishers(t) > 0 for t in (
                    '/etdmp/controller/reference', '/forward_velocity_controller/commands'))
                and self.client.commands, STARTUP, 'the controller topics', self.processes)

    def close(self):
        """Stop everything (whatever fails on the way); return the controller's exit code."""
        try:
            if self.client is not None:
                self.client.close()
        finally:
            codes = [p.stop() for p in self.processes]
            self._patch.undo()
        return codes[-1] if codes else None

    def logs(self):
        """Return the nodes' outputs."""
        return '\n'.join(p.log() for p in self.processes)

    def execute(self, path, timeout):
        """Publish ``path``, wait until the controller is idle again; return the records."""
        c = self.client
        with c.lock:
            start = time.monotonic()
            n_status = len(c.status)
        c.publish_path(path)
        c.wait_for(lambda: any(s.startswith('tracking') for _, s in c.status[n_status:]),
                   timeout, 'tracking', self.processes)
        c.wait_for(lambda: c.state() != 'tracking' and c.state() != 'approaching'
                   and c.state() != 'holding', timeout, 'the end of the path', self.processes)
        return self.records(start)

    def records(self, since):
        """Return joints, references and commands received after ``since`` (monotonic)."""
        c = self.client
        with c.lock:
            joints = {k: v for k, v in c.joints.items() if v[1] >= since}
            refs = {k: v for k, v in c.references.items() if k in joints}
            commands = [(w, v) for w, v in c.commands if w >= since]
            status = [s for w, s in c.status if w >= since]
        return joints, refs, commands, status

    def tracking_errors(self, path, joints, refs):
        """Return true tool-tip errors (m) while tracking, checking the reference's timing."""
        stamps = sorted(refs)
        # Said before the arithmetic below meets an empty array (a bare ValueError).
        assert len(stamps) >= 100, f'{len(stamps)} references with joint states received'
        t = np.array(stamps) * 1e-9
        ref = np.array([refs[s] for s in stamps])
        t0 = path_time_offset(path, t, ref)
        tau = t - t0
        tracking = (tau > 0.0) & (tau < path.duration)
        plan = np.array([path.pose(s)[0] for s in tau[tracking]])
        assert np.max(np.linalg.norm(ref[tracking] - plan, axis=1)) < 1e-6, \
            'the reference is not the plan at its nominal speed'
        # Enough of the tracking phase was seen: at 500 Hz this Python client, sharing two cores
        # with the simulation and the controller, may drop many of the 5 topics' messages.
        assert tracking.sum() >= max(100, 0.1 * path.duration * self.rate), tracking.sum()
        tool = np.array([self.ur10.frame_pose(joints[s][0])[0]
                         for s, keep in zip(stamps, tracking) if keep])
        return np.linalg.norm(tool - plan, axis=1)

    def assert_commands_within_limits(self, commands, joints):
        """Velocity limits on every command; acceleration limits between consecutive ones."""
        ik_limits = self.ur10.velocity_limits
        qd = np.array([v for _, v in commands])
        assert np.all(np.abs(qd) <= ik_limits * (1 + 1e-9))
        accel = np.abs(np.diff(qd, axis=0)) * self.rate
        limits = np.array([25.0, 25.0, 35.0, 40.0, 40.0, 40.0])      # config/controller.yaml
        assert np.all(accel <= limits * (1 + 1e-9)), accel.max(axis=0)
        q = np.array([v[0] for v in joints.values()])
        assert np.all(q >= self.ur10.lower) and np.all(q <= self.ur10.upper)


@pytest.fixture(scope='module')
def rig(colcon_install, tmp_path_factory):
    r = Rig(colcon_install, tmp_path_factory.mktemp('controller_125'), 125.0)
    try:
        yield r
    finally:
        # Stopped whatever happened before (the nodes of a failed test too).
        code = r.close()
    assert code == 0, r.logs()


def report(name, errors):
    rms = np.sqrt(np.mean(errors ** 2))
    print(f'{name}: tracking error RMS {rms * 1e3:.3f} mm, max {errors.max() * 1e3:.3f} mm '
          f'({len(errors)} samples)')
    return rms


def test_path_bytes_are_read_like_rclpy_reads_them():
    msg = Path()
    msg.header.frame_id = 'base_link'
    for i in range(7):
        pose = PoseStamped()
        pose.header.frame_id = ['base_link', '', 'x'][i % 3]
        pose.header.stamp = ns_to_stamp(1_700_000_000_123_456_789 + i * 10_000_001)
        pose.pose.position.x, pose.pose.position.z = 0.1 * i, -0.2 * i
        pose.pose.orientation.z, pose.pose.orientation.w = 0.6, 0.8
        msg.poses.append(pose)
    frame, frames, stamps, p, quats = path_from_cdr(serialize_message(msg))
    assert frame == 'base_link' and frames == {'base_link', '', 'x'}
    np.testing.assert_array_equal(stamps, 1_700_000_000_123_456_789 + np.arange(7) * 10_000_001)
    np.testing.assert_array_equal(p[:, 0], 0.1 * np.arange(7))
    np.testing.assert_array_equal(quats, [[0, 0, 0.6, 0.8]] * 7)
    t = np.arange(500) * 0.004
    positions = np.random.default_rng(0).normal(size=(500, 3))
    data = serialize_message(path_from_numpy(positions, t, stamp=123, frame_id='base_link',
                                             orientation=(0, 0, 0, 1)))     # rclpy's bytes
    frame, frames, stamps, p, quats = path_from_cdr(data)
    np.testing.assert_array_equal(p, positions)
    np.testing.assert_array_equal(stamps, 123 + np.round(t * 1e9).astype(np.int64))
    with pytest.raises(ValueError):
        path_from_cdr(data[:100])


def test_input_counts_as_lost_on_the_robots_time():
    ms = 1_000_000
    watch = InputWatch(timeout=0.1, stall_timeout=1.0)
    assert watch.lost(0, 0, True) == 'never received'
    # Simulated: the clock going on without joint states is lost input...
    watch.received(5000 * ms, 0, True)
    assert watch.lost(5099 * ms, 99 * ms, True) == ''
    assert 'none for 0.101 s of simulated time' in watch.lost(5101 * ms, 101 * ms, True)
    # ... a stalled simulation (clock stopped too, 0.9 s of wall time) is not ...
    assert watch.lost(5000 * ms, 900 * ms, True) == ''
    # ... until it has been silent for stall_timeout of wall time.
    assert 'simulation_stall_timeout' in watch.lost(5000 * ms, 1001 * ms, True)
    # A real robot: its time is the wall clock.
    watch.received(7 * ms, 7 * ms, False)
    assert watch.lost(106 * ms, 106 * ms, False) == ''
    assert 'of wall-clock time' in watch.lost(108 * ms, 108 * ms, False)
    # use_sim_time switched on: a fresh start on the new clock, not a jump of 1.8e9 s.
    assert watch.lost(20 * ms, 110 * ms, True) == ''


class Probe:
    """
    A subscription of joint_states beside the controller's, spun on its own.

    The controller node is not spun in the in-process tests: what is published waits in its
    subscription. The probe's subscription, in the same process, gets every message in the same
    delivery: once the probe has them, so has the controller's subscription.
    """

    def __init__(self, node, context):
        from rclpy.executors import SingleThreadedExecutor
        self.received = []
        node.create_subscription(JointState, 'joint_states', self.received.append, 100)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(node)

    def wait_for(self, count):
        """Spin the probe until it has received ``count`` joint states."""
        wait_for(lambda: self.executor.spin_once(timeout_sec=0.01) or
                 len(self.received) >= count, 10.0, f'{count} joint states delivered')


def test_joint_states_queued_behind_the_clock_are_late_not_lost(ros_env):
    # After the controller's process was not scheduled for a while, its executor may run the
    # watchdog (and the /clock callbacks) before the joint states that queued meanwhile. Those
    # must be used, not reported as lost: a fresh clone's make test next to a busy loop stopped
    # with "stale-input (none for 0.104 s of simulated time)" that way.
    import rclpy
    from etdmp_ros.nodes.controller import ControllerNode
    from rclpy.parameter import Parameter
    from rclpy.time import Time
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = ControllerNode(context=context, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('tool_offset', value=TOOL_OFFSET)])
        source = rclpy.create_node('joint_state_source', context=context)
        pub = source.create_publisher(JointState, 'joint_states', 10)
        probe = Probe(source, context)
        clock = node.get_clock()
        clock._set_ros_time_is_active(True)      # as rclpy's TimeSource does on /clock
        ms = 1_000_000
        clock.set_ros_time_override(Time(nanoseconds=5000 * ms))
        node.watch.received(5000 * ms, time.monotonic_ns(), True, stamp_ns=5000 * ms)
        wait_for(lambda: pub.get_subscription_count() >= 2, 10.0,
                 'the controller (and the probe) to match the publisher')
        stamps = range(5008, 5151, 8)
        for stamp in stamps:                     # every period's, queued in the subscription
            pub.publish(joint_state_msg(Q_INITIAL, stamp=ns_to_stamp(stamp * ms)))
        probe.wait_for(len(stamps))              # delivered to the subscription, not yet taken
        clock.set_ros_time_override(Time(nanoseconds=5160 * ms))   # the clock went on
        node._watchdog()
        assert not node._stale, 'joint states waiting in the subscription were called lost'
        np.testing.assert_allclose(node._q, Q_INITIAL)
        node._watchdog()                         # and with none waiting, lost they are
        clock.set_ros_time_override(Time(nanoseconds=5300 * ms))
        node._watchdog()
        assert node._stale
        probe.executor.shutdown()
        source.destroy_node()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_joint_states_are_taken_in_batches_on_a_thread_of_their_own(ros_env):
    # What the controller reads its joint states with (TopicBatches): a burst of 200 reaches
    # on_batch whole and in order, in a few batches (min_interval 50 ms: the burst queues
    # between two takes), on its own thread; stop() ends the thread and is safe to repeat.
    import rclpy
    from etdmp_ros.ros.batches import TopicBatches
    from rclpy.qos import ReliabilityPolicy
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        owner = rclpy.create_node('owner', context=context)
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        batches, threads_seen = [], set()

        def on_batch(batch):
            threads_seen.add(threading.current_thread().name)
            batches.append(batch)

        reader = TopicBatches(owner, JointState, 'joint_states', qos, on_batch,
                              min_interval=0.05, limit=1000)
        assert reader.node.get_name() == '_owner_joint_states'
        source = rclpy.create_node('source', context=context)
        pub = source.create_publisher(JointState, 'joint_states', qos)
        wait_for(lambda: pub.get_subscription_count() >= 1, 10.0, 'the reader to match')
        reader.start()
        for k in range(200):
            pub.publish(joint_state_msg(Q_INITIAL, stamp=ns_to_stamp(k + 1)))
        wait_for(lambda: sum(map(len, batches)) >= 200, 10.0, 'the 200 joint states taken')
        assert [joint_state_from_cdr(d)[0] for b in batches for d in b] == list(range(1, 201))
        assert len(batches) <= 10, [len(b) for b in batches]
        assert threads_seen == {'_owner_joint_states'}
        reader.stop()
        assert not reader._thread.is_alive()
        reader.stop()
        source.destroy_node()
        owner.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_joint_states_that_never_came_are_lost_when_the_next_one_shows_it():
    # A link down for 0.5 s: the simulation's /clock stopped reaching the controller with its
    # joint states, so its watchdog saw no time pass; then the clock and a joint state 0.5 s
    # later arrive together. Nothing was queued: the ones between were lost.
    ms = 1_000_000
    watch = InputWatch(timeout=0.1, stall_timeout=1.0)
    assert watch.gap(5000 * ms, True) == ''                  # the first: nothing to compare
    for stamp in range(5008, 5200, 8):                       # one a period: nothing lost
        assert watch.gap(stamp * ms, True) == ''
    assert watch.gap(5292 * ms, True) == ''                  # 0.1 s: the timeout itself
    assert 'none for 0.508 s of simulated time' in watch.gap(5800 * ms, True)
    assert watch.gap(8 * ms, True) == ''                     # a restarted simulation
    watch.received(0, 0, False)                              # use_sim_time off: afresh
    assert watch.gap(7 * ms, False) == ''
    assert 'none for 0.200 s of wall-clock time' in watch.gap(207 * ms, False)


@pytest.mark.parametrize('queued', [1, 3])
def test_a_link_loss_noticed_late_is_stale_input_not_a_tracking_error(ros_env, queued):
    # What the controller did when a link came back, the /clock first: it took the next joint
    # state, 0.5 s after the last, and stepped the path 0.5 s on from an arm the simulation's
    # watchdog had braked: "unreachable: tracking error 109 mm". It is lost input. With more
    # joint states queued behind that one (a period apart), it went on from the newest as if
    # nothing had been lost (two_hosts link-down test, once): the gap of the first counts.
    import rclpy
    from etdmp_ros.nodes.controller import ControllerNode
    from rclpy.parameter import Parameter
    from rclpy.time import Time
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = ControllerNode(context=context, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('tool_offset', value=TOOL_OFFSET)])
        source = rclpy.create_node('joint_state_source', context=context)
        pub = source.create_publisher(JointState, 'joint_states', 10)
        probe = Probe(source, context)
        clock = node.get_clock()
        clock._set_ros_time_is_active(True)      # as rclpy's TimeSource does on /clock
        ms = 1_000_000
        clock.set_ros_time_override(Time(nanoseconds=5000 * ms))
        node.watch.received(5000 * ms, time.monotonic_ns(), True, stamp_ns=5000 * ms)
        node.watch.gap(5000 * ms, True)
        wait_for(lambda: pub.get_subscription_count() >= 2, 10.0,
                 'the controller (and the probe) to match the publisher')
        clock.set_ros_time_override(Time(nanoseconds=5500 * ms))   # the link is back
        for k in range(queued):
            pub.publish(joint_state_msg(Q_INITIAL, stamp=ns_to_stamp((5504 + 8 * k) * ms)))
        probe.wait_for(queued)                   # delivered to the subscription, not yet taken
        node._watchdog()
        assert node._stale
        assert node.controller.status == 'stale-input'
        reason = node.controller.reason
        assert reason.startswith('joint states on joint_states are stale'), reason
        assert 'none for 0.504 s of simulated time' in reason, reason
        probe.executor.shutdown()
        source.destroy_node()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_a_joint_state_stamp_must_advance_with_the_robots_clock():
    ms = 1_000_000
    watch = InputWatch(timeout=0.1, stall_timeout=1.0)
    assert watch.implausible(123 * ms, 5000 * ms, True) == ''      # the first: nothing to compare
    watch.received(5000 * ms, 0, True, stamp_ns=5000 * ms)
    assert watch.implausible(5008 * ms, 5008 * ms, True) == ''
    assert watch.implausible(5016 * ms, 5000 * ms, True) == ''      # /clock a tick behind
    future = watch.implausible(105_008 * ms, 5008 * ms, True)
    assert '+100.000 s off the robot clock' in future, future
    assert '-5.000 s off' in watch.implausible(8 * ms, 5008 * ms, True)
    # Late (this process not scheduled while /clock went on, its messages taken first): the
    # stamp advanced, less than the clock. Plausible: it is the robot's, it came late.
    assert watch.implausible(5008 * ms, 5112 * ms, True) == ''
    # But one that did not advance while the clock went on is no news from the robot.
    assert '-0.112 s off' in watch.implausible(5000 * ms, 5112 * ms, True)
    # Ahead of this process's view of the clock (its /clock messages still queued), but not
    # ahead of the wall clock since the last one: the clock lags, the stamp is the robot's.
    assert '+0.104 s off' in watch.implausible(5176 * ms, 5072 * ms, True)
    assert watch.implausible(5176 * ms, 5072 * ms, True, wall_ns=180 * ms) == ''
    assert '+0.104 s off' in watch.implausible(5176 * ms, 5072 * ms, True, wall_ns=50 * ms)
    assert '+100.000 s off' in watch.implausible(105_008 * ms, 5008 * ms, True,
                                                 wall_ns=1000 * ms)
    # A restarted simulation: its clock went back with its stamps, which is plausible (the
    # controller then drops the path: its time went back).
    assert watch.implausible(8 * ms, 8 * ms, True) == ''
    # A robot on its own, unsynchronized clock: only the advance counts.
    watch.received(7 * ms, 7 * ms, False, stamp_ns=42_000 * ms)
    assert watch.implausible(42_008 * ms, 15 * ms, False) == ''


def test_after_a_late_joint_state_the_ones_on_time_are_taken():
    # A fresh clone beside a busy loop: one joint state came 0.104 s late (taken: late, not
    # false), then every one on time was refused "+0.112 s off the robot clock" for the rest
    # of the run, the late one's receipt having become the reference they were measured by.
    ms = 1_000_000
    watch = InputWatch(timeout=0.1, stall_timeout=1.0)
    watch.received(5000 * ms, 0, True, stamp_ns=5000 * ms)
    assert watch.implausible(5008 * ms, 5112 * ms, True, wall_ns=112 * ms) == ''      # late
    watch.received(5112 * ms, 112 * ms, True, stamp_ns=5008 * ms)
    # The simulation catches up (its time runs ahead of the wall clock for a moment).
    for k, stamp in enumerate(range(5120, 5400, 8)):
        wall = (120 + 4 * k) * ms
        assert watch.implausible(stamp * ms, stamp * ms, True, wall_ns=wall) == '', stamp
        watch.received(stamp * ms, wall, True, stamp_ns=stamp * ms)
    # Stamps from the future are still refused after it.
    assert '+100.000 s off' in watch.implausible(105_400 * ms, 5400 * ms, True,
                                                 wall_ns=300 * ms)


def test_a_stalled_simulation_is_late_input_not_lost_input(rig):
    """
    Freeze the simulation (SIGSTOP) for 0.3 s mid-letter: no stale-input, the letter goes on.

    What a loaded machine does to it for ~0.1 s (a process not scheduled): its clock stops with its
    joint states, so the arm did not move and the controller must wait, not drop the path. Then
    a freeze longer than simulation_stall_timeout (1 s): the simulation counts as gone.
    """
    path = g_plan()[0]
    c = rig.client
    sim = rig.processes[0]
    with c.lock:
        start, n_status = time.monotonic(), len(c.status)
    c.publish_path(path)
    c.wait_for(lambda: c.state() == 'tracking', 30.0, 'tracking', rig.processes)
    time.sleep(1.0)             # the subject: a freeze 1 s into the letter (mid-letter) ...
    os.kill(sim.pid, signal.SIGSTOP)
    time.sleep(0.3)             # ... for 0.3 s
    os.kill(sim.pid, signal.SIGCONT)
    c.wait_for(lambda: c.state() == 'idle', 30.0, 'the end of the letter', rig.processes)
    joints, refs, commands, _ = rig.records(start)
    with c.lock:
        status = [s for _, s in c.status[n_status:]]
    assert not any(s.startswith('stale-input') for s in status), status
    assert status[-1] == 'idle', status
    errors = rig.tracking_errors(path, joints, refs)
    assert errors.max() <= 3e-3, errors.max()
    rig.assert_commands_within_limits(commands, joints)
    np.testing.assert_allclose(rig.ur10.frame_pose(c.latest_q())[0], path.positions[-1],
                               atol=0.5e-3)

    c.publish_path(path)
    c.wait_for(lambda: c.state() == 'tracking', 30.0, 'tracking', rig.processes)
    os.kill(sim.pid, signal.SIGSTOP)
    try:
        c.wait_for(lambda: c.state().startswith('stale-input'), 3.0, 'stale input',
                   rig.processes)
    finally:
        os.kill(sim.pid, signal.SIGCONT)
    assert 'simulation_stall_timeout' in c.status[-1][1], c.status[-1]
    c.wait_for(lambda: c.state() == 'idle', 10.0, 'idle after the simulation is back',
               rig.processes)


def test_letter_g_at_500_hz(colcon_install, tmp_path):
    rig = Rig(colcon_install, tmp_path, 500.0)
    try:
        path = g_plan()[0]
        joints, refs, commands, status = rig.execute(path, timeout=30.0)
        assert status[-1] == 'idle', status
        errors = rig.tracking_errors(path, joints, refs)
        rms = report('G through ROS at 500 Hz', errors)
        assert rms <= 1e-3 and errors.max() <= 3e-3
        rig.assert_commands_within_limits(commands, joints)
    finally:
        assert rig.close() == 0, rig.logs()


def test_stale_joint_states_and_shutdown_send_zeros(colcon_install, tmp_path):
    # This process plays the robot: joint states at 125 Hz that never move, so the controller
    # keeps commanding motion towards a path 5 cm away, until the states stop.
    rig = Rig(colcon_install, tmp_path, 125.0, sim=False)
    c = rig.client
    stop = threading.Event()
    last = [None]

    def publish():
        next_time = time.monotonic()
        while not stop.is_set():
            stamp = ns_to_stamp(time.monotonic_ns())
            c.joint_pub.publish(joint_state_msg(Q_INITIAL, np.zeros(6), stamp=stamp))
            last[0] = time.monotonic()
            next_time += 1.0 / 125.0
            time.sleep(max(0.0, next_time - time.monotonic()))     # the robot's pace: 125 Hz

    robot = threading.Thread(target=publish, daemon=True)
    robot.start()
    try:
        c.wait_for(lambda: c.state() == 'idle', STARTUP, 'joint states', rig.processes)
        p0, r0 = rig.ur10.frame_pose(Q_INITIAL)
        target = PoseTrajectory([0.0, 2.0], [p0 + [0.05, 0, 0], p0 + [0.1, 0, 0]], [r0, r0])
        c.publish_path(target)
        c.wait_for(lambda: c.state() == 'approaching', 10.0, 'the approach', rig.processes)
        c.wait_for(lambda: np.any(c.commands[-1][1]), 5.0, 'a motion command', rig.processes)
        with c.lock:
            assert np.any(c.commands[-1][1])          # commanding motion
        stop.set()
        robot.join()
        c.wait_for(lambda: c.state() == 'stale-input', 2.0, 'stale input', rig.processes)
        c.wait_for(lambda: sum(w > last[0] and not np.any(v) for w, v in c.commands[-20:])
                   >= 0.1 * 125 / 2, 5.0, 'zero commands after the stale input', rig.processes)
        with c.lock:
            moving = [w for w, v in c.commands if np.any(v)]
            zeros = [w for w, v in c.commands if not np.any(v) and w > last[0]]
        timeout = 0.1                                  # config/controller.yaml
        # Zeros within two control periods of going stale (+ 20 ms for transport and a busy
        # machine's scheduling), and no motion command after that.
        assert moving[-1] < last[0] + timeout + 2.0 / 125.0 + 0.02
        assert zeros[0] - last[0] <= timeout + 2.0 / 125.0 + 0.02, zeros[0] - last[0]
        assert len(zeros) >= 0.1 * 125 / 2                # and keeps sending zeros
        # Joint states back: idle (the path was dropped); then Ctrl-C while moving again.
        stop.clear()
        robot = threading.Thread(target=publish, daemon=True)
        robot.start()
        c.wait_for(lambda: c.state() == 'idle', 5.0, 'idle after stale input', rig.processes)
        c.publish_path(target)
        c.wait_for(lambda: c.state() == 'approaching', 10.0, 'the approach', rig.processes)
        c.wait_for(lambda: np.any(c.commands[-1][1]), 5.0, 'a motion command', rig.processes)
        rig.controller.process.send_signal(signal.SIGINT)
        assert rig.controller.process.wait(timeout=10) == 0
        c.wait_for(lambda: c.status[-1][1].startswith('idle') and trailing_zeros(c) >= EXIT_ZEROS,
                   5.0, "the controller's last commands and status")
        with c.lock:
            assert np.any(c.commands[-EXIT_ZEROS - 1][1])
            assert not np.any(c.commands[-1][1])       # the last word is zero velocity
            assert c.status[-1][1] == 'idle: shutdown'
    finally:
        stop.set()
        robot.join()
        rig.close()


def trailing_zeros(client):
    """Return how many zero commands the client received after its last motion command."""
    with client.lock:
        return next((k for k, (_, v) in enumerate(reversed(client.commands)) if np.any(v)),
                    len(client.commands))


def test_letter_g_through_ros(rig):
    path = g_plan()[0]
    joints, refs, commands, status = rig.execute(path, timeout=30.0)
    assert status[-1] == 'idle', status
    errors = rig.tracking_errors(path, joints, refs)
    rms = report('G through ROS at 125 Hz', errors)
    assert rms <= 1e-3 and errors.max() <= 3e-3
    rig.assert_commands_within_limits(commands, joints)
    assert not np.any(commands[-1][1])
    q_end = rig.client.latest_q()
    np.testing.assert_allclose(rig.ur10.frame_pose(q_end)[0], path.positions[-1], atol=0.5e-3)


def test_stirring_through_ros(rig):
    path = stir_plan()[0]
    joints, refs, commands, status = rig.execute(path, timeout=40.0)
    assert status[-1] == 'idle', status
    errors = rig.tracking_errors(path, joints, refs)
    rms = report('stirring through ROS at 125 Hz', errors)
    assert rms <= 1e-3 and errors.max() <= 3e-3
    rig.assert_commands_within_limits(commands, joints)


def test_pause_sends_zeros_and_resume_finishes(rig):
    path = g_plan()[0]
    c = rig.client
    c.publish_path(path)
    c.wait_for(lambda: c.state() == 'tracking', 30.0, 'tracking', rig.processes)
    time.sleep(0.5)             # the subject: a pause mid-letter ...
    asked = time.monotonic()
    assert c.call_pause(True).success
    time.sleep(0.5)             # ... and 0.5 s paused, in which zeros must keep coming
    assert c.state() == 'paused'
    with c.lock:
        paused_at = next(w for w, s in c.status if w >= asked and s == 'paused')
        moving = [w for w, v in c.commands if w >= asked and np.any(v)]
        zeros = [w for w, v in c.commands if w >= asked and not np.any(v)]
    # The node reports 'paused' after sending the first zero; nothing moves two periods later.
    assert not moving or moving[-1] < paused_at + 2.0 / rig.rate, (moving[-3:], paused_at)
    assert len(zeros) > 0.4 * rig.rate                 # and zeros keep coming while paused
    resumed_at = time.monotonic()
    assert c.call_pause(False).success
    c.wait_for(lambda: 'tracking' in rig.records(resumed_at)[3], 30.0, 'tracking again',
               rig.processes)
    c.wait_for(lambda: c.state() == 'idle', 30.0, 'the end of the resumed path', rig.processes)
    np.testing.assert_allclose(rig.ur10.frame_pose(c.latest_q())[0], path.positions[-1],
                               atol=0.5e-3)


def test_unreachable_and_malformed_paths_are_refused(rig):
    c = rig.client
    path = g_plan()[0]
    far = PoseTrajectory(path.t, path.positions + [1.5, 0.0, 0.0], path.rotations)
    since = time.monotonic()
    c.publish_path(far)
    c.wait_for(lambda: c.state() == 'unreachable', 10.0, 'the refusal', rig.processes)
    with c.lock:
        reason = c.status[-1][1]
    assert 'out of reach' in reason
    # Malformed paths: wrong frame, NaN, stamps going back. Logged, ignored, node alive.
    bad = Path()
    bad.header.frame_id = 'map'
    bad.poses = [PoseStamped()]
    huge = path.positions[:3].copy()
    huge[1, 0] = 1e308   # a traceback in the checking thread before, the path dropped unsaid
    for message, said in ((bad, "frame 'map' is not base_link"),
                          (serialize_path(np.full((3, 3), np.nan), [0.0, 0.1, 0.2]), 'NaN'),
                          (serialize_path(path.positions[:3], [0.0, 0.2, 0.1]), 'increase'),
                          (serialize_path(huge, [0.0, 0.1, 0.2]), 'beyond 100 m')):
        seen = len(rig.controller.log())
        c.path_pub.publish(message)
        # The path topic keeps only the latest message: one at a time, each once refused.
        c.wait_for(lambda: said in rig.controller.log()[seen:], 10.0, f'the refusal: {said}',
                   rig.processes)
    _, _, commands, status = rig.records(since)
    assert status == ['unreachable: ' + reason.split(': ', 1)[1]]
    assert commands and not any(np.any(v) for _, v in commands)      # the arm never moved
    log = rig.controller.log()
    assert "frame 'map' is not base_link" in log and 'NaN' in log and 'increase' in log
    assert 'coordinate of 1e+308 m, beyond 100 m' in log and 'Traceback' not in log
    assert rig.controller.process.poll() is None


def test_parameters_are_validated(rig):
    c = rig.client
    refused = c.set_parameter('position_gain', 500.0)    # above the 125 Hz control rate
    assert not refused.successful and 'control rate' in refused.reason
    assert not c.set_parameter('approach_speed', -1.0).successful
    assert c.set_parameter('approach_speed', 0.3).successful
    assert c.set_parameter('approach_speed', 0.25).successful


def test_control_steps_run_at_the_configured_priority(rig):
    # The executor's thread (the process's main thread) at SCHED_FIFO 50, Fast DDS's UDP
    # reception threads (dds.udp.*) at SCHED_FIFO RECEPTION_PRIORITY (under it), its other
    # threads (dds.*) at normal priority; or, where that is not permitted, a warning and all
    # normal.
    pid = rig.controller.process.pid
    policies = threads.scheduling(pid)
    reception, middleware = threads.middleware(policies)
    assert middleware == {(os.SCHED_OTHER, 0)}, policies
    log = rig.controller.log()
    if 'SCHED_FIFO priority 50 refused' in log:     # no CAP_SYS_NICE / rtprio limit here
        assert policies[pid][1:] == (os.SCHED_OTHER, 0), policies
        assert reception == {(os.SCHED_OTHER, 0)}, policies
    else:
        assert reception == {(os.SCHED_FIFO, RECEPTION_PRIORITY)}, policies
        assert 'control steps at SCHED_FIFO priority 50' in log, log
        assert policies[pid][1:] == (os.SCHED_FIFO, 50), policies


def test_a_refused_priority_changes_nothing_and_a_worker_can_drop_one():
    result = {}

    def worker():
        result['reason'] = set_realtime_priority(100)        # above SCHED_FIFO's 99
        result['policy'] = os.sched_getscheduler(0)
        result['unchanged'] = set_realtime_priority(0)
        result['granted'] = set_realtime_priority(10) == ''  # where permitted
        result['raised'] = os.sched_getscheduler(0)
        normal_scheduling()
        result['lowered'] = os.sched_getscheduler(0)

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert result['reason'].startswith('SCHED_FIFO priority 100 refused'), result
    assert result['policy'] == os.SCHED_OTHER and result['unchanged'] == ''
    assert result['raised'] == (os.SCHED_FIFO if result['granted'] else os.SCHED_OTHER)
    assert result['lowered'] == os.SCHED_OTHER


def test_singularity_halt_through_ros(rig):
    c = rig.client
    assert c.set_parameter('check_paths', False).successful
    try:
        q_a = c.latest_q()
        q_b = q_a.copy()
        q_b[4] = 0.4                                  # through wrist_2 = 0
        t = np.linspace(0.0, 4.0, 201)
        poses = [rig.ur10.frame_pose(q_a + (q_b - q_a) * s / t[-1]) for s in t]
        path = PoseTrajectory(t, [p for p, _ in poses], [r for _, r in poses])
        joints, refs, commands, status = rig.execute(path, timeout=30.0)
    finally:
        assert c.set_parameter('check_paths', True).successful
    with c.lock:
        final = c.status[-1][1]
    assert final.startswith('halted-singularity: ') and 'condition number' in final, \
        (final, rig.controller.log())
    rig.assert_commands_within_limits(commands, joints)
    assert not np.any(commands[-1][1])
    q = np.array([v[0] for v in joints.values()])
    assert q[:, 4].max() < -0.05                      # stopped short of the singularity
    assert 'halted-singularity' in rig.controller.log()


def test_a_late_first_joint_state_does_not_lock_the_robot_out():
    # Two runs of the fault tests on a machine busy with starting nodes: the first joint state
    # the controller took had queued (its receipt, the reference, 0.152 s late); every joint
    # state after it read "+0.152 s off the robot clock" and the controller never took one.
    ms = 1_000_000
    watch = InputWatch(timeout=0.1, stall_timeout=1.0)
    watch.received(5152 * ms, 0, True, stamp_ns=5000 * ms)
    refused = []
    for stamp in range(5160, 5600, 8):
        robot = wall = stamp     # on time from now on
        why = watch.implausible(stamp * ms, robot * ms, True, wall_ns=(wall - 5152) * ms)
        if why:
            refused.append(stamp)
            continue
        watch.received(robot * ms, (wall - 5152) * ms, True, stamp_ns=stamp * ms)
    # Refused for one timeout of robot time (the controller goes stale meanwhile), then taken.
    assert refused and refused[-1] - refused[0] <= 110, refused
    assert watch.implausible(5600 * ms, 5600 * ms, True, wall_ns=448 * ms) == ''
    # Forged stamps in a burst (the attacks: three at once) still never make such a run.
    for k in range(3):
        assert '+100.0' in watch.implausible((105_600 + 8 * k) * ms, 5600 * ms, True,
                                             wall_ns=448 * ms)
    # Nor do forged stamps beside the robot's: each one taken ends their run.
    for k in range(40):
        t = 5608 + 8 * k
        assert '+0.500 s off' in watch.implausible((t + 500) * ms, t * ms, True,
                                                   wall_ns=(t - 5152) * ms)
        assert watch.implausible(t * ms, t * ms, True, wall_ns=(t - 5152) * ms) == ''
        watch.received(t * ms, (t - 5152) * ms, True, stamp_ns=t * ms)

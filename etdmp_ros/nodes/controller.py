"""
controller: makes the UR10 tool tip follow ``/etdmp/path`` (:class:`TrajectoryController`).

Subscribes ``/joint_states`` (sensor_msgs/JointState) and ``/etdmp/path`` (nav_msgs/Path,
transient local); publishes ``/forward_velocity_controller/commands`` (std_msgs/
Float64MultiArray, 6 joint velocities in rad/s, UR order), ``/etdmp/tool_pose``
(geometry_msgs/PoseStamped, base_link), ``/etdmp/controller/reference`` (PoseStamped: where
the tool should be, while following a reference), ``/etdmp/controller/tracking_error``
(std_msgs/Float64, metres: distance from the reference to the tool tip; both stamped or sent with
the joint state they belong to) and ``/etdmp/controller/status`` (std_msgs/String,
transient local, on change: ``<state>`` or ``<state>: <reason>``, the states of
:data:`etdmp_ros.robot.STATUSES`). Service ``/controller/pause`` (std_srvs/SetBool): true pauses
(zero command at once), false resumes the path where it was paused.

Timing. A control step runs when a joint state arrives, at most ``control_rate`` times per
second (in step with the robot, as a ros2_control controller is), on the joint state's stamp
(simulated time from ur10_sim; the receipt time if the stamp is zero). A watchdog at
``control_rate`` (wall clock) publishes zeros while paused and once no joint state has arrived
for ``joint_state_timeout`` of the robot's time (:class:`InputWatch`): the node's clock, under
``use_sim_time`` the simulation's, so a simulation that stalls stops that time too and is not
mistaken for lost input; one silent for ``simulation_stall_timeout`` of wall time is gone.
Joint states whose stamps jump by more than ``joint_state_timeout`` from one to the next were
lost in between (a network link that was down, its /clock gone with them): the same stop.
Idle, halted or refused, the controller keeps sending explicit zeros, because the real
``forward_velocity_controller`` applies the last command forever. Path: pose ``k`` is
timed at its stamp minus the first pose's stamp (the header stamp is ignored); a path whose
stamps are all equal is timed by its length (``untimed_path_speed``); all-zero orientations
mean "keep the tool's current orientation"; an empty path stops the arm (idle). A timed path
whose first pose's stamp lies on the time base of the path being tracked, and which matches it
at the current path time, continues it (dmp_server's re-plan of a remainder when the goal
moves): it is taken over at once at that path time, without an approach, and checked while it
is followed (a failed check stops it, as any path); any other path is checked first. Frames:
``base_link`` or empty only. Paths arrive as raw bytes and are parsed with numpy, so a long path
never stalls the control loop (see :mod:`etdmp_ros.ros.conversions._path_cdr`).
"""

from dataclasses import fields, replace
import math
import sys
import threading
import time

from etdmp_ros import limits
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.robot import (ControllerConfig, trajectory_from_path, TrajectoryController,
                             TrajectoryError, UR10Model)
from etdmp_ros.ros import system
from etdmp_ros.ros.conversions import (joint_state_from_cdr, ns_to_stamp, path_from_cdr,
                                       velocity_command_msg)
from etdmp_ros.ros.parameters import declare
from etdmp_ros.ros.spin import normal_scheduling, rate_qos, run, set_realtime_priority
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
import numpy as np
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import SetBool


NODE_NAME = 'controller'
JOINT_STATES_TOPIC = 'joint_states'
PATH_TOPIC = 'etdmp/path'
COMMAND_TOPIC = 'forward_velocity_controller/commands'
TOOL_POSE_TOPIC = 'etdmp/tool_pose'
STATUS_TOPIC = 'etdmp/controller/status'
ERROR_TOPIC = 'etdmp/controller/tracking_error'
REFERENCE_TOPIC = 'etdmp/controller/reference'
FRAMES = ('', 'base_link')
#: Zero commands sent on exit, a few ms apart (a lost one would leave the arm moving).
EXIT_ZEROS = 3
#: s a path received before the first joint state waits for one (e.g. a latched path).
WAIT_FOR_JOINT_STATES = 5.0
#: s between two warnings about ignored joint states (each says how many were ignored).
IGNORED_LOG_PERIOD = 2.0

DESCRIPTION = system.node(NODE_NAME)
#: The controller's own parameters (the scene's are read-only).
PARAMETERS = frozenset(p.name for p in DESCRIPTION.parameters)
# Node parameters that are fields of ControllerConfig under another name.
CONFIG_NAMES = {'control_rate': 'rate', 'joint_acceleration_limits': 'acceleration_limits'}


class TrackingSummary:
    """
    What the log line at the end of a tracked path reports (and the benchmarks read).

    The tracking error (metres, the controller's own: reference minus forward kinematics), the
    control steps against the control periods the path spanned (from the joint states' stamps),
    the joint states received and the largest wall-clock gap between two of them.
    """

    def __init__(self, period):
        """Start empty; ``period`` is the control period (s)."""
        self.period = period
        self.steps = 0
        self.received = 0
        self.max_gap = 0.0
        self._sum_sq = 0.0
        self._max_error = 0.0
        self._first = self._last = None
        self._max_gap_at = None

    def joint_state(self, gap, t):
        """Count a joint state received while tracking (stamp ``t``), ``gap`` s after the last."""
        self.received += 1
        if gap > self.max_gap:
            self.max_gap, self._max_gap_at = gap, t

    def step(self, t, error):
        """Count a control step at stamp ``t`` (s) with tracking error ``error`` (m)."""
        self.steps += 1
        self._sum_sq += error * error
        self._max_error = max(self._max_error, error)
        self._first = t if self._first is None else self._first
        self._last = t

    @property
    def periods(self):
        """Control periods from the first to the last step, both included."""
        return 0 if self._first is None else round((self._last - self._first) / self.period) + 1

    def summary(self):
        """Return the figures as one line of text."""
        rms = math.sqrt(self._sum_sq / max(self.steps, 1))
        return (f'error RMS {rms * 1e3:.3f} mm, max {self._max_error * 1e3:.3f} mm; '
                f'{self.steps} control steps in {self.periods} periods '
                f'({self.received} joint states received, largest gap '
                f'{self.max_gap * 1e3:.1f} ms'
                + (f' at t = {self._max_gap_at:.3f} s)' if self._max_gap_at is not None else ')'))


class InputWatch:
    """
    When the joint states count as lost: no new one for ``timeout`` of the robot's time.

    The robot's time is the time in which it moves. A real robot's is the wall clock (steady
    here: the system clock may jump). A simulated robot's is the simulation's /clock
    (``use_sim_time``): when the simulation stalls (its process not scheduled on a busy
    machine), its time and its joint states stop together and the arm does not move, so nothing
    is stale; the clock going on without joint states is. A simulation whose clock and joint
    states both stop for ``stall_timeout`` of wall time counts as gone. Receipt times are used,
    never the messages' stamps, which a wrong publisher can set to anything.
    """

    def __init__(self, timeout, stall_timeout):
        """Timeouts in seconds (``stall_timeout`` applies only to simulated time)."""
        self.timeout = timeout
        self.stall_timeout = stall_timeout
        self._robot = None      # robot time (ns) of the latest receipt
        self._wall = None       # steady time (ns) of the latest receipt
        self._stamp = None      # stamp (ns) of the latest joint state accepted
        self._arrived = None    # stamp (ns) of the latest plausible joint state to arrive
        self._simulated = False

    def received(self, robot_ns, wall_ns, simulated, stamp_ns=None):
        """Note a joint state (stamped ``stamp_ns``) received at these robot and steady times."""
        if simulated != self._simulated:
            self._stamp = self._arrived = None
        self._robot, self._wall, self._simulated = robot_ns, wall_ns, simulated
        if stamp_ns is not None:
            self._stamp = stamp_ns

    def implausible(self, stamp_ns, robot_ns, simulated, wall_ns=None):
        """
        Return why a joint state stamped ``stamp_ns`` cannot be the robot's ('' if it can).

        Its stamp must have advanced from the last accepted one's as the robot's time did, to
        within ``timeout``: a stamp far in the future would end the path at once (the
        controller's time is the stamps'), one far in the past would read as a restart. On a
        starved machine this process's view of the robot's clock (its /clock messages) and the
        joint states arrive out of step, both ways, so:

        - one that advanced, but less than the clock, is late, not false: this process was not
          scheduled while the robot's clock went on (its /clock messages taken first), or the
          transport held it back; refusing it stopped the arm as stale-input ("its stamp is
          -0.104 s off the robot clock") on a machine loaded 9 times over;
        - one ahead of the clock is the clock lagging (its /clock messages still queued) when
          its stamp advanced no more than the wall clock (``wall_ns``, steady) did since the last
          one was taken, plus ``timeout``: refusing it stopped the G next to a busy core ("+0.104
          s off ... advanced 0.176 s ... while the clock advanced 0.072 s"). A stamp 100 s ahead
          still is no stamp of the robot's.

        The controller goes on from such a joint state; its missed steps re-synchronise the
        path (etdmp_ros.robot._controller).
        """
        if self._stamp is None or simulated != self._simulated:
            return ''
        advance = (stamp_ns - self._stamp) * 1e-9
        skew = advance - (robot_ns - self._robot) * 1e-9
        if abs(skew) <= self.timeout or (skew < 0.0 and advance > 0.0):
            return ''
        if skew > 0.0 and wall_ns is not None and \
                advance <= (wall_ns - self._wall) * 1e-9 + self.timeout:
            return ''
        return (f'its stamp is {skew:+.3f} s off the robot clock (advanced '
                f'{(stamp_ns - self._stamp) * 1e-9:.3f} s since the last accepted one while the '
                f'clock advanced {(robot_ns - self._robot) * 1e-9:.3f} s), not from the robot')

    def gap(self, stamp_ns, simulated):
        """
        Return why the joint states before this one (stamped ``stamp_ns``) were lost, or ''.

        The robot's time advanced more than ``timeout`` between two joint states that arrived
        one after the other: the ones between never came (a network link that was down), even
        if nothing noticed meanwhile, the robot's /clock having stopped reaching this node with
        them. Joint states that only queued behind a busy process all arrive, a period apart.
        """
        previous, self._arrived = self._arrived, stamp_ns
        if previous is None or (stamp_ns - previous) * 1e-9 <= self.timeout:
            return ''
        clock = 'simulated' if simulated else 'wall-clock'
        return (f'none for {(stamp_ns - previous) * 1e-9:.3f} s of {clock} time: those '
                'between the last two never came')

    def lost(self, robot_ns, wall_ns, simulated):
        """Return why the joint states count as lost at these times ('' if they do not)."""
        if self._wall is None:
            return 'never received'
        if simulated != self._simulated:        # use_sim_time switched: start afresh
            self.received(robot_ns, wall_ns, simulated)
            return ''
        age = (robot_ns - self._robot) * 1e-9
        if age > self.timeout:
            clock = 'simulated' if simulated else 'wall-clock'
            return f'none for {age:.3f} s of {clock} time'
        silent = (wall_ns - self._wall) * 1e-9
        if simulated and silent > self.stall_timeout:
            return (f'none for {silent:.3f} s of wall-clock time, and the simulation clock '
                    'stopped with them (simulation_stall_timeout)')
        return ''


class ControllerNode(Node):
    """The controller node: joint states and paths in, joint velocity commands out."""

    def __init__(self, **kwargs):
        """Declare parameters, build the controller, create the topics and the service."""
        super().__init__(NODE_NAME, **kwargs)
        params = self._declare_parameters()
        self.config = self._config(params)
        self.watch = InputWatch(params['joint_state_timeout'],
                                params['simulation_stall_timeout'])
        self.untimed_speed = (params['untimed_path_speed'], params['untimed_path_angular_speed'])
        self.check_paths = params['check_paths']
        self.max_path_poses = params['max_path_poses']
        self.model = UR10Model(tool_offset=params['tool_offset'])
        self.controller = TrajectoryController(self.model, self.config)
        self.period = self.controller.period

        self._lock = threading.Lock()           # guards the controller and the fields below
        self._q = None                          # latest joint positions
        self._rotation = None                   # tool rotation at _q
        self._last_receipt = None               # time.monotonic() of the latest joint state
        self._sim_clock = self.get_clock()      # the robot's time under use_sim_time
        self._last_step = None                  # stamp (s) of the latest control step
        self._stale = False
        self._ignored, self._ignored_log_time = 0, -math.inf     # joint states ignored
        self._status = None
        self._path_generation = 0
        self._tracked = TrackingSummary(self.period)
        self._check_lock = threading.Lock()

        # A second of history: a slow reader must never block a control step's publish().
        rate = rate_qos(self.config.rate)
        self._command_pub = self.create_publisher(Float64MultiArray, COMMAND_TOPIC, rate)
        self._pose_pub = self.create_publisher(PoseStamped, TOOL_POSE_TOPIC, rate)
        self._error_pub = self.create_publisher(Float64, ERROR_TOPIC, rate)
        self._reference_pub = self.create_publisher(PoseStamped, REFERENCE_TOPIC, rate)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._status_pub = self.create_publisher(String, STATUS_TOPIC, latched)
        # Raw bytes, read with numpy (joint_state_from_cdr): a flood of joint states for other
        # joints is refused in microseconds. A deep history, not depth 1: such a flood must
        # not overwrite the robot's own before they are read. Best effort: a reliable reader
        # holds every later sample back until a lost one is repaired, so one lost joint state
        # meant none for ~0.1 s (stale input); best effort, the next one comes a period later.
        self._joint_state_sub = self.create_subscription(
            JointState, JOINT_STATES_TOPIC, self._on_joint_state,
            QoSProfile(depth=limits.JOINT_STATE_QUEUE, reliability=ReliabilityPolicy.BEST_EFFORT),
            raw=True)
        self.create_subscription(Path, PATH_TOPIC, self._on_path, latched, raw=True)
        self.create_service(SetBool, '~/pause', self._on_pause)
        self.create_timer(self.period, self._watchdog,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._publish_status()
        self.get_logger().info(
            f'following {PATH_TOPIC} at up to {self.config.rate:g} Hz, tool offset '
            f'{np.round(self.model.tool_offset, 4).tolist()} m, actuation delay '
            f'{self.controller.delay * 1000:.1f} ms; pause: {self.get_name()}/pause')

    def use_thread_priority(self):
        """
        Schedule the calling thread by the parameter thread_priority (the node program).

        Call from the thread that will spin the executor (the control steps), once the node
        exists. The program makes this change, not the node, so a test or a composed process
        keeps its scheduling. The path checks run in threads of normal priority.
        """
        priority = self.get_parameter('thread_priority').value
        reason = set_realtime_priority(priority)
        if reason:
            self.get_logger().warning(
                f'{reason}: the control steps run under normal scheduling and may be late when '
                'the machine is busy (grant CAP_SYS_NICE or an rtprio limit, or set '
                'thread_priority 0)')
        elif priority:
            self.get_logger().info(f'control steps at SCHED_FIFO priority {priority}')

    # ---------------------------------------------------------------------------- parameters
    def _declare_parameters(self):
        return declare(self, DESCRIPTION)

    @staticmethod
    def _config(params, base=None):
        """Return a validated ControllerConfig from parameter values (ValueError if bad)."""
        fields_ = {f.name for f in fields(ControllerConfig)}
        values = {}
        for name, value in params.items():
            key = CONFIG_NAMES.get(name, name)
            if key in fields_:
                values[key] = tuple(value) if isinstance(value, (list, tuple)) else value
        if 'actuation_delay' in values and values['actuation_delay'] < 0:
            values['actuation_delay'] = None
        if 'posture_gain' in params and 'initial_joint_positions' in params:
            values['posture'] = tuple(params['initial_joint_positions'])
        if 'acceleration_limits' in values and len(values['acceleration_limits']) != 6:
            raise ValueError('joint_acceleration_limits must have 6 values (UR joint order)')
        config = replace(base, **values) if base is not None else ControllerConfig(**values)
        config.validate()
        if config.condition_halt <= config.condition_slowdown:
            raise ValueError('condition_halt must be above condition_slowdown')
        return config

    def _validate_parameters(self, parameters):
        changes = {p.name: p.value for p in parameters if p.name in PARAMETERS}
        try:
            self._config(changes, base=self.config)
        except (ValueError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        changes = {p.name: p.value for p in parameters if p.name in PARAMETERS}
        with self._lock:
            new = self._config(changes, base=self.config)
            for f in fields(ControllerConfig):
                setattr(self.controller.config, f.name, getattr(new, f.name))
            self.watch.timeout = changes.get('joint_state_timeout', self.watch.timeout)
            self.watch.stall_timeout = changes.get('simulation_stall_timeout',
                                                   self.watch.stall_timeout)
            self.check_paths = changes.get('check_paths', self.check_paths)
            self.max_path_poses = changes.get('max_path_poses', self.max_path_poses)
            self.untimed_speed = (changes.get('untimed_path_speed', self.untimed_speed[0]),
                                  changes.get('untimed_path_angular_speed',
                                              self.untimed_speed[1]))

    # ------------------------------------------------------------------------------ control
    def _on_joint_state(self, data):
        receipt = time.monotonic()
        with self._lock:
            times = self._input_times()
            self._use_joint_states(self._read_joint_state(data, times), times, receipt)

    def _use_joint_states(self, newest, times, receipt):
        """
        Take the joint states queued in the subscription and step once, on the newest.

        ``newest`` is (stamp, q) of one read already, or None. The executor hands over one
        message per wait: what queued meanwhile is taken here (a flood from another publisher
        costs microseconds each, not an executor cycle). Return whether a joint state was used.
        """
        handle = self._joint_state_sub.handle
        with handle:
            for _ in range(limits.JOINT_STATE_QUEUE):
                taken = handle.take_message(JointState, True)
                if taken is None:
                    break
                newest = self._read_joint_state(taken[0], times) or newest
        if newest is None:
            return False
        stamp, q, gap = newest
        if gap and not self._stale:
            # Joint states were lost, noticed only now: stop as the watchdog would have.
            self.watch.received(*times, stamp_ns=stamp)
            self._q = q
            self._input_lost(gap)
            return True
        t = stamp * 1e-9
        if self.controller.status == 'tracking' and self._last_receipt is not None:
            self._tracked.joint_state(receipt - self._last_receipt, t)
        self._last_receipt = receipt
        self.watch.received(*times, stamp_ns=stamp)
        self._q = q
        if self._last_step is not None and self._last_step - 1e-9 <= t \
                < self._last_step + 0.75 * self.period and not self._stale:
            return True     # joint states faster than control_rate: step at control_rate
        if self._stale:
            self._stale = False
            self.get_logger().info('joint states are back')
        self._last_step = t
        resyncs = self.controller.resyncs
        command = self.controller.step(q, t)
        if self.controller.resyncs != resyncs:
            at, gap, before, after = self.controller.last_gap
            self.get_logger().warning(
                f'no control step for {gap * 1e3:.0f} ms (joint states late: this process was '
                f'not scheduled?); the arm went on with its last command meanwhile: the path '
                f'goes on from path time {after:.3f} s, nearest to the tool, instead of '
                f'{before:.3f} s')
        self._summarize(command, t)
        self._rotation = command.tool_rotation
        self._publish_command(command.qd)
        self._publish_feedback(command, ns_to_stamp(stamp))
        self._publish_status()
        return True

    def _read_joint_state(self, data, times):
        """
        Return (stamp ns, q, gap) of serialized joint state bytes, None if they are not usable.

        ``gap``: why the joint states before it count as lost ('' if they do not,
        :meth:`InputWatch.gap`).
        """
        try:
            stamp, q, _ = joint_state_from_cdr(data)
        except ValueError as exc:
            self._ignore(str(exc))
            return None
        if stamp == 0:      # unstamped: measured when received
            stamp = self.get_clock().now().nanoseconds
        implausible = self.watch.implausible(stamp, times[0], times[2], times[1])
        if implausible:
            self._ignore(implausible)
            return None
        return stamp, q, self.watch.gap(stamp, times[2])

    def _ignore(self, reason):
        """Count a joint state ignored; say why at most every IGNORED_LOG_PERIOD seconds."""
        self._ignored += 1
        now = time.monotonic()
        if now >= self._ignored_log_time + IGNORED_LOG_PERIOD:
            more = f' ({self._ignored} ignored since the last report)' if self._ignored > 1 else ''
            self.get_logger().warning(f'joint state ignored: {reason}{more}')
            self._ignored, self._ignored_log_time = 0, now

    def _summarize(self, command, t):
        """Accumulate a path's tracking figures; log them when its tracking ends."""
        if command.status == 'tracking':
            self._tracked.step(t, command.tracking_error)
        elif self._tracked.steps:
            self.get_logger().info(f'path tracked: {self._tracked.summary()}; actuation delay '
                                   f'estimate {self.controller.delay * 1e3:.1f} ms')
            self._tracked = TrackingSummary(self.period)

    def _input_times(self):
        """Return (robot time, steady time, simulated) now, in ns (see :class:`InputWatch`)."""
        wall = time.monotonic_ns()
        if self._sim_clock.ros_time_is_active:
            robot = self._sim_clock.now().nanoseconds
            if robot:                   # 0: no /clock received yet, the wall clock until then
                return robot, wall, True
        return wall, wall, False

    def _watchdog(self):
        with self._lock:
            times = self._input_times()
            lost = self.watch.lost(*times)
            # After the process was not scheduled for a while, the executor may run this timer
            # and the /clock callbacks before the joint states that queued meanwhile: those are
            # late, not lost.
            if lost and self._use_joint_states(None, times, time.monotonic()):
                return
            if lost:
                self._input_lost(lost)

    def _input_lost(self, lost):
        """Zero velocity, the path dropped, status stale-input saying why (``lost``)."""
        if not self._stale:
            self._stale = True
            reason = f'joint states on {JOINT_STATES_TOPIC} are stale ({lost})'
            self.controller.input_lost(reason)
            if self._last_receipt is not None:
                self.get_logger().error(f'{reason}: zero velocity command')
        self._publish_command(np.zeros(6))
        self._publish_status()

    def _publish_command(self, qd):
        self._command_pub.publish(velocity_command_msg(qd))

    def _publish_feedback(self, command, stamp):
        # Built and sent only while someone listens: each publication costs this 125 Hz loop
        # tens of microseconds of CPU, and each delivery as much in the receiving process.
        if self._pose_pub.get_subscription_count():
            self._pose_pub.publish(_pose_msg(command.tool_position, command.tool_rotation,
                                             stamp))
        if command.reference_position is not None:
            if self._reference_pub.get_subscription_count():
                self._reference_pub.publish(_pose_msg(command.reference_position,
                                                      command.reference_rotation, stamp))
            if self._error_pub.get_subscription_count():
                self._error_pub.publish(Float64(data=float(command.tracking_error)))

    def _publish_status(self):
        status = self.controller.status
        reason = self.controller.reason
        text = f'{status}: {reason}' if reason else status
        if text == self._status:
            return
        self._status = text
        self._status_pub.publish(String(data=text))
        if status in ('halted-singularity', 'halted-joint-limit', 'unreachable'):
            self.get_logger().error(f'{status}: {reason}; zero velocity command')
        else:
            self.get_logger().info(f'status: {text}')

    # ------------------------------------------------------------------------- path, pause
    def _on_path(self, data):
        try:
            frame, pose_frames, stamps, positions, quaternions = path_from_cdr(
                data, self.max_path_poses)
        except ValueError as exc:
            self.get_logger().error(f'path ignored: {exc}')
            return
        bad = ({frame} | pose_frames) - set(FRAMES)
        if bad:
            self.get_logger().error(f'path ignored: frame {sorted(bad)[0]!r} is not base_link '
                                    '(no TF here: send paths in base_link)')
            return
        with self._lock:
            self._path_generation += 1
            if len(stamps) == 0:
                self.controller.cancel('empty path received')
                self._publish_status()
                return
        # Checking a path takes milliseconds: not in the executor, which runs the control steps.
        threading.Thread(target=self._accept_path, daemon=True, name='path_check',
                         args=(self._path_generation, stamps, positions, quaternions)).start()

    def _accept_path(self, generation, stamps, positions, quaternions):
        """Time, check and hand over a received path (worker thread; the newest path wins)."""
        normal_scheduling()         # not real-time work (the thread inherits the executor's)
        try:
            self._take_path(generation, stamps, positions, quaternions)
        except Exception as exc:   # noqa: B902 - a path the checks missed: said, never a traceback
            self.get_logger().error(f'path ignored: it could not be checked: '
                                    f'{type(exc).__name__}: {str(exc)[:limits.MAX_REASON_CHARS]}')

    def _take_path(self, generation, stamps, positions, quaternions):
        q, rotation = self._wait_for_robot()
        if q is None:
            self.get_logger().error(f'path ignored: no joint states for {WAIT_FOR_JOINT_STATES:g}'
                                    f' s, the robot pose is unknown (is {JOINT_STATES_TOPIC} '
                                    'published?)')
            return
        try:
            path = trajectory_from_path(stamps, positions, quaternions, rotation,
                                        *self.untimed_speed)
        except TrajectoryError as exc:
            self.get_logger().error(f'path ignored: {exc}')
            return
        # Timed poses: the first one's stamp lets a re-planned remainder be spliced in.
        timed = len(stamps) > 1 and stamps[-1] != stamps[0]
        stamp = stamps[0] * 1e-9 if timed else None
        # A continuation of the path being tracked (a re-plan of its remainder) is taken over at
        # once and checked while it is followed: it differs from the tracked path only ahead of
        # the current path time, and a failed check stops it as it would any path.
        with self._lock:
            if generation != self._path_generation:
                return
            spliced = self.controller.continues(path, stamp)
            if spliced:
                self.controller.follow(path, stamp)
                self.get_logger().info(f'path continued: {len(stamps)} poses over '
                                       f'{path.duration:.2f} s (taken over at once, checked '
                                       'while followed)')
        with self._check_lock:      # one check at a time: the checker has one model
            reason = self.controller.check(path, q) if self.check_paths else ''
        with self._lock:
            if generation != self._path_generation:
                return              # a newer path arrived meanwhile
            if reason:
                self.controller.reject(reason)
            elif not spliced:
                self.controller.follow(path, stamp)
                self.get_logger().info(f'new path: {len(stamps)} poses over '
                                       f'{path.duration:.2f} s')
            self._publish_status()

    def _wait_for_robot(self):
        """Return (q, tool rotation) once a control step has run (None, None on timeout)."""
        deadline = time.monotonic() + WAIT_FOR_JOINT_STATES
        while rclpy.ok(context=self.context):
            with self._lock:
                if self._rotation is not None:
                    return self._q.copy(), self._rotation.copy()
            if time.monotonic() > deadline:
                break
            time.sleep(0.01)
        return None, None

    def _on_pause(self, request, response):
        with self._lock:
            self.controller.set_paused(bool(request.data))
            if request.data:
                self._publish_command(np.zeros(6))
            self._publish_status()
        response.success = True
        response.message = 'paused: zero velocity' if request.data else 'resumed'
        return response

    # -------------------------------------------------------------------------------- exit
    def send_zeros(self):
        """Publish zero velocity a few times (on exit: before the context shuts down)."""
        with self._lock:
            self.controller.shutdown()
            for _ in range(EXIT_ZEROS):
                self._publish_command(np.zeros(6))
                time.sleep(0.005)
            self._publish_status()
        self._command_pub.wait_for_all_acked(Duration(seconds=0.2))


def _pose_msg(position, rotation, stamp):
    pose = PoseStamped()
    pose.header.stamp = stamp
    pose.header.frame_id = 'base_link'
    p = pose.pose.position
    p.x, p.y, p.z = (float(v) for v in position)
    o = pose.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in quat.from_matrix(rotation))
    return pose


def main(args=None):
    """Run the controller until Ctrl-C (or SIGTERM); send zero velocity before exiting."""
    # Let the control steps preempt a path check (worker thread) within 1 ms instead of 5 ms.
    sys.setswitchinterval(0.001)

    def make_nodes(nodes):
        nodes.append(ControllerNode())
        nodes[-1].use_thread_priority()

    return run(make_nodes, NODE_NAME, args)


if __name__ == '__main__':
    raise SystemExit(main())

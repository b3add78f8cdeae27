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
(zero command at once), false resumes the path where it was paused. What it did, as data:
``/controller/events`` (:mod:`etdmp_ros.ros.events`: ``path_accepted``, ``path_ignored``,
``path_tracked`` with its tracking figures, ``halted``).

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

from dataclasses import fields
import math
import sys
import threading
import time

from etdmp_ros import limits
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.robot import (CheckError, CheckProcess, ControllerConfig, InputWatch,
                             TrackingSummary, trajectory_from_path, TrajectoryController,
                             TrajectoryError, UR10Model)
from etdmp_ros.ros import qos, system, topics
from etdmp_ros.ros.batches import TopicBatches
from etdmp_ros.ros.conversions import (joint_state_from_cdr, ns_to_stamp, path_from_cdr,
                                       velocity_command_msg)
from etdmp_ros.ros.events import ERROR, EventPublisher
from etdmp_ros.ros.node_parameters import ControllerParameters
from etdmp_ros.ros.parameters import declare, values as parameter_values
from etdmp_ros.ros.spin import normal_scheduling, rate_qos, run, set_realtime_priority
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
import numpy as np
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import SetBool


NODE_NAME = 'controller'
JOINT_STATES_TOPIC = topics.JOINT_STATES
PATH_TOPIC = topics.PATH
FRAMES = ('', 'base_link')
#: Zero commands sent on exit, a few ms apart (a lost one would leave the arm moving).
EXIT_ZEROS = 3
#: s a path received before the first joint state waits for one (e.g. a latched path).
WAIT_FOR_JOINT_STATES = 5.0
#: s between two warnings about ignored joint states (each says how many were ignored).
IGNORED_LOG_PERIOD = 2.0

DESCRIPTION = system.node(NODE_NAME)


class ControllerNode(Node):
    """The controller node: joint states and paths in, joint velocity commands out."""

    def __init__(self, **kwargs):
        """Declare parameters, build the controller, create the topics and the service."""
        super().__init__(NODE_NAME, **kwargs)
        p, self.config = self._settings(declare(self, DESCRIPTION))
        self.watch = InputWatch(p.joint_state_timeout, p.simulation_stall_timeout)
        self.untimed_speed = (p.untimed_path_speed, p.untimed_path_angular_speed)
        self.check_paths = p.check_paths
        self.max_path_poses = p.max_path_poses
        self.model = UR10Model(tool_offset=p.tool_offset)
        self.controller = TrajectoryController(self.model, self.config)
        # Paths are checked in a process of its own: a check holds the GIL for ~50 ms, which
        # the control thread would wait for whenever the machine preempts the checking thread.
        self._checker = CheckProcess(p.tool_offset, self.controller.config)
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

        # A second of history: a slow reader must never block a control step's publish().
        rate = rate_qos(self.config.rate)
        self._command_pub = self.create_publisher(Float64MultiArray, topics.COMMANDS, rate)
        self._pose_pub = self.create_publisher(PoseStamped, topics.TOOL_POSE, rate)
        self._error_pub = self.create_publisher(Float64, topics.TRACKING_ERROR, rate)
        self._reference_pub = self.create_publisher(PoseStamped, topics.REFERENCE, rate)
        self._status_pub = self.create_publisher(String, topics.CONTROLLER_STATUS, qos.LATCHED)
        self.events = EventPublisher(self)
        # Raw bytes, read with numpy (joint_state_from_cdr): a flood of joint states for other
        # joints is refused in microseconds. Taken in batches on a thread of their own
        # (TopicBatches, started by start()), not one executor dispatch each. A deep history,
        # not depth 1: such a flood must not overwrite the robot's own before they are read.
        # Best effort: a reliable reader holds every later sample back until a lost one is
        # repaired, so one lost joint state meant none for ~0.1 s (stale input); best effort,
        # the next one comes a period later.
        self._joint_states = TopicBatches(
            self, JointState, JOINT_STATES_TOPIC,
            QoSProfile(depth=limits.JOINT_STATE_QUEUE, reliability=ReliabilityPolicy.BEST_EFFORT),
            self._on_joint_states, min_interval=self.period / 8, limit=limits.JOINT_STATE_QUEUE,
            lock=self._lock)
        self.create_subscription(Path, PATH_TOPIC, self._on_path, qos.LATCHED, raw=True)
        self.create_service(SetBool, topics.PAUSE, self._on_pause)
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

        Call from the thread that will spin the executor (the watchdog, the paths), once the
        node exists; the control steps run at the same priority in the thread of
        :meth:`start`. The program makes this change, not the node, so a test or a composed
        process keeps its scheduling. The path checks run in threads of normal priority.
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
    def _values(self, changes=()):
        return parameter_values(self, DESCRIPTION, changes)

    @staticmethod
    def _settings(values):
        """
        Return the typed parameters and the ControllerConfig of ``values`` ({name: value}).

        Each value is checked by its description (ControllerParameters: ValueError naming it);
        what a description cannot say is checked here and by ControllerConfig.validate: gains
        below the control rate, condition_halt above condition_slowdown. A negative
        actuation_delay is one control period (None).
        """
        p = ControllerParameters.from_values(values)
        config = ControllerConfig(
            rate=p.control_rate, position_gain=p.position_gain,
            orientation_gain=p.orientation_gain,
            actuation_delay=p.actuation_delay if p.actuation_delay >= 0 else None,
            velocity_scale=p.velocity_scale, acceleration_limits=p.joint_acceleration_limits,
            joint_limit_margin=p.joint_limit_margin,
            singular_value_threshold=p.singular_value_threshold, max_damping=p.max_damping,
            condition_slowdown=p.condition_slowdown, condition_halt=p.condition_halt,
            posture=p.initial_joint_positions, posture_gain=p.posture_gain,
            approach_speed=p.approach_speed, approach_angular_speed=p.approach_angular_speed,
            approach_acceleration=p.approach_acceleration,
            approach_tolerance=p.approach_tolerance,
            approach_angle_tolerance=p.approach_angle_tolerance,
            resume_ramp_time=p.resume_ramp_time, hold_time=p.hold_time,
            max_tracking_error=p.max_tracking_error, estimate_delay=p.estimate_delay)
        config.validate()
        if config.condition_halt <= config.condition_slowdown:
            raise ValueError('condition_halt must be above condition_slowdown')
        return p, config

    def _validate_parameters(self, parameters):
        try:
            self._settings(self._values(parameters))
        except (ValueError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        p, new = self._settings(self._values())
        with self._lock:
            for f in fields(ControllerConfig):      # the controller keeps its config object
                setattr(self.controller.config, f.name, getattr(new, f.name))
            self.watch.timeout = p.joint_state_timeout
            self.watch.stall_timeout = p.simulation_stall_timeout
            self.check_paths = p.check_paths
            self.max_path_poses = p.max_path_poses
            self.untimed_speed = (p.untimed_path_speed, p.untimed_path_angular_speed)

    # ------------------------------------------------------------------------------ control
    def start(self):
        """Start taking joint states (the node program; a test may call _watchdog alone)."""
        self._joint_states.start(self.get_parameter('thread_priority').value)

    def _on_joint_states(self, batch):
        self._use_joint_states(batch, time.monotonic())     # under self._lock (TopicBatches)

    def _use_joint_states(self, batch, receipt, times=None):
        """
        Step once, on the newest usable of the joint states ``batch``; whether one was used.

        ``batch``: serialized joint states, oldest first; None: those queued now.

        The clocks (``times``: read here when None) are read once, after the joint states of
        other joints are set aside: reading the ROS clock takes a lock in rclpy's C++ code,
        and it cost more than half the controller's time under a flood of them.
        """
        if batch is None:
            batch = self._joint_states.take()
        parsed = [read for read in map(self._parsed_joint_state, batch) if read is not None]
        if not parsed:
            return False
        times = times or self._input_times()
        # A gap found before the newest still counts: the joint states that queued after a link
        # came back arrive a period apart, only the first of them after the ones lost.
        newest, gap = None, ''
        for stamp, q in parsed:
            read = self._plausible_joint_state(stamp, q, times)
            if read is not None:
                newest, gap = read, gap or read[2]
        if newest is None:
            return False
        stamp, q, _ = newest
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

    def _parsed_joint_state(self, data):
        """Return (stamp ns, q) of serialized joint state bytes, None if they are not usable."""
        try:
            stamp, q, _ = joint_state_from_cdr(data)
        except ValueError as exc:
            self._ignore(str(exc))
            return None
        return stamp, q

    def _plausible_joint_state(self, stamp, q, times):
        """
        Return (stamp ns, q, gap) of a parsed joint state, None if it cannot be the robot's.

        ``gap``: why the joint states before it count as lost ('' if they do not,
        :meth:`InputWatch.gap`).
        """
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
            text = (f'path tracked: {self._tracked.summary()}; actuation delay estimate '
                    f'{self.controller.delay * 1e3:.1f} ms')
            self.get_logger().info(text)
            self.events.publish('path_tracked', text, **self._tracked.figures(),
                                delay_ms=self.controller.delay * 1e3)
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
            if lost and self._use_joint_states(None, time.monotonic(), times):
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
                self.events.publish('halted', f'{reason}: zero velocity command', ERROR,
                                    status='stale-input', reason=reason)
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
            self.events.publish('halted', f'{status}: {reason}; zero velocity command', ERROR,
                                status=status, reason=reason)
        else:
            self.get_logger().info(f'status: {text}')

    # ------------------------------------------------------------------------- path, pause
    def _on_path(self, data):
        try:
            frame, pose_frames, stamps, positions, quaternions = path_from_cdr(
                data, self.max_path_poses)
        except ValueError as exc:
            self._ignore_path(str(exc))
            return
        bad = ({frame} | pose_frames) - set(FRAMES)
        if bad:
            self._ignore_path(f'frame {sorted(bad)[0]!r} is not base_link (no TF here: send '
                              'paths in base_link)')
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
            self._ignore_path(f'it could not be checked: {type(exc).__name__}: '
                              f'{str(exc)[:limits.MAX_REASON_CHARS]}')

    def _ignore_path(self, reason):
        """Say (log line and ``path_ignored`` event) why a received path is not followed."""
        self.get_logger().error(f'path ignored: {reason}')
        self.events.publish('path_ignored', f'path ignored: {reason}', ERROR, reason=reason)

    def _accepted(self, poses, duration, continued):
        """Say (log line and ``path_accepted`` event) that a path is followed from now on."""
        text = (f'path continued: {poses} poses over {duration:.2f} s (taken over at once, '
                'checked while followed)' if continued else
                f'new path: {poses} poses over {duration:.2f} s')
        # The event first: its wall clock is when the path was accepted (a log call under load
        # takes milliseconds).
        self.events.publish('path_accepted', text, poses=poses, duration_s=duration,
                            continued=continued)
        self.get_logger().info(text)

    def _take_path(self, generation, stamps, positions, quaternions):
        q, rotation = self._wait_for_robot()
        if q is None:
            self._ignore_path(f'no joint states for {WAIT_FOR_JOINT_STATES:g} s, the robot pose '
                              f'is unknown (is {JOINT_STATES_TOPIC} published?)')
            return
        try:
            path = trajectory_from_path(stamps, positions, quaternions, rotation,
                                        *self.untimed_speed)
        except TrajectoryError as exc:
            self._ignore_path(str(exc))
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
                self._accepted(len(stamps), path.duration, continued=True)
        try:
            reason = self._checker.check(path, q) if self.check_paths else ''
        except CheckError as exc:   # refused (a spliced path stops): never followed unchecked
            reason = f'it could not be checked: {exc}'
        with self._lock:
            if generation != self._path_generation:
                return              # a newer path arrived meanwhile
            if reason:
                self.controller.reject(reason)
            elif not spliced:
                self.controller.follow(path, stamp)
                self._accepted(len(stamps), path.duration, continued=False)
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
        """
        Publish zero velocity a few times (on exit: before the context shuts down).

        The joint states are no longer taken first: a control step after these would move
        the arm again.
        """
        self._joint_states.stop()
        with self._lock:
            self.controller.shutdown()
            for _ in range(EXIT_ZEROS):
                self._publish_command(np.zeros(6))
                time.sleep(0.005)
            self._publish_status()
        self._command_pub.wait_for_all_acked(Duration(seconds=0.2))

    def destroy_node(self):
        """Stop taking joint states and checking paths, destroy the hidden node, then this one."""
        self._joint_states.stop()
        self._checker.close()
        super().destroy_node()


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
    # Let the control steps preempt the other threads (a path's conversion, the executor's
    # callbacks) within 0.2 ms instead of 5 ms: a step lets go of the GIL a few times (each
    # publish), and each time another thread may hold it up to the interval. (Chosen when the
    # path checks still ran in a thread here: at 1 ms, a flood of junk joint states beside a
    # check starved the simulation of commands for 60 ms, 1 run of 5 on an AMD EPYC; at 0.2 ms,
    # 0 of 4. The checks now run in CheckProcess.)
    sys.setswitchinterval(0.0002)

    def make_nodes(nodes):
        nodes.append(ControllerNode())
        nodes[-1].use_thread_priority()
        nodes[-1].start()

    return run(make_nodes, NODE_NAME, args)


if __name__ == '__main__':
    raise SystemExit(main())

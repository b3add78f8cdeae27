"""
ur10_sim: the MuJoCo UR10 workcell (:class:`etdmp_ros.sim.UR10Sim`) as a ROS 2 node.

Subscribes ``/forward_velocity_controller/commands`` (std_msgs/Float64MultiArray, 6 joint
velocities in rad/s, UR order). Publishes, stamped with the simulated time:

- ``/joint_states``, ``/clock`` and ``/ur10_sim/ground_truth/tool_tip`` (base_link) at
  ``control_rate``;
- ``/camera/camera/color/image_raw`` (rgb8), ``/camera/camera/aligned_depth_to_color/image_raw``
  (16UC1, mm) and their ``camera_info`` at ``camera_rate``, frame ``camera_color_optical_frame``;
- ``/ur10_sim/ground_truth/goal``, ``.../obstacles`` and ``.../bottle`` (the centre of the
  bottle's mouth; base_link) with each camera frame,
  stamped like it (what the camera saw), or at 10 Hz when the camera is off;
- ``/ur10_sim/events`` (:mod:`etdmp_ros.ros.events`): ``braked`` (the command watchdog),
  ``stalled`` (at most one a second), ``stopped`` with the loop's figures, ``failed``; its
  camera process's on ``/ur10_sim_camera/events``;
- ``/ur10_sim/ground_truth/contacts`` (visualization_msgs/MarkerArray, transient local): the
  robot's contacts (:attr:`etdmp_ros.sim.UR10Sim.contacts`; a SPHERE each, text ``<part> <item>
  <depth mm>``) at every tick while there are any, once empty when they end (and at start);
- as a UR driver, robot_state_publisher and realsense-ros would: ``/robot_description``
  (transient local: the UR10 URDF the simulation is built from, tool tip link ``tool_tip``),
  ``/tf`` (the six joint transforms at ``control_rate``) and ``/tf_static`` (the URDF's fixed
  joints; base_link -> camera_link -> ... -> camera_color_optical_frame at ``camera.pose``).
  Without tf2_msgs (it is not on PyPI) one warning, and no /tf or /tf_static.

Threads and processes. The simulation thread runs one control period per tick: apply the
latest command (and scene changes), step the physics, publish the state, then sleep to keep
``real_time_factor``. When a camera frame is due it only takes a snapshot of the scene
(microseconds) and sends it, without waiting, to the camera process
(:mod:`etdmp_ros.nodes._sim_camera`, node ``ur10_sim_camera``), which renders it (milliseconds)
and publishes the images: the physics and the joint states never wait for rendering or image
transport, nor share an interpreter lock with them. The executor thread only receives commands
and parameter changes, validates them and hands them over (at SCHED_FIFO 49 with
``thread_priority``: :meth:`UR10SimNode.use_executor_priority`). Parameters: config/scene.yaml,
config/ur10_sim.yaml (their values are also the built-in defaults: etdmp_ros.ros.system);
``goal_position``, ``obstacle_positions``, ``obstacle_radii``, ``bottle.position``,
``real_time_factor``, ``watchdog_timeout`` and ``teach_script`` can be changed at runtime.

Teaching mode (kinesthetic teaching, simulated): with ``teach_script`` set, a script leads the
tool as a hand in freedrive would (:class:`etdmp_ros.robot.GuidedMotion`), velocity commands
ignored; ``~/teaching`` (transient local) says ``playing <file>``, then ``done <file>`` (or
``idle``). Record ``/joint_states`` meanwhile and learn from it (dmp_server ``demo_files``;
``python -m etdmp_ros.demo.kinesthetic`` does both).
"""

import threading
import time

from etdmp_ros.dmp import DemonstrationError, load_demo
from etdmp_ros.nodes._sim_camera import CameraProcess, CameraPublishers
from etdmp_ros.robot import (CAMERA_OPTICAL_FRAME, camera_transforms, FrameTree, GuidedMotion,
                             GuideError, parse_bottle_position, parse_goal_position,
                             parse_obstacle_positions, parse_obstacle_radii, robot_description)
from etdmp_ros.ros import qos, system, topics
from etdmp_ros.ros.conversions import (contact_markers, joint_state_msg, MovingTransforms,
                                       ns_to_stamp, pose_array_from_numpy, tf_available,
                                       tf_message, velocity_command_array)
from etdmp_ros.ros.events import ERROR, EventPublisher, WARN
from etdmp_ros.ros.node_parameters import Ur10SimParameters
from etdmp_ros.ros.parameters import declare, values as parameter_values
from etdmp_ros.ros.spin import (normal_scheduling, rate_qos, RECEPTION_PRIORITY, run,
                                set_realtime_priority)
from etdmp_ros.sim import MAX_OBSTACLES, UR10Sim
from geometry_msgs.msg import PointStamped, PoseArray
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from visualization_msgs.msg import MarkerArray
import yaml

NODE_NAME = 'ur10_sim'
OPTICAL_FRAME = CAMERA_OPTICAL_FRAME
DESCRIPTION = system.node(NODE_NAME)
#: Fell more than this many ticks behind real time (a stall: overload, a debugger): the
#: simulation's time stops with the stall, as a physics simulator's does under load, instead of
#: bursting through the missed ticks on the command of before it. A tick or two is caught up.
MAX_LAG_TICKS = 2
#: A wall-clock gap between two ticks longer than this many periods is a stall (warned).
LATE_TICKS = 3
#: Consecutive ticks answered by a command before a tick waits for its answer (command_wait):
#: a controller that steps at a lower rate than the simulation, or none, is never waited for.
ANSWERED_TICKS = 10
#: Seconds between two reports of a stalled loop (log line and ``stalled`` event).
STALL_REPORT_PERIOD = 1.0
#: Hz of the goal and obstacle ground truth when the camera is off.
GROUND_TRUTH_RATE = 10.0


class UR10SimNode(Node):
    """The simulation node: a thin shell translating topics and parameters to :class:`UR10Sim`."""

    def __init__(self, **kwargs):
        """Declare parameters, build the simulation, create publishers and the subscription."""
        super().__init__(NODE_NAME, **kwargs)
        p = self._build(declare(self, DESCRIPTION))
        self._answered = threading.Event()   # a command arrived since the last joint states
        self._answered_ticks = self._ignored_commands = 0
        self._lock = threading.Lock()
        self._guide = None            # the teaching mode's script, while it plays
        self._guide_name = ''
        self._checked_guide = None    # (file, GuidedMotion) checked, not yet applied
        self._pending_command = self._pending_goal = self._pending_bottle = None
        self._pending_obstacles = self._pending_radii = None
        self._in_contact = None       # the contacts last published (None: nothing published)
        self._stop, self._thread = threading.Event(), None
        self.failed = self._commands_seen = False
        self._watchdog_was_active = self.sim.watchdog_active
        self._next_camera_time = self._next_truth_time = 0.0
        self._camera = None   # the camera process, once started
        # CPU seconds per part; publish_tf (the /tf messages) is a part of publish_state.
        self.stats = {'physics': 0.0, 'render': 0.0, 'publish_images': 0.0,
                      'publish_state': 0.0, 'publish_tf': 0.0, 'ticks': 0, 'frames': 0,
                      'frames_dropped': 0, 'max_tick_gap': 0.0, 'late_ticks': 0,
                      'waits': 0, 'waits_expired': 0, 'wait_time': 0.0,
                      'contact_ticks': 0, 'contact_pairs': set()}
        self._unreported_stall = (0.0, 0.0)     # (gap, simulated time) not reported yet
        self._last_stall_warning = -1.0
        self._create_topics()
        if p.teach_script:
            self._guide_name = p.teach_script
            self._guide = self._load_guide(p.teach_script)   # a bad one: startup fails
            self._publish_teaching('playing')
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        k = self.sim.intrinsics
        self.get_logger().info(
            f'UR10 workcell ready: control {1.0 / self.tick_period:g} Hz, camera '
            f'{p.camera_rate:g} Hz {k.width}x{k.height} (f = {k.fx:.1f} px), watchdog '
            f'{self.sim.watchdog_timeout:g} s, real-time factor {self.real_time_factor:g}')

    def _build(self, p):
        """Build the simulation from the parameter values ``p``; return them typed."""
        # Dynamic typing of goal_position and obstacle_positions: `ros2 param set` types
        # "[1, 0, 0]" as integer[], "[0.7, 0.2, 0]" as a string and "[]" as bool[];
        # _number_list takes them all as numbers. `obstacle_positions: []` in YAML leaves the
        # parameter unset: no obstacles.
        p.update({n: [] for n in ('obstacle_positions', 'obstacle_radii') if p[n] is None})
        typed = Ur10SimParameters.from_values(p)     # each value by its description
        self._parameter_values = p   # for the camera process (not _parameters: rclpy's name)
        self.sim = UR10Sim.from_parameters(p)   # the workcell (sim layer: from the values)
        self.steps_per_tick = max(1, round(1.0 / (typed.control_rate * self.sim.timestep)))
        self.tick_period = self.steps_per_tick * self.sim.timestep
        if abs(self.tick_period * typed.control_rate - 1.0) > 1e-6:
            self.get_logger().warning(
                f'control_rate {typed.control_rate} Hz is not a whole number of physics steps '
                f'of {self.sim.timestep} s: running at {1.0 / self.tick_period:.3f} Hz')
        self.camera_period = 1.0 / typed.camera_rate if typed.camera_rate > 0 else 0.0
        self.real_time_factor, self.command_wait = typed.real_time_factor, typed.command_wait
        self.thread_priority = typed.thread_priority     # read-only: read once
        return typed

    def _create_topics(self):
        """Create the publishers and the command subscription; publish the latched state."""
        reliable = QoSProfile(depth=10)
        # A second of history: a slow reader must never block the simulation's publish().
        state = rate_qos(1.0 / self.tick_period)
        self._joint_pub = self.create_publisher(JointState, topics.JOINT_STATES, state)
        # Absolute, unlike every other name: rclpy's sim time listens to /clock. A second
        # robot's simulation remaps it to its own (-r /clock:=clock, as the launch file does).
        self._clock_pub = self.create_publisher(Clock, topics.CLOCK, state)
        self._goal_pub = self.create_publisher(PointStamped, topics.GROUND_TRUTH_GOAL, reliable)
        pub = self.create_publisher
        self._obstacles_pub = pub(PoseArray, topics.GROUND_TRUTH_OBSTACLES, reliable)
        self._bottle_pub = pub(PointStamped, topics.GROUND_TRUTH_BOTTLE, reliable)
        self._tool_pub = pub(PointStamped, topics.GROUND_TRUTH_TOOL_TIP, state)
        # Every message matters (the metrics count them), and a late subscriber gets the latest.
        self._contacts_pub = pub(MarkerArray, topics.GROUND_TRUTH_CONTACTS,
                                 qos.latched(state.depth))
        self.events = EventPublisher(self)
        self._camera_publishers = self._tf_pub = None   # made by frame() (run_for), for /tf
        self._publish_description()
        self._teaching_pub = self.create_publisher(String, topics.TEACHING, qos.LATCHED)
        self._teaching_pub.publish(String(data='idle'))
        self.create_subscription(Float64MultiArray, topics.COMMANDS, self._on_command, reliable)

    # --------------------------------------------------------------------------- parameters
    def _validate_parameters(self, parameters):
        try:
            for parameter in parameters:
                if parameter.name in ('goal_position', 'bottle.position'):
                    self.sim.scene.placed(parameter.name, _number_list(parameter))
                elif parameter.name == 'obstacle_positions':
                    points = self.sim.scene.placed(parameter.name, _number_list(parameter))
                    if len(points) > MAX_OBSTACLES:
                        raise ValueError(f'at most {MAX_OBSTACLES} obstacles, got {len(points)}')
                elif parameter.name == 'obstacle_radii':
                    radii = parse_obstacle_radii(_number_list(parameter))
                    if len(radii) > MAX_OBSTACLES:
                        raise ValueError(f'at most {MAX_OBSTACLES} radii, got {len(radii)}')
                elif parameter.name == 'teach_script' and parameter.value:
                    self._checked_guide = (parameter.value, self._load_guide(parameter.value))
            # Every value by its description, after the checks above (their reasons say more).
            Ur10SimParameters.from_values(parameter_values(self, DESCRIPTION, parameters))
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        typed = Ur10SimParameters.from_values(parameter_values(self, DESCRIPTION))
        with self._lock:
            self.real_time_factor = typed.real_time_factor
            self.sim.watchdog_timeout = typed.watchdog_timeout
            self.command_wait = typed.command_wait
            for parameter in parameters:
                if parameter.name == 'goal_position':
                    self._pending_goal = parse_goal_position(_number_list(parameter))
                elif parameter.name == 'bottle.position':
                    self._pending_bottle = parse_bottle_position(_number_list(parameter))
                elif parameter.name == 'obstacle_positions':
                    self._pending_obstacles = parse_obstacle_positions(_number_list(parameter))
                elif parameter.name == 'obstacle_radii':
                    self._pending_radii = parse_obstacle_radii(_number_list(parameter))
                elif parameter.name == 'teach_script':
                    checked, self._checked_guide = self._checked_guide, None
                    if parameter.value and checked and checked[0] == parameter.value:
                        self._guide_name, self._guide = checked
                        self._publish_teaching('playing')
                    elif not parameter.value and self._guide is not None:
                        self._guide = None
                        self._publish_teaching('stopped')

    # ---------------------------------------------------------------------- teaching mode
    def _load_guide(self, path):
        """Return the GuidedMotion of a script file from the current joints; ValueError."""
        try:
            script = load_demo(path)
        except DemonstrationError as err:
            raise ValueError(f'teach_script: {err}') from None
        if script.dim != 3:
            raise ValueError(f'teach_script {path}: needs 3 columns (x, y, z metres), got '
                             f'{script.dim}')
        try:
            guide = GuidedMotion(self.sim.ur10, self.sim.q, script.t, script.positions,
                                 self.tick_period, self.sim.velocity_limits)
        except GuideError as err:
            raise ValueError(f'teach_script {path}: {err}') from None
        self.get_logger().info(f'teaching mode: {path} leads the tool for {guide.duration:.2f} '
                               's; velocity commands are ignored until it is done')
        return guide

    def _publish_teaching(self, state):
        """Publish the teaching mode's state on ~/teaching ('playing <file>', ...)."""
        self._teaching_pub.publish(String(data=f'{state} {self._guide_name}'))

    # ------------------------------------------------------------------------------ commands
    def _on_command(self, msg):
        try:
            velocities = velocity_command_array(msg)
        except ValueError as exc:
            self.get_logger().warning(f'velocity command rejected (not applied): {exc}',
                                      throttle_duration_sec=1.0)
            return
        clamped = self.sim.validate_velocity_command(velocities)
        if np.any(clamped != velocities):
            self.get_logger().warning('velocity command beyond the UR10 limits '
                                      f'{np.round(self.sim.velocity_limits, 3).tolist()} rad/s: '
                                      'clamped', throttle_duration_sec=1.0)
        with self._lock:
            if self._guide is not None:
                self._ignored_commands += 1
                self.get_logger().warning('teaching mode: velocity command ignored while the '
                                          'script leads the arm', throttle_duration_sec=1.0)
                return
            self._pending_command = clamped
        self._answered.set()

    # ---------------------------------------------------------------------------- simulation
    def start(self):
        """Start the simulation thread (and the camera process when the camera is on)."""
        if self.camera_period:
            self._camera = CameraProcess(self)
        self._thread = threading.Thread(target=self._run, name='ur10_sim', daemon=True)
        self._thread.start()

    def stop(self):
        """Stop the simulation thread and the camera process (waits for tick and frame)."""
        self._stop.set()
        if self._thread is None:
            self.sim.close()   # run_for() rendered in this thread
            return
        self._thread.join(timeout=5.0)
        if self._camera is not None:
            self._camera.stop()
        self.sim.close()
        stats, age = self.stats, self.sim.largest_command_age
        if stats['ticks']:
            pairs = sorted(f'{a}/{b}' for a, b in stats['contact_pairs'])
            text = (f'stopped at {self.sim.time:.2f} s simulated; {stats["ticks"]} ticks, '
                    f'{stats["late_ticks"]} more than {LATE_TICKS} periods after the previous '
                    f'one, largest wall-clock gap between two {stats["max_tick_gap"] * 1e3:.1f} '
                    f'ms; camera frames published {stats["frames"]}, dropped '
                    f'{stats["frames_dropped"]}; waited for a late command {stats["waits"]} '
                    f'times ({stats["wait_time"] * 1e3:.0f} ms), {stats["waits_expired"]} in '
                    f'vain; a moving command in force {age * 1e3:.0f} ms at most; contacts in '
                    f'{stats["contact_ticks"]} ticks' + (': ' + ', '.join(pairs) if pairs else ''))
            self.get_logger().info(text)
            self.events.publish(
                'stopped', text, t_s=self.sim.time, ticks=stats['ticks'],
                late_ticks=stats['late_ticks'], late_after_periods=LATE_TICKS,
                largest_tick_gap_ms=stats['max_tick_gap'] * 1e3, frames=stats['frames'],
                frames_dropped=stats['frames_dropped'], command_waits=stats['waits'],
                command_wait_ms=stats['wait_time'] * 1e3,
                command_waits_in_vain=stats['waits_expired'], largest_command_age_ms=age * 1e3,
                contact_ticks=stats['contact_ticks'], contact_pairs=' '.join(pairs))

    def use_executor_priority(self):
        """
        Put the calling (executor's) thread at RECEPTION_PRIORITY if thread_priority is set.

        Commands reach the simulation thread through it (at normal priority a SCHED_FIFO 20
        flood starved it; the watchdog braked). Call after :meth:`start`.
        """
        if self.thread_priority and not set_realtime_priority(RECEPTION_PRIORITY):
            self.get_logger().info(f'commands received at SCHED_FIFO {RECEPTION_PRIORITY}')

    def _scheduling(self, paced, realtime):
        """Give the thread SCHED_FIFO while ``paced`` (thread_priority), else normal; return it."""
        priority = self.thread_priority
        if paced and priority and realtime is None:
            reason = set_realtime_priority(priority)
            (self.get_logger().warning if reason else self.get_logger().info)(
                f'{reason}: the simulation ticks under normal scheduling (may be late on a busy '
                'machine)' if reason else f'simulation thread at SCHED_FIFO priority {priority}')
            return not reason
        if not paced and realtime:
            normal_scheduling()     # unpaced it never sleeps: it must not hold a core
            return None
        return realtime

    def _run(self):
        try:
            wall_start, sim_start = time.monotonic(), self.sim.time
            last_tick = realtime = None
            while not self._stop.is_set():
                self._wait_for_the_answer()
                self.tick()
                now = time.monotonic()
                if last_tick is not None:
                    self._note_gap(now - last_tick)
                last_tick = now
                rtf = self.real_time_factor
                realtime = self._scheduling(rtf > 0, realtime)
                if rtf <= 0:
                    continue
                delay = wall_start + (self.sim.time - sim_start) / rtf - now
                if delay > 0:
                    self._stop.wait(delay)
                elif delay < -MAX_LAG_TICKS * self.tick_period / rtf:
                    wall_start, sim_start = time.monotonic(), self.sim.time
        except Exception as exc:   # noqa: B902 - report why the simulation stopped, then exit
            if self._stop.is_set() or not self.context.ok():
                return   # shutting down (Ctrl-C): publishing may fail, that is expected
            self.failed = True
            self.get_logger().fatal(f'simulation stopped: {type(exc).__name__}: {exc}')
            self.events.publish('failed', f'simulation stopped: {type(exc).__name__}: {exc}',
                                ERROR, reason=f'{type(exc).__name__}: {exc}')
            self.context.try_shutdown()
        finally:
            if self._camera is None:
                self.sim.close()   # rendered in this thread (the camera process has its own)

    def _wait_for_the_answer(self):
        """
        Wait up to command_wait for the command answering the last joint states (soft lockstep).

        Only while a controller has answered the last ANSWERED_TICKS ticks: then a tick without
        its answer means the controller is late (not scheduled on a busy machine), and stepping
        on would move the arm on the old command, unanswered. Waiting slows the simulation (its
        time waits too); an answer that does not come in time is stepped without, and waiting
        stops until the controller answers every tick again.
        """
        answered = self._answered.is_set()
        if not answered and self.command_wait > 0 and self._answered_ticks >= ANSWERED_TICKS:
            start = time.monotonic()
            answered = self._answered.wait(self.command_wait)
            self.stats['waits'] += 1
            self.stats['wait_time'] += time.monotonic() - start
            if not answered:
                self.stats['waits_expired'] += 1
        self._answered_ticks = self._answered_ticks + 1 if answered else 0

    def _note_gap(self, gap):
        """
        Keep the largest wall-clock gap between ticks; warn about those over LATE_TICKS.

        At most one warning a second, naming the largest stall since the previous one (a
        throttled log would show the first and hide a longer one right after it).
        """
        stats = self.stats
        stats['max_tick_gap'] = max(stats['max_tick_gap'], gap)
        rtf = self.real_time_factor
        if rtf > 0 and gap > LATE_TICKS * self.tick_period / rtf:
            stats['late_ticks'] += 1
            if gap > self._unreported_stall[0]:
                self._unreported_stall = (gap, self.sim.time)
        # Said at most once a second, in the log and as an event: a reliable event publisher
        # whose reader is starved too would block this loop once its history is full.
        now = time.monotonic()
        if (self._unreported_stall[0] > 0.0
                and now - self._last_stall_warning >= STALL_REPORT_PERIOD):
            gap, at = self._unreported_stall
            self._unreported_stall, self._last_stall_warning = (0.0, 0.0), now
            text = (f'simulation loop stalled: {gap * 1e3:.0f} ms between two ticks at t = '
                    f'{at:.3f} s (the machine is overloaded?)')
            self.get_logger().warning(text)
            self.events.publish('stalled', text, WARN, gap_ms=gap * 1e3, t_s=at,
                                late_ticks=stats['late_ticks'])

    def run_for(self, duration):
        """Run ``duration`` s of simulated time in the calling thread, unpaced (benchmarks)."""
        end = self.sim.time + duration - 1e-9
        while self.sim.time < end:
            self.tick()

    def _take_inputs(self):
        """Apply what arrived since the last tick: the command (or the script's), scene changes."""
        sim = self.sim
        with self._lock:
            command, self._pending_command = self._pending_command, None
            goal, self._pending_goal = self._pending_goal, None
            bottle, self._pending_bottle = self._pending_bottle, None
            obstacles, self._pending_obstacles = self._pending_obstacles, None
            radii, self._pending_radii = self._pending_radii, None
            guide = self._guide
        if guide is not None:
            command = guide.command(sim.q)
            if guide.done:
                with self._lock:
                    if self._guide is guide:
                        self._guide = None
                self.get_logger().info(f'teaching mode: {self._guide_name} played '
                                       f'({guide.duration:.2f} s); velocity commands apply '
                                       f'again ({self._ignored_commands} ignored)')
                self._publish_teaching('done')
        if command is not None:
            sim.set_velocity_command(command)
            if not self._commands_seen or self._watchdog_was_active:
                if self._commands_seen:
                    self.get_logger().info('velocity commands resumed')
                self._commands_seen = True
        if goal is not None:
            sim.set_goal(goal)
        if bottle is not None:
            sim.set_bottle(bottle)
        if obstacles is not None or radii is not None:
            sim.set_obstacles(sim.obstacle_positions if obstacles is None else obstacles, radii)

    def tick(self):
        """Run one control period: take inputs, step, publish; render if a frame is due."""
        sim, stats = self.sim, self.stats
        self._take_inputs()
        c0 = time.process_time()
        sim.step(self.steps_per_tick)
        c1 = time.process_time()
        if sim.watchdog_active and not self._watchdog_was_active and self._commands_seen:
            text = (f'no velocity command for {sim.watchdog_timeout:g} s: braking to zero until '
                    f'the next one (the last at t = {sim.command_time:.3f} s, braked at t = '
                    f'{sim.braked_at:.3f} s)')
            self.get_logger().warning(text)
            self.events.publish('braked', text, WARN, timeout_s=sim.watchdog_timeout,
                                last_command_s=sim.command_time, braked_s=sim.braked_at)
        self._watchdog_was_active = sim.watchdog_active
        stamp = ns_to_stamp(round(sim.time * 1e9))
        self._answered.clear()      # the next command answers these joint states
        self._publish_state(stamp)
        self._publish_contacts(stamp)
        c2 = time.process_time()
        stats['physics'] += c1 - c0
        stats['publish_state'] += c2 - c1
        stats['ticks'] += 1
        if self.camera_period and sim.time >= self._next_camera_time - 1e-9:
            self._next_camera_time += self.camera_period
            if self._next_camera_time < sim.time:   # fell behind: skip, never burst
                self._next_camera_time = sim.time + self.camera_period
            self._publish_ground_truth(stamp)
            if self._camera is not None:
                self._camera.offer(sim.camera_state(), round(sim.time * 1e9))
            else:   # run_for(): render here
                self.frame(sim.camera_state(), stamp)
        elif not self.camera_period and sim.time >= self._next_truth_time - 1e-9:
            self._next_truth_time = sim.time + 1.0 / GROUND_TRUTH_RATE
            self._publish_ground_truth(stamp)

    def frame(self, state, stamp):
        """
        Render a camera state here and publish it (images only while someone subscribes).

        What :meth:`run_for` does (benchmarks, in-process tests); the running node renders in
        its camera process instead, which publishes the same topics the same way.
        """
        if self._camera_publishers is None:
            self._camera_publishers = CameraPublishers(self, topics.CAMERA,
                                                       self.sim.intrinsics)
        self._camera_publishers.publish(self.sim, state, stamp, self.stats)
        self.stats['frames'] += 1

    def _publish_description(self):
        """Publish /robot_description and /tf_static once (latched); set up /tf."""
        urdf = robot_description(self.sim.scene.tool_offset)
        self._description_pub = self.create_publisher(String, topics.ROBOT_DESCRIPTION,
                                                      qos.LATCHED)
        self._description_pub.publish(String(data=urdf))
        if not tf_available():
            self.get_logger().warning('tf2_msgs is not installed: no /tf or /tf_static (the '
                                      'topics and /robot_description are unchanged otherwise)')
            return
        from tf2_msgs.msg import TFMessage
        frames = FrameTree(urdf)
        static = frames.fixed + camera_transforms(self.sim.camera_pose)
        self._tf_static_pub = self.create_publisher(TFMessage, topics.TF_STATIC, qos.LATCHED)
        self._tf_static_pub.publish(tf_message(static, ns_to_stamp(round(self.sim.time * 1e9))))
        self._frames = frames
        self._moving = MovingTransforms(frames.parents, frames.children, frames.translations)
        # tf2_ros's QoS for /tf: reliable, 100 deep.
        self._tf_pub = self.create_publisher(TFMessage, topics.TF, QoSProfile(depth=100))

    def _publish_state(self, stamp):
        sim = self.sim
        self._joint_pub.publish(joint_state_msg(sim.q, sim.qd, stamp=stamp))
        self._clock_pub.publish(Clock(clock=stamp))
        self._tool_pub.publish(_point_stamped(sim.tool_tip_position, stamp))
        if self._tf_pub is not None:
            c0 = time.process_time()
            self._tf_pub.publish(self._moving.update(self._frames.moving(sim.q), stamp.sec,
                                                     stamp.nanosec))
            self.stats['publish_tf'] += time.process_time() - c0

    def _publish_contacts(self, stamp):
        """Publish the contacts while there are any, and once when they are gone (or at start)."""
        contacts = self.sim.contacts
        if contacts:
            self.stats['contact_ticks'] += 1
            pairs = {(c.part, c.item) for c in contacts}
            new = pairs - self.stats['contact_pairs']
            self.stats['contact_pairs'] |= pairs
            if new:
                self.get_logger().error(
                    'contact: ' + ', '.join(f'{c.part} touches {c.item} ({c.depth * 1e3:.1f} '
                                            f'mm deep)' for c in contacts
                                            if (c.part, c.item) in new)
                    + f' at t = {self.sim.time:.3f} s')
        elif self._in_contact == ():
            return
        self._in_contact = contacts
        self._contacts_pub.publish(contact_markers(contacts, stamp))

    def _publish_ground_truth(self, stamp):
        sim = self.sim
        self._goal_pub.publish(_point_stamped(sim.goal_position, stamp))
        self._bottle_pub.publish(_point_stamped(sim.bottle_mouth, stamp))
        obstacles = pose_array_from_numpy(sim.obstacle_positions, frame_id='base_link')
        obstacles.header.stamp = stamp
        self._obstacles_pub.publish(obstacles)


def _number_list(parameter):
    """Return a parameter's value as a list of floats; ValueError for non-numeric types."""
    if parameter.type_ in (Parameter.Type.DOUBLE_ARRAY, Parameter.Type.INTEGER_ARRAY):
        return [float(v) for v in parameter.value]
    if parameter.type_ == Parameter.Type.STRING:   # "[0.7, 0.2, 0]": ints and floats mixed
        try:
            value = yaml.safe_load(parameter.value)
        except yaml.YAMLError:
            value = None
        if isinstance(value, list) and all(isinstance(v, (int, float)) and
                                           not isinstance(v, bool) for v in value):
            return [float(v) for v in value]
    if parameter.type_ in (Parameter.Type.BOOL_ARRAY, Parameter.Type.STRING_ARRAY,
                           Parameter.Type.BYTE_ARRAY) and len(parameter.value) == 0:
        return []   # `ros2 param set ... "[]"` types an empty list as bool[]
    raise ValueError(f'{parameter.name} must be a list of numbers (e.g. [0.7, 0.2, 0.0]), got '
                     f'{parameter.type_.name.lower()} {parameter.value!r}')


def _point_stamped(position, stamp):
    msg = PointStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = 'base_link'
    msg.point.x, msg.point.y, msg.point.z = (float(v) for v in position)
    return msg


def main(args=None):
    """Run the ur10_sim node until Ctrl-C (or SIGTERM)."""
    def make(nodes):
        nodes.append(UR10SimNode())
        nodes[-1].start()
        nodes[-1].use_executor_priority()
    return run(make, NODE_NAME, args)


if __name__ == '__main__':
    raise SystemExit(main())

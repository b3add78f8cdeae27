"""
dmp_server: learn skills from recorded demonstrations and serve ``/generalize``.

Its place in the system: docs/design.md#nodes-and-interfaces; bad input:
docs/design.md#bad-input-policy. ``ros2 run etdmp_ros dmp_server --ros-args --params-file
config/scene.yaml --params-file config/dmp_server.yaml``. The logic lives in ROS-free
modules: :mod:`etdmp_ros.skills.library` (demonstrations → skills, persistence),
:mod:`etdmp_ros.geometry.task_plane` and
:mod:`etdmp_ros.skills.planning` (request → timed base_link path),
:mod:`etdmp_ros.skills.plan_checks` (goals and plans the arm cannot take),
:mod:`etdmp_ros.skills.following` (a plan in execution that follows its goal and obstacles),
:mod:`etdmp_ros.skills.inputs` (the latest inputs and their ages). This node converts messages
and parameters; its settings, teaching and markers are in the private modules beside it.

Topics: subscribes ``/joint_states`` (tool position by the UR10 model's forward kinematics) or
``/etdmp/tool_pose``, ``/etdmp/goal``, ``/etdmp/obstacles`` with ``/etdmp/obstacle_volumes``
(each obstacle's radius), ``/etdmp/demonstrations`` (teaching); serves ``/generalize``
(nav_msgs/srv/GetPlan) and, for clients that must not share parameters with others,
``~/teach`` and ``~/generalize_with`` (rcl_interfaces/srv/SetParametersAtomically: the skill's
name and settings in the request, described in etdmp_ros.ros.system); publishes
``/etdmp/path`` (transient local) and ``/etdmp/markers``, and what it did as data on
``/dmp_server/events`` (:mod:`etdmp_ros.ros.events`: a skill ``learned`` or ``refused``, a plan
refused, a path published, a moved goal or obstacle ``followed``).

Threads: the executor (``_spin.make_executor``) runs the input callbacks and parameters;
/generalize is served by a thread of its own, first come first served, one call at a time
(:mod:`etdmp_ros.ros.queued_service`: a request that waited longer than
``max_request_wait`` is refused as busy at once, so none is lost unanswered under overload; a
call takes about a millisecond of this node's own work, the round trip is dominated by rclpy's
message conversion and DDS); markers are built and published by a worker thread after the
response. The state is locked, so a multi-threaded executor (e.g. in a user's own process) is
safe too: the latest inputs (:class:`etdmp_ros.skills.inputs.LatestInputs`, with the Pinocchio
model) have their own lock, ``_state_lock`` guards the count of plans, ``_follow_lock`` the plan
in execution, ``_core_lock`` the skills' rollouts (their caches are not thread-safe; a rollout
takes well under a millisecond), and the skill library has its own lock. Settings are an
immutable snapshot, replaced whole when parameters change.
"""

import pathlib
import threading
import time

from etdmp_ros import limits
from etdmp_ros.dmp import builtin_demo
from etdmp_ros.nodes._dmp_markers import PlanMarkers
from etdmp_ros.nodes._dmp_settings import Settings
from etdmp_ros.nodes._dmp_teaching import service_values, short, Teaching
from etdmp_ros.robot import UR10Model
from etdmp_ros.ros import qos, system, topics
from etdmp_ros.ros.conversions import (cylinders_from_markers, joint_state_arrays, ns_to_stamp,
                                       path_from_numpy, point_to_numpy, pose_array_to_numpy,
                                       serialize_path)
from etdmp_ros.ros.events import ERROR, EventPublisher, WARN
from etdmp_ros.ros.parameters import (declared_settings, InvalidConfiguration,
                                      values as parameter_values)
from etdmp_ros.ros.queued_service import QueuedService
from etdmp_ros.ros.spin import run
from etdmp_ros.skills.following import FollowedPlan, Following
from etdmp_ros.skills.inputs import LatestInputs
from etdmp_ros.skills.library import BASE_FRAMES, default_skills_dir, SkillLibrary
from etdmp_ros.skills.plan_checks import ArmChecks, check_goal
from etdmp_ros.skills.planning import bounded, Plan, plan_path
from geometry_msgs.msg import PointStamped, PoseArray, PoseStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray


NODE_NAME = 'dmp_server'
DESCRIPTION = system.node(NODE_NAME)
_THROTTLE = 5.0   # s between repeated warnings about the same bad input
VOLUMES_WAIT = 1.0   # s a new plan waits for the first obstacle volumes
BUSY_LOG_PERIOD = 2.0   # s between two reports of requests refused as busy (counted)
#: /generalize keeps up to MAX_QUEUED_REQUESTS requests waiting (rclpy's default: 10).
_SERVICE_QOS = QoSProfile(depth=limits.MAX_QUEUED_REQUESTS,
                          reliability=ReliabilityPolicy.RELIABLE)


class DmpServer(Node):
    """The /generalize service node: skills, latest inputs, plans, markers."""

    def __init__(self, **kwargs):
        """Declare parameters, learn the skills, warm up, then start serving."""
        super().__init__(NODE_NAME, **kwargs)
        log = self.get_logger()
        self._settings = declared_settings(self, DESCRIPTION, Settings.from_values)
        settings = self._settings
        self._state_lock = threading.Lock()
        self._core_lock = threading.Lock()
        try:
            self._model = UR10Model(tool_offset=settings.parameters.tool_offset)
            self._inputs = LatestInputs(self._model)    # keeps the model for itself
            self._arm_checks = ArmChecks(UR10Model(tool_offset=self._model.tool_offset))  # core
        except (OSError, ValueError) as err:   # no example-robot-data, or a bad tool_offset
            log.fatal(f'cannot load the UR10 model: {err}')
            raise InvalidConfiguration(str(err)) from None
        self._skills_dir = settings.parameters.skills_dir or str(default_skills_dir())
        self._library = SkillLibrary(settings.formulation, settings.n_basis)
        self.events = EventPublisher(self)   # what it did, as data (etdmp_ros.ros.events)
        self._teaching = Teaching(self._library, self._skills_dir, log, self.get_name(),
                                  self.events)
        self._learn_skills(settings)
        self._warm_up()
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._create_interfaces(settings)
        self._refused_busy, self._busy_log_time = 0, -float('inf')
        self._planned = 0   # requests answered with a plan
        self._follow_lock = threading.Lock()
        self._followed = None   # Following: the plan in execution, while it may still move
        self._generalize = QueuedService(self, GetPlan, topics.GENERALIZE, self._on_generalize,
                                         self._refuse_busy, _SERVICE_QOS,
                                         settings.max_request_wait, limits.MAX_QUEUED_REQUESTS)
        log.info(f'serving /generalize with skill {settings.skill!r} '
                 f'({settings.plan.method}); skills: {", ".join(self._library.names())}')

    def _create_interfaces(self, settings):
        """Create the subscriptions, the teaching and ~/generalize_with services, publishers."""
        inputs = MutuallyExclusiveCallbackGroup()
        self._input_group = inputs
        self._tool_subscriptions = {}  # tool_position_source -> subscription (made on first use)
        self._subscribe_tool_source(settings.tool_position_source)
        self.create_subscription(PointStamped, topics.GOAL, self._on_goal, 10,
                                 callback_group=inputs)
        self.create_subscription(PointStamped, topics.BOTTLE, self._on_bottle, 10,
                                 callback_group=inputs)
        self.create_subscription(PoseArray, topics.OBSTACLES, self._on_obstacles, 10,
                                 callback_group=inputs)
        self.create_subscription(MarkerArray, topics.OBSTACLE_VOLUMES, self._on_volumes, 10,
                                 callback_group=inputs)
        # Raw: the size is checked before the bytes are decoded (numpy, not message objects).
        # One teaching at a time, from the topic or the service.
        teaching = MutuallyExclusiveCallbackGroup()
        self.create_subscription(
            Path, topics.DEMONSTRATIONS,
            lambda data: self._teaching.on_demonstration(data, self._settings), 10,
            callback_group=teaching, raw=True)
        # Requests that carry their skill and settings (docs/dmp_server.md): concurrent clients
        # cannot mix, and no parameter changes.
        self.create_service(SetParametersAtomically, topics.TEACH,
                            lambda request, response: self._teaching.on_teach(
                                request, response, self._settings),
                            callback_group=teaching)
        with_settings = self.create_service(SetParametersAtomically, topics.GENERALIZE_WITH,
                                            self._on_generalize_with,
                                            callback_group=MutuallyExclusiveCallbackGroup())
        self._generalize_with_name = self.resolve_service_name(with_settings.srv_name)
        self._path_pub = self.create_publisher(Path, topics.PATH, qos.LATCHED)
        self._markers = PlanMarkers(self.create_publisher(MarkerArray, topics.MARKERS,
                                                          qos.LATCHED),
                                    self._core_lock, self.get_logger())

    # -- parameters -------------------------------------------------------------------------------

    def _values(self, changes=()):
        return parameter_values(self, DESCRIPTION, changes)

    def _validate_parameters(self, params):
        try:
            settings = Settings.from_values(self._values(params))
        except ValueError as err:
            return SetParametersResult(successful=False, reason=str(err))
        if any(p.name == 'skill' for p in params) and settings.skill not in self._library:
            self.get_logger().warn(f'skill {settings.skill!r} is not known (yet): requests fail '
                                   'until it is taught; known: '
                                   f'{", ".join(self._library.names())}')
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params):
        settings = Settings.from_values(self._values())
        self._library.formulation, self._library.n_basis = settings.formulation, settings.n_basis
        self._settings = settings
        self._generalize.max_wait = settings.max_request_wait
        self._subscribe_tool_source(settings.tool_position_source)

    def _subscribe_tool_source(self, source):
        """
        Subscribe the topic of the tool position source, if not done yet.

        Only the source in use is subscribed at first: the other one would be delivered at the
        control rate for nothing. A subscription once made stays (destroying one while the
        executor runs is avoided); the callbacks keep both latest values.
        """
        if source in self._tool_subscriptions:
            return
        group = self._input_group
        if source == 'joint_states':
            sub = self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state,
                                           qos_profile_sensor_data, callback_group=group)
        else:
            sub = self.create_subscription(PoseStamped, topics.TOOL_POSE, self._on_tool_pose,
                                           qos_profile_sensor_data, callback_group=group)
        self._tool_subscriptions[source] = sub

    # -- skills -------------------------------------------------------------------------------

    def _learn_skills(self, settings):
        log = self.get_logger()
        started = time.perf_counter()
        for name in settings.parameters.builtin_skills:
            try:
                self._library.add(name, builtin_demo(name), 'built-in')
            except ValueError as err:
                log.error(f'built-in skill {name!r} not learned: {err}')
        taught = pathlib.Path(self._skills_dir).expanduser()
        sources = (('demo_files', settings.parameters.demo_files),
                   ('skills_dir', [taught] if taught.is_dir() else []))
        for what, paths in sources:
            added, errors = self._library.add_files(
                paths, settings.plane, mcap_topic=settings.parameters.mcap_topic or None,
                recorded_dim=settings.recorded_dim, plane_tolerance=settings.plane_tolerance,
                kinematics=self._model)
            for message in errors:
                log.error(f'{what}: demonstration not learned: {message}')
            for entry in added:
                log.info(f'learned skill {entry.name!r} ({entry.demo.dim}D, '
                         f'{entry.demo.n_samples} samples) from {entry.source}')
        log.info(f'learned {len(self._library)} skills in '
                 f'{(time.perf_counter() - started) * 1e3:.0f} ms')
        if settings.skill not in self._library:
            log.warn(f'the active skill {settings.skill!r} is not known: requests fail until it '
                     'is taught or the parameter skill is changed')

    def _warm_up(self):
        """Run a plan per skill so numba compiles (or loads) the rollout before the first call."""
        started = time.perf_counter()
        for name in self._library.names():
            skill = self._library.skill(name)
            middle = (skill.start + skill.goal) / 2.0 + 0.1 * skill.size
            try:
                skill.generalize(skill.start, skill.goal, obstacles=[middle])
                # And the online rollout of a followed plan (its numba loop).
                run = skill.online(skill.start, skill.goal, obstacles=[middle])
                run.step(goal=skill.goal + 0.01 * skill.size)
                run.run(run.t + 2 * run.dt)
            except ValueError:
                pass
        path_from_numpy(np.zeros((2, 3)), np.zeros(2))
        self.get_logger().info(f'warm-up took {(time.perf_counter() - started) * 1e3:.0f} ms')

    # -- inputs -------------------------------------------------------------------------------

    def _frame_ok(self, frame_id, topic):
        if frame_id in BASE_FRAMES:
            return True
        self.get_logger().warn(f'{topic}: ignoring a message in frame {frame_id!r}; only '
                               'base_link is accepted', throttle_duration_sec=_THROTTLE)
        return False

    def _on_joint_state(self, msg):
        try:
            q, _ = joint_state_arrays(msg)
        except ValueError as err:
            self.get_logger().warn(f'/joint_states: ignored: {err}',
                                   throttle_duration_sec=_THROTTLE)
            return
        self._inputs.keep('joint_states', q)

    def _on_tool_pose(self, msg):
        p = point_to_numpy(msg.pose.position)
        if self._frame_ok(msg.header.frame_id, '/etdmp/tool_pose') and \
                self._bounded_ok(p, '/etdmp/tool_pose'):
            self._inputs.keep('tool_pose', p)

    def _bounded_ok(self, points, topic):
        """Return whether a message's points are finite and bounded, else WARN (throttled)."""
        try:
            bounded(points, topic)
        except ValueError as err:
            self.get_logger().warn(f'{err}: ignored', throttle_duration_sec=_THROTTLE)
            return False
        return True

    def _on_goal(self, msg):
        self._on_goal_object(msg, 'marker', '/etdmp/goal')

    def _on_bottle(self, msg):
        self._on_goal_object(msg, 'bottle', '/etdmp/bottle')

    def _on_goal_object(self, msg, kind, topic):
        """Keep a perceived goal object; follow it if it is the goal_object of the plan."""
        p = point_to_numpy(msg.point)
        if not self._frame_ok(msg.header.frame_id, topic) or not self._bounded_ok(p, topic):
            return
        settings = self._settings
        self._inputs.keep(kind, p)
        if settings.goal_object != kind:
            return
        goal = p + settings.goal_offset
        outside = settings.plan.workspace.violation(goal)
        if outside is not None:   # kept: a request using it fails with the reason
            self.get_logger().warn(f'{topic} ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) + goal_offset '
                                   f"is out of the UR10's reach: {outside[1]}; requests using "
                                   'it fail', throttle_duration_sec=_THROTTLE)
        self._follow(goal=goal)

    def _on_obstacles(self, msg):
        points = pose_array_to_numpy(msg)
        if not self._frame_ok(msg.header.frame_id, '/etdmp/obstacles') or \
                not self._bounded_ok(points, '/etdmp/obstacles'):
            return
        self._inputs.keep('obstacles', points)
        self._follow(obstacles=True)

    def _on_volumes(self, msg):
        """Keep the latest obstacle volumes: each obstacle's top-face centre and radius."""
        try:
            tops, radii = cylinders_from_markers(msg)
        except ValueError as err:
            self.get_logger().warn(f'/etdmp/obstacle_volumes: ignored: {err}',
                                   throttle_duration_sec=_THROTTLE)
            return
        self._inputs.keep('volumes', (tops, radii))

    def _tool_position(self, settings):
        return self._inputs.tool_position(settings.tool_position_source,
                                          settings.tool_state_max_age)

    def _perceived_goal(self, settings):
        """Return the perceived goal object (goal_object) plus goal_offset."""
        return self._inputs.perceived_goal(settings.goal_object, settings.goal_max_age,
                                           settings.goal_offset)

    def _current_volumes(self, settings, new_plan=False):
        """
        Return the obstacles to plan around: (points (m, 3), radii (m,) in metres).

        The perceived ones (/etdmp/obstacles), each with the radius of the nearest volume
        (/etdmp/obstacle_volumes), then ``static_obstacles`` (points: radius 0). Stale ones and
        ones without a volume are warned about. For a ``new_plan`` (in /generalize's thread),
        perceived obstacles while /etdmp/obstacle_volumes has a publisher but no volume has
        come yet (its subscription matched after the points') wait up to VOLUMES_WAIT for one,
        then raise ValueError: planned as points they would be hit.
        """
        expected = new_plan and self.count_publishers(topics.OBSTACLE_VOLUMES) > 0
        points, radii, stale, unsized = self._inputs.obstacles_with_radii(
            settings.obstacle_max_age, settings.static_obstacles, VOLUMES_WAIT * expected)
        if unsized and expected and self._inputs.volumes.value is None:
            raise ValueError(f'{unsized} perceived obstacle(s) but no volume received yet on '
                             '/etdmp/obstacle_volumes (it has a publisher)')
        if stale:
            self.get_logger().warn('/etdmp/obstacles is older than obstacle_max_age '
                                   f'{settings.obstacle_max_age:g} s: ignored',
                                   throttle_duration_sec=_THROTTLE)
        if unsized:
            self.get_logger().warn(
                f'{unsized} perceived obstacle(s) without a volume on '
                '/etdmp/obstacle_volumes: planned as points (radius 0)',
                throttle_duration_sec=_THROTTLE)
        return points, radii

    def _request_point(self, pose_stamped, what, settings):
        frame = pose_stamped.header.frame_id
        if frame == '':
            if what == 'start':
                return self._tool_position(settings)
            return self._perceived_goal(settings)
        if frame != 'base_link':
            meaning = 'the tool position' if what == 'start' else 'the perceived goal'
            raise ValueError(f'{what}.header.frame_id {frame!r} is not base_link; only base_link '
                             f'is accepted (or an empty frame id for {meaning})')
        return bounded(point_to_numpy(pose_stamped.pose.position), what)

    # -- /generalize ----------------------------------------------------------------------------

    def _on_generalize(self, request, response):
        settings = self._settings
        stamp = self.get_clock().now().nanoseconds
        try:
            start = self._request_point(request.start, 'start', settings)
            goal = self._request_point(request.goal, 'goal', settings)
            q = request.goal.pose.orientation
            skill, plan = self._plan(settings, start, goal, (q.x, q.y, q.z, q.w))
        except (ValueError, ArithmeticError) as err:   # PlanningError, UnknownSkillError, ...
            self.get_logger().error(f'/generalize with skill {settings.skill!r}: {short(err)}')
            self.events.publish('plan_refused', f'/generalize with skill {settings.skill!r}: '
                                f'{short(err)}', ERROR, service='/generalize',
                                skill=settings.skill, reason=short(err))
            response.plan = path_from_numpy(np.zeros((0, 3)), stamp=stamp)
            return response
        response.plan = path_from_numpy(plan.positions, plan.t, stamp, 'base_link',
                                        plan.orientation)
        self._execute(settings, skill, plan, stamp, request.goal.header.frame_id == '',
                      response.plan.header)
        return response

    def _on_generalize_with(self, request, response):
        """Serve ~/generalize_with: /generalize with the skill and settings in the request."""
        settings = self._settings
        stamp = self.get_clock().now().nanoseconds
        try:
            given = service_values('generalize_with', request)
            changes = [Parameter(name, value=given[name]) for name in
                       ('skill', 'method', 'duration', 'execute') if name in given]
            if changes:   # this request's settings, checked as ros2 param set checks them
                settings = Settings.from_values(self._values(changes))
            start = given.get('start')
            start = self._tool_position(settings) if start is None else bounded(start, 'start')
            goal = given.get('goal')
            goal = self._perceived_goal(settings) if goal is None else bounded(goal, 'goal')
            if start.shape != (3,) or goal.shape != (3,):
                raise ValueError(f'start and goal must be 3 numbers [x, y, z], got '
                                 f'{start.size} and {goal.size}')
            skill, plan = self._plan(settings, start, goal, given.get('goal_orientation'))
        except (ValueError, ArithmeticError) as err:
            reason = f'with skill {settings.skill!r}: {short(err)}'
            self.get_logger().error(f'{self._generalize_with_name}: {reason}')
            self.events.publish('plan_refused', f'{self._generalize_with_name}: {reason}', ERROR,
                                service=self._generalize_with_name, skill=settings.skill,
                                reason=short(err))
            response.result.reason = reason
            return response
        self._execute(settings, skill, plan, stamp, 'goal' not in given,
                      Header(stamp=ns_to_stamp(stamp), frame_id='base_link'))
        response.result.successful = True
        response.result.reason = (
            f'planned skill {settings.skill!r} ({plan.method}): {len(plan.t)} poses over '
            f'{plan.t[-1]:.2f} s' + (', published on /etdmp/path' if settings.execute else
                                     ' (execute false: not published)'))
        return response

    def _plan(self, settings, start, goal, goal_orientation):
        """
        Return (skill, Plan) of ``settings.skill`` from ``start`` to ``goal`` (base_link).

        Raises ValueError or ArithmeticError with the reason: the goal's checks, the planning's
        and the timing check's.
        """
        obstacles, radii = self._current_volumes(settings, new_plan=True)
        skill = self._library.skill(settings.skill, settings.formulation, settings.n_basis)
        check_goal(goal, skill, settings.plan.workspace, settings.plane, settings.skill)
        with self._core_lock, np.errstate(over='raise', invalid='raise', divide='raise'):
            plan = plan_path(skill, start, goal, obstacles, settings.plan, settings.plane,
                             goal_orientation=goal_orientation, obstacle_radii=radii)
            if settings.check_timing or settings.check_arm:
                q = self._inputs.joints(settings.tool_state_max_age)
                self._arm_checks.check(
                    plan, skill, settings.initial_joints if q is None else q, obstacles, radii,
                    settings.plan, settings.check_timing,
                    settings.arm_clearance if settings.check_arm else None)
        return skill, plan

    def _execute(self, settings, skill, plan, stamp, perceived_goal, header):
        """Count a plan made, and publish it for the controller unless ``execute`` is false."""
        with self._state_lock:
            self._planned += 1
        if settings.execute:
            self._start_following(skill, plan, settings, stamp, perceived_goal=perceived_goal)
            # The same Path as the response, its bytes written with numpy (0.1 ms, where rclpy
            # serializes the message in ~2).
            self._path_pub.publish(serialize_path(plan.positions, plan.t, stamp, 'base_link',
                                                  plan.orientation))
            self.events.publish('path_published', f'{settings.skill} ({plan.method}): '
                                f'{len(plan.t)} poses over {plan.t[-1]:.2f} s published',
                                skill=settings.skill, method=plan.method, poses=len(plan.t),
                                duration_s=plan.t[-1], stamp_ns=stamp)
            if settings.publish_markers and self._markers.wanted():
                self._markers.request(settings, skill, plan, header)
        self.get_logger().debug(f'planned {settings.skill} ({plan.method}), '
                                f'{len(plan.t)} poses over {plan.t[-1]:.2f} s')

    def _refuse_busy(self, request, response, waited):
        """Answer a request that waited too long with an empty plan; say so every few seconds."""
        response.plan = path_from_numpy(np.zeros((0, 3)), stamp=self.get_clock().now().nanoseconds)
        self._refused_busy += 1
        now = time.monotonic()
        if now >= self._busy_log_time + BUSY_LOG_PERIOD:
            more = (f' ({self._refused_busy} refused so since the last report)'
                    if self._refused_busy > 1 else '')
            self.get_logger().error(
                f'/generalize refused as busy: the request waited {waited:.2f} s for its turn, '
                f'more than max_request_wait {self._settings.max_request_wait:g} s; requests '
                f'come faster than they are planned{more}')
            self._refused_busy, self._busy_log_time = 0, now
        return response

    def stop(self):
        """Stop serving /generalize (called before the node is destroyed)."""
        service = getattr(self, '_generalize', None)
        if service is not None and service.running:
            service.stop()
            answered = service.answered
            self.get_logger().info(
                f'/generalize answered {sum(answered.values())} requests: {self._planned} with '
                f'a plan, {answered["handled"] - self._planned} refused with a reason, '
                f'{answered["refused"]} refused as busy, {answered["failed"]} failed')

    def destroy_node(self):
        """Stop the /generalize thread, then destroy the node."""
        self.stop()
        super().destroy_node()

    # -- following a plan in execution (online ET-DMP) ------------------------------------------

    def _start_following(self, skill, plan, settings, stamp, perceived_goal):
        """Keep the plan just published, to re-plan its remainder when its inputs move."""
        followed = None
        if settings.follow_goal:
            try:
                with self._core_lock:
                    followed = Following(FollowedPlan(skill, plan, settings.plan,
                                                      settings.plane),
                                         skill, stamp, perceived_goal)
            except ValueError as err:   # e.g. a skill the online rollout cannot take
                self.get_logger().warn(f'the plan will not follow its goal: {short(err)}')
        with self._follow_lock:
            self._followed = followed

    def _follow(self, goal=None, obstacles=False):
        """Re-plan the remainder of the plan in execution if its goal or obstacles moved."""
        settings = self._settings
        with self._follow_lock:
            f = self._followed
            if f is None or not settings.follow_goal:
                return
            tau_now = (self.get_clock().now().nanoseconds - f.stamp) * 1e-9
            if f.ended(tau_now):
                self._followed = None           # done: nothing left to follow
                return
            threshold = settings.follow_threshold
            new_goal = None if goal is None else f.goal_to_follow(goal, threshold)
            new_obstacles = None if not obstacles else f.obstacles_to_follow(
                *self._current_volumes(settings), threshold)
            if new_goal is None and new_obstacles is None:
                return
            received = time.perf_counter()
            try:
                tool = self._tool_position(settings)
            except ValueError:
                tool = None
            tau_c = f.controller_path_time(tool, tau_now)
            try:
                with self._core_lock, np.errstate(over='raise', invalid='raise',
                                                  divide='raise'):
                    if new_goal is not None:
                        check_goal(new_goal, f.skill, settings.plan.workspace,
                                   settings.plane, settings.skill)
                    first = f.plan.update(
                        tau_c + settings.follow_lead, goal=new_goal,
                        obstacles=None if new_obstacles is None else new_obstacles[0],
                        obstacle_radii=None if new_obstacles is None else new_obstacles[1])
            except (ValueError, ArithmeticError) as err:
                # Said once for this goal or obstacle set, not at every message that shows it.
                f.refused(goal=new_goal is not None, obstacles=new_obstacles is not None)
                self.get_logger().error(f'the plan in execution does not follow: '
                                        f'{short(err)}; it goes on as it was')
                self.events.publish('follow_refused', f'the plan in execution does not follow: '
                                    f'{short(err)}', WARN, reason=short(err), stamp_ns=f.stamp)
                return
            self._publish_remainder(f, first, tau_c, new_goal, new_obstacles, received, settings)

    def _publish_remainder(self, f, first, tau_c, new_goal, new_obstacles, received, settings):
        """Publish a followed plan's new remainder (and its markers); say what was followed."""
        p = f.plan
        keep = f.remainder_start(tau_c)
        # Its bytes written with numpy: 0.2 ms where building the message takes ~8.
        orientation = p.orientation if isinstance(p.orientation, tuple) else p.orientation[keep:]
        message = serialize_path(p.positions[keep:], p.t[keep:], f.stamp, 'base_link', orientation)
        published_ns = time.time_ns()
        self._path_pub.publish(message)
        took = (time.perf_counter() - received) * 1e3
        what = ' and '.join(
            ([f'goal moved to ({new_goal[0]:.3f}, {new_goal[1]:.3f}, {new_goal[2]:.3f})']
             if new_goal is not None else []) +
            ([f'obstacles moved to {np.round(new_obstacles[0], 3).tolist()}']
             if new_obstacles is not None else []))
        text = (f'following: {what}: re-planned from path time {p.t[first]:.2f} s (the '
                f'controller at about {tau_c:.2f} s), {len(p.t) - keep} poses to '
                f'{p.duration:.2f} s published in {took:.1f} ms (update {p.updates})')
        self.events.publish(
            'followed', text, goal=[] if new_goal is None else new_goal,
            obstacles=[] if new_obstacles is None else new_obstacles[0],
            from_path_time_s=p.t[first], controller_path_time_s=tau_c, poses=len(p.t) - keep,
            end_s=p.duration, took_ms=took, update=p.updates, stamp_ns=f.stamp,
            published_wall_ns=published_ns)
        self.get_logger().info(text)
        if settings.publish_markers and self._markers.wanted():
            shown = Plan(p.t, p.positions, p.velocities, p.orientation, f.start, p.goal,
                         p.obstacles, settings.plan.method, None)
            header = Header(stamp=ns_to_stamp(f.stamp), frame_id='base_link')
            self._markers.request(settings, f.skill, shown, header)


def main(args=None):
    """Run the dmp_server node until Ctrl-C (or SIGTERM)."""
    return run(lambda nodes: nodes.append(DmpServer()), NODE_NAME, args,
               startup_errors=(InvalidConfiguration,))


if __name__ == '__main__':
    main()

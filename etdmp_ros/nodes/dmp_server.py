"""
dmp_server: learn skills from recorded demonstrations and serve ``/generalize``.

Its place in the system: docs/design.md#nodes-and-interfaces; what it does with bad input:
docs/design.md#bad-input-policy.

``ros2 run etdmp_ros dmp_server --ros-args --params-file config/scene.yaml --params-file
config/dmp_server.yaml``. The logic lives in ROS-free modules: :mod:`etdmp_ros.skills.library`
(demonstrations → skills, persistence), :mod:`etdmp_ros.geometry.task_plane` and
:mod:`etdmp_ros.skills.planning` (request → timed base_link path). This node converts messages and
parameters and keeps the latest inputs.

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
safe too: ``_state_lock`` guards the latest inputs and the Pinocchio model,
``_core_lock`` the skills' rollouts (their caches are not thread-safe; a rollout takes well under
a millisecond), and the skill library has its own lock. Settings are an immutable snapshot,
replaced whole when parameters change.
"""

from dataclasses import dataclass, field, replace
import pathlib
import threading
import time

from etdmp_ros import limits
from etdmp_ros.dmp import AVOIDANCES, builtin_demo, FORMULATIONS, METHODS, ObstacleGains
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.robot import DEFAULT_ACCELERATION_LIMITS, UR10Model
from etdmp_ros.robot._arm_check import arm_obstacle_violation, ArmGeometry
from etdmp_ros.robot._timing import joint_timing_violation, plan_joints
from etdmp_ros.ros import qos, system, topics
from etdmp_ros.ros.conversions import (cylinders_from_markers, joint_state_arrays, ns_to_stamp,
                                       path_from_cdr, path_from_numpy, point_to_numpy,
                                       points_from_numpy, pose_array_to_numpy, serialize_path)
from etdmp_ros.ros.events import ERROR, EventPublisher, WARN
from etdmp_ros.ros.parameters import (declared_settings, InvalidConfiguration, plain,
                                      values as parameter_values)
from etdmp_ros.ros.queued_service import QueuedService
from etdmp_ros.ros.spin import run
from etdmp_ros.skills.library import (BASE_FRAMES, check_skill_name, default_skills_dir,
                                      RECORDED_DIMS, recorded_orientations, recorded_path_demo,
                                      save_skill_demo, SkillLibrary)
from etdmp_ros.skills.planning import (bounded, FOLLOW_CONFIRMATIONS, FollowedPlan, place_demo,
                                       Plan, PLAN_ORIENTATION_MODES, plan_path, PlanSettings,
                                       Workspace)
from geometry_msgs.msg import PointStamped, PoseArray, PoseStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray


NODE_NAME = 'dmp_server'
DESCRIPTION = system.node(NODE_NAME)
TOOL_SOURCES = DESCRIPTION.parameter('tool_position_source').choices
_THROTTLE = 5.0   # s between repeated warnings about the same bad input
#: Where a skill taught at runtime came from (its source in the library): it may be re-taught.
_TAUGHT = 'taught on '
#: Seconds between two reports of requests refused as busy (each report counts them).
BUSY_LOG_PERIOD = 2.0
#: /generalize keeps up to MAX_QUEUED_REQUESTS requests waiting (rclpy's default: 10).
_SERVICE_QOS = QoSProfile(depth=limits.MAX_QUEUED_REQUESTS,
                          reliability=ReliabilityPolicy.RELIABLE)


def _short(text):
    """Return ``text`` cut to MAX_REASON_CHARS characters (a log line stays readable)."""
    text = str(text)
    if len(text) <= limits.MAX_REASON_CHARS:
        return text
    return text[:limits.MAX_REASON_CHARS - 3] + '...'


def _choice(values, name, choices):
    if values[name] not in choices:
        raise ValueError(f'{name} must be one of {", ".join(choices)}, got {values[name]!r}')
    return values[name]


@dataclass(frozen=True, eq=False)
class Settings:
    """Everything a request or an input callback needs, validated; replaced whole on change."""

    skill: str
    formulation: str
    n_basis: int
    plan: PlanSettings
    plane: TaskPlane
    static_obstacles: np.ndarray
    obstacle_max_age: float
    goal_max_age: float
    tool_position_source: str
    tool_state_max_age: float
    teach_skill_name: str
    recorded_dim: str
    plane_tolerance: float
    execute: bool
    publish_markers: bool
    teach_overwrite: bool
    check_timing: bool
    check_arm: bool
    arm_clearance: float
    max_request_wait: float
    follow_goal: bool
    follow_threshold: float
    follow_lead: float
    initial_joints: np.ndarray
    goal_object: str = 'marker'
    goal_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_values(cls, values):
        """Build from {parameter name: value}; raise ValueError saying what is wrong."""
        check_skill_name(values['skill'])
        check_skill_name(values['teach_skill_name'])
        static = np.asarray(values['static_obstacles'], dtype=float)
        if static.size % 3:
            raise ValueError('static_obstacles must be numbers x1, y1, z1, x2, ... (a multiple '
                             f'of 3), got {len(static)} values')
        bounded(static, 'static_obstacles')
        gains = ObstacleGains(gamma=values['obstacle_gamma'], beta=values['obstacle_beta'],
                              gamma2=values['obstacle_gamma2'],
                              k_relative=values['obstacle_k_relative'])
        workspace = Workspace(reach=values['reach_radius'], margin=values['reach_margin'],
                              min_radius=values['min_reach_radius'],
                              min_height=values['min_height'])
        plan = PlanSettings(
            method=_choice(values, 'method', METHODS), mode=values['mode'],
            independent_axis=values['independent_axis'], duration=values['duration'],
            output_period=values['output_period'], gains=gains, obstacle_k=values['obstacle_k'],
            obstacle_margin=values['obstacle_margin'], goal_clearance=values['goal_clearance'],
            min_distance=values['min_distance'], orientation=values['tool_orientation'],
            orientation_mode=_choice(values, 'orientation_mode', PLAN_ORIENTATION_MODES),
            workspace=workspace, tool_radius=values['tool_radius'],
            obstacle_clearance=values['obstacle_clearance'],
            avoidance=_choice(values, 'avoidance', AVOIDANCES))
        plane = TaskPlane.create(values['task_plane.origin'], values['task_plane.x_axis'],
                                 values['task_plane.y_axis'], values['task_plane.scale'])
        return cls(
            skill=values['skill'], formulation=_choice(values, 'formulation', FORMULATIONS),
            n_basis=values['n_basis'], plan=plan, plane=plane,
            static_obstacles=static.reshape(-1, 3), obstacle_max_age=values['obstacle_max_age'],
            goal_max_age=values['goal_max_age'],
            tool_position_source=_choice(values, 'tool_position_source', TOOL_SOURCES),
            tool_state_max_age=values['tool_state_max_age'],
            teach_skill_name=values['teach_skill_name'],
            recorded_dim=_choice(values, 'recorded_dim', RECORDED_DIMS),
            plane_tolerance=values['plane_tolerance'], execute=values['execute'],
            publish_markers=values['publish_markers'], teach_overwrite=values['teach_overwrite'],
            check_timing=values['check_timing'], check_arm=values['check_arm'],
            arm_clearance=values['arm_clearance'], max_request_wait=values['max_request_wait'],
            follow_goal=values['follow_goal'], follow_threshold=values['follow_threshold'],
            follow_lead=values['follow_lead'],
            initial_joints=_joints(values['initial_joint_positions']),
            goal_object=_choice(values, 'goal_object', system.GOAL_OBJECTS),
            goal_offset=_offset(values['goal_offset']))


def _offset(values):
    offset = np.asarray(values, dtype=float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)) or np.any(np.abs(offset) > 2.0):
        raise ValueError(f'goal_offset must be 3 finite numbers [x, y, z] within 2 m, got '
                         f'{values!r}')
    return offset


def _joints(values):
    q = np.asarray(values, dtype=float)
    if q.shape != (6,) or not np.all(np.isfinite(q)):
        raise ValueError(f'initial_joint_positions must be 6 finite numbers, got {values!r}')
    return q


class _Latest:
    """A value received on a topic and when (time.monotonic), or nothing yet."""

    __slots__ = ('value', 'received')

    def __init__(self):
        self.value, self.received = None, None

    def update(self, value):
        self.value, self.received = value, time.monotonic()

    def fresh(self, max_age):
        """Return the value if it is not older than max_age seconds (0: any age), else None."""
        if self.value is None or (max_age > 0.0 and time.monotonic() - self.received > max_age):
            return None
        return self.value

    def age(self):
        return time.monotonic() - self.received


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
        self._joint_state = _Latest()
        self._tool_pose = _Latest()
        self._goal = _Latest()
        self._bottle = _Latest()
        self._obstacles = _Latest()
        self._volumes = _Latest()
        try:
            self._model = UR10Model(tool_offset=self.get_parameter('tool_offset').value)
            self._timing_model = UR10Model(tool_offset=self._model.tool_offset)  # _core_lock
            self._arm = ArmGeometry(self._timing_model)                      # _core_lock
        except (OSError, ValueError) as err:   # no example-robot-data, or a bad tool_offset
            log.fatal(f'cannot load the UR10 model: {err}')
            raise InvalidConfiguration(str(err)) from None
        skills_dir = self.get_parameter('skills_dir').value
        self._skills_dir = skills_dir or str(default_skills_dir())
        self._library = SkillLibrary(settings.formulation, settings.n_basis)
        self._learn_skills(settings)
        self._warm_up()
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        inputs = MutuallyExclusiveCallbackGroup()
        self._inputs = inputs
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
        self.create_subscription(Path, topics.DEMONSTRATIONS, self._on_demonstration, 10,
                                 callback_group=teaching, raw=True)
        # Requests that carry their skill and settings (docs/dmp_server.md): concurrent clients
        # cannot mix, and no parameter changes.
        self.create_service(SetParametersAtomically, topics.TEACH, self._on_teach,
                            callback_group=teaching)
        with_settings = self.create_service(SetParametersAtomically, topics.GENERALIZE_WITH,
                                            self._on_generalize_with,
                                            callback_group=MutuallyExclusiveCallbackGroup())
        self._generalize_with_name = self.resolve_service_name(with_settings.srv_name)
        self._path_pub = self.create_publisher(Path, topics.PATH, qos.LATCHED)
        self._marker_pub = self.create_publisher(MarkerArray, topics.MARKERS, qos.LATCHED)
        self.events = EventPublisher(self)
        self._pending_markers = None
        self._marker_thread = None   # builds markers after a call, off the service's path
        self._refused_busy, self._busy_log_time = 0, -float('inf')
        self._planned = 0   # requests answered with a plan
        self._follow_lock = threading.Lock()
        self._followed = None   # _Followed: the plan in execution, while it may still move
        self._generalize = QueuedService(self, GetPlan, topics.GENERALIZE, self._on_generalize,
                                         self._refuse_busy, _SERVICE_QOS,
                                         settings.max_request_wait, limits.MAX_QUEUED_REQUESTS)
        log.info(f'serving /generalize with skill {settings.skill!r} '
                 f'({settings.plan.method}); skills: {", ".join(self._library.names())}')

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
        if source == 'joint_states':
            sub = self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state,
                                           qos_profile_sensor_data, callback_group=self._inputs)
        else:
            sub = self.create_subscription(PoseStamped, topics.TOOL_POSE, self._on_tool_pose,
                                           qos_profile_sensor_data, callback_group=self._inputs)
        self._tool_subscriptions[source] = sub

    # -- skills -------------------------------------------------------------------------------

    def _learn_skills(self, settings):
        log = self.get_logger()
        started = time.perf_counter()
        for name in self.get_parameter('builtin_skills').value:
            try:
                self._library.add(name, builtin_demo(name), 'built-in')
            except ValueError as err:
                log.error(f'built-in skill {name!r} not learned: {err}')
        taught = pathlib.Path(self._skills_dir).expanduser()
        sources = (('demo_files', self._values()['demo_files']),
                   ('skills_dir', [taught] if taught.is_dir() else []))
        for what, paths in sources:
            added, errors = self._library.add_files(
                paths, settings.plane, mcap_topic=self.get_parameter('mcap_topic').value or None,
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

    def _protected_sources(self, name, settings):
        """Return the sources a taught skill ``name`` must not replace (teach_overwrite)."""
        source = self._library.source(name)
        if source is None or settings.teach_overwrite or source.startswith(_TAUGHT):
            return ()
        skills_dir = pathlib.Path(self._skills_dir).expanduser()
        if source != 'built-in' and pathlib.Path(source).parent == skills_dir:
            return ()   # taught before and saved: re-teaching replaces it
        return (source,)

    def _on_demonstration(self, data):
        """Learn a Path on /etdmp/demonstrations as teach_skill_name (ros2 topic pub)."""
        settings = self._settings
        try:
            if len(data) > limits.MAX_TAUGHT_PATH_BYTES:
                raise ValueError(f'the Path is {len(data)} bytes, more than '
                                 f'MAX_TAUGHT_PATH_BYTES = {limits.MAX_TAUGHT_PATH_BYTES} (about '
                                 f'{limits.MAX_DEMO_SAMPLES} poses, MAX_DEMO_SAMPLES); not '
                                 'decoded')
            frame, pose_frames, stamps, positions, quaternions = path_from_cdr(data)
            wrong = sorted(({frame} | pose_frames) - set(BASE_FRAMES))
            if wrong:
                raise ValueError(f'frame {_short(repr(wrong[0]))} is not base_link (no TF here)')
            t = (stamps - stamps[0]) * 1e-9 if len(stamps) else None
            quaternions = recorded_orientations(quaternions)
        except ValueError as err:
            self._taught(settings.teach_skill_name, err)
            return
        self._teach(settings.teach_skill_name, t, positions, quaternions, settings,
                    '/etdmp/demonstrations')

    def _on_teach(self, request, response):
        """Serve ~/teach: the skill's name and its demonstration are in the request."""
        settings = self._settings
        name = next((a.value.string_value for a in request.parameters if a.name == 'name'), '')
        try:
            given = self._service_values('teach', request)
            name = check_skill_name(given['name'])
            if len(given['t']) > limits.MAX_DEMO_SAMPLES:
                raise ValueError(f'{len(given["t"])} samples, more than MAX_DEMO_SAMPLES = '
                                 f'{limits.MAX_DEMO_SAMPLES}')
            t = np.asarray(given['t'], dtype=float)
            positions = np.asarray(given['positions'], dtype=float)
            quaternions = np.asarray(given.get('orientations', []), dtype=float)
            if positions.size != 3 * t.size or quaternions.size not in (0, 4 * t.size):
                raise ValueError(f'{t.size} times need {3 * t.size} position values (x, y, z '
                                 f'each) and none or {4 * t.size} orientation values, got '
                                 f'{positions.size} and {quaternions.size}')
            positions = positions.reshape(-1, 3)
            quaternions = recorded_orientations(quaternions.reshape(-1, 4)) \
                if quaternions.size else None
            if 'recorded_dim' in given:
                settings = replace(settings, recorded_dim=given['recorded_dim'])
        except ValueError as err:
            response.result.reason = self._taught(name, err)
            return response
        response.result.successful, response.result.reason = self._teach(
            name, t - t[0] if t.size else t, positions, quaternions, settings,
            f'/{self.get_name()}/teach')
        return response

    def _teach(self, name, t, positions, quaternions, settings, where):
        """
        Learn a demonstration as skill ``name`` and save it; return (learned, what was done).

        What happened is logged too (INFO, or ERROR with the reason); a refused demonstration
        replaces nothing.
        """
        try:
            if len(positions) > limits.MAX_DEMO_SAMPLES:
                raise ValueError(f'{len(positions)} poses, more than MAX_DEMO_SAMPLES = '
                                 f'{limits.MAX_DEMO_SAMPLES}')
            if len(positions):
                bounded(positions[np.argmax(np.abs(positions).max(axis=1))], 'a pose')
            with np.errstate(over='raise', invalid='raise', divide='raise'):
                demo = recorded_path_demo(name, positions, t, settings.plane,
                                          settings.recorded_dim, settings.plane_tolerance,
                                          quaternions)
                self._check_usable(demo, settings)
                entry = self._library.add(name, demo, _TAUGHT + where,
                                          protected=self._protected_sources(name, settings))
        except (ValueError, ArithmeticError) as err:
            return False, self._taught(name, err)
        log = self.get_logger()
        try:
            file, save_error = str(save_skill_demo(self._skills_dir, entry.demo)), ''
            saved = f'saved to {file}'
        except (OSError, ValueError) as err:
            saved = f'NOT saved (it is lost on restart): {err}'
            file, save_error = '', str(err)
            log.error(f'taught skill {name!r} {saved}')
        text = (f'learned skill {name!r} ({demo.dim}D, {demo.n_samples} samples) from {where}, '
                f'{saved}')
        log.info(text)
        self.events.publish('learned', text, skill=name, dim=demo.dim, samples=demo.n_samples,
                            duration_s=demo.duration, source=where, saved=file,
                            save_error=save_error)
        return True, text

    def _taught(self, name, err):
        """Log (ERROR) and return why a taught demonstration of skill ``name`` is refused."""
        hint = ''
        if 'exists already' in str(err):
            hint = ' (set teach_overwrite to true to replace it, or choose another name)'
        text = (f'taught demonstration for skill {name!r} rejected: {_short(err)}{hint}; the '
                'skills already learned are kept')
        self.get_logger().error(text)
        self.events.publish('refused', text, ERROR, skill=name, reason=f'{_short(err)}{hint}')
        return text

    @staticmethod
    def _check_usable(demo, settings):
        """
        Raise ValueError if ``demo`` could not be generalized into a plan with these settings.

        What the Demonstration and learning check already (sample count, duration, extent,
        finite products: etdmp_ros.limits) is not repeated; here: a plan of the demonstration's
        own duration must have at least 3 poses at output_period.
        """
        if settings.plan.duration == 0.0 and demo.duration < 2 * settings.plan.output_period:
            raise ValueError(f'it lasts {demo.duration:.3g} s, less than two output periods '
                             f'({settings.plan.output_period:g} s): a plan of its own duration '
                             'would have fewer than 3 poses')

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
        with self._state_lock:
            self._joint_state.update(q)

    def _on_tool_pose(self, msg):
        p = point_to_numpy(msg.pose.position)
        if self._frame_ok(msg.header.frame_id, '/etdmp/tool_pose') and \
                self._bounded_ok(p, '/etdmp/tool_pose'):
            with self._state_lock:
                self._tool_pose.update(p)

    def _bounded_ok(self, points, topic):
        """Return whether a message's points are finite and bounded, else WARN (throttled)."""
        try:
            bounded(points, topic)
        except ValueError as err:
            self.get_logger().warn(f'{err}: ignored', throttle_duration_sec=_THROTTLE)
            return False
        return True

    def _on_goal(self, msg):
        self._on_goal_object(msg, 'marker', '/etdmp/goal', self._goal)

    def _on_bottle(self, msg):
        self._on_goal_object(msg, 'bottle', '/etdmp/bottle', self._bottle)

    def _on_goal_object(self, msg, kind, topic, latest):
        """Keep a perceived goal object; follow it if it is the goal_object of the plan."""
        p = point_to_numpy(msg.point)
        if not self._frame_ok(msg.header.frame_id, topic) or not self._bounded_ok(p, topic):
            return
        settings = self._settings
        with self._state_lock:
            latest.update(p)
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
        with self._state_lock:
            self._obstacles.update(points)
        self._follow(obstacles=True)

    def _on_volumes(self, msg):
        """Keep the latest obstacle volumes: each obstacle's top-face centre and radius."""
        try:
            tops, radii = cylinders_from_markers(msg)
        except ValueError as err:
            self.get_logger().warn(f'/etdmp/obstacle_volumes: ignored: {err}',
                                   throttle_duration_sec=_THROTTLE)
            return
        with self._state_lock:
            self._volumes.update((tops, radii))

    def _tool_position(self, settings):
        source = settings.tool_position_source
        topic = '/joint_states' if source == 'joint_states' else '/etdmp/tool_pose'
        with self._state_lock:
            latest = self._joint_state if source == 'joint_states' else self._tool_pose
            value = latest.fresh(settings.tool_state_max_age)
            if value is not None and source == 'joint_states':
                value = self._model.tool_position(value)
        if value is None:
            state = 'none received yet' if latest.value is None else \
                f'the latest is {latest.age():.1f} s old (tool_state_max_age ' \
                f'{settings.tool_state_max_age:g} s)'
            raise ValueError(f'the tool position is unknown ({topic}: {state}); give a start '
                             'in base_link instead of an empty frame id')
        return value

    def _perceived_goal(self, settings):
        """Return the perceived goal object (goal_object) plus goal_offset."""
        bottle = settings.goal_object == 'bottle'
        latest, topic = (self._bottle, '/etdmp/bottle') if bottle else (self._goal, '/etdmp/goal')
        with self._state_lock:
            goal = latest.fresh(settings.goal_max_age)
            if goal is None:
                if latest.value is None:
                    raise ValueError(f'no perceived goal yet on {topic}; give a goal in '
                                     'base_link instead of an empty frame id')
                raise ValueError(f'the latest perceived goal is {latest.age():.1f} s old '
                                 f'(goal_max_age {settings.goal_max_age:g} s)')
            return goal + settings.goal_offset

    def _current_obstacles(self, settings):
        """Return the obstacles to plan around: points (m, 3)."""
        return self._current_volumes(settings)[0]

    def _current_volumes(self, settings):
        """
        Return the obstacles to plan around: (points (m, 3), radii (m,) in metres).

        The perceived ones (/etdmp/obstacles), each with the radius of the nearest volume
        (/etdmp/obstacle_volumes, within FOLLOW_MATCH_RADIUS: perception sends both for every
        frame), then ``static_obstacles`` (points: radius 0). A perceived obstacle without a
        volume is a point (warned).
        """
        with self._state_lock:
            seen = self._obstacles.fresh(settings.obstacle_max_age)
            stale = seen is None and self._obstacles.value is not None and \
                len(self._obstacles.value) > 0
            volumes = self._volumes.fresh(settings.obstacle_max_age)
        if stale:
            self.get_logger().warn('/etdmp/obstacles is older than obstacle_max_age '
                                   f'{settings.obstacle_max_age:g} s: ignored',
                                   throttle_duration_sec=_THROTTLE)
        static = settings.static_obstacles
        if seen is None or len(seen) == 0:
            return static, np.zeros(len(static))
        radii = np.zeros(len(seen))
        if volumes is not None and len(volumes[0]):
            gaps = np.linalg.norm(seen[:, None] - volumes[0][None], axis=2)
            nearest = gaps.argmin(axis=1)
            sized = gaps[np.arange(len(seen)), nearest] <= FOLLOW_MATCH_RADIUS
            radii[sized] = volumes[1][nearest[sized]]
        else:
            sized = np.zeros(len(seen), bool)
        if not np.all(sized):
            self.get_logger().warn(
                f'{np.count_nonzero(~sized)} perceived obstacle(s) without a volume on '
                '/etdmp/obstacle_volumes: planned as points (radius 0)',
                throttle_duration_sec=_THROTTLE)
        return np.concatenate([seen, static]), np.concatenate([radii, np.zeros(len(static))])

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

    def _check_goal(self, goal, skill, settings):
        """Refuse a goal out of the arm's reach, or too far from the task plane (2D skills)."""
        where = f'goal ({goal[0]:.3f}, {goal[1]:.3f}, {goal[2]:.3f})'
        outside = settings.plan.workspace.violation(goal)
        if outside is not None:
            raise ValueError(f"{where} is out of the UR10's reach: {outside[1]}")
        if skill.dim == 2:
            height = float(settings.plane.distance(goal.reshape(1, 3))[0])
            if abs(height) > limits.MAX_GOAL_PLANE_DISTANCE:
                raise ValueError(f'{where} is {height:.3f} m from the task plane, more than '
                                 f'MAX_GOAL_PLANE_DISTANCE = {limits.MAX_GOAL_PLANE_DISTANCE:g} '
                                 f'm: not a goal for the 2D skill {settings.skill!r}')

    def _check_plan(self, plan, skill, settings, obstacles, radii):
        """
        Refuse a plan the arm cannot follow in time, or along which it would touch an obstacle.

        One IK along the plan (TIMING_CHECK_SAMPLES poses from the current joints) serves both
        checks (``check_timing``, ``check_arm``); ``obstacles`` (m, 3) and ``radii`` (m,) are the
        obstacles as perceived (top-face centres in base_link, not projected onto the plane).
        """
        if not (settings.check_timing or settings.check_arm):
            return
        with self._state_lock:
            q = self._joint_state.fresh(settings.tool_state_max_age)
        q = settings.initial_joints if q is None else q
        rotations = quat.to_matrix(quat.normalized(plan.orientation))
        idx, joints, violation = plan_joints(self._timing_model, plan.positions, rotations,
                                             plan.t, q, limits.TIMING_CHECK_SAMPLES)
        if settings.check_timing:
            if violation is None:
                fraction = limits.TIMING_LIMIT_FRACTION
                violation = joint_timing_violation(
                    plan.t[idx], joints, self._timing_model.velocity_limits * fraction,
                    np.asarray(DEFAULT_ACCELERATION_LIMITS) * fraction)
            if violation is not None:
                self._refuse_timing(violation, plan, skill, settings)
        if settings.check_arm and len(joints):
            touch = arm_obstacle_violation(self._arm, joints, plan.t[idx], obstacles, radii,
                                           settings.arm_clearance)
            if touch is not None:
                self._refuse_touch(touch, obstacles, radii, settings)

    @staticmethod
    def _refuse_touch(touch, obstacles, radii, settings):
        """Raise the arm check's refusal (an ArmViolation): the part, the obstacle, when."""
        o, r, t = obstacles[touch.obstacle], radii[touch.obstacle], touch.t
        how = (f'{-touch.gap * 1000:.0f} mm into' if touch.gap < 0.0 else
               f'within {touch.gap * 1000:.1f} mm of')
        raise ValueError(
            f'the plan would bring the {touch.part} {how} the obstacle at ({o[0]:.3f}, '
            f'{o[1]:.3f}, {o[2]:.3f}) (radius {r * 1000:.0f} mm) at t = {t:.2f} s, closer than '
            f'arm_clearance {settings.arm_clearance * 1000:g} mm (IK of the plan from the '
            'current joints: the plan keeps the tool clear of obstacles, not the arm); move the '
            'obstacle or the start')

    def _refuse_timing(self, violation, plan, skill, settings):
        """Raise the timing check's refusal; say the shortest feasible duration."""
        tau = settings.plan.duration or skill.tau
        if np.isfinite(violation.slowdown):
            needed = np.ceil(tau * violation.slowdown * 100.0) / 100.0
            hint = (f'; the shortest feasible duration is about {needed:.2f} s (parameter '
                    f'duration, now {tau:g} s)')
        elif len(plan.t) < 3:
            hint = (f'; duration {tau:g} s is too short for output_period '
                    f'{settings.plan.output_period:g} s: set duration to at least '
                    f'{2 * settings.plan.output_period:g} s (more for the arm to follow it)')
        else:
            hint = ''
        raise ValueError(f'{violation.reason}{hint}')

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
            self.get_logger().error(f'/generalize with skill {settings.skill!r}: {_short(err)}')
            self.events.publish('plan_refused', f'/generalize with skill {settings.skill!r}: '
                                f'{_short(err)}', ERROR, service='/generalize',
                                skill=settings.skill, reason=_short(err))
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
            given = self._service_values('generalize_with', request)
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
            reason = f'with skill {settings.skill!r}: {_short(err)}'
            self.get_logger().error(f'{self._generalize_with_name}: {reason}')
            self.events.publish('plan_refused', f'{self._generalize_with_name}: {reason}', ERROR,
                                service=self._generalize_with_name, skill=settings.skill,
                                reason=_short(err))
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

    def _service_values(self, service, request):
        """Return {argument: value} of a request to ``service`` (DESCRIPTION); ValueError."""
        given = {}
        for argument in request.parameters:
            value = parameter_value_to_python(argument.value)
            if value is not None:
                given[argument.name] = plain(value)
        return DESCRIPTION.service(service).values(given)

    def _plan(self, settings, start, goal, goal_orientation):
        """
        Return (skill, Plan) of ``settings.skill`` from ``start`` to ``goal`` (base_link).

        Raises ValueError or ArithmeticError with the reason: the goal's checks, the planning's
        and the timing check's.
        """
        obstacles, radii = self._current_volumes(settings)
        skill = self._library.skill(settings.skill, settings.formulation, settings.n_basis)
        self._check_goal(goal, skill, settings)
        with self._core_lock, np.errstate(over='raise', invalid='raise', divide='raise'):
            plan = plan_path(skill, start, goal, obstacles, settings.plan, settings.plane,
                             goal_orientation=goal_orientation, obstacle_radii=radii)
            self._check_plan(plan, skill, settings, obstacles, radii)
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
            if settings.publish_markers and self._marker_pub.get_subscription_count() > 0:
                self._request_markers((settings, skill, plan, header))
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
                    followed = _Followed(FollowedPlan(skill, plan, settings.plan,
                                                      settings.plane),
                                         skill, stamp, perceived_goal)
            except ValueError as err:   # e.g. a skill the online rollout cannot take
                self.get_logger().warn(f'the plan will not follow its goal: {_short(err)}')
        with self._follow_lock:
            self._followed = followed

    def _follow(self, goal=None, obstacles=False):
        """Re-plan the remainder of the plan in execution if its goal or obstacles moved."""
        settings = self._settings
        with self._follow_lock:
            f = self._followed
            if f is None or not settings.follow_goal:
                return
            now = self.get_clock().now().nanoseconds
            tau_now = (now - f.stamp) * 1e-9
            if tau_now > f.plan.duration + _FOLLOW_AFTER_END:
                self._followed = None           # done: nothing left to follow
                return
            threshold = settings.follow_threshold
            new_goal = None
            if goal is not None and f.perceived_goal:
                placed = f.plan.placed(goal)
                if f.goal_seen.confirm(placed, _goal_moved, threshold) and \
                        _goal_moved(f.plan.goal, placed, threshold) and \
                        _goal_moved(f.refused_goal, placed, threshold):
                    new_goal = goal
            new_obstacles = None
            if obstacles:
                seen, seen_radii = self._current_volumes(settings)
                merged, merged_radii = _merged_obstacles(
                    f.plan.obstacles, f.plan.obstacle_sizes, f.plan.placed(seen), seen_radii,
                    threshold)
                if f.obstacles_seen.confirm(merged, _obstacles_moved, threshold) and \
                        _obstacles_moved(f.plan.obstacles, merged, threshold) and \
                        _obstacles_moved(f.refused_obstacles, merged, threshold):
                    new_obstacles = merged
            if new_goal is None and new_obstacles is None:
                return
            received = time.perf_counter()
            tau_c = self._controller_path_time(f, tau_now, settings)
            t_switch = tau_c + settings.follow_lead
            try:
                with self._core_lock, np.errstate(over='raise', invalid='raise',
                                                  divide='raise'):
                    if new_goal is not None:
                        self._check_goal(new_goal, f.skill, settings)
                    first = f.plan.update(
                        t_switch, goal=new_goal, obstacles=new_obstacles,
                        obstacle_radii=None if new_obstacles is None else merged_radii)
            except (ValueError, ArithmeticError) as err:
                # Said once for this goal or obstacle set, not at every message that shows it.
                f.refused_goal = f.goal_seen.candidate if new_goal is not None else None
                f.refused_obstacles = (f.obstacles_seen.candidate if new_obstacles is not None
                                       else None)
                self.get_logger().error(f'the plan in execution does not follow: '
                                        f'{_short(err)}; it goes on as it was')
                self.events.publish('follow_refused', f'the plan in execution does not follow: '
                                    f'{_short(err)}', WARN, reason=_short(err),
                                    stamp_ns=f.stamp)
                return
            p = f.plan
            keep = p.index(max(0.0, tau_c - _FOLLOW_OVERLAP))
            # Its bytes written with numpy: 0.2 ms where building the message takes ~8.
            orientation = p.orientation if isinstance(p.orientation, tuple) else \
                p.orientation[keep:]
            self._path_pub.publish(serialize_path(p.positions[keep:], p.t[keep:], f.stamp,
                                                  'base_link', orientation))
            took = (time.perf_counter() - received) * 1e3
            what = ' and '.join(
                ([f'goal moved to ({new_goal[0]:.3f}, {new_goal[1]:.3f}, {new_goal[2]:.3f})']
                 if new_goal is not None else []) +
                ([f'obstacles moved to {np.round(new_obstacles, 3).tolist()}']
                 if new_obstacles is not None else []))
            text = (f'following: {what}: re-planned from path time {p.t[first]:.2f} s (the '
                    f'controller at about {tau_c:.2f} s), {len(p.t) - keep} poses to '
                    f'{p.duration:.2f} s published in {took:.1f} ms (update {p.updates})')
            self.events.publish(
                'followed', text, goal=[] if new_goal is None else new_goal,
                obstacles=[] if new_obstacles is None else new_obstacles,
                from_path_time_s=p.t[first], controller_path_time_s=tau_c, poses=len(p.t) - keep,
                end_s=p.duration, took_ms=took, update=p.updates, stamp_ns=f.stamp)
            self.get_logger().info(text)
            if settings.publish_markers and self._marker_pub.get_subscription_count() > 0:
                shown = Plan(p.t, p.positions, p.velocities, p.orientation, f.start, p.goal,
                             p.obstacles, settings.plan.method, None)
                header = Header(stamp=ns_to_stamp(f.stamp), frame_id='base_link')
                self._request_markers((settings, f.skill, shown, header))

    def _controller_path_time(self, f, tau_now, settings):
        """
        Estimate the path time the controller is at: where the tool is closest to the path.

        Searched between the previous estimate and ``tau_now`` (the controller cannot be ahead
        of the time since the plan's stamp); without a tool position, ``tau_now``.
        """
        try:
            tool = self._tool_position(settings)
        except ValueError:
            return tau_now
        p = f.plan
        lo, hi = p.index(f.tau_c), p.index(tau_now) + 1
        if hi <= lo:
            return tau_now
        i = lo + int(np.argmin(np.linalg.norm(p.positions[lo:hi] - tool, axis=1)))
        f.tau_c = float(p.t[i])
        return f.tau_c

    # -- markers --------------------------------------------------------------------------------

    def _request_markers(self, pending):
        """Have the markers of a plan published by a worker thread (the newest plan wins)."""
        with self._state_lock:
            self._pending_markers = pending
            if self._marker_thread is not None:
                return   # it takes the newest pending plan when it is done with this one
            self._marker_thread = threading.Thread(target=self._marker_worker, daemon=True,
                                                   name='markers')
            self._marker_thread.start()

    def _marker_worker(self):
        while True:
            with self._state_lock:
                pending, self._pending_markers = self._pending_markers, None
                if pending is None:
                    self._marker_thread = None
                    return
            try:
                self._publish_markers(*pending)
            except Exception as err:   # noqa: B902 - markers are a view: never take the node down
                self.get_logger().error(f'/etdmp/markers not published: {err}')

    def _publish_markers(self, settings, skill, plan, header):
        other = 'dmp' if plan.method == 'etdmp' else 'etdmp'
        plane = settings.plane if skill.dim == 2 else None
        with self._core_lock:
            try:
                baseline = plan_path(skill, plan.start, plan.goal, plan.obstacles,
                                     replace(settings.plan, method=other),
                                     settings.plane).positions
            except ValueError:   # e.g. the plain DMP refuses a closed letter: show none
                baseline = None
            try:
                demo = place_demo(skill, plan.start, plan.goal, plane, settings.plan.mode,
                                  settings.plan.independent_axis)
            except ValueError:
                demo = None
        colours = {'etdmp': (0.1, 0.8, 0.2, 1.0), 'dmp': (1.0, 0.5, 0.0, 1.0)}
        markers = MarkerArray(markers=[
            _marker(header, 'demo', Marker.LINE_STRIP, demo, (0.6, 0.6, 0.6, 0.8), 0.003),
            _marker(header, f'plan_{plan.method}', Marker.LINE_STRIP, plan.positions,
                    colours[plan.method], 0.005),
            _marker(header, f'plan_{other}', Marker.LINE_STRIP, baseline, colours[other],
                    0.003),
            _marker(header, 'obstacles', Marker.SPHERE_LIST, plan.obstacles,
                    (0.9, 0.1, 0.1, 0.9), 0.03),
            _marker(header, 'start_goal', Marker.SPHERE_LIST, np.stack([plan.start, plan.goal]),
                    (0.2, 0.4, 1.0, 1.0), 0.015),
            _axes_marker(header, 'orientation', plan.positions, plan.orientations),
        ])
        self._marker_pub.publish(markers)


#: The remainder published on a change starts this far (path time, s) before the controller's
#: estimated place, so that it covers where the controller is when it takes it over.
_FOLLOW_OVERLAP = 0.1
#: A perceived obstacle within this distance (m) of one the plan avoids is that one, moved.
FOLLOW_MATCH_RADIUS = 0.05
#: A plan is followed until this long (s) after its end.
_FOLLOW_AFTER_END = 1.0


class _Followed:
    """A plan in execution: its FollowedPlan, its skill, stamp, and what it follows."""

    def __init__(self, plan, skill, stamp, perceived_goal):
        self.plan, self.skill, self.stamp = plan, skill, stamp
        self.perceived_goal = perceived_goal    # the request used the perceived goal
        self.refused_goal = self.refused_obstacles = None    # the last the plan could not take
        self.start = plan.positions[0].copy()
        self.tau_c = 0.0                        # the controller's path time, last estimate
        self.goal_seen, self.obstacles_seen = _Confirmed(), _Confirmed()


class _Confirmed:
    """A perceived value taken as changed once FOLLOW_CONFIRMATIONS messages agree on it."""

    def __init__(self):
        self.candidate, self.count = None, 0

    def confirm(self, value, differ, threshold):
        """Note ``value``; return whether the last FOLLOW_CONFIRMATIONS agree (``differ``)."""
        if differ(self.candidate, value, threshold):
            self.count = 0
        self.candidate, self.count = value, self.count + 1
        return self.count >= FOLLOW_CONFIRMATIONS


def _merged_obstacles(used, used_radii, seen, seen_radii, threshold):
    """
    Return the obstacles (m, 3) and radii (m,) a plan in execution follows: ``used`` updated.

    A seen obstacle within FOLLOW_MATCH_RADIUS of a used one is that one (moved, if by more than
    ``threshold``, and then with its seen radius); the nearest such wins, others near it are
    the same obstacle seen twice. A seen obstacle near none appeared. A used obstacle that is
    not seen is kept where it was: the arm may be hiding it from the camera.
    """
    used, seen = np.asarray(used).reshape(-1, 3), np.asarray(seen).reshape(-1, 3)
    merged, radii = used.copy(), np.array(used_radii, dtype=float).reshape(-1)
    seen_radii = np.asarray(seen_radii, dtype=float).reshape(-1)
    appeared = list(range(len(seen)))
    if len(used):
        gaps = np.linalg.norm(seen[:, None] - used[None], axis=2)
        nearest = gaps.argmin(axis=1) if len(seen) else np.zeros(0, int)
        for j in range(len(used)):
            mine = np.flatnonzero((nearest == j) & (gaps[:, j] <= FOLLOW_MATCH_RADIUS))
            if len(mine):
                best = mine[np.argmin(gaps[mine, j])]
                if gaps[best, j] > threshold:
                    merged[j], radii[j] = seen[best], seen_radii[best]
        appeared = [i for i in range(len(seen)) if gaps[i].min() > FOLLOW_MATCH_RADIUS]
    return (np.vstack([merged, seen[appeared]]), np.concatenate([radii, seen_radii[appeared]]))


def _goal_moved(before, now, threshold):
    """Return whether goal ``now`` is more than ``threshold`` from ``before`` (or no before)."""
    return before is None or bool(np.linalg.norm(now - before) > threshold)


def _obstacles_moved(used, seen, threshold):
    """Return whether the obstacle set ``seen`` differs from ``used`` by more than threshold."""
    if used is None:
        return True
    seen, used = np.asarray(seen).reshape(-1, 3), np.asarray(used).reshape(-1, 3)
    if len(seen) != len(used):
        return True
    if not len(seen):
        return False
    # Each used obstacle's nearest seen one (sets are small and unordered).
    gaps = np.linalg.norm(used[:, None] - seen[None], axis=2).min(axis=1)
    return bool(gaps.max() > threshold)


def _marker(header, ns, kind, points, rgba, size):
    """Return a base_link Marker showing ``points`` (n, 3), or deleting ``ns`` when None/empty."""
    marker = Marker(header=header, ns=ns, id=0, type=kind)
    if points is None or len(points) == 0:
        marker.action = Marker.DELETE
        return marker
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = float(size)
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = (float(c) for c in rgba)
    marker.points = points_from_numpy(points)
    return marker


#: Tool frames shown along a plan on /etdmp/markers (namespace ``orientation``), and the length
#: (m) and width of their axes.
MARKER_AXES, MARKER_AXIS_LENGTH, MARKER_AXIS_WIDTH = 12, 0.04, 0.003
_AXIS_COLOURS = (ColorRGBA(r=1.0, a=1.0), ColorRGBA(g=1.0, a=1.0), ColorRGBA(b=1.0, a=1.0))


def _axes_marker(header, ns, positions, orientations):
    """
    Return a LINE_LIST Marker of the tool's axes at MARKER_AXES poses evenly spread in time.

    Each frame is three lines from the pose's position along the tool's x (red), y (green) and
    z (blue) axes, MARKER_AXIS_LENGTH long: the orientation the plan gives the tool there.
    """
    if len(positions) == 0:
        return _marker(header, ns, Marker.LINE_LIST, None, None, 0.0)
    idx = np.unique(np.linspace(0, len(positions) - 1, MARKER_AXES).round().astype(int))
    axes = quat.to_matrix(quat.normalized(orientations[idx]))      # (k, 3, 3): columns x, y, z
    tips = positions[idx, None, :] + MARKER_AXIS_LENGTH * np.swapaxes(axes, 1, 2)
    points = np.stack([np.repeat(positions[idx, None, :], 3, axis=1), tips], axis=2)
    marker = _marker(header, ns, Marker.LINE_LIST, points.reshape(-1, 3), (1, 1, 1, 1),
                     MARKER_AXIS_WIDTH)
    marker.colors = [c for _ in idx for c in _AXIS_COLOURS for _ in range(2)]
    return marker


def main(args=None):
    """Run the dmp_server node until Ctrl-C (or SIGTERM)."""
    return run(lambda nodes: nodes.append(DmpServer()), NODE_NAME, args,
               startup_errors=(InvalidConfiguration,))


if __name__ == '__main__':
    main()

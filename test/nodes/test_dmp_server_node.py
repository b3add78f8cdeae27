"""
dmp_server as a user runs it: the installed executable in its own process, talked to with rclpy.

The client here does what ``ros2 service call /generalize nav_msgs/srv/GetPlan "{...}"``,
``ros2 topic pub`` and ``ros2 param set`` do. Plans are checked against the ET-DMP core run in
this process on the same demonstration (the node must be a thin shell around it) and against the
acceptance numbers: starts at the start, ends within 1 mm of the goal, lies on the task plane,
keeps the demo's shape (nRMSE), avoids published obstacles; refuses a plan along which a link
of the arm would touch a perceived obstacle (its volume on /etdmp/obstacle_volumes), naming it.
"""

import math
from pathlib import Path as FsPath

import time

from conftest import NodeProcess

from diagnostic_msgs.msg import DiagnosticArray

from etdmp_ros.dmp import builtin_demo, Demonstration, learn, nrmse, ObstacleGains, save_demo

from etdmp_ros.geometry import quaternion as quat

from etdmp_ros.geometry.task_plane import TaskPlane

from etdmp_ros.robot import JOINT_NAMES, UR10Model
from etdmp_ros.robot._arm_check import ArmGeometry
from etdmp_ros.robot._timing import plan_joints

from etdmp_ros.ros import events, qos
from etdmp_ros.ros.conversions import (cylinder_markers, joint_state_msg, path_from_numpy,
                                       path_to_numpy, pose_array_from_numpy)

from etdmp_ros.skills.planning import plan_path

from geometry_msgs.msg import Point, PointStamped, PoseArray, PoseStamped

from nav_msgs.msg import Path

from nav_msgs.srv import GetPlan

import numpy as np
import pytest
from rcl_interfaces.srv import GetParameters, SetParameters, SetParametersAtomically

import rclpy
from rclpy.executors import SingleThreadedExecutor

from rclpy.parameter import Parameter, parameter_value_to_python

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from sensor_msgs.msg import JointState

from std_msgs.msg import Header

from support.waiting import wait_for

from visualization_msgs.msg import MarkerArray

import yaml

# The scene (config/scene.yaml) the node is started with.
SCENE = yaml.safe_load((FsPath(__file__).parents[2] / 'config' / 'scene.yaml').read_text())
SCENE = SCENE['/**']['ros__parameters']
# The node's own settings (config/dmp_server.yaml), for the obstacle gains it plans with.
SERVER = yaml.safe_load((FsPath(__file__).parents[2] / 'config' / 'dmp_server.yaml').read_text())
SERVER = SERVER['dmp_server']['ros__parameters']
PLANE = TaskPlane.create(SCENE['task_plane']['origin'], SCENE['task_plane']['x_axis'],
                         SCENE['task_plane']['y_axis'], 0.02)
Q_INIT = np.array(SCENE['initial_joint_positions'])
TOOL_DOWN = np.array([-math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0])
# A 2D request: start and goal 8 cm apart in the task plane, so the G is about 20 cm tall.
START = np.array([0.80, 0.20, 0.0])
GOAL = np.array([0.74, 0.15, 0.0])
TIMEOUT = 20.0
BASE = Header(frame_id='base_link')
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Client:
    """rclpy in this process, in its own context: service calls, publishers, parameters."""

    def __init__(self, name='dmp_server_test_client'):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.generalize = self.node.create_client(GetPlan, '/generalize')
        self.parameters = self.node.create_client(SetParameters, '/dmp_server/set_parameters')
        self.get_client = self.node.create_client(GetParameters, '/dmp_server/get_parameters')
        # dmp_server's services whose requests carry their skill and settings.
        self.services = {name: self.node.create_client(SetParametersAtomically,
                                                       f'/dmp_server/{name}')
                         for name in ('teach', 'generalize_with')}
        self.pub = {
            'joint_states': self.node.create_publisher(JointState, '/joint_states', 10),
            'goal': self.node.create_publisher(PointStamped, '/etdmp/goal', 10),
            'obstacles': self.node.create_publisher(PoseArray, '/etdmp/obstacles', 10),
            'bottle': self.node.create_publisher(PointStamped, '/etdmp/bottle', 10),
            'tool_pose': self.node.create_publisher(PoseStamped, '/etdmp/tool_pose', 10),
            'demonstrations': self.node.create_publisher(Path, '/etdmp/demonstrations', 10),
        }
        # /etdmp/obstacle_volumes: made by the first test that publishes volumes (until then
        # obstacles come without volumes from a node that has none, as from elsewhere).
        self.paths, self.markers = [], []
        self.node.create_subscription(Path, '/etdmp/path', self.paths.append, LATCHED)
        self.node.create_subscription(MarkerArray, '/etdmp/markers', self.markers.append,
                                      LATCHED)
        self.events = []    # dmp_server's events (etdmp_ros.ros.events), in order
        self.node.create_subscription(
            DiagnosticArray, '/dmp_server/events',
            lambda msg: self.events.extend(events.from_message(msg)),
            qos.latched(events.HISTORY))

    def close(self):
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)

    def wait_for_server(self, server):
        """Wait until /generalize is offered; fail with the node's log if it never is."""
        deadline = time.monotonic() + 60.0
        while not self.generalize.wait_for_service(timeout_sec=0.2):
            assert server.process.poll() is None, f'dmp_server exited:\n{server.log()}'
            assert time.monotonic() < deadline, f'no /generalize:\n{server.log()}'
        assert self.parameters.wait_for_service(timeout_sec=TIMEOUT)

    def wait_for_event(self, kind, timeout=TIMEOUT):
        """Return the first event of ``kind`` received since the last call (or fail)."""
        deadline = time.monotonic() + timeout
        while True:
            found = [e for e in self.events if e.kind == kind]
            if found:
                del self.events[:]
                return found[0]
            assert time.monotonic() < deadline, f'no {kind} event from dmp_server'
            self.spin_for(0.05)

    def spin_for(self, seconds):
        """Process callbacks for a while."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def _result(self, future):
        self.executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
        assert future.done(), 'no answer from dmp_server'
        return future.result()

    def call(self, start=None, goal=None, start_frame='base_link', goal_frame='base_link'):
        """Call /generalize; return (t from the first pose, positions, quaternions, msg)."""
        future = self.generalize.call_async(request(start, goal, start_frame, goal_frame))
        plan = self._result(future).plan
        return path_to_numpy(plan) + (plan,)

    def set_parameters(self, **values):
        """Set dmp_server parameters; return the SetParametersResult list."""
        # An empty list has no type of its own; the only list parameter set empty here is one
        # of floats.
        req = SetParameters.Request(parameters=[
            (Parameter(name, Parameter.Type.DOUBLE_ARRAY, []) if value == [] else
             Parameter(name, value=value)).to_parameter_msg() for name, value in values.items()])
        return self._result(self.parameters.call_async(req)).results

    def get_parameters(self, *names):
        """Return dmp_server's parameters ``names`` as {name: value}."""
        response = self._result(self.get_client.call_async(GetParameters.Request(
            names=list(names))))
        return {name: parameter_value_to_python(v) for name, v in zip(names, response.values)}

    def ask(self, service, **arguments):
        """Call dmp_server's ``service`` (teach, generalize_with); return (successful, reason)."""
        client = self.services[service]
        assert client.wait_for_service(timeout_sec=TIMEOUT)
        result = self._result(client.call_async(SetParametersAtomically.Request(parameters=[
            Parameter(name, value=value).to_parameter_msg()
            for name, value in arguments.items()]))).result
        return result.successful, result.reason

    def publish(self, topic, msg, times=3):
        """Publish a few times (the node's subscription may still be matching) and spin."""
        deadline = time.monotonic() + TIMEOUT
        if topic == 'volumes' and topic not in self.pub:
            self.pub[topic] = self.node.create_publisher(MarkerArray, '/etdmp/obstacle_volumes',
                                                         10)
        while self.pub[topic].get_subscription_count() == 0:
            assert time.monotonic() < deadline, f'dmp_server does not subscribe to {topic}'
            self.spin_for(0.05)
        for _ in range(times):
            self.pub[topic].publish(msg)
            self.spin_for(0.05)
        self.spin_for(0.2)


def request(start, goal, start_frame='base_link', goal_frame='base_link'):
    """Return the GetPlan request that ``ros2 service call`` would send."""
    req = GetPlan.Request()
    for pose, point, frame in ((req.start, start, start_frame), (req.goal, goal, goal_frame)):
        pose.header.frame_id = frame
        if point is not None:
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (
                float(c) for c in point)
    return req


def obstacles_msg(points):
    """Return a PoseArray of obstacle points in base_link."""
    return pose_array_from_numpy(np.reshape(points, (-1, 3)))


def core_plan(name, start, goal, obstacles=(), method='etdmp', **kwargs):
    """Return the core's plan (t, base_link points) for a 2D built-in skill in the task plane."""
    skill = learn(builtin_demo(name))
    traj = skill.generalize(PLANE.to_plane(start), PLANE.to_plane(goal),
                            PLANE.to_plane(np.reshape(obstacles, (-1, 3))), method=method,
                            dt=0.01, **kwargs)
    return traj.t, PLANE.from_plane(traj.x)


def wait_for_log(server, *fragments, timeout=10.0):
    """Return the first ERROR line of the node's log holding all fragments (or fail)."""
    def found():
        return next((line for line in server.log().splitlines()
                     if '[ERROR]' in line and all(f in line for f in fragments)), None)
    return wait_for(found, timeout, f'an ERROR log with {fragments}', [server])


def clearance_2d(positions, obstacles):
    """Smallest in-plane distance from a path to obstacle points (both projected)."""
    xy = PLANE.to_plane(positions) * PLANE.scale
    obs = PLANE.to_plane(np.reshape(obstacles, (-1, 3))) * PLANE.scale
    return float(np.min(np.linalg.norm(xy[:, None] - obs[None], axis=2)))


@pytest.fixture(scope='module')
def server(colcon_install, module_ros_env, tmp_path_factory):
    """One dmp_server for the request tests (they restore what they change)."""
    tmp = tmp_path_factory.mktemp('dmp_server')
    node = NodeProcess(colcon_install, module_ros_env, tmp, 'dmp_server',
                       # Inputs are published once here: they must not expire during a test.
                       {'skills_dir': str(tmp / 'skills'), 'obstacle_max_age': 60.0,
                        'tool_state_max_age': 60.0})
    yield node
    assert node.stop() == 0, node.log()
    assert 'Traceback' not in node.log(), node.log()


@pytest.fixture(scope='module')
def client(server):
    """Return a connected rclpy client."""
    c = Client()
    c.wait_for_server(server)
    yield c
    c.close()


def test_bad_inputs_before_any_perception(server, client):
    # No /etdmp/goal and no /joint_states yet: empty frame ids cannot be resolved.
    assert len(client.call(START, None, goal_frame='')[1]) == 0
    wait_for_log(server, 'no perceived goal yet')
    assert len(client.call(None, GOAL, start_frame='')[1]) == 0
    wait_for_log(server, 'tool position is unknown', '/joint_states')


def test_plan_starts_at_start_ends_at_goal_on_the_plane_with_the_demo_shape(client):
    above = START + [0.0, 0.0, 0.08]     # the pen 8 cm above the table: projected onto it
    t, x, q, msg = client.call(above, GOAL)
    assert msg.header.frame_id == 'base_link'
    assert all(p.header.frame_id == 'base_link' for p in msg.poses)
    np.testing.assert_allclose(x[0], START, atol=1e-9)
    assert np.linalg.norm(x[-1] - GOAL) < 1e-3
    np.testing.assert_allclose(PLANE.distance(x), 0.0, atol=1e-9)
    # The demonstration's shape: nRMSE below the core's own bound for ET-DMP (0.005).
    assert nrmse(PLANE.to_plane(x), builtin_demo('G').positions) < 0.005
    # Exactly the core's ET-DMP plan (the node is a shell around it).
    t_core, x_core = core_plan('G', START, GOAL)
    np.testing.assert_allclose(x, x_core, atol=1e-9)
    # Timing: stamps every output_period (0.01 s) over the demo's duration (2 s); orientation.
    np.testing.assert_allclose(t, t_core, atol=1e-9)
    assert len(t) == 201 and t[-1] == pytest.approx(2.0)
    np.testing.assert_allclose(q, np.tile(TOOL_DOWN, (len(q), 1)), atol=1e-12)
    # Pose stamps = header stamp + t: the plan's time origin is its header stamp.
    stamp0 = msg.poses[0].header.stamp
    assert (stamp0.sec, stamp0.nanosec) == (msg.header.stamp.sec, msg.header.stamp.nanosec)


def test_method_dmp_gives_the_plain_dmp_baseline(client):
    start = np.array([0.66, 0.10, 0.0])          # demo starts up-right of its goal; this: left
    assert client.set_parameters(method='dmp')[0].successful
    try:
        _, x_dmp, _, _ = client.call(start, GOAL)
    finally:
        assert client.set_parameters(method='etdmp')[0].successful
    _, x_et, _, _ = client.call(start, GOAL)
    np.testing.assert_allclose(x_dmp, core_plan('G', start, GOAL, method='dmp')[1], atol=1e-9)
    demo = builtin_demo('G').positions
    assert nrmse(PLANE.to_plane(x_et), demo) < 0.005
    assert nrmse(PLANE.to_plane(x_dmp), demo) > 10 * nrmse(PLANE.to_plane(x_et), demo)
    assert np.linalg.norm(x_dmp[-1] - GOAL) < 1e-3


def test_3d_skill_uses_base_link_directly(client):
    # Stir in the bottle of the scene: the demo is in metres about the bottle's mouth.
    mouth = np.array(SCENE['bottle']['position'] + [SCENE['bottle']['height']])
    demo = builtin_demo('stir')
    goal = mouth + demo.goal
    start = mouth + demo.start + [0.03, -0.02, 0.05]
    assert client.set_parameters(skill='stir')[0].successful
    try:
        t, x, _, _ = client.call(start, goal)
    finally:
        assert client.set_parameters(skill='G')[0].successful
    np.testing.assert_allclose(x[0], start, atol=1e-9)
    assert np.linalg.norm(x[-1] - goal) < 1e-3
    assert nrmse(x, demo.positions) < 0.005
    assert t[-1] == pytest.approx(demo.duration)
    assert np.ptp(x[:, 2]) > 0.2          # not squashed onto the task plane


def test_plans_of_a_skill_with_orientations_turn_the_tool(server, client):
    # Stir: every pose has the core's orientation (the tilted stirrer turned with the motion);
    # the goal pose's orientation, if not all zeros, is reached; a bad one is refused.
    mouth = np.array(SCENE['bottle']['position'] + [SCENE['bottle']['height']])
    skill = learn(builtin_demo('stir'))
    start, goal = mouth + skill.start + [0.03, -0.02, 0.05], mouth + skill.goal
    turned = quat.multiply(quat.about_axis([1.0, 0.0, 0.0], 0.3), TOOL_DOWN)

    def call(orientation):
        req = request(start, goal)
        o = req.goal.pose.orientation
        o.x, o.y, o.z, o.w = (float(c) for c in orientation)
        plan = client._result(client.generalize.call_async(req)).plan
        return path_to_numpy(plan)[2]

    assert client.set_parameters(skill='stir')[0].successful
    try:
        client.spin_for(0.3)
        free, zero, to_goal = call((0, 0, 0, 1)), call((0, 0, 0, 0)), call(turned)
        bad = [call(q) for q in ((0.0, 0.0, 0.6, 0.6), (math.nan, 0.0, 0.0, 1.0))]
        client.spin_for(0.5)
        shown = {m.ns: m for m in client.markers[-1].markers}
        published = path_to_numpy(client.paths[-1])[2]
    finally:
        assert client.set_parameters(skill='G')[0].successful
    # /etdmp/path (numpy-written bytes) carries the same per-pose orientations as the response.
    np.testing.assert_array_equal(published, to_goal)
    expected = plan_path(skill, start, goal).orientation
    np.testing.assert_allclose(free, expected, atol=1e-12)
    np.testing.assert_array_equal(zero, free)
    assert np.degrees(quat.angle_between(free[0], free[len(free) // 3])) > 5.0   # it tilts
    assert np.degrees(quat.angle_between(to_goal[-1], turned)) <= 0.1
    assert np.degrees(quat.angle_between(
        to_goal, plan_path(skill, start, goal, goal_orientation=turned).orientation)).max() < 1e-9
    assert all(len(b) == 0 for b in bad)
    wait_for_log(server, '/generalize', 'not a unit quaternion')
    wait_for_log(server, '/generalize', 'goal orientation', 'NaN or inf')
    # The markers of the last plan (the one to the goal orientation) show the tool's axes.
    axes = shown['orientation']
    points = np.array([(p.x, p.y, p.z) for p in axes.points]).reshape(-1, 3, 2, 3)
    last = quat.to_matrix(quat.normalized(to_goal[-1]))
    np.testing.assert_allclose(points[-1, :, 1] - points[-1, :, 0], 0.04 * last.T, atol=1e-9)
    assert [c.r for c in axes.colors[:6]] == [1, 1, 0, 0, 0, 0]
    assert len(axes.points) == 2 * 3 * 12
    # A goal orientation for a position-only skill is refused, with the reason.
    req = request(START, GOAL)
    req.goal.pose.orientation.x = 1.0
    req.goal.pose.orientation.w = 0.0
    assert len(client._result(client.generalize.call_async(req)).plan.poses) == 0
    wait_for_log(server, 'the skill has no orientations')


def test_an_orientation_the_ur10_cannot_reach_is_refused_with_the_reason(server, client):
    # Stirring 1.08 m out: served with the stirrer's own orientations, refused when it must
    # end pointing back at the base (the wrist would be beyond the arm's reach).
    goal = np.array([1.08, 0.1, 0.2])
    start = goal + [-0.05, 0.05, 0.25]
    req = request(start, goal)
    o = req.goal.pose.orientation
    o.x, o.y, o.z, o.w = 0.0, -math.sqrt(0.5), 0.0, math.sqrt(0.5)
    assert client.set_parameters(skill='stir')[0].successful
    try:
        assert len(client.call(start, goal)[1]) > 100
        assert len(client._result(client.generalize.call_async(req)).plan.poses) == 0
    finally:
        assert client.set_parameters(skill='G')[0].successful
    line = wait_for_log(server, '/generalize', 'with its orientation, is out of reach')
    assert "skill 'stir'" in line and 'pose at t = ' in line


def test_a_taught_path_keeps_its_orientations(server, client):
    # A 3D path whose tool turns by 40 degrees about the vertical as it goes: taught on
    # /etdmp/demonstrations, it becomes a skill with orientations, and a plan from the taught
    # start to its goal reproduces them.
    n = 120
    s = np.linspace(0.0, 1.0, n)
    positions = np.column_stack([0.70 + 0.12 * s, 0.10 * np.sin(np.pi * s),
                                 0.30 - 0.10 * s])
    yaw = quat.about_axis([0.0, 0.0, 1.0], np.radians(40.0) * s)
    taught_q = quat.multiply(yaw, TOOL_DOWN)
    t = np.linspace(0.0, 2.4, n)
    assert client.set_parameters(teach_skill_name='turning', skill='turning')[0].successful
    try:
        client.publish('demonstrations', path_from_numpy(positions, t, 10**9, 'base_link',
                                                         taught_q), times=1)
        deadline = time.monotonic() + TIMEOUT
        while len(q := client.call(positions[0], positions[-1])[2]) == 0:
            assert time.monotonic() < deadline, server.log()
            client.spin_for(0.1)
    finally:
        assert client.set_parameters(teach_skill_name='taught', skill='G')[0].successful
    assert np.degrees(quat.angle_between(q[0], taught_q[0])) < 0.5
    assert np.degrees(quat.angle_between(q[-1], taught_q[-1])) < 0.5
    assert np.degrees(quat.angle_between(q[0], q[-1])) == pytest.approx(40.0, abs=0.5)


def test_obstacles_published_on_the_topic_are_avoided(server, client):
    _, free, _, _ = client.call(START, GOAL)
    # Two obstacles on the obstacle-free path, at the height of the scene's cylinders' tops,
    # without volumes: points, kept clear by the tool's radius and the safety margin.
    on_path = free[[60, 120]] + [0.0, 0.0, SCENE['obstacle']['height']]
    client.publish('obstacles', obstacles_msg(on_path))
    try:
        t, x, _, _ = client.call(START, GOAL)
        assert client.set_parameters(avoidance='paper')[0].successful
        t_paper, x_paper, _, _ = client.call(START, GOAL)
    finally:
        assert client.set_parameters(avoidance='detour')[0].successful
        client.publish('obstacles', obstacles_msg(np.zeros((0, 3))))
    size = np.ptp(PLANE.to_plane(free) * PLANE.scale, axis=0).max()
    assert clearance_2d(free, on_path) < 1e-9
    # The detour: the tool's radius and the margin kept, the timing the obstacle-free plan's.
    kept = SERVER['tool_radius'] + SERVER['obstacle_clearance']
    assert kept - 1e-6 <= clearance_2d(x, on_path) < kept + 0.02 * size
    assert t[-1] == pytest.approx(free_duration := 2.0) and len(t) == len(free)
    np.testing.assert_allclose(PLANE.distance(x), 0.0, atol=1e-9)
    assert np.linalg.norm(x[-1] - GOAL) < 1e-3
    np.testing.assert_allclose(
        x, core_plan('G', START, GOAL, on_path, obstacle_radii=np.full(2, kept / PLANE.scale))[1],
        atol=1e-9)
    # The paper's coupling on demand: its letters clear points by >= 5 % of their size, 1.5 tau.
    assert clearance_2d(x_paper, on_path) > 0.05 * size
    assert t_paper[-1] == pytest.approx(1.5 * free_duration)
    # obstacle_k is in 1/m (0: k_relative / |start - goal|); the core works in demo units.
    gains = ObstacleGains(gamma=SERVER['obstacle_gamma'], beta=SERVER['obstacle_beta'],
                          gamma2=SERVER['obstacle_gamma2'],
                          k=SERVER['obstacle_k'] * PLANE.scale or None,
                          k_relative=SERVER['obstacle_k_relative'])
    np.testing.assert_allclose(x_paper, core_plan('G', START, GOAL, on_path, gains=gains)[1],
                               atol=1e-9)
    # The empty PoseArray cleared them: back to the obstacle-free plan.
    np.testing.assert_allclose(client.call(START, GOAL)[1], free, atol=1e-12)


def test_a_plan_whose_arm_would_touch_an_obstacle_is_refused_naming_the_link(server, client):
    # A tall obstacle (a 40 cm bottle, radius 3 cm, as perception reports it: /etdmp/obstacles
    # and /etdmp/obstacle_volumes) where the first wrist passes half-way through the G: the
    # pen writes 0.1 m and more beside it, but the wrist would sweep through it.
    names = sorted(JOINT_NAMES)
    client.publish('joint_states', joint_state_msg(
        [Q_INIT[JOINT_NAMES.index(name)] for name in names], names=names))
    t, free, q, _ = client.call(START, GOAL)
    model = UR10Model(tool_offset=SCENE['tool_offset'])
    idx, joints, _ = plan_joints(model, free, quat.to_matrix(quat.normalized(q)), t, Q_INIT,
                                 32)
    half = len(idx) // 2
    wrist = ArmGeometry(model).joint_frames(joints[half])[0, 3, :3, 3]
    assert np.min(np.linalg.norm(free[:, :2] - wrist[:2], axis=1)) > 0.1
    top = np.array([[*wrist[:2], 0.4]])
    try:
        # Perceived obstacles while /etdmp/obstacle_volumes has a publisher (perception) but
        # no volume has come yet: not planned as points, refused as not there yet.
        client.publish('volumes', cylinder_markers(top, [0.03], 0), times=0)
        client.publish('obstacles', obstacles_msg(top))
        assert len(client.call(START, GOAL)[1]) == 0
        line = wait_for_log(server, 'no volume received yet on /etdmp/obstacle_volumes')
        assert '1 perceived obstacle(s)' in line, line
        client.publish('volumes', cylinder_markers(top, [0.03], 0))
        assert len(client.call(START, GOAL)[1]) == 0
        line = wait_for_log(server, 'the plan would bring the ', 'closer than arm_clearance')
        links = ('forearm_link', 'wrist_1_link', 'wrist_2_link')
        assert any(f'the {link} ' in line for link in links), line
        assert '(radius 30 mm)' in line, line
        print(line)
        # The same obstacle as short as the scene's (8 cm) stays below the wrist: planned.
        low = np.array([[*wrist[:2], 0.08]])
        client.publish('volumes', cylinder_markers(low, [0.03], 0))
        client.publish('obstacles', obstacles_msg(low))
        assert len(client.call(START, GOAL)[1]) > 100
        # check_arm false: the plan is not checked.
        client.publish('volumes', cylinder_markers(top, [0.03], 0))
        client.publish('obstacles', obstacles_msg(top))
        assert client.set_parameters(check_arm=False)[0].successful
        assert len(client.call(START, GOAL)[1]) > 100
    finally:
        assert client.set_parameters(check_arm=True)[0].successful
        client.publish('obstacles', obstacles_msg(np.zeros((0, 3))))
        client.publish('volumes', cylinder_markers(np.zeros((0, 3)), [], 0))


def test_static_obstacles_and_the_maximum_age(client):
    _, free, _, _ = client.call(START, GOAL)
    point = free[90]
    assert client.set_parameters(static_obstacles=point.tolist())[0].successful
    try:
        _, x, _, _ = client.call(START, GOAL)
    finally:
        assert client.set_parameters(static_obstacles=[])[0].successful
    assert clearance_2d(x, point) > 0.05 * np.ptp(free, axis=0).max()
    # A perceived obstacle older than obstacle_max_age is ignored.
    client.publish('obstacles', obstacles_msg(point))
    assert client.set_parameters(obstacle_max_age=0.3)[0].successful
    try:
        time.sleep(0.5)     # the subject: the obstacle grows older than its maximum age
        _, stale, _, _ = client.call(START, GOAL)
    finally:
        assert client.set_parameters(obstacle_max_age=60.0)[0].successful
        client.publish('obstacles', obstacles_msg(np.zeros((0, 3))))
    np.testing.assert_allclose(stale, free, atol=1e-12)


def test_empty_frames_use_the_tool_position_and_the_perceived_goal(client):
    tool = UR10Model(tool_offset=SCENE['tool_offset']).tool_position(Q_INIT)
    # Joint states in the UR driver's (alphabetical) order: matched by name.
    names = sorted(JOINT_NAMES)
    client.publish('joint_states', joint_state_msg(
        [Q_INIT[JOINT_NAMES.index(name)] for name in names], names=names))
    perceived = np.array(SCENE['goal_position'])
    client.publish('goal', PointStamped(header=BASE, point=point_msg(perceived)))
    _, x, _, _ = client.call(None, None, start_frame='', goal_frame='')
    # The same Pinocchio forward kinematics as the controller, projected onto the task plane.
    np.testing.assert_allclose(x[0], PLANE.from_plane(PLANE.to_plane(tool)), atol=1e-9)
    assert np.linalg.norm(x[-1] - PLANE.from_plane(PLANE.to_plane(perceived))) < 1e-3
    # The tool position may come from /etdmp/tool_pose instead.
    assert client.set_parameters(tool_position_source='tool_pose')[0].successful
    try:
        tool_pose = PoseStamped(header=BASE)
        tool_pose.pose.position = point_msg(START)
        client.publish('tool_pose', tool_pose)
        _, x, _, _ = client.call(None, GOAL, start_frame='')
    finally:
        assert client.set_parameters(tool_position_source='joint_states')[0].successful
    np.testing.assert_allclose(x[0], START, atol=1e-9)


def test_stale_tool_state_is_not_used(server, client):
    assert client.set_parameters(tool_state_max_age=0.2)[0].successful
    try:
        time.sleep(0.4)     # the subject: the tool state grows older than its maximum age
        assert len(client.call(None, GOAL, start_frame='')[1]) == 0
    finally:
        assert client.set_parameters(tool_state_max_age=60.0)[0].successful
    wait_for_log(server, 'tool position is unknown', 's old (tool_state_max_age 0.2 s)')


def point_msg(p):
    """Return a geometry_msgs/Point."""
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


BAD_REQUESTS = [
    ('NaN start', {'start': [math.nan, 0.2, 0.0], 'goal': GOAL}, ('start contains NaN',)),
    ('inf goal', {'start': START, 'goal': [0.7, math.inf, 0.0]}, ('goal contains NaN or inf',)),
    ('start frame', {'start': START, 'goal': GOAL, 'start_frame': 'map'},
     ("'map'", 'base_link')),
    ('goal frame', {'start': START, 'goal': GOAL, 'goal_frame': 'tool0'},
     ("'tool0'", 'base_link')),
    ('start = goal', {'start': GOAL, 'goal': GOAL + [0.0, 0.0, 0.05]}, ('start equals goal',)),
    ('out of reach', {'start': START, 'goal': [1.6, 0.2, 0.0]}, ('out of the UR10', 'reach')),
    ('under the base', {'start': START, 'goal': [0.05, 0.0, 0.0]}, ('reach', 'base axis')),
]


@pytest.mark.parametrize('what, kwargs, fragments', BAD_REQUESTS,
                         ids=[bad[0] for bad in BAD_REQUESTS])
def test_bad_request_gets_an_empty_plan_and_the_node_keeps_serving(
        server, client, what, kwargs, fragments):
    t, x, _, msg = client.call(**kwargs)
    assert len(x) == 0 and msg.header.frame_id == 'base_link'
    wait_for_log(server, '/generalize', *fragments)
    assert len(client.call(START, GOAL)[1]) == 201


def test_obstacle_on_the_goal_and_unknown_skill_fail_cleanly(server, client):
    client.publish('obstacles', obstacles_msg(GOAL + [0.005, 0.0, 0.08]))
    try:
        assert len(client.call(START, GOAL)[1]) == 0
    finally:
        client.publish('obstacles', obstacles_msg(np.zeros((0, 3))))
    wait_for_log(server, 'lies on the goal')
    assert client.set_parameters(skill='no_such_skill')[0].successful   # may be taught later
    try:
        assert len(client.call(START, GOAL)[1]) == 0
    finally:
        assert client.set_parameters(skill='G')[0].successful
    wait_for_log(server, "unknown skill 'no_such_skill'")
    assert len(client.call(START, GOAL)[1]) == 201
    assert server.process.poll() is None


def test_invalid_parameters_are_refused_with_a_reason(client):
    cases = {'method': ('rrt', 'method must be one of'),
             'task_plane.y_axis': ([1.0, 0.0, 0.0], 'orthogonal'),
             'static_obstacles': ([0.1, 0.2], 'multiple of 3'),
             'tool_orientation': ([0.0, 0.0, 0.0, 0.0], 'non-zero quaternion'),
             'teach_skill_name': ('../evil', 'not valid'),
             'duration': (-1.0, '')}     # outside the declared range: refused by rclpy
    for name, (value, reason) in cases.items():
        result = client.set_parameters(**{name: value})[0]
        assert not result.successful, name
        assert reason in result.reason, (name, result.reason)
    assert len(client.call(START, GOAL)[1]) == 201


def test_concurrent_calls_are_all_served(client):
    futures = [client.generalize.call_async(request(START + [0.01 * k, 0.0, 0.0], GOAL))
               for k in range(8)]
    for k, future in enumerate(futures):
        plan = client._result(future).plan
        _, x, _ = path_to_numpy(plan)
        np.testing.assert_allclose(x, core_plan('G', START + [0.01 * k, 0.0, 0.0], GOAL)[1],
                                   atol=1e-9)


def test_plans_are_published_for_the_controller_and_shown_as_markers(client):
    client.spin_for(0.3)
    _, x, _, msg = client.call(START, GOAL)
    client.spin_for(0.5)
    _, published, _ = path_to_numpy(client.paths[-1])
    np.testing.assert_allclose(published, x, atol=0)
    assert client.paths[-1].poses[-1].header.stamp == msg.poses[-1].header.stamp
    shown = {m.ns: m for m in client.markers[-1].markers}
    assert {'demo', 'plan_etdmp', 'plan_dmp', 'obstacles', 'start_goal'} <= set(shown)
    plan_points = np.array([(p.x, p.y, p.z) for p in shown['plan_etdmp'].points])
    np.testing.assert_allclose(plan_points, x, atol=1e-12)
    demo = np.array([(p.x, p.y, p.z) for p in shown['demo'].points])
    np.testing.assert_allclose(demo[[0, -1]], [START, GOAL], atol=1e-9)   # scaled into place
    assert all(m.header.frame_id == 'base_link' for m in shown.values())
    # execute: false plans without publishing.
    count = len(client.paths)
    assert client.set_parameters(execute=False)[0].successful
    try:
        assert len(client.call(START + [0.01, 0.0, 0.0], GOAL)[1]) == 201
        client.spin_for(0.5)
    finally:
        assert client.set_parameters(execute=True)[0].successful
    assert len(client.paths) == count


def letter_z(n=120):
    """Return a 'Z' stroke in base_link (n, 3), 10 cm wide, 4 cm above the task plane."""
    corners = np.array([[0.0, 0.10], [0.10, 0.10], [0.0, 0.0], [0.10, 0.0]])
    s = np.linspace(0.0, 3.0, n)
    xy = np.stack([np.interp(s, np.arange(4), corners[:, i]) for i in range(2)], axis=1)
    # Round the corners a little (a hand-drawn letter), keeping start and end.
    kernel = np.ones(7) / 7
    smooth = np.stack([np.convolve(np.pad(xy[:, i], 3, mode='edge'), kernel, 'valid')
                       for i in range(2)], axis=1)
    return np.column_stack([PLANE.origin[:2] + smooth, np.full(n, 0.04)])


def write_mcap(path, positions, t):
    """Record positions as geometry_msgs/PoseStamped on /tool_pose in a rosbag2 .mcap."""
    from mcap_ros2.writer import Writer
    from support.bags import POSE_STAMPED_MSGDEF
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        schema = writer.register_msgdef('geometry_msgs/msg/PoseStamped', POSE_STAMPED_MSGDEF)
        for k, (p, tk) in enumerate(zip(positions, t)):
            ns = int(1e9 + tk * 1e9)
            msg = {'header': {'stamp': {'sec': ns // 10**9, 'nanosec': ns % 10**9},
                              'frame_id': 'base_link'},
                   'pose': {'position': {'x': p[0], 'y': p[1], 'z': p[2]},
                            'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}}}
            writer.write_message('/tool_pose', schema, msg, log_time=ns, sequence=k)
        writer.finish()


def test_a_plan_in_execution_follows_the_moved_goal(server, client):
    # The plan of a request to the perceived goal is re-planned online when the goal moves: the
    # remainder is published on the plan's own time base (header stamp, pose stamps), starts
    # where the plan was (the tool here: its joint states do not move), ends at the new goal.
    # One message is not enough (a frame rendered while the marker moves); with follow_goal
    # false nothing is re-planned.
    def stamps(path):
        return np.array([p.header.stamp.sec * 10**9 + p.header.stamp.nanosec
                         for p in path.poses])
    client.publish('joint_states', joint_state_msg(Q_INIT))
    perceived = np.array(SCENE['goal_position'])
    client.publish('goal', PointStamped(header=BASE, point=point_msg(perceived)))
    del client.paths[:], client.events[:]
    _, x, _, plan = client.call(None, None, start_frame='', goal_frame='')
    assert len(x) > 100
    deadline = time.monotonic() + TIMEOUT
    while not client.paths:
        assert time.monotonic() < deadline, 'the plan was not published'
        client.spin_for(0.05)
    moved = perceived + [0.0, 0.04, 0.0]
    client.publish('goal', PointStamped(header=BASE, point=point_msg(moved)), times=1)
    client.spin_for(0.3)
    assert len(client.paths) == 1, 'one goal message was followed'
    client.publish('goal', PointStamped(header=BASE, point=point_msg(moved)), times=3)
    deadline = time.monotonic() + TIMEOUT
    while len(client.paths) < 2:
        assert time.monotonic() < deadline, f'the moved goal was not followed:\n{server.log()}'
        client.spin_for(0.05)
    new = client.paths[-1]
    assert new.header.stamp == plan.header.stamp
    _, y, _ = path_to_numpy(new)
    offset = (stamps(new)[0] - stamps(plan)[0]) / 1e9
    k = int(round(offset / 0.01))
    assert offset >= 0.0
    np.testing.assert_allclose(y[:5], x[k:k + 5], atol=1e-9)   # the remainder, from the plan
    assert np.linalg.norm(y[-1] - PLANE.from_plane(PLANE.to_plane(moved))) < 1e-3
    followed = client.wait_for_event('followed')
    np.testing.assert_allclose(followed.numbers('goal'), moved, atol=1e-9)
    assert followed.integer('poses') == len(y) and followed.integer('update') == 1
    assert followed.integer('stamp_ns') == plan.header.stamp.sec * 10**9 + \
        plan.header.stamp.nanosec
    assert followed.number('from_path_time_s') >= offset - 1e-9
    assert client.set_parameters(follow_goal=False)[0].successful
    try:
        client.publish('goal', PointStamped(header=BASE, point=point_msg(perceived)), times=4)
        client.spin_for(0.3)
        assert len(client.paths) == 2, 'followed with follow_goal false'
    finally:
        assert client.set_parameters(follow_goal=True)[0].successful


def test_a_plan_in_execution_follows_an_obstacle_that_appears(server, client):
    # An obstacle that appears on the rest of a plan in execution (three agreeing messages) is
    # avoided by the remainder, published on the plan's time base; it still ends at the goal.
    client.publish('joint_states', joint_state_msg(Q_INIT))
    client.publish('obstacles', obstacles_msg(np.zeros((0, 3))))
    perceived = np.array(SCENE['goal_position'])
    client.publish('goal', PointStamped(header=BASE, point=point_msg(perceived)))
    del client.paths[:], client.events[:]
    _, x, _, plan = client.call(None, None, start_frame='', goal_frame='')
    deadline = time.monotonic() + TIMEOUT
    while not client.paths:
        assert time.monotonic() < deadline, 'the plan was not published'
        client.spin_for(0.05)
    on_path = x[[int(0.6 * len(x))]] + [0.0, 0.0, SCENE['obstacle']['height']]
    assert clearance_2d(x, on_path) < 1e-9
    try:
        client.publish('obstacles', obstacles_msg(on_path), times=3)
        deadline = time.monotonic() + TIMEOUT
        while len(client.paths) < 2:
            assert time.monotonic() < deadline, f'the obstacle was not followed:\n{server.log()}'
            client.spin_for(0.05)
    finally:
        client.publish('obstacles', obstacles_msg(np.zeros((0, 3))))
    new = client.paths[-1]
    assert new.header.stamp == plan.header.stamp
    _, y, _ = path_to_numpy(new)
    size = np.ptp(PLANE.to_plane(x) * PLANE.scale, axis=0).max()
    assert clearance_2d(y, on_path) > 0.05 * size
    np.testing.assert_allclose(y[0], x[np.argmin(np.linalg.norm(x - y[0], axis=1))], atol=1e-9)
    assert np.linalg.norm(y[-1] - x[-1]) < 1e-3
    followed = client.wait_for_event('followed')
    assert len(followed.numbers('goal')) == 0       # the goal did not move: the obstacles did
    # As dmp_server plans with them: placed on the task plane.
    np.testing.assert_allclose(PLANE.to_plane(followed.numbers('obstacles').reshape(-1, 3)),
                               PLANE.to_plane(on_path), atol=1e-9)
    assert followed.integer('poses') == len(y)
    client.spin_for(0.5)    # the cleared obstacle set is followed too: back to no obstacle


def test_the_bottle_as_goal_object_plans_stirring_and_follows_the_moved_bottle(server, client):
    # goal_object bottle: an empty goal frame id means the perceived bottle mouth plus
    # goal_offset (the stir demonstration's goal below the mouth); the plan in execution
    # follows the bottle when it moves, and not the marker.
    mouth = np.array(SCENE['bottle']['position'] + [SCENE['bottle']['height']])
    demo = builtin_demo('stir')
    start = mouth + demo.start + [0.03, -0.02, 0.05]
    client.publish('bottle', PointStamped(header=BASE, point=point_msg(mouth)))
    assert client.set_parameters(skill='stir', goal_object='bottle',
                                 goal_offset=[float(v) for v in demo.goal])[0].successful
    try:
        del client.paths[:]
        t, x, _, plan = client.call(start, None, goal_frame='')
        assert len(x) > 100
        assert np.linalg.norm(x[-1] - (mouth + demo.goal)) < 1e-3
        assert nrmse(x, demo.positions) < 0.005
        deadline = time.monotonic() + TIMEOUT
        while not client.paths:
            assert time.monotonic() < deadline, 'the plan was not published'
            client.spin_for(0.05)
        # The marker moving is not the goal any more.
        client.publish('goal', PointStamped(header=BASE, point=point_msg(
            np.array(SCENE['goal_position']) + [0.0, 0.05, 0.0])), times=4)
        assert len(client.paths) == 1, 'the marker was followed with goal_object bottle'
        moved = mouth + [0.0, 0.02, 0.0]
        client.publish('bottle', PointStamped(header=BASE, point=point_msg(moved)), times=4)
        deadline = time.monotonic() + TIMEOUT
        while len(client.paths) < 2:
            assert time.monotonic() < deadline, f'the bottle was not followed:\n{server.log()}'
            client.spin_for(0.05)
        _, y, _ = path_to_numpy(client.paths[-1])
        assert np.linalg.norm(y[-1] - (moved + demo.goal)) < 1e-3
        for bad in ([0.0, 0.0], [0.0, math.nan, 0.0]):
            assert not client.set_parameters(goal_offset=bad)[0].successful
        assert not client.set_parameters(goal_object='cup')[0].successful
    finally:
        assert client.set_parameters(skill='G', goal_object='marker',
                                     goal_offset=[0.0, 0.0, 0.0])[0].successful


def test_teaching_at_runtime_survives_a_restart(colcon_install, ros_env, tmp_path):
    # Own domain (conftest's ros_env): the module's server must not answer here.
    skills_dir = tmp_path / 'skills'
    files = tmp_path / 'demos'
    files.mkdir()
    wave = np.column_stack([np.linspace(0.0, 8.0, 80), np.sin(np.linspace(0.0, 6.0, 80))])
    save_demo(files / 'wave.csv', Demonstration('wave', wave, np.linspace(0.0, 1.6, 80)))
    arc = np.column_stack([0.7 + 0.1 * np.cos(np.linspace(0, 2, 60)),
                           0.1 * np.sin(np.linspace(0, 2, 60)), np.linspace(0.1, 0.3, 60)])
    write_mcap(files / 'arc.mcap', arc, np.linspace(0.0, 1.2, 60))
    (files / 'broken.csv').write_text('x,y\n1,2\n')
    overrides = {'skills_dir': str(skills_dir), 'demo_files': [str(files)]}
    first = NodeProcess(colcon_install, ros_env, tmp_path, 'dmp_server', overrides, name='first')
    client = Client()
    try:
        client.wait_for_server(first)
        wait_for_log(first, 'broken.csv', 'demonstration not learned')
        # Files learned at start-up: a 2D CSV in demo units and a 3D .mcap recording. The shape
        # is kept: nRMSE against the demonstration's own reproduction below the core's bound.
        for name, demo in (('wave', Demonstration('wave', wave, np.linspace(0.0, 1.6, 80))),
                           ('arc', Demonstration('arc', arc, np.linspace(0.0, 1.2, 60)))):
            assert client.set_parameters(skill=name)[0].successful
            planar = demo.dim == 2
            start, goal = (START, GOAL) if planar else (arc[0] + [0.0, 0.05, 0.0], arc[-1])
            _, x, _, _ = client.call(start, goal)
            assert len(x), first.log()
            reproduction = learn(demo).reproduce().x
            assert nrmse(PLANE.to_plane(x) if planar else x, reproduction) < 0.005, name
        # Teach a 'Z' drawn 4 cm above the table: flat, so it becomes a 2D task-plane skill.
        z_path = letter_z()
        z_times = np.linspace(0.0, 2.4, len(z_path))
        taught = path_from_numpy(z_path, z_times, stamp=10**9)
        assert client.set_parameters(teach_skill_name='zed', skill='zed')[0].successful
        client.publish('demonstrations', taught, times=1)
        deadline = time.monotonic() + TIMEOUT
        while len(x := client.call(START, GOAL)[1]) == 0:
            assert time.monotonic() < deadline, first.log()
            client.spin_for(0.1)
        reproduction = learn(PLANE.to_plane(z_path), t=z_times).reproduce().x
        assert nrmse(PLANE.to_plane(x), reproduction) < 0.005
        np.testing.assert_allclose(PLANE.distance(x), 0.0, atol=1e-9)
        assert (skills_dir / 'zed.csv').is_file()
        # A bad demonstration is refused; what was learned stays.
        client.publish('demonstrations', path_from_numpy(z_path[:5]), times=1)
        wait_for_log(first, "demonstration for skill 'zed' rejected", '5 samples')
        np.testing.assert_allclose(client.call(START, GOAL)[1], x, atol=1e-12)
    finally:
        client.close()
        assert first.stop() == 0, first.log()
    second = NodeProcess(colcon_install, ros_env, tmp_path, 'dmp_server',
                         {'skills_dir': str(skills_dir), 'skill': 'zed'}, name='second')
    client = Client()
    try:
        client.wait_for_server(second)
        np.testing.assert_allclose(client.call(START, GOAL)[1], x, atol=1e-9)
    finally:
        client.close()
        assert second.stop() == 0, second.log()


@pytest.mark.parametrize('overrides, reason', [
    ({'method': 'rrt'}, 'method must be one of etdmp, dmp'),
    ({'output_period': 0.0}, 'output_period'),        # outside the declared range
])
def test_unusable_configuration_stops_the_node_with_the_reason(
        colcon_install, ros_env, tmp_path, overrides, reason):
    node = NodeProcess(colcon_install, ros_env, tmp_path, 'dmp_server', overrides, name='bad')
    try:
        assert node.process.wait(timeout=60) == 1
    finally:
        node.stop()
    log = node.log()
    assert '[FATAL]' in log and 'invalid parameter' in log and reason in log, log
    assert 'Traceback' not in log, log


def test_generalize_with_carries_its_skill_and_settings_in_the_request(client):
    # /generalize takes its skill and duration from parameters that every client shares; these
    # come in the request, and no parameter changes, planned or refused.
    client.publish('obstacles', obstacles_msg(np.zeros((0, 3))))
    before = client.get_parameters('skill', 'duration', 'execute', 'method')
    count = len(client.paths)
    ok, reason = client.ask('generalize_with', skill='W', duration=3.0, start=START.tolist(),
                            goal=GOAL.tolist())
    assert ok, reason
    assert reason == "planned skill 'W' (etdmp): 301 poses over 3.00 s, published on /etdmp/path"
    deadline = time.monotonic() + TIMEOUT
    while len(client.paths) == count:
        assert time.monotonic() < deadline, 'no /etdmp/path'
        client.spin_for(0.05)
    t, x, _ = path_to_numpy(client.paths[-1])
    t_core, x_core = core_plan('W', START, GOAL, tau=3.0)
    np.testing.assert_allclose(x, x_core, atol=1e-9)       # the W, not the parameter's G
    np.testing.assert_allclose(t, t_core, atol=1e-9)
    ok, reason = client.ask('generalize_with', method='dmp', execute=False,
                            start=[0.66, 0.10, 0.0], goal=GOAL.tolist())
    assert ok and reason.endswith('(execute false: not published)'), reason
    for arguments, fragment in (
            ({'skill': 'nope', 'start': START.tolist(), 'goal': GOAL.tolist()},
             "unknown skill 'nope'"),
            ({'skill': 'g', 'start': START.tolist(), 'goal': GOAL.tolist()},
             "unknown skill 'g' (did you mean 'G'?"),
            ({'duration': 0.5, 'start': START.tolist(), 'goal': GOAL.tolist()},
             'shortest feasible duration'),
            ({'duration': 700.0}, 'duration = 700 s is outside its range 0 to 600 s'),
            ({'method': 'spline'}, 'method must be one of etdmp, dmp'),
            ({'skil': 'W'}, "no argument 'skil'"),
            ({'execute': 1}, "argument 'execute' must be a bool"),
            ({'start': [0.8, 0.2], 'goal': GOAL.tolist()}, 'must be 3 numbers'),
            ({'start': [1e308, 0.0, 0.0]}, 'start[0] = 1e+308 m is outside its range')):
        ok, reason = client.ask('generalize_with', **arguments)
        assert not ok and fragment in reason, (arguments, reason)
    assert client.get_parameters('skill', 'duration', 'execute', 'method') == before


def test_teach_learns_the_skill_named_in_the_request(server, client):
    skills = FsPath(client.get_parameters('skills_dir')['skills_dir'])
    before = client.get_parameters('teach_skill_name', 'recorded_dim')
    n = 80
    s = np.linspace(0.0, 1.0, n)
    wave = np.column_stack([0.72 + 0.1 * s, 0.12 + 0.04 * np.sin(6.0 * s), np.zeros(n)])
    t = np.linspace(5.0, 6.6, n)    # any origin: times from the first sample
    ok, reason = client.ask('teach', name='svc_wave', t=t.tolist(),
                            positions=wave.ravel().tolist(), recorded_dim='2d')
    assert ok, reason
    assert reason.startswith("learned skill 'svc_wave' (2D, 80 samples) from /dmp_server/teach, "
                             f'saved to {skills / "svc_wave.csv"}'), reason
    saved = np.loadtxt(skills / 'svc_wave.csv', delimiter=',', skiprows=1)
    np.testing.assert_allclose(saved[:, 0], t - t[0], atol=1e-9)
    np.testing.assert_allclose(saved[:, 1:] * PLANE.scale, PLANE.to_plane(wave) * PLANE.scale,
                               atol=1e-9)
    ok, reason = client.ask('generalize_with', skill='svc_wave', execute=False,
                            start=START.tolist(), goal=GOAL.tolist())
    assert ok and "planned skill 'svc_wave'" in reason, reason
    # Refused with the reason; nothing saved, nothing replaced.
    for arguments, fragment in (
            ({'name': 'G'}, "skill 'G' exists already (built-in)"),
            ({'name': 'g'}, "'g' differs from the known skill 'G' (built-in) only in case"),
            ({'name': 'Svc_Wave'}, "differs from the known skill 'svc_wave'"),
            ({'name': '../x'}, "skill name '../x' is not valid"),
            ({'name': 'short', 't': t[:5].tolist(), 'positions': wave[:5].ravel().tolist()},
             'at least 10'),
            ({'name': 'odd', 'positions': wave.ravel()[:-1].tolist()},
             '80 times need 240 position values'),
            ({'name': 'far', 'positions': (wave * 1e308).ravel().tolist()},
             'is outside its range -100 to 100 m'),
            ({'name': 'many', 't': np.arange(20_001.0).tolist(),
              'positions': np.zeros(60_003).tolist()}, 'more than MAX_DEMO_SAMPLES = 20000'),
            ({'nme': 'typo'}, "no argument 'nme'")):
        given = {'t': t.tolist(), 'positions': wave.ravel().tolist(), **arguments}
        ok, reason = client.ask('teach', **given)
        assert not ok and fragment in reason, (arguments.get('name'), reason)
    saved = {p.stem for p in skills.iterdir()}
    assert 'svc_wave' in saved and not saved & {'G', 'g', 'Svc_Wave', 'short', 'odd', 'far',
                                                'many', 'typo'}, saved
    assert client.get_parameters('teach_skill_name', 'recorded_dim') == before
    wait_for_log(server, "taught demonstration for skill 'g' rejected")


def test_teaching_reports_its_result_as_an_event(client):
    # What dmp_server did with a taught demonstration is data on /dmp_server/events, whatever
    # its log line says: learned with the figures, or refused with the reason.
    n = 60
    s = np.linspace(0.0, 1.0, n)
    wave = np.column_stack([0.72 + 0.1 * s, 0.12 + 0.03 * np.sin(5.0 * s), np.zeros(n)])
    t = np.linspace(0.0, 1.2, n)
    client.spin_for(0.2)
    del client.events[:]
    ok, reason = client.ask('teach', name='evt_wave', t=t.tolist(),
                            positions=wave.ravel().tolist(), recorded_dim='2d')
    assert ok, reason
    learned = client.wait_for_event('learned')
    assert learned.node == 'dmp_server' and learned.level == events.OK
    assert learned.values['skill'] == 'evt_wave' and learned.integer('samples') == n
    assert learned.integer('dim') == 2 and learned.number('duration_s') == pytest.approx(1.2)
    assert learned.values['source'] == '/dmp_server/teach'
    assert learned.values['saved'].endswith('evt_wave.csv') and not learned.values['save_error']
    assert learned.message == reason
    ok, reason = client.ask('teach', name='evt_short', t=t[:5].tolist(),
                            positions=wave[:5].ravel().tolist())
    assert not ok
    refused = client.wait_for_event('refused')
    assert refused.level == events.ERROR and refused.values['skill'] == 'evt_short'
    assert 'at least 10' in refused.values['reason'] and refused.message == reason
    assert 'learned' not in {e.kind for e in client.events}

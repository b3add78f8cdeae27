"""
Two robots on one DDS domain, each in its own namespace: every name of the nodes is relative.

Two sets of ur10_sim (camera off), controller and dmp_server start from the colcon install in
``/robot1`` and ``/robot2`` (``--ros-args -r __ns:=/robotN``, as the launch file's
``namespace`` argument does, with ``/clock`` remapped to the robot's own ``clock``). A call of
``/robotN/generalize`` must move robot N's arm along its plan and leave the other arm where it
is; nothing may be published under the root names.
"""

import threading
import time

from etdmp_ros.ros import config_files, system
from etdmp_ros.ros.background import BackgroundNode
from etdmp_ros.ros.conversions import path_to_numpy, stamp_to_ns
from etdmp_ros.ros.processes import installed_argv, NodeProcess
from geometry_msgs.msg import PointStamped
from nav_msgs.srv import GetPlan
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from support.waiting import wait_for
import yaml

ROBOTS = ('/robot1', '/robot2')
PKG = 'etdmp_ros'
STARTUP = 90.0
#: Control rate of both robots (sim and controller): six processes share the machine.
RATE = 125.0
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: The arm that was not called may not move more than this (rad): it holds still in gravity.
STILL = 1e-4


def start_node(install, env, tmp, node, namespace, overrides=None):
    """
    Start installed ``node`` in ``namespace``, with the system's files and ``overrides``.

    A node's section of its file is keyed by its bare name, which rcl matches only in the root
    namespace (the launch file passes that section's values as parameters for the same
    reason): here they go, with the overrides, into a file keyed by the node's full name.
    """
    files = system.parameter_files(node, install / 'share' / PKG / 'config')
    values = config_files.read_parameter_file(files[-1], node)
    values.update(system.wiring_overrides(node), **(overrides or {}))
    tag = f'{namespace.strip("/")}_{node}'
    files.append(tmp / f'{tag}_overrides.yaml')
    files[-1].write_text(yaml.safe_dump({f'{namespace}/{node}': {'ros__parameters': values}}))
    argv = installed_argv(install, node, files, f'-r __ns:={namespace} -r /clock:=clock')
    return NodeProcess(argv, tmp / f'{tag}.log', dict(env, ROS_HOME=str(tmp / 'ros_home')))


class Client(BackgroundNode):
    """Records both robots' joint states, tool tips and controller status."""

    def __init__(self, domain):
        super().__init__('namespaces_test_client', domain)
        self.lock = threading.Lock()
        self.joints = {ns: [] for ns in ROBOTS}     # (stamp s, q)
        self.tips = {ns: [] for ns in ROBOTS}       # tool tip positions (ground truth)
        self.status = {ns: [] for ns in ROBOTS}
        self.generalize = {}
        n = self.node
        for ns in ROBOTS:
            n.create_subscription(JointState, f'{ns}/joint_states',
                                  lambda m, ns=ns: self._on_joints(ns, m), 100)
            n.create_subscription(PointStamped, f'{ns}/ur10_sim/ground_truth/tool_tip',
                                  lambda m, ns=ns: self._on_tip(ns, m), 100)
            n.create_subscription(String, f'{ns}/etdmp/controller/status',
                                  lambda m, ns=ns: self._on_status(ns, m), LATCHED)
            self.generalize[ns] = n.create_client(GetPlan, f'{ns}/generalize')
        self.start()

    def _on_joints(self, ns, msg):
        with self.lock:
            self.joints[ns].append((stamp_to_ns(msg.header.stamp) * 1e-9,
                                    np.array(msg.position)))

    def _on_tip(self, ns, msg):
        with self.lock:
            self.tips[ns].append(np.array([msg.point.x, msg.point.y, msg.point.z]))

    def _on_status(self, ns, msg):
        with self.lock:
            self.status[ns].append(msg.data.split(':')[0])

    def latest(self, ns):
        """Return robot ``ns``'s newest (stamp, q), tool tip and status."""
        with self.lock:
            return self.joints[ns][-1], self.tips[ns][-1], self.status[ns][-1]


@pytest.fixture(scope='module')
def robots(colcon_install, module_ros_env, tmp_path_factory):
    """Start three nodes per robot and the client; yield the client and the processes."""
    tmp = tmp_path_factory.mktemp('namespaces')
    processes = []
    for ns in ROBOTS:
        processes += [
            start_node(colcon_install, module_ros_env, tmp, 'ur10_sim', ns,
                       {'camera_rate': 0.0, 'control_rate': RATE}),
            start_node(colcon_install, module_ros_env, tmp, 'controller', ns,
                       {'control_rate': RATE, 'approach_speed': 0.25}),
            start_node(colcon_install, module_ros_env, tmp, 'dmp_server', ns)]
    client = Client(module_ros_env['ROS_DOMAIN_ID'])
    try:
        for ns in ROBOTS:
            wait_for(lambda: client.status[ns] and client.status[ns][-1] == 'idle'
                     and client.tips[ns], STARTUP, f'{ns} to be idle', processes)
            wait_for(lambda: client.generalize[ns].service_is_ready(), STARTUP,
                     f'{ns}/generalize', processes)
        # dmp_server says nothing when its first joint state arrives (it plans from the tool
        # position they give): no condition to wait on, a moment for its subscription to match
        # and receive (without it: "the tool position is unknown (none received yet)").
        time.sleep(1.0)
        yield client, processes
    finally:
        client.close()
        codes = [p.stop() for p in processes]
        assert codes == [0] * len(processes), '\n'.join(p.log() for p in processes)


def test_nothing_is_published_under_the_root_names(robots):
    client, _ = robots
    node = client.node
    for name in ('/joint_states', '/etdmp/path', '/forward_velocity_controller/commands',
                 '/ur10_sim/ground_truth/tool_tip', '/etdmp/controller/status'):
        assert node.count_publishers(name) == 0, name
    for ns in ROBOTS:
        assert node.count_publishers(f'{ns}/joint_states') == 1
        assert node.count_publishers(f'{ns}/forward_velocity_controller/commands') == 1
        assert node.count_subscribers(f'{ns}/forward_velocity_controller/commands') >= 1
        assert node.count_publishers(f'{ns}/etdmp/path') == 1
        assert node.count_publishers(f'{ns}/clock') == 1
    names = dict(node.get_service_names_and_types())
    assert '/generalize' not in names
    assert {f'{ns}/generalize' for ns in ROBOTS} <= set(names)
    assert {f'{ns}/controller/pause' for ns in ROBOTS} <= set(names)


@pytest.mark.parametrize('called', ROBOTS)
def test_each_generalize_moves_its_own_arm_only(robots, called):
    client, processes = robots
    other = ROBOTS[1 - ROBOTS.index(called)]
    goal = config_files.read_parameter_file(system.parameter_files('ur10_sim')[0])
    goal = goal['goal_position']
    (_, q_called), _, _ = client.latest(called)
    (_, q_other), _, _ = client.latest(other)
    with client.lock:
        n_status = len(client.status[called])
        n_other = len(client.joints[other])
        n_other_status = len(client.status[other])

    request = GetPlan.Request()
    request.goal.header.frame_id = 'base_link'
    request.goal.pose.position.x, request.goal.pose.position.y = goal[0], goal[1]
    future = client.generalize[called].call_async(request)
    wait_for(future.done, 30.0, f'{called}/generalize', processes)
    plan = future.result().plan
    _, positions, _ = path_to_numpy(plan)
    assert len(positions) > 100
    # The plan is stamped with the called robot's own simulated clock (/robotN/clock).
    (t_called, _), _, _ = client.latest(called)
    assert abs(stamp_to_ns(plan.header.stamp) * 1e-9 - t_called) < 1.0

    wait_for(lambda: 'tracking' in client.status[called][n_status:], 30.0,
             f'{called} to track', processes)
    wait_for(lambda: client.status[called][-1] not in ('approaching', 'tracking', 'holding'),
             120.0, f'{called} to finish', processes)
    (_, q_end), tip, status = client.latest(called)
    assert status == 'idle', client.status[called][n_status:]
    # The called arm moved and its tool tip ended where its plan ends.
    assert np.max(np.abs(q_end - q_called)) > 0.05
    assert np.linalg.norm(tip - positions[-1]) < 3e-3, (tip, positions[-1])
    # The other arm did not move, and its controller never left idle.
    with client.lock:
        q = np.array([q for _, q in client.joints[other][n_other:]])
        other_status = client.status[other][n_other_status:]
    assert len(q) > RATE   # more than a second of the other robot's joint states was seen
    drift = np.max(np.abs(q - q_other))
    print(f'{called}: moved {np.max(np.abs(q_end - q_called)):.3f} rad, tip '
          f'{np.linalg.norm(tip - positions[-1]) * 1e3:.2f} mm from the plan end; {other} '
          f'drifted {drift:.2e} rad')
    assert drift < STILL
    assert other_status == [] and client.latest(other)[2] == 'idle'

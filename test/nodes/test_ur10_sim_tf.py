"""
ur10_sim's /robot_description, /tf and /tf_static, as a UR driver + robot_state_publisher would.

The installed node runs (camera off) while this process commands joint velocities; the /tf and
/tf_static transforms, chained as a tf2 buffer would, must put the pen tip where the simulation's
ground truth says it is (MuJoCo, not the kinematics that made the transforms), and the camera's
optical frame at the ``camera`` pose parameter. Without tf2_msgs the node warns once and
publishes everything else.
"""

import threading
import time

from conftest import NodeProcess

from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.robot import chain_pose, JOINT_NAMES, Transform, UR10Model

from etdmp_ros.ros import system

from etdmp_ros.ros.background import BackgroundNode

from etdmp_ros.ros.config_files import read_parameter_file

from etdmp_ros.ros.conversions import stamp_to_ns, tf_available

from geometry_msgs.msg import PointStamped

import numpy as np
import pinocchio as pin
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile

from sensor_msgs.msg import JointState

from std_msgs.msg import Float64MultiArray, String

from support.waiting import wait_for


LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STARTUP = 60.0
RATE = 125.0
needs_tf2 = pytest.mark.skipif(not tf_available(), reason='tf2_msgs is not importable (not on '
                               'PyPI; make test builds it into .venv from ../shared/ros)')
#: Makes `import tf2_msgs` fail in the node's process: the no-tf2 path.
BLOCK_TF2 = ('import sys\n'
             'class _NoTf2:\n'
             '    def find_spec(self, name, path=None, target=None):\n'
             '        if name == "tf2_msgs" or name.startswith("tf2_msgs."):\n'
             '            raise ImportError("tf2_msgs blocked by the test")\n'
             'sys.meta_path.insert(0, _NoTf2())\n')


class Client(BackgroundNode):
    """Records /tf (by stamp), /tf_static, /robot_description and the true tool tip."""

    def __init__(self, tf):
        super().__init__('ur10_sim_tf_test_client')
        self.lock = threading.Lock()
        self.tf, self.static, self.tips, self.description = {}, [], {}, []
        n = self.node
        if tf:
            from tf2_msgs.msg import TFMessage
            n.create_subscription(TFMessage, '/tf', self._on_tf, 1000)
            n.create_subscription(TFMessage, '/tf_static', self._on_static, LATCHED)
        n.create_subscription(PointStamped, '/ur10_sim/ground_truth/tool_tip', self._on_tip,
                              1000)
        n.create_subscription(String, '/robot_description',
                              lambda m: self.description.append(m.data), LATCHED)
        self.joints = []
        n.create_subscription(JointState, '/joint_states', self.joints.append, 10)
        self.command = n.create_publisher(Float64MultiArray,
                                          '/forward_velocity_controller/commands', 10)
        self.start()

    def _on_tf(self, msg):
        with self.lock:
            for t in msg.transforms:
                self.tf.setdefault(stamp_to_ns(t.header.stamp), []).append(_transform(t))

    def _on_static(self, msg):
        with self.lock:
            self.static = [_transform(t) for t in msg.transforms]

    def _on_tip(self, msg):
        with self.lock:
            self.tips[stamp_to_ns(msg.header.stamp)] = np.array([msg.point.x, msg.point.y,
                                                                 msg.point.z])


def _transform(msg):
    t, r = msg.transform.translation, msg.transform.rotation
    return Transform(msg.header.frame_id, msg.child_frame_id, (t.x, t.y, t.z),
                     (r.x, r.y, r.z, r.w))


@pytest.fixture(scope='module')
def moving_sim(colcon_install, module_ros_env, tmp_path_factory):
    """Run ur10_sim while the joints turn at up to 0.5 rad/s; return (client, scene values)."""
    if not tf_available():
        pytest.skip('tf2_msgs is not importable (not on PyPI; make test builds it into .venv)')
    tmp = tmp_path_factory.mktemp('ur10_sim_tf')
    sim = NodeProcess(colcon_install, module_ros_env, tmp, 'ur10_sim',
                      {'camera_rate': 0.0, 'control_rate': RATE})
    client = Client(tf=True)
    try:
        wait_for(lambda: client.joints and client.static and client.description, STARTUP,
                 'joint states, /tf_static and /robot_description', [sim])
        with client.lock:
            client.tf.clear()
        start = time.monotonic()
        while time.monotonic() - start < 3.0:
            t = time.monotonic() - start
            qd = 0.5 * np.sin(2 * np.pi * 0.5 * t + np.arange(6))
            client.command.publish(Float64MultiArray(data=qd.tolist()))
            time.sleep(0.02)        # the subject: 3 s of motion, commanded at 50 Hz
        client.command.publish(Float64MultiArray(data=[0.0] * 6))
        wait_for(lambda: np.abs(client.joints[-1].velocity).max() < 1e-6, 10.0,
                 'the joints to stop', [sim])
        yield client
    finally:
        client.close()
        assert sim.stop() == 0, sim.log()


@needs_tf2
def test_tf_chain_puts_the_pen_tip_at_the_ground_truth_while_moving(moving_sim):
    c = moving_sim
    with c.lock:
        tf = dict(c.tf)
        tips = dict(c.tips)
        static = list(c.static)
    stamps = sorted(set(tf) & set(tips))
    assert len(stamps) > 2.0 * RATE      # most of the 3 s of movement, at the control rate
    errors, moved = [], []
    for stamp in stamps:
        assert sorted(t.child for t in tf[stamp]) == sorted(
            ['shoulder_link', 'upper_arm_link', 'forearm_link', 'wrist_1_link', 'wrist_2_link',
             'wrist_3_link'])
        p, _ = chain_pose(tf[stamp] + static, 'base_link', 'tool_tip')
        errors.append(np.linalg.norm(p - tips[stamp]))
        moved.append(tips[stamp])
    travel = np.ptp(np.array(moved), axis=0).max()
    print(f'/tf chain vs ground truth: max {max(errors) * 1e3:.4f} mm over {len(stamps)} '
          f'stamps; the tip moved {travel * 1e3:.0f} mm')
    assert travel > 0.05                 # it did move
    assert max(errors) < 1e-3
    # tool0 is a fixed frame of wrist_3_link (tf_static), as robot_state_publisher has it.
    assert {'tool0', 'tool_tip', 'camera_link', 'camera_color_optical_frame'} <= {
        t.child for t in static}


@needs_tf2
def test_camera_transform_is_the_camera_pose_parameter(moving_sim):
    scene = read_parameter_file(system.parameter_files('ur10_sim')[0])
    position, rotation = chain_pose(moving_sim.static, 'base_link', 'camera_color_optical_frame')
    np.testing.assert_allclose(position, scene['camera.position'], atol=1e-9)
    np.testing.assert_allclose(rotation,
                               quat.to_matrix(quat.normalized(scene['camera.orientation'])),
                               atol=1e-9)


@needs_tf2
def test_robot_description_is_the_urdf_with_the_model_joints_and_the_tool(moving_sim):
    urdf = moving_sim.description[-1]
    model = pin.buildModelFromXML(urdf)
    assert tuple(model.names[1:]) == JOINT_NAMES == tuple(UR10Model().model.names[1:])
    assert model.existFrame('tool_tip') and model.existFrame('tool0')
    scene = read_parameter_file(system.parameter_files('ur10_sim')[0])
    tool = model.frames[model.getFrameId('tool_tip')]
    flange = model.frames[model.getFrameId('tool0')]
    offset = (flange.placement.inverse() * tool.placement).translation
    np.testing.assert_allclose(offset, scene['tool_offset'], atol=1e-12)


def test_without_tf2_msgs_one_warning_and_no_tf(colcon_install, ros_env, tmp_path):
    block = tmp_path / 'block'
    block.mkdir()
    (block / 'sitecustomize.py').write_text(BLOCK_TF2)
    env = dict(ros_env, PYTHONPATH=f'{block}:{ros_env.get("PYTHONPATH", "")}')
    sim = NodeProcess(colcon_install, env, tmp_path, 'ur10_sim',
                      {'camera_rate': 0.0, 'control_rate': RATE})
    client = Client(tf=False)
    try:
        wait_for(lambda: len(client.joints) > 20 and client.description, STARTUP,
                 'joint states and /robot_description', [sim])
        time.sleep(1.0)     # the subject: no /tf publisher appears in the graph meanwhile
        assert client.node.count_publishers('/tf') == 0
        assert client.node.count_publishers('/tf_static') == 0
        assert client.node.count_publishers('/joint_states') == 1
        assert '<robot' in client.description[-1]
    finally:
        client.close()
        code = sim.stop()
    log = sim.log()
    assert code == 0, log
    assert log.count('tf2_msgs is not installed') == 1, log
    # The only warning: a stall of the loop is timing (a busy machine), not tf.
    warnings = [line for line in log.splitlines()
                if '[WARN]' in line and 'simulation loop stalled' not in line]
    assert len(warnings) == 1, log

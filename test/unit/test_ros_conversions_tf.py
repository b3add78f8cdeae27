"""
The robot's frame tree (ROS-free) and its TFMessage.

Kinematics against Pinocchio; the message bytes against the plain message rclpy builds.
"""

from etdmp_ros.robot import (camera_transforms, chain_pose, FrameTree, JOINT_NAMES,
                             robot_description, UR10Model)
from etdmp_ros.ros import system
from etdmp_ros.ros.conversions import MovingTransforms, ns_to_stamp, tf_available, tf_message
import numpy as np
import pinocchio as pin
import pytest

TOOL_OFFSET = (0.0, 0.0, 0.16)
RNG = np.random.default_rng(7)


@pytest.fixture(scope='module')
def tree():
    return FrameTree(robot_description(TOOL_OFFSET))


def test_frames_equal_pinocchio_forward_kinematics(tree):
    model = UR10Model(TOOL_OFFSET)
    for q in RNG.uniform(-3.0, 3.0, size=(20, 6)):
        np.testing.assert_allclose(tree.moving(q), tree.moving_reference(q), atol=1e-14)
        transforms = tree.transforms(q)
        for frame in ('shoulder_link', 'wrist_2_link', 'tool0', 'tool_tip'):
            p, r = chain_pose(transforms, 'base_link', frame)
            fp, fr = model.frame_pose(q, model.model.getFrameId(frame))
            np.testing.assert_allclose(p, fp, atol=1e-12)
            np.testing.assert_allclose(r, fr, atol=1e-12)


def test_description_has_the_model_joints_and_the_tool():
    model = pin.buildModelFromXML(robot_description(TOOL_OFFSET))
    assert tuple(model.names[1:]) == JOINT_NAMES
    tip = model.frames[model.getFrameId('tool_tip')].placement
    flange = model.frames[model.getFrameId('tool0')].placement
    np.testing.assert_allclose((flange.inverse() * tip).translation, TOOL_OFFSET, atol=1e-15)


def test_missing_joint_is_refused():
    with pytest.raises(ValueError, match='not in the URDF'):
        FrameTree(robot_description(), joint_names=JOINT_NAMES + ('gripper_joint',))


def test_camera_chain_is_the_camera_pose():
    pose = system.scene_config().camera_pose
    p, r = chain_pose(camera_transforms(pose), 'base_link', 'camera_color_optical_frame')
    np.testing.assert_allclose(p, pose.position, atol=1e-15)
    np.testing.assert_allclose(r, pose.rotation, atol=1e-12)
    # camera_link looks where the optical axis does (REP-103 x forward vs optical z forward).
    _, link = chain_pose(camera_transforms(pose), 'base_link', 'camera_link')
    np.testing.assert_allclose(link[:, 0], pose.rotation[:, 2], atol=1e-12)
    np.testing.assert_allclose(link[:, 2], -pose.rotation[:, 1], atol=1e-12)


@pytest.mark.skipif(not tf_available(), reason='tf2_msgs is not importable (not on PyPI)')
def test_moving_transforms_bytes_are_the_plain_message_serialized(tree):
    from rclpy.serialization import deserialize_message, serialize_message
    from tf2_msgs.msg import TFMessage
    moving = MovingTransforms(tree.parents, tree.children, tree.translations)
    n = len(tree.parents)
    for q, stamp_ns in zip(RNG.uniform(-3, 3, size=(5, 6)), (0, 1, 999_999_999, 12 * 10**9 + 5,
                                                             2**31 * 10**9 - 1)):
        stamp = ns_to_stamp(stamp_ns)
        data = moving.update(tree.moving(q), stamp.sec, stamp.nanosec)
        plain = tf_message(tree.transforms(q)[:n], stamp)
        assert len(data) == len(serialize_message(plain))
        back = deserialize_message(data, TFMessage)
        assert back == plain      # every field, floats bit for bit (padding bytes may differ)
        assert back.transforms[-1].header.stamp.nanosec == stamp.nanosec
        assert back.transforms[2].transform.rotation.w == pytest.approx(tree.moving(q)[2, 3])

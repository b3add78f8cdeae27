"""Image, CameraInfo, JointState and velocity-command conversions (messages, no ROS graph)."""

from etdmp_ros.geometry.camera import CameraIntrinsics
from etdmp_ros.robot import JOINT_NAMES
from etdmp_ros.ros.conversions import (camera_info_msg, image_from_msg, image_msg,
                                       intrinsics_from_camera_info, joint_state_arrays,
                                       joint_state_from_cdr, joint_state_msg, ns_to_stamp,
                                       velocity_command_array, velocity_command_msg)
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Float64MultiArray

RNG = np.random.default_rng(0)


@pytest.mark.parametrize('encoding, image', [
    ('rgb8', RNG.integers(0, 256, (48, 64, 3), dtype=np.uint8)),
    ('bgr8', RNG.integers(0, 256, (48, 64, 3), dtype=np.uint8)),
    ('mono8', RNG.integers(0, 256, (48, 64), dtype=np.uint8)),
    ('16UC1', RNG.integers(0, 65536, (48, 64), dtype=np.uint16)),
    ('32FC1', RNG.random((48, 64), dtype=np.float32)),
])
def test_image_round_trip_through_serialization(encoding, image):
    msg = image_msg(image, encoding, stamp=ns_to_stamp(1_500_000_000), frame_id='cam')
    assert (msg.height, msg.width, msg.encoding, msg.header.frame_id) == (48, 64, encoding, 'cam')
    assert msg.step == image[0].nbytes and len(msg.data) == image.nbytes
    assert msg.header.stamp.sec == 1 and msg.header.stamp.nanosec == 500_000_000
    back = image_from_msg(deserialize_message(serialize_message(msg), Image))
    assert back.dtype == image.dtype and np.array_equal(back, image)


def test_image_from_msg_is_a_view_and_handles_row_padding():
    image = RNG.integers(0, 65536, (4, 5), dtype=np.uint16)
    msg = image_msg(image, '16UC1')
    assert np.shares_memory(image_from_msg(msg), np.frombuffer(msg.data, dtype=np.uint8))
    padded = Image(height=4, width=5, encoding='16UC1', step=12)     # 2 padding bytes a row
    rows = [image[r].tobytes() + b'\xff\xff' for r in range(4)]
    padded.data = b''.join(rows)
    assert np.array_equal(image_from_msg(padded), image)
    swapped = Image(height=4, width=5, encoding='16UC1', step=10, is_bigendian=1)
    swapped.data = image.byteswap().tobytes()
    assert np.array_equal(image_from_msg(swapped), image)


@pytest.mark.parametrize('encoding, image, match', [
    ('rgb8', np.zeros((4, 5), np.uint8), 'shape'),
    ('rgb8', np.zeros((4, 5, 3), np.uint16), 'dtype'),
    ('16UC1', np.zeros((4, 5), np.float32), 'dtype'),
    ('16UC1', np.zeros((4, 5, 3), np.uint16), 'shape'),
    ('yuv422', np.zeros((4, 5), np.uint8), 'unsupported'),
    ('mono8', np.zeros((0, 5), np.uint8), 'shape'),
])
def test_image_msg_refuses_mismatched_arrays(encoding, image, match):
    with pytest.raises(ValueError, match=match):
        image_msg(image, encoding)


@pytest.mark.parametrize('fields, match', [
    ({'encoding': 'rgb8', 'step': 14, 'data': bytes(14 * 4)}, 'step'),
    ({'encoding': 'rgb8', 'step': 15, 'data': bytes(15 * 3)}, 'bytes'),
    ({'encoding': 'jpeg', 'step': 15, 'data': bytes(60)}, 'unsupported'),
])
def test_image_from_msg_refuses_inconsistent_messages(fields, match):
    msg = Image(height=4, width=5, **fields)
    with pytest.raises(ValueError, match=match):
        image_from_msg(msg)


def test_camera_info_round_trip():
    k = CameraIntrinsics.from_fovy(640, 480, 42.5)
    msg = camera_info_msg(k, stamp=ns_to_stamp(7), frame_id='camera_color_optical_frame')
    assert (msg.width, msg.height) == (640, 480)
    assert np.allclose(np.reshape(msg.k, (3, 3)), k.K)
    assert np.allclose(np.reshape(msg.p, (3, 4)), k.P)
    assert np.allclose(np.reshape(msg.r, (3, 3)), np.eye(3))
    assert intrinsics_from_camera_info(msg) == k
    msg.d = [0.1, 0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match='distortion'):
        intrinsics_from_camera_info(msg)


def test_joint_state_round_trip_and_reordering():
    q, qd = np.arange(6) * 0.1, np.arange(6) * -0.2
    msg = joint_state_msg(q, qd, stamp=ns_to_stamp(10))
    assert list(msg.name) == list(JOINT_NAMES)
    back_q, back_qd = joint_state_arrays(deserialize_message(serialize_message(msg), JointState))
    assert np.array_equal(back_q, q) and np.array_equal(back_qd, qd)
    # The UR driver publishes joints in alphabetical order: matched by name.
    order = np.argsort(JOINT_NAMES)
    shuffled = joint_state_msg(q[order], None, names=[JOINT_NAMES[i] for i in order])
    back_q, back_qd = joint_state_arrays(shuffled)
    assert np.array_equal(back_q, q) and back_qd is None


@pytest.mark.parametrize('frame', ['', 'a', 'ab', 'abc', 'base_link'])
@pytest.mark.parametrize('with_velocity', [False, True])
def test_joint_states_read_from_their_bytes_equal_rclpys(frame, with_velocity):
    # Every frame-id length puts the sequences at another alignment.
    order = np.argsort(JOINT_NAMES)
    q, qd = RNG.normal(size=6), RNG.normal(size=6)
    msg = joint_state_msg(q[order], qd[order] if with_velocity else None,
                          names=[JOINT_NAMES[i] for i in order],
                          stamp=ns_to_stamp(1_796_000_000_123_456_789))
    msg.header.frame_id = frame
    stamp, back_q, back_qd = joint_state_from_cdr(serialize_message(msg))
    assert stamp == 1_796_000_000_123_456_789
    assert np.array_equal(back_q, q)
    assert np.array_equal(back_qd, qd) if with_velocity else back_qd is None


def test_joint_states_from_bytes_refuse_what_the_arrays_refuse():
    for bad, match in ((joint_state_msg(np.zeros(3), names=['a', 'b', 'c']), 'lacks'),
                       (JointState(name=list(JOINT_NAMES), position=[0.0] * 5), '5 positions'),
                       (joint_state_msg(np.full(6, np.nan)), 'NaN')):
        with pytest.raises(ValueError, match=match):
            joint_state_from_cdr(serialize_message(bad))
    with pytest.raises(ValueError):
        joint_state_from_cdr(serialize_message(joint_state_msg(np.zeros(6)))[:40])


def test_joint_states_from_bytes_look_names_up_by_their_bytes():
    # The same names again: the order remembered (also the refusal), each message read anew.
    junk = serialize_message(joint_state_msg(np.zeros(3), names=['a', 'b', 'c']))
    for _ in range(2):
        with pytest.raises(ValueError, match=r"lacks joints .* \(has \['a', 'b', 'c'\]\)"):
            joint_state_from_cdr(junk)
    order = [5, 3, 1, 0, 2, 4]
    names = [JOINT_NAMES[i] for i in order]
    for k in range(3):
        q = np.arange(6.0) + k
        data = serialize_message(joint_state_msg(q[order], names=names))
        _, back, _ = joint_state_from_cdr(data)
        assert np.array_equal(back, q)
    # Asked for other names, the same bytes give another answer.
    _, two, _ = joint_state_from_cdr(junk.replace(b'a\x00', b'x\x00'), names=['c', 'x'])
    assert np.array_equal(two, [0.0, 0.0])
    # More distinct name lists than are kept: each still read right.
    for n in range(70):
        one = joint_state_msg([float(n)], names=[f'joint_{n}'])
        assert joint_state_from_cdr(serialize_message(one), names=[f'joint_{n}'])[1] == [n]


def test_joint_state_arrays_refuses_bad_messages():
    good = joint_state_msg(np.zeros(6), np.zeros(6))
    missing = joint_state_msg(np.zeros(5), names=JOINT_NAMES[:5])
    with pytest.raises(ValueError, match='lacks'):
        joint_state_arrays(missing)
    short = JointState(name=list(JOINT_NAMES), position=[0.0] * 5)
    with pytest.raises(ValueError, match='5 positions'):
        joint_state_arrays(short)
    good.velocity[2] = float('nan')
    with pytest.raises(ValueError, match='NaN'):
        joint_state_arrays(good)


def test_velocity_command_round_trip_and_validation():
    qd = np.array([0.1, -0.2, 0.3, 0.0, 0.5, -0.6])
    msg = deserialize_message(serialize_message(velocity_command_msg(qd)), Float64MultiArray)
    assert np.array_equal(velocity_command_array(msg), qd)
    for bad in ([0.1] * 5, [0.1] * 7, [], [0.0] * 5 + [float('inf')]):
        with pytest.raises(ValueError):
            velocity_command_array(Float64MultiArray(data=bad))

"""Geometry conversions: the Path builder and its bytes agree with rclpy's own messages."""

from etdmp_ros.ros.conversions import (ns_to_stamp, path_from_cdr, path_from_numpy, path_to_numpy,
                                       points_from_numpy, pose_array_from_numpy,
                                       pose_array_to_numpy, serialize_path, stamp_to_ns)
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion
from nav_msgs.msg import Path
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

RNG = np.random.default_rng(4)
X = RNG.uniform(-1.0, 1.0, (501, 3))
T = np.arange(501) * 0.01
Q = (0.1, -0.2, 0.3, 0.9)
STAMP = 1_795_453_000 * 10**9 + 123_456_789


def reference_path(positions, t, stamp, frame_id, q):
    """Build the Path the ordinary way: constructors and attribute assignment."""
    path = Path(header=Header(stamp=ns_to_stamp(stamp), frame_id=frame_id))
    for p, tk in zip(positions, t):
        pose = PoseStamped()
        pose.header.frame_id = frame_id
        pose.header.stamp = ns_to_stamp(stamp + int(round(tk * 1e9)))
        pose.pose.position = Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))
        pose.pose.orientation = Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])
        path.poses.append(pose)
    return path


def test_path_builder_equals_the_ordinary_build():
    built = path_from_numpy(X, T, STAMP, 'base_link', Q)
    assert built == reference_path(X, T, STAMP, 'base_link', Q)
    assert serialize_message(built) is not None
    assert path_from_numpy(X[:7], T[:7], STAMP, 'map', Q) == \
        reference_path(X[:7], T[:7], STAMP, 'map', Q)
    assert points_from_numpy(X[:3]) == [Point(x=a, y=b, z=c) for a, b, c in X[:3].tolist()]


@pytest.mark.parametrize('n', [0, 1, 2, 501])
@pytest.mark.parametrize('frame_id', ['base_link', '', 'ab', 'abc', 'abcd', 'wörld'])
def test_cdr_bytes_deserialize_to_the_built_path(n, frame_id):
    data = serialize_path(X[:n], T[:n], STAMP, frame_id, Q)
    built = path_from_numpy(X[:n], T[:n], STAMP, frame_id, Q)
    assert deserialize_message(data, Path) == built
    # Same size as rclpy's serializer (only its padding bytes are uninitialised there).
    assert len(data) == len(serialize_message(built))


def test_path_round_trip_keeps_relative_times_exactly():
    t, x, q = path_to_numpy(path_from_numpy(X, T, STAMP, 'base_link', Q))
    np.testing.assert_array_equal(x, X)
    np.testing.assert_allclose(t, T, atol=1e-9)      # epoch-sized stamps, ns precision
    np.testing.assert_allclose(q, np.tile(Q, (501, 1)))
    assert path_to_numpy(Path())[1].shape == (0, 3)
    untimed = path_from_numpy(X[:3], stamp=7)
    assert [stamp_to_ns(p.header.stamp) for p in untimed.poses] == [7, 7, 7]
    assert untimed.poses[0].pose.orientation == Quaternion()


def test_path_builder_refuses_bad_shapes():
    with pytest.raises(ValueError, match=r'shape \(n, 3\)'):
        path_from_numpy(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r't must have shape \(4,\)'):
        serialize_path(np.zeros((4, 3)), np.zeros(3))
    with pytest.raises(ValueError, match='orientation'):
        path_from_numpy(np.zeros((1, 3)), orientation=(0, 0, 1))


def test_pose_arrays_and_stamps():
    msg = pose_array_from_numpy(X[:4], stamp=ns_to_stamp(STAMP))
    assert msg.header.frame_id == 'base_link' and stamp_to_ns(msg.header.stamp) == STAMP
    np.testing.assert_array_equal(pose_array_to_numpy(msg), X[:4])
    assert all(p.orientation == Pose().orientation for p in msg.poses)
    assert pose_array_to_numpy(pose_array_from_numpy(np.zeros((0, 3)))).shape == (0, 3)
    assert ns_to_stamp(-1).sec == -1 and ns_to_stamp(-1).nanosec == 999_999_999


def test_cdr_bytes_read_back_by_the_controller_reader():
    # /etdmp/path is published as these bytes; the controller reads raw bytes with path_from_cdr.
    frame, pose_frames, stamps, positions, quaternions = path_from_cdr(
        serialize_path(X, T, STAMP, 'base_link', Q))
    assert frame == 'base_link' and pose_frames == {'base_link'}
    np.testing.assert_array_equal(stamps - STAMP, np.round(T * 1e9).astype(np.int64))
    np.testing.assert_array_equal(positions, X)
    np.testing.assert_array_equal(quaternions, np.tile(Q, (len(X), 1)))


def unit_quaternions(n, seed=5):
    """Return ``n`` random unit quaternions (n, 4), (x, y, z, w)."""
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@pytest.mark.parametrize('n', [1, 2, 501])
@pytest.mark.parametrize('frame_id', ['base_link', 'abc', 'wörld'])
def test_per_pose_orientations_in_the_built_path_and_its_bytes(n, frame_id):
    qs = unit_quaternions(n)
    built = path_from_numpy(X[:n], T[:n], STAMP, frame_id, qs)
    reference = reference_path(X[:n], T[:n], STAMP, frame_id, Q)
    for pose, q in zip(reference.poses, qs.tolist()):
        pose.pose.orientation = Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])
    assert built == reference
    data = serialize_path(X[:n], T[:n], STAMP, frame_id, qs)
    assert deserialize_message(data, Path) == built
    expected = serialize_message(built)
    assert len(data) == len(expected)
    # Byte for byte where rclpy writes bytes: its padding is left unset, ours is zero.
    written = np.frombuffer(data, np.uint8) != np.frombuffer(expected, np.uint8)
    assert np.all(np.frombuffer(data, np.uint8)[written] == 0)
    _, _, _, positions, quaternions = path_from_cdr(data)
    np.testing.assert_array_equal(positions, X[:n])
    np.testing.assert_array_equal(quaternions, qs)
    with pytest.raises(ValueError, match=r'orientations must have shape'):
        serialize_path(X[:n], T[:n], STAMP, frame_id, qs[:n - 1] if n > 1 else qs[:0])

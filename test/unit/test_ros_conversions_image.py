"""
Image conversions: the reader of serialized images agrees with rclpy's own serialization.

And what perception accepts from a camera: encodings it names, this host's byte order, a
pinhole camera matrix in camera_info.
"""

import sys

from builtin_interfaces.msg import Time
from etdmp_ros.geometry.camera import CameraIntrinsics
from etdmp_ros.ros.conversions import (camera_image_from_msg, camera_info_msg, ENCODINGS,
                                       header_stamp_ns, image_from_cdr, image_from_msg, image_msg,
                                       intrinsics_from_camera_info)
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Image

RNG = np.random.default_rng(7)


def example(encoding, height=5, width=7):
    """Return a random image of ``encoding`` (shape and dtype as image_msg wants them)."""
    dtype, channels = ENCODINGS[encoding]
    shape = (height, width, channels) if channels > 1 else (height, width)
    if np.dtype(dtype).kind == 'f':
        return RNG.uniform(-10.0, 10.0, shape).astype(dtype)
    return RNG.integers(0, np.iinfo(dtype).max, shape, endpoint=True).astype(dtype)


@pytest.mark.parametrize('encoding', sorted(ENCODINGS))
@pytest.mark.parametrize('frame_id', ['', 'camera_color_optical_frame', 'abc'])
def test_cdr_reader_equals_rclpy_deserialization(encoding, frame_id):
    msg = image_msg(example(encoding), encoding, stamp=Time(sec=12, nanosec=345),
                    frame_id=frame_id)
    data = serialize_message(msg)
    pixels = image_from_cdr(data)
    expected = image_from_msg(deserialize_message(data, Image))
    assert pixels.dtype == expected.dtype and pixels.shape == expected.shape
    np.testing.assert_array_equal(pixels, expected)
    assert header_stamp_ns(data) == 12_000_000_345


def test_padded_rows_and_the_other_byte_order():
    # Rows padded beyond their pixels (step > width * 2) and big-endian 16-bit data.
    depth = example('16UC1', 4, 3)
    msg = Image(height=4, width=3, encoding='16UC1', is_bigendian=1, step=8)
    rows = np.zeros((4, 4), dtype='>u2')
    rows[:, :3] = depth
    msg.data = rows.tobytes()
    data = serialize_message(msg)
    np.testing.assert_array_equal(image_from_cdr(data), depth)
    np.testing.assert_array_equal(image_from_cdr(data),
                                  image_from_msg(deserialize_message(data, Image)))


def test_a_full_camera_frame_is_read_without_copying():
    rgb = example('rgb8', 480, 640)
    data = serialize_message(image_msg(rgb, 'rgb8'))
    pixels = image_from_cdr(data)
    np.testing.assert_array_equal(pixels, rgb)
    assert not pixels.flags.owndata and not pixels.flags.writeable


@pytest.mark.parametrize('cut', [0, 3, 20, -1])
def test_bytes_that_are_no_image_are_refused(cut):
    data = serialize_message(image_msg(example('mono8'), 'mono8', frame_id='cam'))
    with pytest.raises(ValueError):
        image_from_cdr(data[:cut] if cut >= 0 else b'\x07' + data[1:])


def test_an_unsupported_encoding_is_refused_as_by_image_from_msg():
    msg = Image(height=1, width=1, encoding='yuv422', step=2, data=b'\x00\x00')
    with pytest.raises(ValueError, match='unsupported image encoding'):
        image_from_cdr(serialize_message(msg))


def test_camera_images_in_the_other_byte_order_are_refused():
    """is_bigendian = 1 on 16-bit depth (the attack: little-endian data flagged big): refused."""
    depth = example('16UC1', 4, 3)
    msg = image_msg(depth, '16UC1')
    np.testing.assert_array_equal(camera_image_from_msg(msg, ('16UC1',)), depth)
    assert msg.is_bigendian == int(sys.byteorder == 'big')
    msg.is_bigendian = int(not msg.is_bigendian)
    # The plain conversion trusts the flag and swaps the bytes: 1.1 m would read 20 m ...
    np.testing.assert_array_equal(image_from_msg(msg), depth.byteswap())
    # ... the camera reader refuses it, naming the flag.
    with pytest.raises(ValueError, match=r'16UC1 image flagged \w+-endian \(is_bigendian = '):
        camera_image_from_msg(msg, ('16UC1',))
    # 8-bit pixels have no byte order: the flag does not matter.
    rgb = example('rgb8', 2, 2)
    msg = image_msg(rgb, 'rgb8')
    msg.is_bigendian = 1
    np.testing.assert_array_equal(camera_image_from_msg(msg, ('rgb8', 'bgr8')), rgb)
    with pytest.raises(ValueError, match="image encoding 'rgb8', expected 16UC1 or mono16"):
        camera_image_from_msg(msg, ('16UC1', 'mono16'))


@pytest.mark.parametrize('index, value', [(1, 5.0), (3, 0.1), (6, 1.0), (7, -2.0), (8, 0.0),
                                          (8, 2.0), (0, float('nan')), (4, -617.0)])
def test_a_camera_matrix_that_is_no_pinhole_one_is_refused(index, value):
    """Skew, a last row other than [0, 0, 1], NaN, a negative focal length: ValueError."""
    k = CameraIntrinsics.from_fovy(640, 480, 42.5)
    msg = camera_info_msg(k)
    assert intrinsics_from_camera_info(msg) == k
    matrix = list(msg.k)
    matrix[index] = value
    msg.k = matrix
    with pytest.raises(ValueError, match='not a pinhole camera matrix'):
        intrinsics_from_camera_info(msg)

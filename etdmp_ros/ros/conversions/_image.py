"""
sensor_msgs/Image <-> numpy and CameraInfo <-> :class:`CameraIntrinsics` (no cv_bridge).

Fast paths: pixel data goes into the message as ONE ``array.array('B')`` copy of the numpy
buffer, which rclpy takes as it is. Any other sequence (``arr.tobytes()``, a list) is checked
element by element when rclpy's field checks are on (``ROS_PYTHON_CHECK_FIELDS=1``): ~100 ms
for a 640x480 rgb8 frame instead of ~0.1 ms (test/benchmarks/bench_sim.py measures both).
:func:`image_from_msg` returns a zero-copy numpy view of ``msg.data``; :func:`image_from_cdr` the
same from the serialized bytes a ``raw=True`` subscription hands over, without the message
(rclpy's deserialization of a 640x480 frame costs a millisecond and a copy).
"""

from __future__ import annotations

import array
from collections.abc import Collection
import sys
from typing import Any, cast

from builtin_interfaces.msg import Time
from etdmp_ros.geometry.camera import CameraIntrinsics
import numpy as np
from numpy.typing import ArrayLike, NDArray
from sensor_msgs.msg import CameraInfo, Image

from ._cdr import Bytes, CdrReader

# encoding -> (dtype, channels); the encodings a RealSense driver and OpenCV users exchange.
ENCODINGS: dict[str, tuple[type[np.generic], int]] = {
    'rgb8': (np.uint8, 3),
    'bgr8': (np.uint8, 3),
    'mono8': (np.uint8, 1),
    '16UC1': (np.uint16, 1),
    'mono16': (np.uint16, 1),
    '32FC1': (np.float32, 1),
}
_BIG_ENDIAN_HOST = sys.byteorder == 'big'


def _encoding(encoding: str) -> tuple[type[np.generic], int]:
    try:
        return ENCODINGS[encoding]
    except KeyError:
        raise ValueError(f'unsupported image encoding {encoding!r}; supported: '
                         f'{", ".join(ENCODINGS)}') from None


def image_msg(image: ArrayLike, encoding: str, stamp: Time | None = None, frame_id: str = ''
              ) -> Image:
    """
    Return a sensor_msgs/Image holding ``image`` (H, W) or (H, W, C) in ``encoding``.

    The dtype and channel count must match the encoding exactly (rgb8/bgr8: uint8 (H, W, 3);
    mono8: uint8 (H, W); 16UC1/mono16: uint16 (H, W); 32FC1: float32 (H, W)): nothing is
    converted silently. ``stamp``: a builtin_interfaces/Time. Raises ValueError.
    """
    dtype, channels = _encoding(encoding)
    pixels = np.asarray(image)
    if pixels.dtype != dtype:
        raise ValueError(f'{encoding} needs dtype {np.dtype(dtype).name}, got {pixels.dtype}')
    shape_ok = (pixels.ndim == 3 and pixels.shape[2] == channels) if channels > 1 else \
        (pixels.ndim == 2 or (pixels.ndim == 3 and pixels.shape[2] == 1))
    if not shape_ok or pixels.shape[0] < 1 or pixels.shape[1] < 1:
        expected = f'(H, W, {channels})' if channels > 1 else '(H, W)'
        raise ValueError(f'{encoding} needs an image of shape {expected}, got {pixels.shape}')
    pixels = np.ascontiguousarray(pixels)
    msg = Image()
    if stamp is not None:
        msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(pixels.shape[0]), int(pixels.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = int(_BIG_ENDIAN_HOST and pixels.dtype.itemsize > 1)
    msg.step = msg.width * channels * pixels.dtype.itemsize
    data = array.array('B')
    # numpy declares no buffer protocol (__buffer__) to type checkers before Python 3.12.
    data.frombytes(cast(Any, pixels.reshape(-1).view(np.uint8)))
    msg.data = data
    return msg


def image_from_msg(msg: Image) -> NDArray[Any]:
    """
    Return the pixels of a sensor_msgs/Image as numpy (H, W) or (H, W, C) (see ENCODINGS).

    A view of ``msg.data`` without copying when the byte order is the host's (copy it before
    changing it if the message is kept elsewhere). Raises ValueError for an unsupported encoding
    or sizes that do not fit (step shorter than a row, data shorter than step * height).
    """
    return _pixels(msg.encoding, int(msg.height), int(msg.width), int(msg.step),
                   bool(msg.is_bigendian), msg.data)


def camera_image_from_msg(msg: Image, encodings: Collection[str]) -> NDArray[Any]:
    """
    Return the pixels of an Image from a camera driver, as :func:`image_from_msg` does.

    Raises ValueError unless ``msg.encoding`` is one of ``encodings`` and 16-bit or wider pixels
    are in this host's byte order: ROS 2 runs on little-endian hosts only, so a RealSense driver
    never sends ``is_bigendian = 1``; such a flag (or the data) is wrong, and swapping the bytes
    as it asks turned 1.1 m into 20 m.
    """
    if msg.encoding not in encodings:
        raise ValueError(f'image encoding {msg.encoding!r}, expected {" or ".join(encodings)}')
    dtype, _ = _encoding(msg.encoding)
    if np.dtype(dtype).itemsize > 1 and bool(msg.is_bigendian) != _BIG_ENDIAN_HOST:
        order = 'big' if msg.is_bigendian else 'little'
        raise ValueError(f'{msg.encoding} image flagged {order}-endian (is_bigendian = '
                         f'{int(msg.is_bigendian)}) on this {sys.byteorder}-endian host: no '
                         'camera driver sends that, the flag or the data is wrong')
    return image_from_msg(msg)


def image_from_cdr(data: Bytes) -> NDArray[Any]:
    """
    Return the pixels of a serialized sensor_msgs/Image, as :func:`image_from_msg` would.

    ``data``: the CDR bytes (a ``raw=True`` subscription's message). A read-only view of
    ``data`` without copying when the byte order is the host's. Raises ValueError for bytes
    that are not an Image, an unsupported encoding or sizes that do not fit.
    """
    reader = CdrReader(data)
    reader.int32(), reader.uint32(), reader.string()     # header: stamp, frame_id
    height, width = reader.uint32(), reader.uint32()
    encoding = reader.string()
    bigendian = bool(reader.uint8())
    step = reader.uint32()
    return _pixels(encoding, height, width, step, bigendian, reader.byte_sequence())


def _pixels(encoding: str, height: int, width: int, step: int, bigendian: bool,
            data: Bytes | array.array[int]) -> NDArray[Any]:
    kind, channels = _encoding(encoding)
    dtype = np.dtype(kind)
    row_bytes = width * channels * dtype.itemsize
    if height < 1 or width < 1:
        raise ValueError(f'empty image: {width}x{height}')
    if step < row_bytes:
        raise ValueError(f'image step {step} is shorter than a row of {width} {encoding} '
                         f'pixels ({row_bytes} bytes)')
    if len(data) < step * height:
        raise ValueError(f'image data has {len(data)} bytes, {encoding} {width}x{height} '
                         f'with step {step} needs {step * height}')
    raw = np.frombuffer(data, dtype=np.uint8, count=step * height).reshape(height, step)
    pixels = raw[:, :row_bytes]
    if step % dtype.itemsize == 0:
        pixels = raw.view(dtype)[:, :width * channels]
    else:   # rows not aligned to the pixel type: one copy
        pixels = np.ascontiguousarray(pixels).view(dtype)
    if dtype.itemsize > 1 and bigendian != _BIG_ENDIAN_HOST:
        pixels = pixels.byteswap()
    return pixels.reshape(height, width, channels) if channels > 1 else pixels


def camera_info_msg(intrinsics: CameraIntrinsics, stamp: Time | None = None,
                    frame_id: str = '') -> CameraInfo:
    """Return the sensor_msgs/CameraInfo of an undistorted pinhole :class:`CameraIntrinsics`."""
    msg = CameraInfo()
    if stamp is not None:
        msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.width, msg.height = int(intrinsics.width), int(intrinsics.height)
    msg.distortion_model = 'plumb_bob'
    msg.d = [0.0] * 5
    msg.k = intrinsics.K.ravel().tolist()
    msg.r = np.eye(3).ravel().tolist()
    msg.p = intrinsics.P.ravel().tolist()
    return msg


def intrinsics_from_camera_info(msg: CameraInfo) -> CameraIntrinsics:
    """
    Return the :class:`CameraIntrinsics` of a sensor_msgs/CameraInfo (from K and the size).

    Raises ValueError if K is not a pinhole camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0,
    1]]`` (finite, fx and fy positive, no skew: nothing here would apply one) or distortion is
    non-zero (the images would need undistorting first). Whether the values are plausible for
    the camera is the caller's check (:func:`etdmp_ros.perception._frames.check_intrinsics`).
    """
    k = np.asarray(msg.k, dtype=float).reshape(-1)
    if k.size != 9 or not np.all(np.isfinite(k)) or k[0] <= 0 or k[4] <= 0 or \
            np.any(k[[1, 3, 6, 7]] != 0) or k[8] != 1:
        raise ValueError(f'camera_info K is not a pinhole camera matrix [fx, 0, cx, 0, fy, cy, '
                         f'0, 0, 1]: {k.tolist()}')
    if len(msg.d) and np.any(np.asarray(msg.d, dtype=float) != 0):
        raise ValueError(f'camera_info has distortion {list(msg.d)}: undistort the images first')
    return CameraIntrinsics(int(msg.width), int(msg.height), float(k[0]), float(k[4]),
                            float(k[2]), float(k[5]))

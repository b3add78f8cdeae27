"""
sensor_msgs/CompressedImage from a serialized sensor_msgs/Image, as image_transport names it.

``compressed_image_transport`` publishes ``<image topic>/compressed``: colour as JPEG with the
format ``"rgb8; jpeg compressed bgr8"``, single-channel 16-bit (depth in mm) as lossless PNG
with ``"16UC1; png compressed "``. :func:`compress_image_cdr` turns the bytes a ``raw=True``
subscription kept into the bytes of that message (header copied), without rclpy messages;
:func:`compressed_image_from_cdr` decodes one back to numpy.
"""

from __future__ import annotations

import struct
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ._cdr import Bytes, CdrReader
from ._image import image_from_cdr

#: The topic image_transport's compressed plugin publishes beside ``topic``.
COMPRESSED_SUFFIX = '/compressed'
COMPRESSED_IMAGE_TYPE = 'sensor_msgs/msg/CompressedImage'


def _header(data: Bytes) -> tuple[int, int, str, str]:
    """Return (sec, nanosec, frame_id, encoding) of a serialized Image."""
    reader = CdrReader(data)
    sec, nanosec, frame_id = reader.int32(), reader.uint32(), reader.string()
    reader.uint32(), reader.uint32()                        # height, width
    return sec, nanosec, frame_id, reader.string()


def _string(out: bytearray, text: str) -> None:
    out += b'\x00' * (-(len(out) - 4) % 4)
    raw = text.encode() + b'\x00'
    out += struct.pack('<I', len(raw)) + raw


def compressed_image_cdr(sec: int, nanosec: int, frame_id: str, image_format: str,
                         payload: Bytes) -> bytes:
    """Return the CDR bytes (little endian) of a sensor_msgs/CompressedImage."""
    out = bytearray(b'\x00\x01\x00\x00') + struct.pack('<iI', sec, nanosec)
    _string(out, frame_id)
    _string(out, image_format)
    out += b'\x00' * (-(len(out) - 4) % 4)
    out += struct.pack('<I', len(payload)) + bytes(payload)
    return bytes(out)


def compress_image_cdr(data: Bytes, jpeg_quality: int = 90, png_level: int = 1) -> bytes:
    """
    Return the serialized CompressedImage of a serialized Image (``data``: its CDR bytes).

    rgb8 / bgr8 / mono8: JPEG of ``jpeg_quality``; 16UC1 / mono16: PNG (lossless) of
    ``png_level`` with zlib's run-length strategy (a 640x480 simulated depth image: 16 KB in
    about 6 ms, a quarter smaller than the default strategy, as fast). Raises ValueError for
    other encodings.
    """
    sec, nanosec, frame_id, encoding = _header(data)
    pixels: Any = image_from_cdr(data)
    if encoding in ('rgb8', 'bgr8', 'mono8'):
        if encoding == 'rgb8':
            pixels = cv2.cvtColor(np.ascontiguousarray(pixels), cv2.COLOR_RGB2BGR)
        ok, encoded = cv2.imencode('.jpg', np.ascontiguousarray(pixels),
                                   [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        image_format = f'{encoding}; jpeg compressed ' + ('mono8' if encoding == 'mono8'
                                                          else 'bgr8')
    elif encoding in ('16UC1', 'mono16'):
        ok, encoded = cv2.imencode('.png', np.ascontiguousarray(pixels),
                                   [cv2.IMWRITE_PNG_COMPRESSION, int(png_level),
                                    cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE])
        image_format = f'{encoding}; png compressed '
    else:
        raise ValueError(f'no compression for image encoding {encoding!r}')
    if not ok:
        raise ValueError(f'OpenCV could not compress a {encoding} image')
    return compressed_image_cdr(sec, nanosec, frame_id, image_format, encoded.tobytes())


def compressed_image_from_cdr(data: Bytes) -> tuple[int, str, NDArray[Any]]:
    """
    Return (stamp ns, format, pixels) of a serialized CompressedImage.

    Pixels as the original Image held them: colour (H, W, 3) in the original's channel order
    (rgb8 or bgr8), 16-bit images as uint16 (H, W).
    """
    reader = CdrReader(data)
    sec, nanosec = reader.int32(), reader.uint32()
    reader.string()                                          # frame_id
    image_format = reader.string()
    payload = np.frombuffer(reader.byte_sequence(), dtype=np.uint8)
    pixels: Any = cv2.imdecode(payload, cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise ValueError(f'could not decode a {image_format!r} compressed image')
    if image_format.split(';')[0].strip() == 'rgb8' and pixels.ndim == 3:
        pixels = cv2.cvtColor(pixels, cv2.COLOR_BGR2RGB)
    return sec * 1_000_000_000 + nanosec, image_format, pixels

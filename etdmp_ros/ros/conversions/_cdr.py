r"""
What can be read from a serialized (CDR) message without deserializing it.

A subscription created with ``raw=True`` hands over the message's bytes: keeping them costs
nothing, while rclpy's conversion into Python objects costs tens of microseconds per small
message and milliseconds per image. Recorders keep the bytes and decode later; this reads the
one field they need at once: the stamp of a message that starts with a std_msgs/Header
(4-byte encapsulation header ``\x00\x01`` little endian or ``\x00\x00`` big endian, then
int32 sec and uint32 nanosec).

:class:`CdrReader` reads the fields of a plain message one after the other (XCDR1, as Fast DDS
writes it: each primitive aligned to its size relative to the start of the payload, after the
encapsulation header); the image reader (:func:`image_from_cdr`) is built on it.
"""

from __future__ import annotations

import importlib
import struct
from typing import Any

from etdmp_ros.geometry.arrays import Array
import numpy as np

#: Serialized message bytes (rclpy gives bytes; views of them are read too).
Bytes = bytes | bytearray | memoryview


def message_class(type_name: str) -> type:
    """
    Return the Python class of a ROS message type name (``pkg/msg/Name`` or ``pkg/Name``).

    What the graph reports (``get_topic_names_and_types``); ValueError naming the type when its
    package is not installed here or has no such message.
    """
    package, *middle, name = type_name.split('/')
    if middle not in ([], ['msg']) or not package or not name:
        raise ValueError(f'not a message type name: {type_name!r}')
    try:
        return getattr(importlib.import_module(f'{package}.msg'), name)
    except (ImportError, AttributeError):
        raise ValueError(f'{type_name} is not installed here') from None


def header_stamp_ns(data: Bytes) -> int:
    """Return the header stamp (integer ns) of a serialized message that starts with a Header."""
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        raise ValueError('not a CDR-encoded message with a header')
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    return int(sec * 1_000_000_000 + nanosec)


class CdrReader:
    """
    Read the fields of a serialized (CDR) message in order: ``uint32()``, ``string()``, ....

    Offsets are payload-relative (after the 4-byte encapsulation header). Raises ValueError on
    bytes that are not CDR or end too early.
    """

    def __init__(self, data: Bytes) -> None:
        """Check the encapsulation header; position the reader at the payload's first byte."""
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise ValueError('not a CDR-encoded message (bad encapsulation header)')
        self.data = data
        self.order = '<' if data[1] == 1 else '>'
        self.offset = 0

    def _unpack(self, fmt: str, size: int) -> Any:
        self.offset += -self.offset % size
        try:
            (value,) = struct.unpack_from(self.order + fmt, self.data, 4 + self.offset)
        except struct.error:
            raise ValueError('serialized message ends too early') from None
        self.offset += size
        return value

    def int32(self) -> int:
        """Return the next int32."""
        return self._unpack('i', 4)

    def uint32(self) -> int:
        """Return the next uint32."""
        return self._unpack('I', 4)

    def uint8(self) -> int:
        """Return the next uint8."""
        return self._unpack('B', 1)

    def string(self) -> str:
        """Return the next string: uint32 length (with the NUL), the bytes, the NUL."""
        length = self.uint32()
        start = 4 + self.offset
        if length == 0 or start + length > len(self.data):
            raise ValueError('malformed string in serialized message')
        self.offset += length
        return bytes(self.data[start:start + length - 1]).decode('utf-8', errors='replace')

    def skip_string(self) -> None:
        """Step over the next string (see :meth:`string`) without decoding it."""
        length = self.uint32()
        if length == 0 or 4 + self.offset + length > len(self.data):
            raise ValueError('malformed string in serialized message')
        self.offset += length

    def byte_sequence(self) -> memoryview:
        """Return the next sequence<uint8> as a memoryview of the data (no copy)."""
        length = self.uint32()
        start = 4 + self.offset
        if start + length > len(self.data):
            raise ValueError(f'serialized sequence of {length} bytes is longer than the message')
        self.offset += length
        return memoryview(self.data)[start:start + length]

    def float64_sequence(self, limit: int | None = None) -> Array:
        """
        Return the next sequence<float64> as a numpy array (a copy, native byte order).

        ``limit``: the most elements accepted (ValueError beyond it, before anything is read).
        """
        length = self.uint32()
        if limit is not None and length > limit:
            raise ValueError(f'serialized sequence of {length} numbers, more than {limit}')
        if length:
            self.offset += -self.offset % 8
        start = 4 + self.offset
        if start + 8 * length > len(self.data):
            raise ValueError(f'serialized sequence of {length} numbers is longer than the message')
        self.offset += 8 * length
        return np.frombuffer(self.data, dtype=self.order + 'f8', count=length,
                             offset=start).astype(float)

"""
tf2_msgs/TFMessage of :class:`etdmp_ros.robot.Transform` lists (what a tf broadcaster sends).

``tf2_msgs`` is imported here only: callers check :func:`tf_available` first (it is not on PyPI,
so an install may lack it; ur10_sim then publishes no /tf).
"""

from __future__ import annotations

from collections.abc import Iterable
import struct
from typing import Any

from builtin_interfaces.msg import Time
from etdmp_ros.geometry.arrays import Array
from geometry_msgs.msg import TransformStamped


def tf_available() -> bool:
    """Return whether tf2_msgs can be imported."""
    try:
        import tf2_msgs.msg  # noqa: F401
    except ImportError:
        return False
    return True


def _transform_msg(parent: str, child: str, translation: Iterable[float],
                   quaternion: Iterable[float], stamp: Time | None) -> TransformStamped:
    msg = TransformStamped()
    if stamp is not None:
        msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    t = msg.transform.translation
    t.x, t.y, t.z = (float(v) for v in translation)
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = (float(v) for v in quaternion)
    return msg


def tf_message(transforms: Iterable[Any], stamp: Time | None) -> Any:
    """Return a TFMessage of ``transforms`` (:class:`Transform` list), all stamped ``stamp``."""
    from tf2_msgs.msg import TFMessage
    return TFMessage(transforms=[_transform_msg(t.parent, t.child, t.translation, t.quaternion,
                                                stamp) for t in transforms])


class MovingTransforms:
    """
    The TFMessage of transforms whose translations are fixed and rotations move (joint frames).

    Its bytes (CDR) are made once by rclpy's serializer from a plain :func:`tf_message`; then
    :meth:`update` only writes the stamps and quaternions into them, where serializing that
    message with marker values found them, and the node publishes the bytes (CDR's layout
    depends only on the frame names, which do not change). Building and publishing the six
    TransformStamped messages per tick took ~80 us of CPU (500 Hz: 4 % of a core), this takes
    ~10 us. The plain message is the reference: test/unit/test_ros_conversions_tf.py deserializes
    these bytes and compares them with it, field for field.
    """

    def __init__(self, parents: Iterable[str], children: Iterable[str],
                 translations: Iterable[Iterable[float]]) -> None:
        """Serialize the message once and find where each stamp and rotation lies in it."""
        from rclpy.serialization import serialize_message
        transforms = [_Fixed(p, c, t) for p, c, t in zip(parents, children, translations)]
        msg = tf_message(transforms, None)
        for i, m in enumerate(msg.transforms):   # markers: values no other field holds
            m.header.stamp.sec, m.header.stamp.nanosec = _SEC_MARK + i, _NSEC_MARK + i
            r = m.transform.rotation
            r.x, r.y, r.z, r.w = (_ROTATION_MARK + 4 * i + k for k in range(4))
        data = serialize_message(msg)
        if data[:2] != b'\x00\x01':
            raise RuntimeError('TFMessage is not serialized as little-endian CDR')
        self._offsets: list[tuple[int, int]] = []
        for i in range(len(transforms)):
            stamp = _find(data, struct.pack('<iI', _SEC_MARK + i, _NSEC_MARK + i))
            marks = (_ROTATION_MARK + 4 * i + k for k in range(4))
            rotation = _find(data, struct.pack('<4d', *marks))
            self._offsets.append((stamp, rotation))
        # The bytes of the plain message (CDR padding is not always zeroed, so not the markers').
        self._buffer = bytearray(serialize_message(tf_message(transforms, None)))
        if len(self._buffer) != len(data):
            raise RuntimeError('the serialized TFMessage changed size with its values')

    def update(self, quaternions: Array, sec: int, nanosec: int) -> bytes:
        """Return the message's bytes with rotations ``quaternions`` (n, 4) and the stamp."""
        buffer = self._buffer
        for (stamp, rotation), q in zip(self._offsets, quaternions.tolist()):
            _STAMP.pack_into(buffer, stamp, sec, nanosec)
            _ROTATION.pack_into(buffer, rotation, *q)
        return bytes(buffer)


_STAMP = struct.Struct('<iI')
_ROTATION = struct.Struct('<4d')
_SEC_MARK, _NSEC_MARK, _ROTATION_MARK = 0x5EC0000, 0x2EC0000, 1234.56789


def _find(data: bytes, marker: bytes) -> int:
    """Return the one offset of ``marker`` in ``data``; RuntimeError if not exactly one."""
    offset = data.find(marker)
    if offset < 0 or data.find(marker, offset + 1) >= 0:
        raise RuntimeError('cannot locate a field in the serialized TFMessage')
    return offset


class _Fixed:
    """A transform without rotation yet (for :class:`MovingTransforms`)."""

    def __init__(self, parent: str, child: str, translation: Iterable[float]) -> None:
        """Keep the frames and the translation; the rotation is the identity."""
        self.parent, self.child, self.translation = parent, child, translation
        self.quaternion = (0.0, 0.0, 0.0, 1.0)

r"""
What can be read from a serialized (CDR) message without deserializing it.

A subscription created with ``raw=True`` hands over the message's bytes: keeping them costs
nothing, while rclpy's conversion into Python objects costs tens of microseconds per small
message and milliseconds per image. Recorders keep the bytes and decode later; this reads the
one field they need at once: the stamp of a message that starts with a std_msgs/Header
(4-byte encapsulation header ``\x00\x01`` little endian or ``\x00\x00`` big endian, then
int32 sec and uint32 nanosec).
"""

import struct


def header_stamp_ns(data):
    """Return the header stamp (integer ns) of a serialized message that starts with a Header."""
    if len(data) < 12 or data[0] != 0 or data[1] not in (0, 1):
        raise ValueError('not a CDR-encoded message with a header')
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    return sec * 1_000_000_000 + nanosec

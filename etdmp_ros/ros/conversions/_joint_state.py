"""
sensor_msgs/JointState <-> arrays, and the UR joint velocity command (std_msgs/Float64MultiArray).

Joint states are matched by NAME (the UR driver publishes them in alphabetical order, not in
UR order); commands are positional, in UR joint order (``JOINT_NAMES``), as the UR ROS 2
driver's ``forward_velocity_controller`` expects.
"""

from __future__ import annotations

import array
from collections.abc import Sequence, Sized
from typing import Any, cast

from builtin_interfaces.msg import Time
from etdmp_ros.geometry.arrays import Array
from etdmp_ros.limits import MAX_JOINT_STATE_JOINTS
from etdmp_ros.robot import JOINT_NAMES
import numpy as np
from numpy.typing import ArrayLike
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ._cdr import Bytes, CdrReader


def _doubles(values: ArrayLike) -> array.array[float]:
    data = array.array('d')
    # numpy declares no buffer protocol (__buffer__) to type checkers before Python 3.12.
    data.frombytes(cast(Any, np.ascontiguousarray(values, dtype=np.float64).reshape(-1)
                        .view(np.uint8)))
    return data


def joint_state_msg(positions: ArrayLike, velocities: ArrayLike | None = None,
                    efforts: ArrayLike | None = None, names: Sequence[str] = JOINT_NAMES,
                    stamp: Time | None = None) -> JointState:
    """
    Return a sensor_msgs/JointState for ``names`` (default: the UR10's, in UR order).

    ``stamp``: a builtin_interfaces/Time (e.g. ``ns_to_stamp(t_ns)``), or None for zero.
    """
    msg = JointState()
    if stamp is not None:
        msg.header.stamp = stamp
    msg.name = list(names)
    msg.position = _doubles(positions)
    if velocities is not None:
        msg.velocity = _doubles(velocities)
    if efforts is not None:
        msg.effort = _doubles(efforts)
    return msg


def _check_lengths(n: int, position: Sized, velocity: Sized) -> None:
    if len(position) != n or len(velocity) not in (0, n):
        raise ValueError(f'joint state has {n} names, {len(position)} positions and '
                         f'{len(velocity)} velocities')


def _order(joint_names: Sequence[str], names: Sequence[str]) -> list[int]:
    """Return the indices of ``names`` in a joint state's ``joint_names``; ValueError if absent."""
    index = {name: i for i, name in enumerate(joint_names)}
    missing = [name for name in names if name not in index]
    if missing:
        shown = list(joint_names) if len(joint_names) <= 12 else list(joint_names[:12]) + ['...']
        raise ValueError(f'joint state lacks joints {missing} (has {shown})')
    return [index[name] for name in names]


#: What :func:`_order` said of the serialized names of recent joint states, per names asked
#: for: a publisher sends the same names every time, so a joint state costs one lookup of its
#: names' bytes, not their decoding (a flood of joint states for other joints: 3 instead of 10
#: microseconds each on an AMD EPYC). Emptied when it holds :data:`_ORDERS_KEPT` of them.
_ORDERS: dict[tuple[str, ...], dict[bytes, list[int] | str]] = {}
_ORDERS_KEPT = 64


def _cached_order(reader: CdrReader, n: int, names: Sequence[str]) -> list[int]:
    """:func:`_order` of the ``n`` names at ``reader``, which steps over them."""
    start = reader.offset
    for _ in range(n):
        reader.skip_string()
    seen = _ORDERS.setdefault(tuple(names), {})
    key = bytes(reader.data[4 + start:4 + reader.offset])
    order = seen.get(key)
    if order is None:
        end, reader.offset = reader.offset, start
        try:
            order = _order([reader.string() for _ in range(n)], names)
        except ValueError as exc:
            order = str(exc)
        reader.offset = end
        if len(seen) >= _ORDERS_KEPT:
            seen.clear()
        seen[key] = order
    if isinstance(order, str):
        raise ValueError(order)
    return order


def _picked(position: ArrayLike, velocity: Sequence[float] | Array, order: list[int]
            ) -> tuple[Array, Array | None]:
    positions = np.asarray(position, dtype=float)[order]
    velocities = np.asarray(velocity, dtype=float)[order] if len(velocity) else None
    if not np.all(np.isfinite(positions)) or \
            (velocities is not None and not np.all(np.isfinite(velocities))):
        raise ValueError('joint state holds NaN or infinite values')
    return positions, velocities


def joint_state_arrays(msg: JointState, names: Sequence[str] = JOINT_NAMES
                       ) -> tuple[Array, Array | None]:
    """
    Return ``(positions, velocities)`` of ``names`` from a JointState, reordered to ``names``.

    ``velocities`` is None if the message has none. Raises ValueError if a joint is missing,
    the arrays' lengths disagree with ``name`` or a value is not finite.
    """
    _check_lengths(len(msg.name), msg.position, msg.velocity)
    return _picked(msg.position, msg.velocity, _order(msg.name, names))


def joint_state_from_cdr(data: Bytes, names: Sequence[str] = JOINT_NAMES
                         ) -> tuple[int, Array, Array | None]:
    """
    Return ``(stamp_ns, positions, velocities)`` of ``names`` from a serialized JointState.

    What :func:`joint_state_arrays` returns, read from the bytes (a ``raw=True`` subscription)
    without building message objects: a few microseconds, so that a flood of joint states for
    other joints costs little (their names are checked before anything else is read). Raises
    ValueError like it, and on malformed bytes or more than
    :data:`~etdmp_ros.limits.MAX_JOINT_STATE_JOINTS` joints.
    """
    reader = CdrReader(data)
    sec, nanosec = reader.int32(), reader.uint32()
    reader.skip_string()                                # frame_id
    n = reader.uint32()
    if n > MAX_JOINT_STATE_JOINTS:
        raise ValueError(f'joint state names {n} joints, more than {MAX_JOINT_STATE_JOINTS}')
    order = _cached_order(reader, n, names)
    position = reader.float64_sequence(MAX_JOINT_STATE_JOINTS)
    velocity = reader.float64_sequence(MAX_JOINT_STATE_JOINTS)
    _check_lengths(n, position, velocity)
    positions, velocities = _picked(position, velocity, order)
    return sec * 1_000_000_000 + nanosec, positions, velocities


def velocity_command_msg(velocities: ArrayLike) -> Float64MultiArray:
    """Return the Float64MultiArray command of joint velocities (rad/s, UR joint order)."""
    msg = Float64MultiArray()
    msg.data = _doubles(velocities)
    return msg


def velocity_command_array(msg: Float64MultiArray, size: int = len(JOINT_NAMES)
                           ) -> Array:
    """Return the velocities (size,) of a Float64MultiArray command; ValueError if malformed."""
    data = np.asarray(msg.data, dtype=float)
    if data.shape != (size,):
        raise ValueError(f'velocity command must have {size} values (UR joint order), '
                         f'got {data.size}')
    if not np.all(np.isfinite(data)):
        raise ValueError(f'velocity command must be finite, got {data.tolist()}')
    return data

"""
What a node reports happened, as data: ``~/events`` (diagnostic_msgs/DiagnosticArray).

A log line is for people: its wording may change. What a program needs to know (a skill was
taught or refused, a path was published, accepted or tracked with these figures, the
simulation stalled) each node also publishes on its ``~/events`` topic, one
DiagnosticArray per event holding one DiagnosticStatus:

- ``name``: ``<node>: <kind>`` (diagnostic_updater's ``node: task`` form), the kind one of
  the node's documented events (docs/ros.md#events), e.g. ``dmp_server: followed``;
- ``level``: OK, WARN or ERROR, as the log line's severity;
- ``message``: the log line's text, for people;
- ``values``: the facts as key-value pairs, the keys documented with the event; numbers in
  Python's shortest round-trip form, several numbers (a point, points) separated by spaces,
  flags ``true`` / ``false``; always ``wall_clock_ns``, the wall clock when it happened (ns
  since the epoch, the clock ``/rosout`` stamps log lines with and the demo's recorder stamps
  receipts with), so that latencies between processes can be measured;
- ``header.stamp``: the node's clock (the simulation's under ``use_sim_time``).

The topic is latched (transient local, the last :data:`HISTORY` events), so a recorder that
finds it late still gets what happened at start-up. Reliable: none is lost to a slow reader.
The human log lines stay as they were; nothing reads their text.
"""

from collections.abc import Iterable
from dataclasses import dataclass, field
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from etdmp_ros.geometry.arrays import Array
from etdmp_ros.ros import qos, topics
import numpy as np

#: The levels of DiagnosticStatus, as ints.
OK, WARN, ERROR = (int.from_bytes(level, 'little') for level in (
    DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR))
#: Events kept for subscribers that join late.
HISTORY = 100
#: The value every event carries: the wall clock (ns since the epoch) when it happened.
WALL_CLOCK = 'wall_clock_ns'
TYPE_NAME = 'diagnostic_msgs/msg/DiagnosticArray'


def _text(value: Any) -> str:
    """Return a value as an event's text (see the module docstring)."""
    if isinstance(value, (bool, np.bool_)):
        return 'true' if value else 'false'
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, str):
        return value
    return ' '.join(_text(v) for v in np.asarray(value).ravel().tolist())


class EventPublisher:
    """
    A node's ``~/events`` publisher (:meth:`publish`).

    An event is handed to the transport before :meth:`publish` returns (rmw_fastrtps publishes
    synchronously by default), so a node may exit right after publishing its last one. Waiting
    for the readers' acknowledgements instead (``wait_for_all_acked``) would cost every exit
    up to Fast DDS's heartbeat period: its reliable readers acknowledge on the writer's
    heartbeat, every 3 s by default (measured here: acknowledged 2.0 to 2.7 s after the
    publish), and a wait of 0.5 s at the simulation's and the camera's exits ran out nearly
    every time, adding a second to every stop without making delivery surer.
    """

    def __init__(self, node: Any, topic: str = topics.EVENTS) -> None:
        """Create the latched publisher on ``node``."""
        self._node = node
        self._publisher = node.create_publisher(DiagnosticArray, topic, qos.latched(HISTORY))

    def publish(self, kind: str, message: str = '', level: int = OK, **values: Any) -> None:
        """
        Publish one event: ``kind``, the human ``message``, its ``level``, its facts ``values``.

        Values: numbers, flags, text, or sequences of numbers (see the module docstring).
        """
        wall = time.time_ns()
        status = DiagnosticStatus(level=bytes([level]), name=f'{self._node.get_name()}: {kind}',
                                  message=message)
        status.values = [KeyValue(key=key, value=_text(value)) for key, value in values.items()]
        status.values.append(KeyValue(key=WALL_CLOCK, value=str(wall)))
        array = DiagnosticArray(status=[status])
        array.header.stamp = self._node.get_clock().now().to_msg()
        self._publisher.publish(array)


@dataclass(frozen=True)
class Event:
    """One event as read back (:func:`from_message`); ``values`` as published (text)."""

    node: str
    kind: str
    level: int
    message: str
    stamp_ns: int
    values: dict[str, str] = field(default_factory=dict)

    @property
    def wall_ns(self) -> int:
        """Return the wall clock (ns since the epoch) when it happened."""
        return int(self.values[WALL_CLOCK])

    def number(self, key: str) -> float | None:
        """Return value ``key`` as a float (None if the event has no such value)."""
        return float(self.values[key]) if key in self.values else None

    def integer(self, key: str) -> int | None:
        """Return value ``key`` as an int (None if the event has no such value)."""
        return int(self.values[key]) if key in self.values else None

    def numbers(self, key: str) -> Array:
        """Return value ``key`` as a float array (empty if the event has no such value)."""
        return np.array([float(v) for v in self.values.get(key, '').split()])

    def flag(self, key: str) -> bool:
        """Return value ``key`` as a bool (False if the event has no such value)."""
        return self.values.get(key) == 'true'


def from_message(msg: Any) -> list['Event']:
    """Return the :class:`Event` s of a DiagnosticArray published by :class:`EventPublisher`."""
    stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    found = []
    for status in msg.status:
        node, _, kind = status.name.rpartition(': ')
        level = status.level if isinstance(status.level, int) else \
            int.from_bytes(status.level, 'little')
        found.append(Event(node, kind, level, status.message, stamp,
                           {kv.key: kv.value for kv in status.values}))
    return found


def of_kind(events: Iterable['Event'], node: str, kind: str) -> list['Event']:
    """Return the events of ``node`` (its name, without namespace) of ``kind``, in order."""
    return [e for e in events if e.node == node and e.kind == kind]

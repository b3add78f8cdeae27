"""
Writing and reading rosbag2-compatible MCAP recordings, without rclpy.

A recording is one ``.mcap`` file in the ``ros2`` profile (schema encoding ``ros2msg``, message
encoding ``cdr``), as ``ros2 bag record -s mcap`` writes it: each topic is a channel with its
type's message definition embedded as rosbag2 embeds it (:func:`message_definition`: the
``.msg`` text, then every type it uses, each after a line of 80 ``=`` and ``MSG: pkg/Type``),
its publishers' QoS profiles in the channel's ``offered_qos_profiles`` (so that ``ros2 bag
play`` offers latched topics latched again) and the serialized messages as they were received.
:class:`BagWriter` also writes rosbag2's ``metadata.yaml`` beside the file, which makes its
folder a bag (``ros2 bag play <folder>``); the ``.mcap`` alone is what Foxglove reads (neither
tool is installed here: checked with mcap-ros2-support and the ``rosbags`` library).

Times: a message's log time is when the recorder received it (ns since the epoch, as
``ros2 bag record`` stamps it); its publish time is the same.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
import os
from pathlib import Path
import re
import sys
from typing import Any

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
import yaml

#: rosbag2's metadata version (Jazzy), and the distribution named in it.
METADATA_VERSION = 9
ROS_DISTRO = 'jazzy'
SEPARATOR = '=' * 80
PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring'))
#: rmw's "infinite" duration, as rosbag2 writes it for deadline, lifespan and lease.
INFINITE = {'sec': 9223372036, 'nsec': 854775807}


class BagError(RuntimeError):
    """A message definition could not be found, or a file is not such a recording."""


def _share_dirs() -> list[Path]:
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return [Path(p) / 'share' for p in prefixes + [sys.prefix]]


def _msg_file(package: str, name: str) -> Path:
    for share in _share_dirs():
        path = share / package / 'msg' / f'{name}.msg'
        if path.is_file():
            return path
    raise BagError(f'no message definition {package}/msg/{name}.msg in '
                   f'{", ".join(str(s) for s in _share_dirs())}')


def _split_type(type_name: str) -> tuple[str, str]:
    """Return (package, name) of ``pkg/msg/Name`` or ``pkg/Name``."""
    parts = type_name.split('/')
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[1] != 'msg'):
        raise BagError(f'not a message type name: {type_name!r}')
    return parts[0], parts[-1]


def _dependencies(package: str, text: str) -> list[str]:
    """Return the sorted message types (``pkg/Name``) that the fields of a .msg text use."""
    found: set[str] = set()
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        field_type, rest = (line.split(None, 1) + [''])[:2]
        if '=' in rest.split(' ', 1)[0] or '=' in field_type:
            continue                                        # a constant
        base = re.sub(r'(\[[^\]]*\]|<=\d+)+$', '', field_type)
        base = re.sub(r'<=\d+$', '', base)
        if base in PRIMITIVES:
            continue
        if '/' in base:
            found.add('/'.join(_split_type(base)))
        elif base == 'Header':
            found.add('std_msgs/Header')
        else:
            found.add(f'{package}/{base}')
    return sorted(found)


def message_definition(type_name: str) -> str:
    """
    Return the message definition of ``type_name`` (``pkg/msg/Name``) as rosbag2 embeds it.

    The type's own ``.msg`` text (from ``share/<pkg>/msg/`` of the ROS installation or this
    environment), then each type it uses, depth first, once: a line of 80 ``=``, ``MSG:
    pkg/Name``, its ``.msg`` text. Raises BagError when a file is missing.
    """
    package, name = _split_type(type_name)
    parts: list[str] = []
    seen: set[str] = set()

    def add(package: str, name: str, header: bool) -> None:
        text = _msg_file(package, name).read_text()
        parts.append((f'{SEPARATOR}\nMSG: {package}/{name}\n' if header else '')
                     + text.rstrip('\n'))
        for dependency in _dependencies(package, text):
            if dependency not in seen:
                seen.add(dependency)
                used_package, used_name = dependency.split('/')
                add(used_package, used_name, True)

    seen.add(f'{package}/{name}')
    add(package, name, False)
    return '\n'.join(parts) + '\n'


def qos_profile(reliable: bool = True, transient_local: bool = False, depth: int = 10
                ) -> dict[str, Any]:
    """Return one offered QoS profile as rosbag2 (metadata version 9) writes it."""
    return {'history': 'keep_last', 'depth': int(depth),
            'reliability': 'reliable' if reliable else 'best_effort',
            'durability': 'transient_local' if transient_local else 'volatile',
            'deadline': dict(INFINITE), 'lifespan': dict(INFINITE), 'liveliness': 'automatic',
            'liveliness_lease_duration': dict(INFINITE),
            'avoid_ros_namespace_conventions': False}


class BagWriter:
    """
    Write a rosbag2-compatible MCAP file; on :meth:`close`, its ``metadata.yaml`` beside it.

    ``add_topic`` before the topic's first message; ``write`` messages in any order (readers
    sort by log time). Chunks are zstd-compressed.
    """

    def __init__(self, path: str | os.PathLike[str], metadata_yaml: bool = True) -> None:
        """Open ``path`` for writing (its folder is created)."""
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.path, 'wb')
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library='etdmp_ros')
        self._metadata_yaml = metadata_yaml
        self._schemas: dict[str, int] = {}
        # topic -> [channel id, type, qos profiles, count]
        self.topics: dict[str, list[Any]] = {}
        self._first: int | None = None
        self._last: int | None = None

    def add_topic(self, topic: str, type_name: str,
                  qos_profiles: Iterable[dict[str, Any]] = ()) -> None:
        """Register ``topic`` of ``type_name`` (``pkg/msg/Name``) with its offered QoS."""
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                type_name, 'ros2msg', message_definition(type_name).encode())
        profiles = list(qos_profiles)
        channel = self._writer.register_channel(
            topic, 'cdr', self._schemas[type_name],
            {'offered_qos_profiles': yaml.safe_dump(profiles, sort_keys=False) if profiles
             else '', 'topic_type_hash': ''})
        self.topics[topic] = [channel, type_name, profiles, 0]

    def write(self, topic: str, log_ns: int, data: bytes | bytearray | memoryview) -> None:
        """Write one serialized (CDR) message of ``topic`` received at ``log_ns``."""
        entry = self.topics[topic]
        self._writer.add_message(entry[0], log_time=int(log_ns), data=bytes(data),
                                 publish_time=int(log_ns), sequence=entry[3])
        entry[3] += 1
        self._first = log_ns if self._first is None else min(self._first, log_ns)
        self._last = log_ns if self._last is None else max(self._last, log_ns)

    def _metadata(self) -> dict[str, Any]:
        start = int(self._first or 0)
        duration = int((self._last or 0) - start)
        count = sum(entry[3] for entry in self.topics.values())
        return {'rosbag2_bagfile_information': {
            'version': METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': count,
            'topics_with_message_count': [
                {'topic_metadata': {'name': topic, 'type': type_name,
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': profiles,
                                    'type_description_hash': ''},
                 'message_count': n}
                for topic, (_, type_name, profiles, n) in self.topics.items()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.path.name],
            'files': [{'path': self.path.name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration}, 'message_count': count}],
            'custom_data': {},
            'ros_distro': ROS_DISTRO}}

    def close(self) -> None:
        """Finish the file (summary, indexes, rosbag2's metadata); write metadata.yaml."""
        text = yaml.safe_dump(self._metadata(), sort_keys=False)
        self._writer.add_metadata('rosbag2', {'serialized_metadata': text})
        self._writer.finish()
        self._stream.close()
        if self._metadata_yaml:
            (self.path.parent / 'metadata.yaml').write_text(text)

    def __enter__(self) -> BagWriter:
        """Return the writer."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the file."""
        self.close()


def topics(path: str | os.PathLike[str]) -> dict[str, tuple[str, int]]:
    """Return {topic: (type, message count)} of an MCAP file, from its summary."""
    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    if summary is None:
        raise BagError(f'{path}: no summary (not a finished MCAP file)')
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    return {c.topic: (summary.schemas[c.schema_id].name, int(counts.get(c.id, 0)))
            for c in summary.channels.values()}


def read_messages(path: str | os.PathLike[str], names: Iterable[str] | None = None
                  ) -> Iterator[tuple[str, str, int, bytes]]:
    """Yield (topic, type, log ns, CDR bytes) of ``path`` by log time (``names``: only those)."""
    with open(path, 'rb') as stream:
        reader = make_reader(stream)
        for schema, channel, message in reader.iter_messages(
                topics=None if names is None else list(names), log_time_order=True):
            if schema is None:
                raise BagError(f'{path}: topic {channel.topic} has no message type (schema)')
            yield channel.topic, schema.name, message.log_time, message.data

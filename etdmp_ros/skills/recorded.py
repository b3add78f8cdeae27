"""
Recorded paths: the base_link poses of a rosbag2 ``.mcap`` topic, or of recorded joint states.

A demonstration recorded as ``geometry_msgs/msg/PoseStamped`` (one sample per message, timed by
the header stamps, or by the recording times when the stamps are unset), ``nav_msgs/msg/Path``
(the last Path in the file, timed by its poses' stamps) or ``sensor_msgs/msg/JointState``
(kinesthetic teaching: the tool tip's poses by the controller's forward kinematics, trimmed to
where the tool moves: :func:`joint_state_path`). :mod:`etdmp_ros.skills.library` turns such a
path into a demonstration (``recorded_path_demo``); the rules are in its docstring.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
import itertools
import os
from pathlib import Path
from typing import Any, TYPE_CHECKING

from etdmp_ros import limits
from etdmp_ros.dmp import check_file_size, DemonstrationError, unit_quaternions
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:   # the robot package loads Pinocchio: imported where joint states are read
    from etdmp_ros.robot import UR10Model

#: rosbag2 schema names of the message types a demonstration can be recorded as.
POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
PATH = 'nav_msgs/msg/Path'
JOINT_STATE = 'sensor_msgs/msg/JointState'
RECORDED_TYPES = (POSE_STAMPED, PATH, JOINT_STATE)
_TYPES_TEXT = f'{POSE_STAMPED}, {PATH} or {JOINT_STATE}'
#: A joint-state recording starts and ends with the arm at rest (the user takes hold of it, lets
#: go): the motion is where the tool tip is farther than MOTION_THRESHOLD (m) from both the
#: first and the last sample's position, and the demonstration is trimmed to it, widened to
#: the last sample before it within SETTLED_THRESHOLD (m) of the start and the first after it
#: within that of the end, so that it starts and ends (nearly) at rest.
MOTION_THRESHOLD = 1e-3
SETTLED_THRESHOLD = 1e-4
BASE_FRAMES = ('', 'base_link')
#: Orientations that mean "none recorded" when every pose carries one of them.
UNSET_ORIENTATIONS = ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


@dataclass(frozen=True, eq=False)
class RecordedPath:
    """
    Positions (n, 3) in base_link recorded on ``topic``, with times ``t`` (n,) or None.

    ``orientations`` (n, 4) (x, y, z, w) in base_link, or None when none were recorded
    (:func:`recorded_orientations`).
    """

    positions: Array
    t: Array | None
    topic: str
    orientations: Array | None = None


def recorded_orientations(values: ArrayLike, where: str = 'path') -> Array | None:
    """
    Return the recorded orientations (n, 4) of a path's poses, normalised, or None for none.

    ``values`` (n, 4) are the poses' quaternions (x, y, z, w). None when every one is the zero
    quaternion or every one exactly the message default (0, 0, 0, 1) (UNSET_ORIENTATIONS);
    otherwise a zero or non-finite one raises DemonstrationError naming its pose.
    """
    q = np.asarray(values, dtype=float).reshape(-1, 4)
    for unset in UNSET_ORIENTATIONS:
        if len(q) and np.all(q == np.array(unset)):
            return None
    return unit_quaternions(q, len(q), where, lambda row: f'pose {row}')


def read_mcap_path(path: str | os.PathLike[str], topic: str | None = None,
                   kinematics: UR10Model | None = None) -> RecordedPath:
    """
    Read the base_link path of a PoseStamped, Path or JointState topic from a ``.mcap`` file.

    ``topic`` may be None when the file holds exactly one such topic. ``kinematics``: the
    :class:`etdmp_ros.robot.UR10Model` (with the controller's tool offset) that turns joint
    states into tool poses; a JointState topic needs it. Raises DemonstrationError (missing
    reader package, unreadable file, no or ambiguous topic, wrong frame, no samples).
    """
    path = Path(path)
    chosen, kind, records = _read_mcap_topic(path, topic)
    if not records:
        raise DemonstrationError(f'{path}: topic {chosen!r} holds no messages')
    if kind == JOINT_STATE:
        return joint_state_path(records, kinematics, f'{path}: topic {chosen!r}', chosen)
    if len(records) > limits.MAX_DEMO_SAMPLES and kind == POSE_STAMPED:
        raise DemonstrationError(f'{path}: topic {chosen!r} holds more than MAX_DEMO_SAMPLES = '
                                 f'{limits.MAX_DEMO_SAMPLES} messages; not learned')
    if kind == POSE_STAMPED:
        frames = {msg.header.frame_id for _, msg in records}
        positions = [_xyz(msg.pose.position) for _, msg in records]
        quaternions = [_xyzw(msg.pose.orientation) for _, msg in records]
        stamps = np.array([_stamp(msg.header.stamp) for _, msg in records])
        if np.all(stamps == stamps[0]):   # unset header stamps: use the recording times
            stamps = np.array([log_time * 1e-9 for log_time, _ in records])
    else:
        last = records[-1][1]   # the most recent plan/path recorded on the topic
        if len(last.poses) > limits.MAX_DEMO_SAMPLES:
            raise DemonstrationError(f'{path}: the last Path on {chosen!r} has '
                                     f'{len(last.poses)} poses, more than MAX_DEMO_SAMPLES = '
                                     f'{limits.MAX_DEMO_SAMPLES}; not learned')
        frames = {last.header.frame_id} | {pose.header.frame_id for pose in last.poses}
        positions = [_xyz(pose.pose.position) for pose in last.poses]
        quaternions = [_xyzw(pose.pose.orientation) for pose in last.poses]
        stamps = np.array([_stamp(pose.header.stamp) for pose in last.poses])
    wrong = sorted(frames - set(BASE_FRAMES))
    if wrong:
        raise DemonstrationError(f'{path}: topic {chosen!r} is in frame {wrong[0]!r}; only '
                                 'base_link recordings can be used (no TF here)')
    orientations = recorded_orientations(quaternions, f'{path}: topic {chosen!r}')
    return RecordedPath(np.array(positions, dtype=float).reshape(-1, 3), stamps, chosen,
                        orientations)


def _read_mcap_topic(path: Path, topic: str | None) -> tuple[str, str, list[tuple[int, Any]]]:
    """
    Return (topic, its type, [(log time ns, decoded message)]) of a ``.mcap`` file's topic.

    ``topic``: as :func:`read_mcap_path`'s. At most one message more than a demonstration may
    have is read. Raises DemonstrationError (reader missing, file unreadable, no such topic).
    """
    try:
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        raise DemonstrationError(f'{path}: reading .mcap files needs the Python package '
                                 'mcap-ros2-support (pip install mcap-ros2-support)') from None
    try:
        check_file_size(path)
        with open(path, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            topics = _mcap_topics(reader)
            chosen = _choose_topic(path, topics, topic)
            kind = topics[chosen]
            most = (limits.MAX_RECORDED_JOINT_STATES if kind == JOINT_STATE
                    else limits.MAX_DEMO_SAMPLES) + 1
            records = [(message.log_time, decoded) for _, _, message, decoded in
                       itertools.islice(reader.iter_decoded_messages(topics=[chosen]), most)]
    except DemonstrationError:
        raise
    except MemoryError:
        raise DemonstrationError(f'{path}: too large to read (out of memory)') from None
    except OSError as err:
        raise DemonstrationError(f'{path}: cannot read: {err.strerror or err}') from None
    except Exception as err:   # noqa: B902 - the mcap readers raise many types on corrupt files
        raise DemonstrationError(f'{path}: not a readable rosbag2 .mcap file '
                                 f'({type(err).__name__}: {err})') from None
    return chosen, kind, records


def _mcap_topics(reader: Any) -> dict[str, str]:
    """
    Return {topic: schema name} of the recordable channels (RECORDED_TYPES) in an mcap file.

    A channel that the summary's statistics count no message on is left out: a recorder that
    subscribed a topic nobody published (``ros2 bag record -a`` of a partial system) has
    nothing to learn from it, and it must not make the topic to learn from ambiguous.
    """
    summary = reader.get_summary()
    pairs: Iterable[tuple[str, Any]]
    if summary is not None:
        counts = (None if summary.statistics is None
                  else summary.statistics.channel_message_counts)   # unlisted: none
        pairs = [(channel.topic, summary.schemas.get(channel.schema_id))
                 for channel_id, channel in summary.channels.items()
                 if counts is None or counts.get(channel_id, 0) > 0]
    else:   # no summary section (e.g. an interrupted recording): scan the records once
        pairs = {channel.topic: schema for schema, channel, _ in reader.iter_messages()}.items()
    return {topic: schema.name for topic, schema in pairs
            if schema is not None and schema.name in RECORDED_TYPES}


def _choose_topic(path: Path, topics: Mapping[str, str], topic: str | None) -> str:
    if topic:
        if topic not in topics:
            raise DemonstrationError(f'{path}: no {_TYPES_TEXT} topic named '
                                     f'{topic!r} (found: {", ".join(sorted(topics)) or "none"})')
        return topic
    if len(topics) != 1:
        found = ', '.join(sorted(topics)) or 'none'
        raise DemonstrationError(f'{path}: cannot tell which topic to learn from: the file holds '
                                 f'{len(topics)} {_TYPES_TEXT} topics ({found}); '
                                 'name one (parameter mcap_topic)')
    return next(iter(topics))


def joint_state_path(records: Sequence[tuple[int, Any]], kinematics: UR10Model | None, where: str,
                     topic: str = 'joint_states') -> RecordedPath:
    """
    Turn recorded joint states into the tool tip's base_link path (kinesthetic teaching).

    ``records``: [(log time ns, sensor_msgs/JointState)] in order of recording. Joints are
    matched by name (any order, extra joints such as a gripper's ignored); every message must
    give the six UR10 joints' positions, finite. Times: the header stamps, or the recording
    times when the stamps are unset. The tool poses are ``kinematics``'s forward kinematics
    (the controller's tool tip), trimmed to the motion (:data:`MOTION_THRESHOLD`) and, beyond
    MAX_DEMO_SAMPLES samples, decimated evenly. Return a :class:`RecordedPath` with the
    orientations. Raises DemonstrationError saying which message is wrong.
    """
    from etdmp_ros.robot import JOINT_NAMES
    if kinematics is None:
        raise DemonstrationError(f'{where}: joint states need the UR10 model (forward '
                                 'kinematics) to become tool positions; none is available')
    if len(records) > limits.MAX_RECORDED_JOINT_STATES:
        raise DemonstrationError(f'{where}: more than MAX_RECORDED_JOINT_STATES = '
                                 f'{limits.MAX_RECORDED_JOINT_STATES} joint states; not learned')
    joints = np.empty((len(records), len(JOINT_NAMES)))
    columns: list[int] = []
    names: list[str] | None = None
    for row, (_, msg) in enumerate(records):
        given = list(msg.name)
        if names is None or names != given:
            names = given
            missing = [j for j in JOINT_NAMES if j not in names]
            if missing:
                raise DemonstrationError(f'{where}: message {row} has no position of '
                                         f'{", ".join(missing)} (it names {names})')
            columns = [names.index(j) for j in JOINT_NAMES]
        if len(msg.position) != len(names):
            raise DemonstrationError(f'{where}: message {row} names {len(names)} joints but '
                                     f'gives {len(msg.position)} positions')
        joints[row] = [msg.position[c] for c in columns]
    bad = np.flatnonzero(~np.all(np.isfinite(joints), axis=1))
    if bad.size:
        raise DemonstrationError(f'{where}: message {bad[0]} has a NaN or inf joint position')
    stamps = np.array([_stamp(msg.header.stamp) for _, msg in records])
    if np.all(stamps == stamps[0]):   # unset header stamps: use the recording times
        stamps = np.array([log_time * 1e-9 for log_time, _ in records])
    positions = np.array([kinematics.tool_position(q) for q in joints])
    span = _motion_span(positions)
    if span is None:
        raise DemonstrationError(f'{where}: the tool never moves more than MOTION_THRESHOLD = '
                                 f'{MOTION_THRESHOLD * 1e3:g} mm from where it starts: nothing '
                                 'to learn')
    first, last = span
    keep = np.arange(first, last + 1)
    if len(keep) > limits.MAX_DEMO_SAMPLES:
        keep = keep[np.linspace(0, len(keep) - 1, limits.MAX_DEMO_SAMPLES).round().astype(int)]
    rotations = [kinematics.frame_pose(q)[1] for q in joints[keep]]
    orientations = np.array([quat.from_matrix(r) for r in rotations])
    return RecordedPath(positions[keep], stamps[keep], topic, orientations)


def _motion_span(positions: Array) -> tuple[int, int] | None:
    """Return (first, last) indices of the motion in ``positions``, or None if none."""
    from_start = np.linalg.norm(positions - positions[0], axis=1)
    from_end = np.linalg.norm(positions - positions[-1], axis=1)
    if not np.any(from_start > MOTION_THRESHOLD):
        return None
    moves = int(np.argmax(from_start > MOTION_THRESHOLD))
    stops = len(positions) - 1 - int(np.argmax(from_end[::-1] > MOTION_THRESHOLD))
    settled = np.flatnonzero(from_start[:moves] <= SETTLED_THRESHOLD)
    first = int(settled[-1]) if settled.size else 0
    settled = np.flatnonzero(from_end[stops + 1:] <= SETTLED_THRESHOLD)
    last = stops + 1 + int(settled[0]) if settled.size else len(positions) - 1
    return first, last


def _xyz(point: Any) -> tuple[float, float, float]:
    return (point.x, point.y, point.z)


def _xyzw(quaternion: Any) -> tuple[float, float, float, float]:
    return (quaternion.x, quaternion.y, quaternion.z, quaternion.w)


def _stamp(stamp: Any) -> float:
    return stamp.sec + stamp.nanosec * 1e-9

"""
The skills the DMP server knows, learned from recorded demonstrations (no ROS needed here).

Where demonstrations come from:

- the built-in demos (``etdmp_ros.dmp.builtin_demo``);
- files: ``.csv``, ``.npy``, ``.npz`` (``etdmp_ros.dmp.load_demo``) and rosbag2 ``.mcap``
  recordings of a ``geometry_msgs/msg/PoseStamped`` topic (one sample per message, timed by the
  header stamps, or by the recording times when the stamps are unset) or a ``nav_msgs/msg/Path``
  topic (the last Path in the file, timed by its poses' stamps), or of a
  ``sensor_msgs/msg/JointState`` topic (kinesthetic teaching: the arm moved by hand in freedrive
  while ``ros2 bag record /joint_states`` ran): the tool tip's poses by the forward kinematics
  the controller uses (:func:`joint_state_path`), trimmed to where the tool moves;
- paths taught at runtime (the DMP server's ``/etdmp/demonstrations`` topic), persisted as CSV.

What a demonstration's coordinates mean is given by its dimension, one rule for every source:

- 2 coordinates: a 2D skill in demo units (letters, wiping), executed in the task plane;
- 3 coordinates: a 3D skill in base_link metres (stirring), used directly.

A recorded or taught path is a sequence of base_link positions (metres). It becomes a 2D skill
(its projection onto the task plane, in demo units; see :mod:`etdmp_ros.geometry.task_plane`)
or a 3D skill according to ``recorded_dim``: ``'2d'``, ``'3d'`` or ``'auto'`` (2D when the path is
flat and parallel to the task plane: its distances to the plane spread over at most
``plane_tolerance`` metres, so a letter written 5 cm above the table is still a letter). Positions
must be given in ``base_link`` (an empty frame id counts as base_link): no TF is available to
transform others. A path whose poses all carry the same stamp (unset) is taken as sampled uniformly
over 1 s, the convention of ``load_demo`` for files without times.

Recorded and taught poses also bring the tool's orientations (:func:`recorded_orientations`):
the demonstration then has orientations (base_link for a 3D skill, the task plane's frame for a
2D one; docs/orientation.md), unless every pose carries the all-zero quaternion or exactly the
message default (0, 0, 0, 1), which mean "no orientation recorded": such a path stays the
position-only demonstration it always was.
"""

from dataclasses import dataclass, field
import itertools
import os
from pathlib import Path
import re
import threading

from etdmp_ros import limits
from etdmp_ros.dmp import (check_file_size, Demonstration, DemonstrationError, FORMULATIONS, learn,
                           load_demo, save_demo, unit_quaternions)
from etdmp_ros.geometry import quaternion as quat
import numpy as np

#: File types a demonstration can be read from.
SUFFIXES = ('.csv', '.npy', '.npz', '.mcap')
#: How a recorded base_link path becomes a skill (see the module docstring).
RECORDED_DIMS = ('auto', '2d', '3d')
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

# Skill names become file names in the skills folder: keep them portable and path-free.
_NAME = re.compile(r'[A-Za-z0-9][A-Za-z0-9_-]{0,63}\Z')


class SkillExistsError(ValueError):
    """A skill would replace one that must not be replaced (e.g. a built-in one)."""


class SkillNameClashError(ValueError):
    """A new skill's name equals a known skill's but for case (``g`` beside ``G``)."""


class UnknownSkillError(ValueError):
    """A skill name that the library does not know (the message lists the known ones)."""


def check_skill_name(name):
    """Return ``name`` if it is a valid skill name, else raise ValueError saying why."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f'skill name {name!r} is not valid: use 1-64 letters, digits, "_" or '
                         '"-", starting with a letter or digit')
    return name


def default_skills_dir(environ=None):
    """Return where taught skills are kept: ``$ROS_HOME/etdmp_ros/skills`` or ``~/.ros/...``."""
    environ = os.environ if environ is None else environ
    ros_home = environ.get('ROS_HOME')
    base = Path(ros_home) if ros_home else Path(environ.get('HOME', '~')).expanduser() / '.ros'
    return base / 'etdmp_ros' / 'skills'


def demonstration_files(paths):
    """
    Expand files and folders into the list of demonstration files to read, in order.

    A folder contributes its files with a known suffix (sorted, not recursive, hidden files
    skipped). A file is kept as given whatever its suffix, so that loading it reports a clear
    error; a missing path raises DemonstrationError.
    """
    files = []
    for entry in paths:
        path = Path(entry).expanduser()
        if path.is_dir():
            files.extend(sorted(p for p in path.iterdir() if p.is_file() and
                                p.suffix.lower() in SUFFIXES and not p.name.startswith('.')))
        elif path.exists():
            files.append(path)
        else:
            raise DemonstrationError(f'{path}: no such file or folder')
    return files


@dataclass(frozen=True, eq=False)
class RecordedPath:
    """
    Positions (n, 3) in base_link recorded on ``topic``, with times ``t`` (n,) or None.

    ``orientations`` (n, 4) (x, y, z, w) in base_link, or None when none were recorded
    (:func:`recorded_orientations`).
    """

    positions: np.ndarray
    t: np.ndarray | None
    topic: str
    orientations: np.ndarray | None = None


def recorded_orientations(values, where='path'):
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


def recorded_path_demo(name, positions, t, plane, recorded_dim='auto', plane_tolerance=0.01,
                       orientations=None):
    """
    Turn a base_link path (n, 3) with times ``t`` (n,) or None into a Demonstration.

    The result is 2D (demo units on ``plane``, a TaskPlane) or 3D (metres), following
    ``recorded_dim`` (see the module docstring). Times that are all equal count as unset.
    ``orientations`` (n, 4) in base_link (see :func:`recorded_orientations`), if given, are
    kept, in the plane's frame for a 2D skill. Raises DemonstrationError if the path is
    unusable.
    """
    if recorded_dim not in RECORDED_DIMS:
        raise DemonstrationError(f'recorded_dim must be one of {RECORDED_DIMS}, '
                                 f'got {recorded_dim!r}')
    positions = np.asarray(positions, dtype=float)
    where = f'demonstration {name!r}'
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise DemonstrationError(f'{where}: expected (n, 3) base_link positions, got shape '
                                 f'{positions.shape}')
    if not np.all(np.isfinite(positions)):
        raise DemonstrationError(f'{where}: positions contain NaN or inf')
    if t is not None:
        t = np.asarray(t, dtype=float)
        if t.size and np.all(t == t.flat[0]):
            t = None
        elif t.size:
            t = t - t.flat[0]
    dim = recorded_dim
    if dim == 'auto':
        heights = plane.distance(positions) if len(positions) else np.zeros(1)
        dim = '2d' if np.ptp(heights) <= plane_tolerance else '3d'
    if orientations is not None:
        orientations = unit_quaternions(orientations, len(positions), where,
                                        lambda row: f'pose {row}')
    if dim == '2d':
        positions = plane.to_plane(positions)
        if orientations is not None:
            orientations = plane.orientation_to_plane(orientations)
    return Demonstration(name, positions, t, orientations)


def read_mcap_path(path, topic=None, kinematics=None):
    """
    Read the base_link path of a PoseStamped, Path or JointState topic from a ``.mcap`` file.

    ``topic`` may be None when the file holds exactly one such topic. ``kinematics``: the
    :class:`etdmp_ros.robot.UR10Model` (with the controller's tool offset) that turns joint
    states into tool poses; a JointState topic needs it. Raises DemonstrationError (missing
    reader package, unreadable file, no or ambiguous topic, wrong frame, no samples).
    """
    path = Path(path)
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


def _mcap_topics(reader):
    """
    Return {topic: schema name} of the recordable channels (RECORDED_TYPES) in an mcap file.

    A channel that the summary's statistics count no message on is left out: a recorder that
    subscribed a topic nobody published (``ros2 bag record -a`` of a partial system) has
    nothing to learn from it, and it must not make the topic to learn from ambiguous.
    """
    from etdmp_ros.skills.recordings import reader_topics
    return {topic: name for topic, (name, count) in reader_topics(reader).items()
            if name in RECORDED_TYPES and count != 0}


def _choose_topic(path, topics, topic):
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


def joint_state_path(records, kinematics, where, topic='joint_states'):
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
    columns, names = None, None
    for row, (_, msg) in enumerate(records):
        if names != list(msg.name):
            names = list(msg.name)
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
    first, last = _motion_span(positions)
    if first is None:
        raise DemonstrationError(f'{where}: the tool never moves more than MOTION_THRESHOLD = '
                                 f'{MOTION_THRESHOLD * 1e3:g} mm from where it starts: nothing '
                                 'to learn')
    keep = np.arange(first, last + 1)
    if len(keep) > limits.MAX_DEMO_SAMPLES:
        keep = keep[np.linspace(0, len(keep) - 1, limits.MAX_DEMO_SAMPLES).round().astype(int)]
    rotations = [kinematics.frame_pose(q)[1] for q in joints[keep]]
    orientations = np.array([quat.from_matrix(r) for r in rotations])
    return RecordedPath(positions[keep], stamps[keep], topic, orientations)


def _motion_span(positions):
    """Return (first, last) indices of the motion in ``positions``, or (None, None) if none."""
    from_start = np.linalg.norm(positions - positions[0], axis=1)
    from_end = np.linalg.norm(positions - positions[-1], axis=1)
    if not np.any(from_start > MOTION_THRESHOLD):
        return None, None
    moves = int(np.argmax(from_start > MOTION_THRESHOLD))
    stops = len(positions) - 1 - int(np.argmax(from_end[::-1] > MOTION_THRESHOLD))
    settled = np.flatnonzero(from_start[:moves] <= SETTLED_THRESHOLD)
    first = int(settled[-1]) if settled.size else 0
    settled = np.flatnonzero(from_end[stops + 1:] <= SETTLED_THRESHOLD)
    last = stops + 1 + int(settled[0]) if settled.size else len(positions) - 1
    return first, last


def _xyz(point):
    return (point.x, point.y, point.z)


def _xyzw(quaternion):
    return (quaternion.x, quaternion.y, quaternion.z, quaternion.w)


def _stamp(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def load_demonstration(path, plane, name=None, mcap_topic=None, recorded_dim='auto',
                       plane_tolerance=0.01, kinematics=None):
    """
    Read one demonstration file (``.csv``, ``.npy``, ``.npz`` or ``.mcap``).

    The name defaults to the file's stem. ``.mcap`` recordings are base_link paths (joint
    states through ``kinematics``: :func:`read_mcap_path`) turned into 2D or 3D demonstrations
    by :func:`recorded_path_demo` (``plane``, ``recorded_dim``, ``plane_tolerance``). Raises
    DemonstrationError.
    """
    path = Path(path)
    name = path.stem if name is None else name
    if path.suffix.lower() != '.mcap':
        return load_demo(path, name=name)
    recorded = read_mcap_path(path, mcap_topic, kinematics)
    try:
        return recorded_path_demo(name, recorded.positions, recorded.t, plane, recorded_dim,
                                  plane_tolerance, recorded.orientations)
    except DemonstrationError as err:
        raise DemonstrationError(f'{path} (topic {recorded.topic!r}): {err}') from None


def save_skill_demo(skills_dir, demo):
    """
    Write ``demo`` to ``<skills_dir>/<demo.name>.csv`` (with a ``t`` column) and return the path.

    The file is replaced atomically, so a crash never leaves a half-written skill behind.
    """
    check_skill_name(demo.name)
    folder = Path(skills_dir).expanduser()
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / f'{demo.name}.csv'
    partial = folder / f'.{demo.name}.partial.csv'   # hidden: never loaded as a skill
    save_demo(partial, demo)
    os.replace(partial, target)
    return target


@dataclass(eq=False)
class SkillEntry:
    """A named demonstration, where it came from, and the skills learned from it."""

    name: str
    demo: Demonstration
    source: str
    _learned: dict = field(default_factory=dict, repr=False)

    @property
    def planar(self):
        """Return True for a 2D skill (task plane, demo units), False for 3D (base_link)."""
        return self.demo.dim == 2


class SkillLibrary:
    """
    Named skills, each learned from one demonstration; safe to use from several threads.

    :meth:`add` learns the demonstration at once (so a bad one is rejected before it replaces
    anything); :meth:`skill` returns the learned skill for a formulation and number of basis
    functions, learning and caching it on first use.
    """

    def __init__(self, formulation='ijspeert', n_basis=100):
        """Create an empty library that learns with ``formulation`` and ``n_basis``."""
        if formulation not in FORMULATIONS:
            raise ValueError(f'formulation must be one of {FORMULATIONS}, got {formulation!r}')
        self.formulation = formulation
        self.n_basis = int(n_basis)
        self._entries = {}
        self._lock = threading.RLock()

    def __len__(self):
        """Return the number of skills."""
        with self._lock:
            return len(self._entries)

    def __contains__(self, name):
        """Return True if a skill of that name is known."""
        with self._lock:
            return name in self._entries

    def names(self):
        """Return the known skill names, sorted."""
        with self._lock:
            return sorted(self._entries)

    def source(self, name):
        """Return where skill ``name`` came from (its SkillEntry.source), or None if unknown."""
        with self._lock:
            entry = self._entries.get(name)
            return None if entry is None else entry.source

    def add(self, name, demo, source, protected=()):
        """
        Learn ``demo`` (a Demonstration) as skill ``name`` and return its SkillEntry.

        Replaces a skill of the same name only if learning succeeds and the existing skill's
        source is not in ``protected`` (then SkillExistsError). A name that equals another
        skill's but for case (``g`` beside ``G``) is refused (SkillNameClashError): names are
        case-sensitive, and the two would be one file in a skills folder on a case-insensitive
        file system. Raises DemonstrationError (or ValueError for a bad name) and leaves the
        library unchanged on failure.
        """
        check_skill_name(name)
        self._check_new(name, protected)
        if not isinstance(demo, Demonstration):
            raise TypeError(f'expected a Demonstration, got {type(demo).__name__}')
        if demo.dim not in (2, 3):
            raise DemonstrationError(
                f'demonstration {name!r} has {demo.dim} coordinate(s); a skill needs 2 (a task '
                'plane skill in demo units) or 3 (a base_link skill in metres)')
        if demo.name != name:
            demo = Demonstration(name, demo.positions, demo.t, demo.orientations)
        entry = SkillEntry(name, demo, str(source))
        key = (self.formulation, self.n_basis)
        entry._learned[key] = learn(demo, n_basis=self.n_basis, formulation=self.formulation)
        with self._lock:
            self._check_new(name, protected)   # again: another thread may have added one
            self._entries[name] = entry
        return entry

    def _check_new(self, name, protected):
        """Raise if skill ``name`` may not be added (a protected one, or a case clash)."""
        with self._lock:
            existing = self._entries.get(name)
            if existing is not None and existing.source in protected:
                raise SkillExistsError(f'skill {name!r} exists already ({existing.source}) and '
                                       'is not replaced')
            other = self._case_twin(name)
            if other is not None:
                raise SkillNameClashError(
                    f'skill name {name!r} differs from the known skill {other.name!r} '
                    f'({other.source}) only in case: choose another name, or {other.name!r} '
                    'itself to replace that one (names are case-sensitive, and the two would '
                    'be one file on a case-insensitive file system)')

    def _case_twin(self, name):
        """Return the entry whose name equals ``name`` but for case (not ``name`` itself)."""
        folded = name.casefold()
        return next((e for n, e in self._entries.items()
                     if n != name and n.casefold() == folded), None)

    def get(self, name):
        """Return the SkillEntry of ``name`` or raise UnknownSkillError listing the known ones."""
        with self._lock:
            entry = self._entries.get(name)
            if entry is None:
                twin = self._case_twin(name) if isinstance(name, str) else None
                hint = f' (did you mean {twin.name!r}? names are case-sensitive)' if twin else ''
                raise UnknownSkillError(f'unknown skill {name!r}{hint}; known skills: '
                                        f'{", ".join(sorted(self._entries)) or "none"}')
            return entry

    def skill(self, name, formulation=None, n_basis=None):
        """Return the learned Skill of ``name`` (learned on first use for these settings)."""
        entry = self.get(name)
        key = (formulation or self.formulation, int(n_basis or self.n_basis))
        with self._lock:
            learned = entry._learned.get(key)
            if learned is None:
                learned = learn(entry.demo, n_basis=key[1], formulation=key[0])
                entry._learned[key] = learned
            return learned

    def add_files(self, paths, plane, mcap_topic=None, recorded_dim='auto', plane_tolerance=0.01,
                  kinematics=None):
        """
        Learn every demonstration file in ``paths`` (files or folders), named by file stem.

        ``kinematics``: the UR10Model that turns recorded joint states into tool poses.

        Returns (added SkillEntries, error messages); a bad file is reported and skipped, the
        others are still learned.
        """
        added, errors = [], []
        for entry in paths:
            try:
                files = demonstration_files([entry])
            except DemonstrationError as err:
                errors.append(str(err))
                continue
            for path in files:
                try:
                    demo = load_demonstration(path, plane, mcap_topic=mcap_topic,
                                              recorded_dim=recorded_dim,
                                              plane_tolerance=plane_tolerance,
                                              kinematics=kinematics)
                    added.append(self.add(path.stem, demo, str(path)))
                except ValueError as err:   # DemonstrationError, or a stem that is no name
                    errors.append(str(err) if str(path) in str(err) else f'{path}: {err}')
                except MemoryError:
                    errors.append(f'{path}: too large to learn (out of memory)')
                except Exception as err:   # noqa: B902 - one bad file never stops the others
                    errors.append(f'{path}: not learned ({type(err).__name__}: '
                                  f'{str(err)[:limits.MAX_REASON_CHARS]})')
        return added, errors

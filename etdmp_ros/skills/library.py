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

Recordings are read by :mod:`etdmp_ros.skills.recorded` (its names are imported here too).

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

from __future__ import annotations

from collections.abc import Container, Iterable, Mapping
from dataclasses import dataclass, field
import os
from pathlib import Path
import re
import threading
from typing import TYPE_CHECKING

from etdmp_ros import limits
from etdmp_ros.dmp import (Demonstration, DemonstrationError, FORMULATIONS, learn, load_demo,
                           save_demo, Skill, unit_quaternions)
from etdmp_ros.geometry.task_plane import TaskPlane
# Recorded paths are read there; these names are imported from here too.
from etdmp_ros.skills.recorded import (BASE_FRAMES, joint_state_path,  # noqa: F401
                                       MOTION_THRESHOLD, read_mcap_path, recorded_orientations,
                                       RecordedPath, SETTLED_THRESHOLD)
import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:   # the robot package loads Pinocchio: imported where joint states are read
    from etdmp_ros.robot import UR10Model

#: File types a demonstration can be read from.
SUFFIXES = ('.csv', '.npy', '.npz', '.mcap')
#: How a recorded base_link path becomes a skill (see the module docstring).
RECORDED_DIMS = ('auto', '2d', '3d')

# Skill names become file names in the skills folder: keep them portable and path-free.
_NAME = re.compile(r'[A-Za-z0-9][A-Za-z0-9_-]{0,63}\Z')


class SkillExistsError(ValueError):
    """A skill would replace one that must not be replaced (e.g. a built-in one)."""


class SkillNameClashError(ValueError):
    """A new skill's name equals a known skill's but for case (``g`` beside ``G``)."""


class UnknownSkillError(ValueError):
    """A skill name that the library does not know (the message lists the known ones)."""


def check_skill_name(name: object) -> str:
    """Return ``name`` if it is a valid skill name, else raise ValueError saying why."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f'skill name {name!r} is not valid: use 1-64 letters, digits, "_" or '
                         '"-", starting with a letter or digit')
    return name


def default_skills_dir(environ: Mapping[str, str] | None = None) -> Path:
    """Return where taught skills are kept: ``$ROS_HOME/etdmp_ros/skills`` or ``~/.ros/...``."""
    environ = os.environ if environ is None else environ
    ros_home = environ.get('ROS_HOME')
    base = Path(ros_home) if ros_home else Path(environ.get('HOME', '~')).expanduser() / '.ros'
    return base / 'etdmp_ros' / 'skills'


def demonstration_files(paths: Iterable[str | os.PathLike[str]]) -> list[Path]:
    """
    Expand files and folders into the list of demonstration files to read, in order.

    A folder contributes its files with a known suffix (sorted, not recursive, hidden files
    skipped). A file is kept as given whatever its suffix, so that loading it reports a clear
    error; a missing path raises DemonstrationError.
    """
    files: list[Path] = []
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


def recorded_path_demo(name: str, positions: ArrayLike, t: ArrayLike | None, plane: TaskPlane,
                       recorded_dim: str = 'auto', plane_tolerance: float = 0.01,
                       orientations: ArrayLike | None = None) -> Demonstration:
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
    x = np.asarray(positions, dtype=float)
    where = f'demonstration {name!r}'
    if x.ndim != 2 or x.shape[1] != 3:
        raise DemonstrationError(f'{where}: expected (n, 3) base_link positions, got shape '
                                 f'{x.shape}')
    if not np.all(np.isfinite(x)):
        raise DemonstrationError(f'{where}: positions contain NaN or inf')
    times = None if t is None else np.asarray(t, dtype=float)
    if times is not None:
        if times.size and np.all(times == times.flat[0]):
            times = None
        elif times.size:
            times = times - times.flat[0]
    dim = recorded_dim
    if dim == 'auto':
        heights = plane.distance(x) if len(x) else np.zeros(1)
        dim = '2d' if np.ptp(heights) <= plane_tolerance else '3d'
    quats = None if orientations is None else unit_quaternions(
        orientations, len(x), where, lambda row: f'pose {row}')
    if dim == '2d':
        x = plane.to_plane(x)
        if quats is not None:
            quats = plane.orientation_to_plane(quats)
    # times None: uniform over 1 s, which Demonstration sets (its field is typed as set).
    return Demonstration(name, x, times, quats)  # type: ignore[arg-type]


def load_demonstration(path: str | os.PathLike[str], plane: TaskPlane, name: str | None = None,
                       mcap_topic: str | None = None, recorded_dim: str = 'auto',
                       plane_tolerance: float = 0.01,
                       kinematics: UR10Model | None = None) -> Demonstration:
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


def save_skill_demo(skills_dir: str | os.PathLike[str], demo: Demonstration) -> Path:
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
    _learned: dict[tuple[str, int], Skill] = field(default_factory=dict, repr=False)

    @property
    def planar(self) -> bool:
        """Return True for a 2D skill (task plane, demo units), False for 3D (base_link)."""
        return self.demo.dim == 2


class SkillLibrary:
    """
    Named skills, each learned from one demonstration; safe to use from several threads.

    :meth:`add` learns the demonstration at once (so a bad one is rejected before it replaces
    anything); :meth:`skill` returns the learned skill for a formulation and number of basis
    functions, learning and caching it on first use.
    """

    def __init__(self, formulation: str = 'ijspeert', n_basis: int = 100) -> None:
        """Create an empty library that learns with ``formulation`` and ``n_basis``."""
        if formulation not in FORMULATIONS:
            raise ValueError(f'formulation must be one of {FORMULATIONS}, got {formulation!r}')
        self.formulation = formulation
        self.n_basis = int(n_basis)
        self._entries: dict[str, SkillEntry] = {}
        self._lock = threading.RLock()

    def __len__(self) -> int:
        """Return the number of skills."""
        with self._lock:
            return len(self._entries)

    def __contains__(self, name: object) -> bool:
        """Return True if a skill of that name is known."""
        with self._lock:
            return name in self._entries

    def names(self) -> list[str]:
        """Return the known skill names, sorted."""
        with self._lock:
            return sorted(self._entries)

    def source(self, name: str) -> str | None:
        """Return where skill ``name`` came from (its SkillEntry.source), or None if unknown."""
        with self._lock:
            entry = self._entries.get(name)
            return None if entry is None else entry.source

    def add(self, name: str, demo: Demonstration, source: object,
            protected: Container[str] = ()) -> SkillEntry:
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

    def _check_new(self, name: str, protected: Container[str]) -> None:
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

    def _case_twin(self, name: str) -> SkillEntry | None:
        """Return the entry whose name equals ``name`` but for case (not ``name`` itself)."""
        folded = name.casefold()
        return next((e for n, e in self._entries.items()
                     if n != name and n.casefold() == folded), None)

    def get(self, name: str) -> SkillEntry:
        """Return the SkillEntry of ``name`` or raise UnknownSkillError listing the known ones."""
        with self._lock:
            entry = self._entries.get(name)
            if entry is None:
                twin = self._case_twin(name) if isinstance(name, str) else None
                hint = f' (did you mean {twin.name!r}? names are case-sensitive)' if twin else ''
                raise UnknownSkillError(f'unknown skill {name!r}{hint}; known skills: '
                                        f'{", ".join(sorted(self._entries)) or "none"}')
            return entry

    def skill(self, name: str, formulation: str | None = None, n_basis: int | None = None
              ) -> Skill:
        """Return the learned Skill of ``name`` (learned on first use for these settings)."""
        entry = self.get(name)
        key = (formulation or self.formulation, int(n_basis or self.n_basis))
        with self._lock:
            learned = entry._learned.get(key)
            if learned is None:
                learned = learn(entry.demo, n_basis=key[1], formulation=key[0])
                entry._learned[key] = learned
            return learned

    def add_files(self, paths: Iterable[str | os.PathLike[str]], plane: TaskPlane,
                  mcap_topic: str | None = None, recorded_dim: str = 'auto',
                  plane_tolerance: float = 0.01, kinematics: UR10Model | None = None
                  ) -> tuple[list[SkillEntry], list[str]]:
        """
        Learn every demonstration file in ``paths`` (files or folders), named by file stem.

        ``kinematics``: the UR10Model that turns recorded joint states into tool poses.

        Returns (added SkillEntries, error messages); a bad file is reported and skipped, the
        others are still learned.
        """
        added: list[SkillEntry] = []
        errors: list[str] = []
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

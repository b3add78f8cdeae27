"""
Demonstrations: the recorded movements a skill is learned from, their files, the built-in set.

A demonstration is a path ``positions`` of shape (T, d) sampled at times ``t`` (T,) in seconds.
Files hold one demonstration each:

- ``.csv``: comma separated, UTF-8, a header row naming the columns, one sample per line. A column
  named ``t``, ``time`` or ``stamp`` (any case) holds the sample times in seconds. Columns named
  ``qx``, ``qy``, ``qz``, ``qw`` (any case; all four or none), by convention after the
  positions, hold the tool orientation of each sample as a quaternion in ROS order (e.g.
  ``t,x,y,z,qx,qy,qz,qw``); every other column is a position coordinate, in file order (e.g.
  ``t,x,y`` or ``x,y,z``).
- ``.npy``: a numeric array (T, d) of positions (or (T,) for d = 1).
- ``.npz``: arrays ``positions`` (T, d) and, optionally, ``t`` (T,) and ``quaternions`` (T, 4).

Orientations are optional (``Demonstration.orientations`` is None without them). They are
normalised on reading; a zero or non-finite quaternion is refused with its line (or index). For a
2D skill they are expressed in the task plane's axes (x, y and the normal z); for a 3D skill in
base_link (docs/orientation.md).

Sizes are bounded (:mod:`etdmp_ros.limits`): a file is refused before it is read when it is
larger than ``MAX_DEMO_FILE_BYTES``; an ``.npy`` array (alone or in an ``.npz``) when its header
claims more than ``MAX_DEMO_ARRAY_BYTES`` (read before anything is allocated); a CSV when it has
more than ``MAX_DEMO_SAMPLES`` data rows (reading stops there). A demonstration has at most
``MAX_DEMO_SAMPLES`` samples of at most ``MAX_DEMO_COORDINATES`` coordinates, each at most
``MAX_DEMO_COORDINATE`` in absolute value, lasts at most ``MAX_DEMO_DURATION`` with samples at
least ``MIN_DEMO_SAMPLE_INTERVAL`` apart. Every failure of reading (I/O, memory, a corrupt
archive) is a :class:`DemonstrationError` naming the file.

Without sample times the samples are taken as uniform over tau = 1 s (``t = linspace(0, 1, T)``),
the convention of the pbdlib letters the paper uses. Files are never unpickled: object arrays
are refused (a pickle can run arbitrary code).

The built-in demonstrations (``builtin_demo_names()``) are original to this project, authored by
``tools/make_builtin_demos.py``: the handwritten letters "G", "P", "R", "W" and a board "wipe"
(2D, demo units, letters 10 units tall) and a bottle "stir" (3D, metres, z up, origin on
the bottle axis at its mouth). "wipe" and "stir" carry orientations (the sponge's long side
along the stroke; a tilted stirrer circling with the spiral), the letters none.
"""

from __future__ import annotations

import csv
import functools
from importlib import resources
from importlib.resources.abc import Traversable
import io
import itertools
import os
from pathlib import Path
from typing import Any, BinaryIO, IO
import zipfile

from etdmp_ros import limits
from etdmp_ros.geometry.arrays import Array
import numpy as np

from ._demonstration import (Demonstration, from_arrays, MIN_SAMPLES, unit_quaternions,
                             validate)
from ._errors import DemonstrationError

TIME_COLUMNS = ('t', 'time', 'stamp')
#: CSV columns of the orientation quaternion, in the order (x, y, z, w) it is stored in.
ORIENTATION_COLUMNS = ('qx', 'qy', 'qz', 'qw')
SUFFIXES = ('.csv', '.npy', '.npz')

_DATA_DIR = 'data'


def load_demo(path: str | os.PathLike[str], name: str | None = None) -> Demonstration:
    """
    Read a demonstration from a ``.csv``, ``.npy`` or ``.npz`` file (see the module docstring).

    ``name`` defaults to the file name without its suffix. Raises :class:`DemonstrationError`
    saying what is wrong and where (file, line, column) for a missing, unreadable, malformed or
    unusable file.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise DemonstrationError(f'{path}: unknown demonstration file type {path.suffix!r}; '
                                 f'use one of {", ".join(SUFFIXES)}')
    if not path.exists():
        raise DemonstrationError(f'{path}: no such file')
    if not path.is_file():
        raise DemonstrationError(f'{path}: not a regular file')
    name = path.stem if name is None else name
    try:
        check_file_size(path)
        if suffix == '.csv':
            try:
                text = path.read_text(encoding='utf-8-sig')
            except UnicodeDecodeError as err:
                raise DemonstrationError(f'{path}: not a UTF-8 text file ({err.reason} at '
                                         f'byte {err.start})') from None
            return _parse_csv(text, str(path), name)
        return _load_numpy(path, suffix, name)
    except DemonstrationError:
        raise
    except OSError as err:
        raise DemonstrationError(f'{path}: cannot read: {err.strerror or err}') from None
    except MemoryError:
        raise DemonstrationError(f'{path}: too large to read (out of memory)') from None
    except (EOFError, ValueError, zipfile.BadZipFile, csv.Error, OverflowError,
            KeyError) as err:
        raise DemonstrationError(f'{path}: unreadable {suffix} file ({type(err).__name__}: '
                                 f'{_shorten(str(err))})') from None


def check_file_size(path: str | os.PathLike[str]) -> int:
    """Raise DemonstrationError if the file at ``path`` is larger than MAX_DEMO_FILE_BYTES."""
    size = Path(path).stat().st_size
    if size > limits.MAX_DEMO_FILE_BYTES:
        raise DemonstrationError(f'{path}: {size} bytes, larger than the limit of '
                                 f'{limits.MAX_DEMO_FILE_BYTES} bytes (MAX_DEMO_FILE_BYTES); '
                                 'not read')
    return size


def _shorten(text: str, limit: int | None = None) -> str:
    limit = limits.MAX_REASON_CHARS if limit is None else limit
    return text if len(text) <= limit else text[:limit - 3] + '...'


def save_demo(path: str | os.PathLike[str], demo: Demonstration,
              precision: int | None = None) -> None:
    """
    Write ``demo`` to ``path`` in the format its suffix names; :func:`load_demo` reads it back.

    - ``.csv``: header ``t,x``, ``t,x,y``, ``t,x,y,z``, or ``t,x0,...,x{d-1}`` for d > 3, then
      ``qx,qy,qz,qw`` if the demonstration has orientations. Numbers are written in the
      shortest form that reads back to the same float (exact round trip) unless ``precision``
      (decimal places) is given.
    - ``.npy``: positions only; the times and orientations are NOT stored (times read back as
      uniform over 1 s).
    - ``.npz``: ``positions``, ``t`` and, with orientations, ``quaternions``.
    """
    if not isinstance(demo, Demonstration):
        raise TypeError(f'save_demo expects a Demonstration, got {type(demo).__name__}')
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise DemonstrationError(f'{path}: unknown demonstration file type {path.suffix!r}; '
                                 f'use one of {", ".join(SUFFIXES)}')
    if suffix == '.npy':
        with open(path, 'wb') as f:
            np.save(f, demo.positions, allow_pickle=False)
    elif suffix == '.npz':
        arrays: dict[str, Any] = {'positions': demo.positions, 't': demo.t}
        if demo.has_orientation:
            arrays['quaternions'] = demo.orientations
        with open(path, 'wb') as f:
            np.savez(f, **arrays)
    else:
        path.write_text(_format_csv(demo, precision), encoding='utf-8')


def builtin_demo_names() -> list[str]:
    """Names of the demonstrations shipped with the package, sorted."""
    return list(_builtin_files())


def builtin_demo(name: str) -> Demonstration:
    """
    Load a shipped demonstration by name (see :func:`builtin_demo_names`).

    The result is shared between callers, which is safe because its arrays are read-only.
    """
    files = _builtin_files()
    if name not in files:
        raise DemonstrationError(f'unknown built-in demonstration {name!r}; available: '
                                 f'{", ".join(files)}')
    return _load_builtin(name)


@functools.lru_cache(maxsize=None)
def _load_builtin(name: str) -> Demonstration:
    resource = _builtin_files()[name]
    return _parse_csv(resource.read_text(encoding='utf-8'), f'built-in demo {name!r}', name)


@functools.lru_cache(maxsize=1)
def _builtin_files() -> dict[str, Traversable]:
    # importlib.resources finds the data both in a source tree and in an installed package.
    data = resources.files(__package__).joinpath(_DATA_DIR)
    found = {}
    if data.is_dir():
        for entry in data.iterdir():
            if entry.name.endswith('.csv') and entry.is_file():
                found[entry.name[:-len('.csv')]] = entry
    return {name: found[name] for name in sorted(found)}


def _column_names(dim: int) -> list[str]:
    if dim <= 3:
        return ['x', 'y', 'z'][:dim]
    return [f'x{k}' for k in range(dim)]


def _format_number(value: float, precision: int | None) -> str:
    if precision is None:
        return np.format_float_positional(value, unique=True, trim='-')
    return np.format_float_positional(value, precision=precision, unique=True, trim='-')


def _format_csv(demo: Demonstration, precision: int | None) -> str:
    out = io.StringIO()
    quaternions = list(ORIENTATION_COLUMNS) if demo.has_orientation else []
    out.write(','.join(['t'] + _column_names(demo.dim) + quaternions) + '\n')
    q = demo.orientations
    rows = demo.positions if q is None else np.hstack([demo.positions, q])
    for t, row in zip(demo.t, rows):
        out.write(','.join(_format_number(v, precision) for v in (t, *row)) + '\n')
    return out.getvalue()


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _parse_csv(text: str, source: str, name: str) -> Demonstration:
    reader = enumerate(csv.reader(io.StringIO(text)), start=1)
    read = list(itertools.islice(reader, limits.MAX_CSV_ROWS + 1))
    rows = [(number, cells) for number, cells in read if any(c.strip() for c in cells)]
    if len(read) > limits.MAX_CSV_ROWS or len(rows) > limits.MAX_DEMO_SAMPLES + 1:
        raise DemonstrationError(f'{source}: more than {limits.MAX_DEMO_SAMPLES} samples (or '
                                 f'{limits.MAX_CSV_ROWS} lines), the limit MAX_DEMO_SAMPLES; not '
                                 'learned')
    if not rows:
        raise DemonstrationError(f'{source}: empty file; expected a header row such as '
                                 f'"t,x,y" followed by one sample per line')
    header_line, cells = rows[0]
    header = [h.strip() for h in cells]
    time_cols, quat_cols, pos_cols = _csv_columns(header, header_line, source)
    data = rows[1:]
    values = _csv_values(data, header, source)
    if len(data) < MIN_SAMPLES:
        raise DemonstrationError(f'{source}: {len(data)} data rows; a demonstration needs at '
                                 f'least {MIN_SAMPLES} samples')
    positions = values[:, pos_cols]
    t = values[:, time_cols[0]] if time_cols else np.linspace(0.0, 1.0, len(data))
    lines = [line for line, _ in data]
    pos_names = [header[k] for k in pos_cols]
    time_name = header[time_cols[0]] if time_cols else 't'

    def locate(row: int, col: int | None = None) -> str:
        column = time_name if col is None else pos_names[col]
        return f'line {lines[row]}, column {column!r}'

    validate(positions, t, source, locate)
    orientations: Array | None = None
    if quat_cols:
        orientations = unit_quaternions(values[:, quat_cols], len(data), source,
                                        lambda row: f'line {lines[row]}')
    return Demonstration(name, positions, t, orientations)


def _csv_columns(header: list[str], header_line: int,
                 source: str) -> tuple[list[int], list[int], list[int]]:
    """Return the indices of the time, quaternion and position columns the header names."""
    if all(_is_number(h) for h in header):
        raise DemonstrationError(f'{source}: no header row: line {header_line} holds numbers; the '
                                 f'first line must name the columns, e.g. "t,x,y" or "x,y"')
    for k, h in enumerate(header, start=1):
        if not h:
            raise DemonstrationError(f'{source}: header (line {header_line}) column {k} has no '
                                     f'name')
    duplicates = sorted({h for h in header if header.count(h) > 1})
    if duplicates:
        raise DemonstrationError(f'{source}: header (line {header_line}) repeats column(s) '
                                 f'{", ".join(duplicates)}')
    time_cols = [k for k, h in enumerate(header) if h.lower() in TIME_COLUMNS]
    if len(time_cols) > 1:
        raise DemonstrationError(f'{source}: header (line {header_line}) has more than one time '
                                 f'column: {", ".join(header[k] for k in time_cols)}')
    quat_cols = [k for name in ORIENTATION_COLUMNS for k, h in enumerate(header)
                 if h.lower() == name]
    if quat_cols and len(quat_cols) != len(ORIENTATION_COLUMNS):
        named = [header[k] for k in quat_cols]
        raise DemonstrationError(f'{source}: header (line {header_line}) names the orientation '
                                 f'column(s) {", ".join(named)} but not all of '
                                 f'{", ".join(ORIENTATION_COLUMNS)}; orientations need the four '
                                 'quaternion columns (x, y, z, w)')
    pos_cols = [k for k in range(len(header)) if k not in time_cols and k not in quat_cols]
    if not pos_cols:
        raise DemonstrationError(f'{source}: header (line {header_line}) names no position '
                                 f'column, only the time column {header[time_cols[0]]!r}')

    if len(header) > limits.MAX_DEMO_COORDINATES + 1 + len(quat_cols):
        raise DemonstrationError(f'{source}: header (line {header_line}) names {len(header)} '
                                 f'columns; at most {limits.MAX_DEMO_COORDINATES} coordinates '
                                 'and a time column (MAX_DEMO_COORDINATES)')
    return time_cols, quat_cols, pos_cols


def _csv_values(data: list[tuple[int, list[str]]], header: list[str], source: str) -> Array:
    """Return the numbers (T, columns) of the CSV's data rows, (line number, cells) each."""
    values = np.empty((len(data), len(header)))
    for i, (line, cells) in enumerate(data):
        if len(cells) != len(header):
            raise DemonstrationError(f'{source}: line {line} has {len(cells)} cells but the '
                                     f'header names {len(header)} columns ({",".join(header)})')
        for k, cell in enumerate(cells):
            cell = cell.strip()
            if not cell:
                raise DemonstrationError(f'{source}: line {line}, column {header[k]!r} is '
                                         f'empty')
            try:
                values[i, k] = float(cell)
            except ValueError:
                raise DemonstrationError(f'{source}: line {line}, column {header[k]!r}: '
                                         f'{_shorten(repr(cell), 40)} is not a number') from None
    return values


_NPY_MAGIC = b'\x93NUMPY'
_ZIP_MAGIC = b'PK\x03\x04'
_PICKLE_REFUSED = 'holds pickled (object) data; refusing to unpickle it (unsafe). Save plain ' \
    'numeric arrays'


def _load_numpy(path: Path, suffix: str, name: str) -> Demonstration:
    with open(path, 'rb') as f:
        head = f.read(len(_NPY_MAGIC))
    if not head:
        raise DemonstrationError(f'{path}: empty file')
    if head[:1] == b'\x80':
        raise DemonstrationError(f'{path}: is a pickle, not a {suffix} file; refusing to '
                                 f'unpickle it (unsafe)')
    if not head.startswith((_NPY_MAGIC, _ZIP_MAGIC)):
        # Checked here because np.load takes any other content for a pickle.
        raise DemonstrationError(f'{path}: not a valid {suffix} file: neither a .npy array nor '
                                 f'an .npz archive')
    if head.startswith(_NPY_MAGIC):
        with open(path, 'rb') as f:
            _check_npy_header(f, str(path))
    try:
        loaded = np.load(path, allow_pickle=False)
    except ValueError as err:
        if 'pickle' in str(err):
            raise DemonstrationError(f'{path}: {_PICKLE_REFUSED}') from None
        raise DemonstrationError(f'{path}: not a valid {suffix} file ({err})') from None
    except EOFError:
        raise DemonstrationError(f'{path}: empty or truncated {suffix} file') from None
    if isinstance(loaded, np.ndarray):
        if suffix != '.npy':
            raise DemonstrationError(f'{path}: holds a single .npy array, not an .npz archive')
        return from_arrays(loaded, None, str(path), name)
    with loaded:
        if suffix != '.npz':
            raise DemonstrationError(f'{path}: holds an .npz archive, not a single .npy array')
        keys = sorted(loaded.files)
        if 'positions' not in keys:
            raise DemonstrationError(f'{path}: no array named "positions" (found: '
                                     f'{_shorten(", ".join(keys), 80) or "nothing"})')
        for key in ['positions'] + [k for k in ('t', 'quaternions') if k in keys]:
            member_name = f'{key}.npy' if f'{key}.npy' in loaded.zip.namelist() else key
            with loaded.zip.open(member_name) as member:
                _check_npy_header(member, f'{path}: array {key!r}')
        try:
            positions = loaded['positions']
            t = loaded['t'] if 't' in keys else None
            orientations = loaded['quaternions'] if 'quaternions' in keys else None
        except ValueError as err:
            if 'pickle' in str(err):
                raise DemonstrationError(f'{path}: {_PICKLE_REFUSED}') from None
            raise DemonstrationError(f'{path}: unreadable array ({err})') from None
    return from_arrays(positions, t, str(path), name, orientations)


def _check_npy_header(stream: BinaryIO | IO[bytes], source: str) -> None:
    """
    Read the header of the .npy array at ``stream`` and refuse it before it is allocated.

    Refuses object arrays (pickles), more than 2 dimensions, more than MAX_DEMO_SAMPLES rows or
    MAX_DEMO_COORDINATES columns and more than MAX_DEMO_ARRAY_BYTES in all.
    """
    try:
        version = np.lib.format.read_magic(stream)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(stream, max_header_size=10000)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(stream, max_header_size=10000)
    except (ValueError, EOFError, OSError) as err:
        raise DemonstrationError(f'{source}: not a valid .npy array '
                                 f'({_shorten(str(err), 120)})') from None
    if dtype.hasobject:
        raise DemonstrationError(f'{source}: {_PICKLE_REFUSED}')
    rows = shape[0] if shape else 1
    columns = shape[1] if len(shape) > 1 else 1
    size = int(np.prod(shape, dtype=object)) * dtype.itemsize
    problem = None
    if len(shape) > 2:
        problem = f'{len(shape)} dimensions (a demonstration is (T, d))'
    elif rows > limits.MAX_DEMO_SAMPLES:
        problem = f'{rows} samples, more than MAX_DEMO_SAMPLES = {limits.MAX_DEMO_SAMPLES}'
    elif columns > limits.MAX_DEMO_COORDINATES:
        problem = (f'{columns} coordinates, more than MAX_DEMO_COORDINATES = '
                   f'{limits.MAX_DEMO_COORDINATES}')
        if rows < columns:
            problem += '; if the array is stored as (d, T), transpose it to (T, d)'

    elif size > limits.MAX_DEMO_ARRAY_BYTES:
        problem = f'{size} bytes, more than MAX_DEMO_ARRAY_BYTES = {limits.MAX_DEMO_ARRAY_BYTES}'
    if problem:
        raise DemonstrationError(f'{source}: its header claims shape '
                                 f'{_shorten(str(shape), 80)}: {problem}; not loaded')

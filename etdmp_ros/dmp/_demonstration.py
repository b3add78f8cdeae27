"""
A demonstration: a recorded path, its times and orientations, checked as the package takes it.

:class:`Demonstration` holds ``positions`` (T, d) at increasing times ``t`` (T,) in seconds and,
optionally, ``orientations`` (T, 4); building one checks it against :mod:`etdmp_ros.limits` and
raises :class:`DemonstrationError` saying what is wrong and where (``locate`` names a sample the
way its source does: an array index, a file's line). Reading and writing files:
:mod:`etdmp_ros.dmp._demos`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from etdmp_ros import limits
from etdmp_ros.geometry.arrays import Array, Quaternions
from etdmp_ros.geometry.quaternion import MIN_NORM, unit_and_norm
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._errors import DemonstrationError

# Forcing-term fitting and finite-difference accelerations need a few samples per basis width;
# fewer than this is almost certainly a truncated or mis-parsed file.
MIN_SAMPLES = 10


@dataclass(frozen=True, eq=False, repr=False)
class Demonstration:
    """
    One demonstrated movement: ``positions`` (T, d) at strictly increasing times ``t`` (T,).

    Arrays are copied to read-only float64 on construction. ``t`` defaults to uniform samples
    over tau = 1 s. A 1-D ``positions`` (T,) is taken as a one-dimensional movement (T, 1).
    ``orientations`` (T, 4), optional, are unit quaternions (x, y, z, w), normalised here.
    Raises :class:`DemonstrationError` if the data is unusable (too short, NaN/inf, time not
    increasing, shapes inconsistent, a zero quaternion).
    """

    name: str
    positions: Array
    # None (the default) means uniform times over 1 s: __post_init__ sets them, so the field
    # holds an array.
    t: Array = field(default=None)  # type: ignore[arg-type]
    orientations: Quaternions | None = field(default=None)

    def __post_init__(self) -> None:
        """Validate and freeze the arrays."""
        if not isinstance(self.name, str) or not self.name:
            raise DemonstrationError(f'demonstration name must be a non-empty string, '
                                     f'got {self.name!r}')
        where = f'demonstration {self.name!r}'
        positions = _as_float_array(self.positions, 'positions', where)
        if positions.ndim == 1:
            positions = positions[:, None]
        if self.t is None:
            t = np.linspace(0.0, 1.0, positions.shape[0] if positions.ndim == 2 else 0)
        else:
            t = _as_float_array(self.t, 't', where)
        validate(positions, t, where, _array_location)
        positions = positions.copy()
        t = t.copy()
        positions.flags.writeable = False
        t.flags.writeable = False
        object.__setattr__(self, 'positions', positions)
        object.__setattr__(self, 't', t)
        if self.orientations is not None:
            q = unit_quaternions(self.orientations, len(positions), where,
                                 lambda row: f'orientations[{row}]')
            q.flags.writeable = False
            object.__setattr__(self, 'orientations', q)

    @property
    def n_samples(self) -> int:
        """Return the number of samples T."""
        return self.positions.shape[0]

    @property
    def dim(self) -> int:
        """Return the number of position coordinates d."""
        return self.positions.shape[1]

    @property
    def has_orientation(self) -> bool:
        """Return True if the samples carry orientations."""
        return self.orientations is not None

    @property
    def duration(self) -> float:
        """Time from the first to the last sample in seconds (the DMP's tau)."""
        return float(self.t[-1] - self.t[0])

    @property
    def start(self) -> Array:
        """First position (d,)."""
        return self.positions[0].copy()

    @property
    def goal(self) -> Array:
        """Last position (d,)."""
        return self.positions[-1].copy()

    def __repr__(self) -> str:
        """Summarise without printing the arrays."""
        return (f'Demonstration(name={self.name!r}, samples={self.n_samples}, dim={self.dim}, '
                f'duration={self.duration:g} s'
                f'{", with orientations" if self.has_orientation else ""})')


def from_arrays(positions: ArrayLike, t: ArrayLike | None, source: str, name: str,
                orientations: ArrayLike | None = None) -> Demonstration:
    """Build a Demonstration from arrays read from ``source``; its errors name array indices."""
    positions = _as_float_array(positions, 'positions', source)
    if positions.ndim == 1:
        positions = positions[:, None]
    if t is not None:
        t = _as_float_array(t, 't', source)
    elif positions.ndim == 2:
        t = np.linspace(0.0, 1.0, positions.shape[0])
    # t is None only for positions that are not (T, d), which validate refuses first.
    validate(positions, t, source, _array_location)  # type: ignore[arg-type]
    if orientations is not None:
        orientations = unit_quaternions(orientations, len(positions), source,
                                        lambda row: f'quaternions[{row}]')
    return Demonstration(name, positions, t, orientations)  # type: ignore[arg-type]


def _as_float_array(value: object, what: str, where: str) -> Array:
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as err:
        raise DemonstrationError(f'{where}: {what} is not an array ({err})') from None
    if array.dtype.kind not in 'iuf':
        if array.dtype.kind == 'O':
            # Lists of numbers arrive as object arrays only when ragged or mixed with non-numbers.
            try:
                return np.asarray(array.tolist(), dtype=np.float64)
            except (TypeError, ValueError):
                pass
        raise DemonstrationError(f'{where}: {what} must be real numbers, got dtype '
                                 f'{array.dtype} (shape {array.shape})')
    return array.astype(np.float64, copy=False)


def _array_location(row: int, col: int | None = None) -> str:
    return f't[{row}]' if col is None else f'positions[{row}, {col}]'


def validate(positions: Array, t: Array, where: str, locate: Callable[..., str]) -> None:
    """Raise DemonstrationError unless positions (T, d) and t (T,) form a usable demonstration."""
    if positions.ndim != 2:
        raise DemonstrationError(f'{where}: positions must be a (T, d) array, got shape '
                                 f'{positions.shape}')
    n, dim = positions.shape
    if dim < 1:
        raise DemonstrationError(f'{where}: positions have no coordinates (shape '
                                 f'{positions.shape})')
    if n < MIN_SAMPLES:
        hint = ''
        if 1 <= n < dim:
            hint = '; if the array is stored as (d, T), transpose it to (T, d)'
        raise DemonstrationError(f'{where}: {n} samples; a demonstration needs at least '
                                 f'{MIN_SAMPLES}{hint}')
    if t.shape != (n,):
        raise DemonstrationError(f'{where}: t must have shape ({n},) to match positions '
                                 f'{positions.shape}, got {t.shape}')
    bad: NDArray[np.intp] = np.argwhere(~np.isfinite(positions))
    if bad.size:
        row, col = bad[0]
        raise DemonstrationError(f'{where}: {locate(row, col)} is {positions[row, col]}; '
                                 f'positions must be finite ({len(bad)} bad value(s))')
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise DemonstrationError(f'{where}: {locate(bad[0])} is {t[bad[0]]}; times must be '
                                 f'finite')
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        row = bad[0] + 1
        raise DemonstrationError(f'{where}: time does not increase at {locate(row)}: '
                                 f'{t[row]!r} after {t[row - 1]!r}; times must be strictly '
                                 f'increasing')
    _check_limits(positions, t, where, locate)


def _check_limits(positions: Array, t: Array, where: str, locate: Callable[..., str]) -> None:
    """Raise DemonstrationError unless the demonstration fits :mod:`etdmp_ros.limits`."""
    n, dim = positions.shape
    if n > limits.MAX_DEMO_SAMPLES:
        raise DemonstrationError(f'{where}: {n} samples, more than the limit '
                                 f'MAX_DEMO_SAMPLES = {limits.MAX_DEMO_SAMPLES}')
    if dim > limits.MAX_DEMO_COORDINATES:
        raise DemonstrationError(f'{where}: {dim} coordinates, more than the limit '
                                 f'MAX_DEMO_COORDINATES = {limits.MAX_DEMO_COORDINATES}')
    duration = float(t[-1] - t[0])
    if duration > limits.MAX_DEMO_DURATION:
        raise DemonstrationError(f'{where}: lasts {duration:.6g} s, longer than the limit '
                                 f'MAX_DEMO_DURATION = {limits.MAX_DEMO_DURATION:g} s (check '
                                 'the time stamps)')
    steps = np.diff(t)
    row = int(np.argmin(steps)) + 1
    if steps[row - 1] < limits.MIN_DEMO_SAMPLE_INTERVAL:
        raise DemonstrationError(f'{where}: samples {steps[row - 1]:.3g} s apart at '
                                 f'{locate(row)}, closer than MIN_DEMO_SAMPLE_INTERVAL = '
                                 f'{limits.MIN_DEMO_SAMPLE_INTERVAL:g} s')
    big = np.argwhere(np.abs(positions) > limits.MAX_DEMO_COORDINATE)
    if big.size:
        row, col = big[0]
        raise DemonstrationError(f'{where}: {locate(row, col)} is {positions[row, col]:.3g}, '
                                 f'beyond the limit MAX_DEMO_COORDINATE = '
                                 f'{limits.MAX_DEMO_COORDINATE:g} in absolute value')


def unit_quaternions(values: ArrayLike, n: int, where: str,
                     locate: Callable[[int], str]) -> Quaternions:
    """
    Check and normalise demonstrated orientations: ``values`` (n, 4), ROS order (x, y, z, w).

    ``locate(row)`` names a sample in messages (``orientations[3]``, ``line 5``). Raises
    DemonstrationError for a wrong shape or dtype, a non-finite or a zero quaternion.
    """
    try:
        q = np.asarray(values)
    except (TypeError, ValueError) as err:
        raise DemonstrationError(f'{where}: orientations are not an array ({err})') from None
    if q.dtype.kind not in 'iuf':
        raise DemonstrationError(f'{where}: orientations must be real numbers, got dtype '
                                 f'{q.dtype} (shape {q.shape})')
    q = q.astype(np.float64)
    if q.shape != (n, 4):
        raise DemonstrationError(f'{where}: orientations must have shape ({n}, 4): one '
                                 f'quaternion (x, y, z, w) per sample, got {q.shape}')
    bad = np.flatnonzero(~np.all(np.isfinite(q), axis=1))
    if bad.size:
        raise DemonstrationError(f'{where}: the orientation at {locate(bad[0])} is '
                                 f'{q[bad[0]].tolist()}; quaternions must be finite '
                                 f'({bad.size} bad sample(s))')
    unit, norm = unit_and_norm(q)   # no overflow: (1e308, 0, 0, 1e308) is a rotation too
    bad = np.flatnonzero(norm < MIN_NORM)
    if bad.size:
        raise DemonstrationError(f'{where}: the orientation at {locate(bad[0])} is the zero '
                                 f'quaternion {q[bad[0]].tolist()}, which is no rotation '
                                 f'({bad.size} such sample(s)); give unit quaternions '
                                 '(x, y, z, w)')
    # Quaternions already unit to round-off are kept as they are, so that normalising is
    # idempotent (a file written and read back keeps every bit).
    return np.where(np.abs(norm - 1.0)[:, None] <= 4e-16, q, unit)

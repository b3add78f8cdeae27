"""
Euclidean transformation between the real and the virtual situation (paper Eq. 7-14, 23).

``I_D = x0_D - g_D`` is the demonstration's start relative to its goal and ``I_C = x0_C - g_C`` the
requested one. ``R`` is an orthogonal matrix that turns the direction of ``I_C`` onto the
direction of ``I_D``; the DMP runs in the virtual situation from ``x0' = R I_C + g_C`` and its
output is mapped back with ``x = R^T (x' - g_C) + g_C`` (velocities and accelerations with
``R^T``).

- 1D (Eq. 7): ``R = sign(I_D) sign(I_C)``, a reflection about the goal.
- 2D (Eq. 8, 10) and 3D mode 1 (Eq. 9): the rotation by the angle between ``I_C`` and ``I_D``
  in the plane they span. In 2D this is the planar rotation by the SIGNED angle
  ``theta = atan2(I_C x I_D, I_C . I_D)`` (the paper's arccos loses the sign); in 3D it is
  Rodrigues' rotation about ``k = I_C x I_D / |I_C x I_D|``. One formula serves both (and any
  dimension): ``R = I + (cos theta - 1)(u u^T + w w^T) + sin theta (w u^T - u w^T)`` with
  ``u = I_C/|I_C|`` and ``w`` the unit part of ``I_D`` orthogonal to ``u``.
  When ``I_C`` and ``I_D`` are anti-parallel the plane is not unique. We choose ``w`` as the unit
  part, orthogonal to ``u``, of the coordinate axis least aligned with ``I_D`` (the lowest index on
  ties); in 3D the rotation is then by pi about ``k = u x w``, which is perpendicular to that axis.
- 3D mode 2: the independent axis (default z) follows the 1D rule, the other two the 2D rule on
  their projections; the 3D problem becomes a 1D and a 2D one.

``scale`` is the spatial scaling ``(g - x0')_i / (g_D - x0_D)_i`` that the Ijspeert DMP applies in
the virtual situation. Because ``R I_C`` is parallel to ``I_D`` (per block in mode 2) it is one
number per block, ``|I_C| / |I_D|``, and needs no division by a component of ``I_D`` that may be
~0. A block in which the demonstration does not move (``|I_D_block| ~ 0``) uses the overall ratio.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from etdmp_ros.geometry.arrays import Array, Rotations
import numpy as np
from numpy.typing import ArrayLike

from ._errors import GeneralizationError

try:  # The fast path is optional: without numba the numpy formula below serves.
    import numba
except ImportError:  # pragma: no cover - numba is pinned in requirements
    numba = None  # type: ignore[assignment]

#: Relative size below which a vector counts as zero (and a direction as undefined).
EPS = 1e-9


@dataclass(frozen=True)
class EuclideanTransform:
    """
    The transform between real and virtual situation for one start (or a batch of B starts).

    ``R`` has shape (d, d) or (B, d, d): virtual offset = R @ real offset. ``scale`` has shape (d,)
    or (B, d).
    """

    R: Rotations
    scale: Array

    def to_virtual(self, points: ArrayLike, goal: Array) -> Array:
        """Map real points (..., d) to the virtual situation about ``goal`` (Eq. 12, 23)."""
        points = np.asarray(points, dtype=float)
        return _apply(self.R, points - goal, transpose=False) + goal

    def from_virtual(self, points: ArrayLike, goal: Array) -> Array:
        """Map virtual points back to the real situation about ``goal`` (Eq. 13)."""
        points = np.asarray(points, dtype=float)
        return _apply(self.R, points - goal, transpose=True) + goal

    def vectors_from_virtual(self, vectors: ArrayLike) -> Array:
        """Map virtual velocities or accelerations back (``R^T v``, Eq. 14)."""
        return _apply(self.R, np.asarray(vectors, dtype=float), transpose=True)


def _apply(R: Array, y: Array, transpose: bool) -> Array:
    """Apply R (or R^T) to row vectors y; batched R (B, d, d) pairs with y (B, d) or (B, n, d)."""
    Rt = R if transpose else np.swapaxes(R, -1, -2)
    if R.ndim == 2 or y.ndim == 3:
        return y @ Rt
    return (y[:, None] @ Rt)[:, 0]


def plane_rotation(i_demo: ArrayLike, i_current: ArrayLike) -> Rotations:
    """
    Rotations turning each row of ``i_current`` (B, d) onto the direction of ``i_demo`` (d,).

    Returns R with shape (B, d, d). Rows that are ~0 give the identity; d == 1 gives the 1D sign
    rule. This is Eq. 8/10 (signed angle) in 2D and Eq. 9 (Rodrigues) in 3D. The same formula
    row by row in numba when it is importable (an online update places a few hundred goals:
    0.26 ms in numpy), else :func:`plane_rotation_numpy`.
    """
    i_demo = np.asarray(i_demo, dtype=float)
    i_current = np.atleast_2d(np.asarray(i_current, dtype=float))
    if numba is None or i_current.shape[1] < 2:
        return plane_rotation_numpy(i_demo, i_current)
    n_demo = float(np.linalg.norm(i_demo))
    e_demo = i_demo / n_demo if n_demo > 0.0 else np.zeros(len(i_demo))
    axis = np.zeros(len(i_demo))
    axis[int(np.argmin(np.abs(e_demo)))] = 1.0
    return _plane_rotation_nb(np.ascontiguousarray(i_current), e_demo, n_demo > 0.0, axis, EPS)


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _plane_rotation_nb(i_current: Array, e_demo: Array,
                           demo_ok: bool, axis: Array,
                           eps: float) -> Array:  # pragma: no cover - numba
        n, d = i_current.shape
        R = np.zeros((n, d, d))
        u, w = np.empty(d), np.empty(d)
        for b in range(n):
            for i in range(d):
                R[b, i, i] = 1.0
            n_cur = math.sqrt(np.sum(i_current[b] ** 2))
            if not (n_cur > 0.0 and demo_ok):
                continue
            cos = 0.0
            for i in range(d):
                u[i] = i_current[b, i] / n_cur
                cos += u[i] * e_demo[i]
            cos = min(1.0, max(-1.0, cos))
            for i in range(d):
                w[i] = e_demo[i] - cos * u[i]
            flat = math.sqrt(np.sum(w ** 2)) <= eps
            if flat:    # anti-parallel (or parallel): the axis least aligned with I_D
                along = 0.0
                for i in range(d):
                    along += u[i] * axis[i]
                for i in range(d):
                    w[i] = axis[i] - along * u[i]
            w_norm = math.sqrt(np.sum(w ** 2))
            for i in range(d):
                w[i] /= w_norm
            sin = 0.0 if flat else math.sqrt(max(0.0, 1.0 - cos ** 2))
            for i in range(d):
                for j in range(d):
                    R[b, i, j] += ((cos - 1.0) * (u[i] * u[j] + w[i] * w[j])
                                   + sin * (w[i] * u[j] - u[i] * w[j]))
        return R


def plane_rotation_numpy(i_demo: ArrayLike, i_current: ArrayLike) -> Rotations:
    """Compute :func:`plane_rotation` with numpy only (the reference; and d == 1)."""
    i_demo = np.asarray(i_demo, dtype=float)
    i_current = np.atleast_2d(np.asarray(i_current, dtype=float))
    n, d = i_current.shape
    eye = np.broadcast_to(np.eye(d), (n, d, d)).copy()
    n_demo = np.linalg.norm(i_demo)
    n_cur = np.linalg.norm(i_current, axis=1)
    ok = (n_cur > 0.0) & (n_demo > 0.0)
    if d == 1:
        eye[:, 0, 0] = np.where(ok, np.sign(i_demo[0]) * np.sign(i_current[:, 0]), 1.0)
        return eye
    u = np.zeros_like(i_current)
    u[ok] = i_current[ok] / n_cur[ok, None]
    e_demo = i_demo / n_demo if n_demo > 0.0 else np.zeros(d)
    cos = np.clip(u @ e_demo, -1.0, 1.0)
    w = e_demo - cos[:, None] * u
    w_norm = np.linalg.norm(w, axis=1)
    # Anti-parallel (or parallel) pairs span no plane: take the axis least aligned with I_D.
    axis = np.zeros(d)
    axis[int(np.argmin(np.abs(e_demo)))] = 1.0
    flat = ok & (w_norm <= EPS)
    w[flat] = axis - (u[flat] @ axis)[:, None] * u[flat]
    w_norm = np.linalg.norm(w, axis=1)
    w[ok] /= w_norm[ok, None]
    sin = np.where(flat, 0.0, np.sqrt(np.maximum(0.0, 1.0 - cos ** 2)))
    cos = np.where(ok, cos, 1.0)
    uu = np.einsum('bi,bj->bij', u, u)
    ww = np.einsum('bi,bj->bij', w, w)
    wu = np.einsum('bi,bj->bij', w, u)
    R = (eye + (cos - 1.0)[:, None, None] * (uu + ww)
         + sin[:, None, None] * (wu - wu.transpose(0, 2, 1)))
    R[~ok] = np.eye(d)
    return R


def _norm_ratio(i_demo: Array, i_current: Array, fallback: Array) -> Array:
    """Return ``|I_C| / |I_D|`` per row, or ``fallback`` where ``|I_D|`` is 0."""
    n_demo = np.linalg.norm(i_demo)
    n_cur = np.linalg.norm(np.atleast_2d(i_current), axis=1)
    return n_cur / n_demo if n_demo > 0.0 else fallback


def transforms(i_demo: ArrayLike, i_current: ArrayLike, mode: int = 1, independent_axis: int = 2,
               size: float = 0.0) -> EuclideanTransform:
    """
    Batched transforms: ``i_current`` (B, d) → EuclideanTransform with R (B, d, d), scale (B, d).

    ``size`` is the demonstration's size: ``|I_D|`` below EPS of it counts as zero. Raises
    GeneralizationError for an undefined transform (start at the goal, demonstration that starts
    at its goal, bad mode or axis).
    """
    i_demo = np.asarray(i_demo, dtype=float)
    i_current = np.atleast_2d(np.asarray(i_current, dtype=float))
    n, d = i_current.shape
    n_demo = np.linalg.norm(i_demo)
    n_cur = np.linalg.norm(i_current, axis=1)
    if not n_demo > EPS * size:
        raise GeneralizationError(
            'the demonstration starts at its goal (|I_D| = 0): the Euclidean transformation is '
            "undefined; use method='dmp' with formulation='hoffmann'")
    bad = np.flatnonzero(n_cur <= EPS * n_demo)
    if bad.size:
        raise GeneralizationError(
            f'start equals goal (|x0 - g| = {n_cur[bad[0]]:.3g}) for start #{bad[0]}: '
            'the rotation is undefined and there is no movement to make')
    overall = n_cur / n_demo
    if mode == 1 or d < 3:
        R = plane_rotation(i_demo, i_current)
        return EuclideanTransform(R, np.repeat(overall[:, None], d, axis=1))
    if mode != 2:
        raise GeneralizationError(f'mode must be 1 or 2, got {mode!r}')
    if d != 3 or int(independent_axis) not in (0, 1, 2):
        raise GeneralizationError(
            f'mode 2 needs 3 dimensions and an independent axis in 0..2, got d={d}, '
            f'axis={independent_axis!r}')
    a = int(independent_axis)
    plane = [(a + 1) % 3, (a + 2) % 3]   # cyclic order keeps the 2D rotation right-handed
    R = np.zeros((n, 3, 3))
    scale = np.empty((n, 3))
    for block in ([a], plane):
        sub_demo, sub_cur = i_demo[block], i_current[:, block]
        quiet = np.linalg.norm(sub_demo) <= EPS * n_demo
        R_block = plane_rotation(np.zeros(len(block)) if quiet else sub_demo, sub_cur)
        R[np.ix_(np.arange(n), block, block)] = R_block  # type: ignore[arg-type]
        ratio = overall if quiet else _norm_ratio(sub_demo, sub_cur, overall)
        scale[:, block] = ratio[:, None]
    return EuclideanTransform(R, scale)


def euclidean_transform(i_demo: ArrayLike, i_current: ArrayLike, mode: int = 1,
                        independent_axis: int = 2, size: float = 0.0) -> EuclideanTransform:
    """Transform for one start: ``I_D`` (d,), ``I_C`` (d,) → EuclideanTransform with R (d, d)."""
    batch = transforms(i_demo, np.asarray(i_current, dtype=float)[None], mode, independent_axis,
                       size)
    return EuclideanTransform(batch.R[0], batch.scale[0])

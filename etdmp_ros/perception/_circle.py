"""Circles fitted to the rim points of an object (Gauss-Newton on the radial residuals)."""

from __future__ import annotations

from collections.abc import Sequence

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike

#: A point (x, y).
Point = Sequence[float] | Array


def fit_circle_and_radius(points: ArrayLike, start: Point, radius: float, iterations: int = 30
                          ) -> tuple[Array, float, float]:
    """
    Return (centre (2,), radius, rms) of the circle fitted to points (N, 2), radius free.

    Least squares of the radial residuals ``|p - c| - r`` by Gauss-Newton in (c, r) from
    ``start`` (a point inside the circle) and ``radius``. Well posed only when the points
    cover enough of the circle (:func:`rim_arc`): a short arc fits circles of many radii.
    """
    p = np.asarray(points, dtype=float)
    cx, cy = (float(v) for v in start)
    r = float(radius)
    for _ in range(iterations):
        dx, dy = p[:, 0] - cx, p[:, 1] - cy
        n = np.maximum(np.hypot(dx, dy), 1e-12)
        residual = n - r
        # Residuals' Jacobian: -(ux, uy, 1); normal equations J^T J step = -J^T residual.
        jac = np.stack([-dx / n, -dy / n, -np.ones_like(n)], axis=1)
        normal = jac.T @ jac
        if np.linalg.cond(normal) > 1e12:
            break
        step = np.linalg.solve(normal, -jac.T @ residual)
        cx, cy, r = cx + step[0], cy + step[1], r + step[2]
        if step @ step < 1e-14:
            break
    residual = np.hypot(p[:, 0] - cx, p[:, 1] - cy) - r
    return np.array([cx, cy]), float(r), float(np.sqrt(np.mean(residual ** 2)))


def rim_arc(points: ArrayLike, centre: ArrayLike) -> float:
    """Return the angle (rad) of the circle about ``centre`` that points (N, 2) span."""
    d = np.asarray(points, dtype=float) - centre
    angles = np.sort(np.arctan2(d[:, 1], d[:, 0]))
    if len(angles) < 2:
        return 0.0
    gaps = np.diff(np.append(angles, angles[0] + 2.0 * np.pi))
    return float(2.0 * np.pi - gaps.max())


def fit_circle(points: ArrayLike, radius: float, start: Point, iterations: int = 20
               ) -> tuple[Array, float]:
    """
    Return (centre (2,), rms) of the circle of given radius fitted to points (N, 2).

    Least squares of the radial residuals ``|p - c| - radius`` by Gauss-Newton from ``start``
    (a point inside the circle: with a short arc the other solution, mirrored across the
    chord, is then never reached).
    """
    p = np.asarray(points, dtype=float)
    cx, cy = (float(v) for v in start)
    for _ in range(iterations):
        dx, dy = p[:, 0] - cx, p[:, 1] - cy
        n = np.maximum(np.hypot(dx, dy), 1e-12)
        residual = n - radius
        ux, uy = dx / n, dy / n          # the Jacobian of the residuals is -(ux, uy)
        a, b, c = float(ux @ ux), float(ux @ uy), float(uy @ uy)
        det = a * c - b * b
        if det < 1e-12 * (a + c) ** 2:   # all points on one line through the centre
            break
        gx, gy = float(ux @ residual), float(uy @ residual)
        step_x, step_y = (c * gx - b * gy) / det, (a * gy - b * gx) / det
        cx, cy = cx + step_x, cy + step_y
        if step_x * step_x + step_y * step_y < 1e-14:
            break
    residual = np.hypot(p[:, 0] - cx, p[:, 1] - cy) - radius
    return np.array([cx, cy]), float(np.sqrt(np.mean(residual ** 2)))

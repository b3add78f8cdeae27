"""
Similarity between a generalized movement and the demonstration (paper Eq. 15-16).

The definitions: docs/design.md#similarity-measure.
"""

from __future__ import annotations

from typing import NamedTuple

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike

from ._transform import plane_rotation


class Similarity(NamedTuple):
    """Both nRMSE values: ``paper`` is Eq. 16 as printed, ``conventional`` the usual RMSE form."""

    paper: float
    conventional: float


def _resample(y: Array, n: int) -> Array:
    """Resample (m, d) samples to n by linear interpolation in normalised phase (index)."""
    if len(y) == n:
        return y
    src = np.linspace(0.0, 1.0, len(y))
    dst = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(dst, src, y[:, i]) for i in range(y.shape[1])], axis=1)


def similarity(generated: ArrayLike, demo: ArrayLike, n_samples: int | None = None) -> Similarity:
    """
    Compute the nRMSE of ``generated`` (m, d) against ``demo`` (n, d), both variants.

    Both are taken relative to their own goal (last sample); the generated one is rotated so its
    start direction matches the demo's (the Eq. 10 angle, Rodrigues in 3D, the sign in 1D);
    both are resampled to the same number of samples by phase and divided by their own largest
    absolute coordinate (Eq. 15). In 3D only the start direction is aligned, as in the paper: a
    twist about that direction counts as a difference. Then, with
    ``m_k = mean_i (D_gen_i^k - D_demo_i^k)^2`` per axis k, ``paper = sqrt(sum_k m_k^2)``
    (Eq. 16 as printed) and ``conventional = sqrt(sum_k m_k)``.
    """
    gen = np.asarray(generated, dtype=float)
    dem = np.asarray(demo, dtype=float)
    gen = gen[:, None] if gen.ndim == 1 else gen
    dem = dem[:, None] if dem.ndim == 1 else dem
    if (gen.ndim != 2 or dem.ndim != 2 or gen.shape[1] != dem.shape[1]
            or min(len(gen), len(dem)) < 2):
        raise ValueError(
            f'expected two (n, d) paths with the same d, got {gen.shape} and {dem.shape}')
    if not (np.all(np.isfinite(gen)) and np.all(np.isfinite(dem))):
        raise ValueError('paths contain NaN or inf')
    gen = gen - gen[-1]
    dem = dem - dem[-1]
    R = plane_rotation(dem[0], gen[0][None])[0]
    gen = gen @ R.T
    n = int(n_samples) if n_samples else max(len(gen), len(dem))
    gen, dem = _resample(gen, n), _resample(dem, n)
    gen = gen / max(np.abs(gen).max(), 1e-300)
    dem = dem / max(np.abs(dem).max(), 1e-300)
    per_axis = np.mean((gen - dem) ** 2, axis=0)
    return Similarity(float(np.sqrt(np.sum(per_axis ** 2))), float(np.sqrt(np.sum(per_axis))))


def nrmse(generated: ArrayLike, demo: ArrayLike, variant: str = 'conventional',
          n_samples: int | None = None) -> float:
    """Compute the nRMSE of ``generated`` against ``demo`` (variant "conventional" or "paper")."""
    if variant not in Similarity._fields:
        raise ValueError(f'variant must be one of {Similarity._fields}, got {variant!r}')
    return getattr(similarity(generated, demo, n_samples), variant)


def clearance(x: ArrayLike, obstacles: ArrayLike) -> float:
    """Smallest distance from any sample of path(s) ``x`` (..., d) to any obstacle point (n, d)."""
    x = np.asarray(x, dtype=float)
    obs = np.asarray(obstacles, dtype=float).reshape(-1, x.shape[-1])
    if len(obs) == 0:
        return float('inf')
    return float(np.min(np.linalg.norm(x[..., None, :] - obs, axis=-1)))

"""
Obstacle coupling term lambda* (paper Eq. 22-27), evaluated in the virtual situation.

For each obstacle point ``o_i`` inside the safe-region test ``|o_i - x| < |x - g|`` (Eq. 25-26)::

    phi_i   = arccos((o_i - x) . v / (|o_i - x| |v|))
    R_i v   = r_i_hat x v,  r_i = (o_i - x) x v   (v turned by +pi/2 about r_i: away from o_i)
    lambda* = sum_i (gamma phi_i exp(-beta |phi_i|) + gamma2 exp(-k d_i)) R_i v,  d_i = |o_i - x|

Every term is ``r_i_hat x v``, so ``lambda* = Omega x v`` with ``Omega = sum_i c_i r_i_hat``: the
coupling only turns the velocity and does no work, which is why convergence to g is kept
(Eq. 28-29). The integrator uses this form and applies it as an exact rotation of v.

2D vectors are treated as 3D with z = 0 (``r_i`` is along z). When ``v`` is parallel to
``o_i - x``, ``r_i`` vanishes; we then take ``r_i_hat = +z`` in 2D (turn left) and in 3D the unit
vector ``e x v / |e x v|`` for the coordinate axis ``e`` least aligned with ``v``, so the
Eq. 26 term still pushes sideways.
"""

from __future__ import annotations

from dataclasses import dataclass

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class ObstacleGains:
    """
    Gains of the obstacle coupling.

    ``gamma`` and ``beta`` are the steering gains of Eq. 24 (Hoffmann et al. used gamma = 1000,
    beta = 20/pi). ``gamma2`` and ``k`` are the gain and decay of the distance term of Eq. 26.
    ``k`` is in 1/length; None means ``k_relative / |x0 - g|``, i.e. the repulsion decays over a
    fixed fraction of the movement's size, which keeps defaults meaningful for letters in demo
    units and for motions in metres alike.

    The defaults were chosen on the paper's four letters, 3 starts each, with one or two obstacle
    points placed on the obstacle-free ET-DMP path (36 runs): smallest clearance 7 % of the letter
    size, median nRMSE 0.23 (0.001 without obstacles), goal reached within 0.4 % of the size.
    Hoffmann's gamma = 1000 cleared no better and bent the letters more (median nRMSE 0.25).

    The default avoidance of obstacles with a size, the detour (docs/design.md#obstacles-with-a-
    size), uses only the last two: ``clearance_margin``, the extra clearance it aims for beyond
    each radius and the distance within which an obstacle acts at all, as a fraction of the
    movement's size (its largest distance from the goal); ``ramp``, the arc length over which
    the detour leaves and rejoins the obstacle-free plan, in units of the radius plus margin.
    """

    gamma: float = 250.0
    beta: float = 20.0 / np.pi
    gamma2: float = 300.0
    k: float | None = None
    k_relative: float = 10.0
    clearance_margin: float = 0.005
    ramp: float = 1.0
    detour_acceleration: float = 1.0

    def decay(self, length_scale: float | Array) -> float | Array:
        """
        Return ``k`` (1/length) for movements whose start-goal distance is ``length_scale``.

        A float for a number, an array for an array of them.
        """
        if np.ndim(length_scale):
            scale = np.asarray(length_scale, dtype=float)
            if self.k is not None:
                return np.full(scale.shape, float(self.k))
            return self.k_relative / np.maximum(scale, 1e-300)
        if self.k is not None:
            return float(self.k)
        return self.k_relative / max(float(length_scale), 1e-300)

    def validate(self) -> None:
        """Raise ValueError unless every gain is finite and non-negative."""
        for name in ('gamma', 'beta', 'gamma2', 'k_relative', 'clearance_margin', 'ramp',
                     'detour_acceleration'):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0.0:
                raise ValueError(f'obstacle gain {name} must be finite and >= 0, got {value!r}')
        if self.k is not None and (not np.isfinite(self.k) or self.k < 0.0):
            raise ValueError(f'obstacle gain k must be finite and >= 0, got {self.k!r}')


def _as3(a: ArrayLike) -> Array:
    """Embed (..., 2) vectors in 3D with z = 0; leave (..., 3) as they are."""
    a = np.asarray(a, dtype=float)
    if a.shape[-1] == 3:
        return a
    return np.concatenate([a, np.zeros(a.shape[:-1] + (1,))], axis=-1)


def steering_axis(x: Array, v: ArrayLike, obstacles: ArrayLike, goal: ArrayLike,
                  gamma: float, beta: float, gamma2: float,
                  k: float | Array) -> Array:
    """
    ``Omega`` (..., 3) such that ``lambda* = Omega x v`` (Eq. 22-27 with the safe region).

    ``x``, ``v``, ``goal``: (..., d) with d in (2, 3); ``obstacles``: (..., n_obs, d).
    """
    x3, v3, g3, o3 = _as3(x), _as3(v), _as3(goal), _as3(obstacles)
    to_obs = o3 - x3[..., None, :]
    dist = np.linalg.norm(to_obs, axis=-1)
    speed = np.linalg.norm(v3, axis=-1)[..., None]
    active = (dist < np.linalg.norm(x3 - g3, axis=-1)[..., None]) & (speed > 0.0) & (dist > 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        cos_phi = np.einsum('...ni,...i->...n', to_obs, v3) / (dist * speed)
    phi = np.arccos(np.clip(np.nan_to_num(cos_phi), -1.0, 1.0))
    r = np.cross(to_obs, v3[..., None, :])
    r_norm = np.linalg.norm(r, axis=-1, keepdims=True)
    fallback = np.broadcast_to(_fallback_axis(v3, x.shape[-1] == 2)[..., None, :], r.shape)
    scale = np.maximum(speed[..., None], 1e-300)
    r_hat = np.where(r_norm > 1e-12 * scale * np.maximum(dist[..., None], 1e-300),
                     r / np.maximum(r_norm, 1e-300), fallback)
    c = gamma * phi * np.exp(-beta * np.abs(phi)) + gamma2 * np.exp(-k * dist)
    c = np.where(active, c, 0.0)
    return np.einsum('...n,...ni->...i', c, r_hat)


def _fallback_axis(v3: Array, planar: bool) -> Array:
    """Deterministic unit axis perpendicular to v for when v points straight at an obstacle."""
    if planar:
        return np.broadcast_to(np.array([0.0, 0.0, 1.0]), v3.shape)
    e = np.zeros(v3.shape)
    idx = np.argmin(np.abs(v3), axis=-1)
    np.put_along_axis(e, idx[..., None], 1.0, axis=-1)
    axis = np.cross(e, v3)
    return axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-300)


def obstacle_coupling(x: Array, v: ArrayLike, obstacles: ArrayLike,
                      goal: ArrayLike, gains: ObstacleGains = ObstacleGains(),
                      length_scale: float | Array = 1.0) -> Array:
    """
    Compute the coupling term lambda* (Eq. 27) in the same dimension as ``x`` (2 or 3).

    ``length_scale`` sets the default decay ``k`` (see ObstacleGains).
    """
    omega = steering_axis(x, v, obstacles, goal, gains.gamma, gains.beta, gains.gamma2,
                          gains.decay(length_scale))
    lam = np.cross(omega, _as3(v))
    return lam[..., :np.asarray(x).shape[-1]]

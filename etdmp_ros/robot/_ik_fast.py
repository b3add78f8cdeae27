"""
numba kernels of one control step: the fast path of DifferentialIK and TrajectoryController.

Each kernel has a readable numpy twin (``DifferentialIK.solve(..., fast=False)``,
``PoseTrajectory.pose``, ``pinocchio.log3``) that tests use as the oracle. numba here has no
LAPACK (that needs SciPy), so the 6x6 SVD is a one-sided Jacobi (Hestenes) SVD: for ``A = J``,
plane rotations ``V`` make the columns of ``J V`` orthogonal; their norms are the singular values
and ``J V = U S``. Damped least squares then needs no ``U``:
``qd = V diag(s / (s^2 + l^2)) U^T xi = V diag(1 / (s^2 + l^2)) (J V)^T xi``.
Without numba :data:`AVAILABLE` is False and callers use the numpy path.

Why this module stays (measured against its numpy twins, 2 shared cores, other work running):

- ``.venv-bench/bin/python test/benchmarks/bench_controller.py --no-ros`` (G, 125 Hz, plant one
  period late), per ``TrajectoryController.step``, p50 / p99: numba 25.8 / 62.6 us, numpy
  102.0 / 213.5 us (194 us p99 in a second run); IK core (kinematics + solve) 12.5 / 28.7 vs
  54.5 / 113.8 us. pin-pink ``solve_ik`` 98.3 / 216.8 us (quadprog), 103.2 / 208.7 us (daqp):
  pink / ours at p50 is 4.0x with numba and 1.0x with numpy. The numpy step misses both
  targets (p99 <= 200 us, >= 3x cheaper than pink); tracking is the same to 0.1 um.
- ``test/benchmarks/bench_system.py --runs 3 --skills G --load idle busy`` (controller numpy
  only through a switch that existed for this measurement), medians, controller CPU (cores):
  125 Hz idle 0.126 numba / 0.133 numpy, busy 0.117 / 0.144; 500 Hz idle 0.292 / 0.374. The
  whole loop's sum at 125 Hz varies more from run to run than that (0.80 to 0.85 cores both
  ways); at 500 Hz 1.23 / 1.33 cores.
- Compilation: :func:`warm_up` takes 7.9 s with an empty numba cache (a fresh machine, once),
  0.2 s loading the cache.
"""

from __future__ import annotations

from collections.abc import Callable
import math
from typing import Any, cast, TypeVar

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import NDArray

try:  # The fast path is optional: without numba the numpy path serves.
    import numba
except ImportError:  # pragma: no cover - numba is pinned in requirements
    numba = None  # type: ignore[assignment]

AVAILABLE = numba is not None
_F = TypeVar('_F', bound=Callable[..., Any])


def _njit(function: _F) -> _F:
    return cast(_F, numba.njit(cache=True, fastmath=False)(function)) if AVAILABLE else function


@_njit
def jacobi_svd(jac: Array, av: Array, v: Array) -> Array:
    """
    Fill ``av`` = J V (orthogonal columns) and ``v`` = V; return the singular values (6,).

    One-sided Jacobi: sweep the column pairs, rotating each pair to orthogonality, until every
    pair's cosine is below 1e-15 (a 6x6 converges in about 6 sweeps).
    """
    n = jac.shape[1]
    av[:, :] = jac
    v[:, :] = 0.0
    for i in range(n):
        v[i, i] = 1.0
    for _ in range(60):
        rotated = False
        for p in range(n - 1):
            for q in range(p + 1, n):
                alpha = 0.0
                beta = 0.0
                gamma = 0.0
                for k in range(av.shape[0]):
                    alpha += av[k, p] * av[k, p]
                    beta += av[k, q] * av[k, q]
                    gamma += av[k, p] * av[k, q]
                if gamma == 0.0 or abs(gamma) <= 1e-15 * math.sqrt(alpha * beta):
                    continue
                rotated = True
                zeta = (beta - alpha) / (2.0 * gamma)
                t = (1.0 if zeta >= 0.0 else -1.0) / (abs(zeta) + math.sqrt(1.0 + zeta * zeta))
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = c * t
                for k in range(av.shape[0]):
                    a_p = av[k, p]
                    a_q = av[k, q]
                    av[k, p] = c * a_p - s * a_q
                    av[k, q] = s * a_p + c * a_q
                for k in range(n):
                    v_p = v[k, p]
                    v_q = v[k, q]
                    v[k, p] = c * v_p - s * v_q
                    v[k, q] = s * v_p + c * v_q
        if not rotated:
            break
    sigma = np.empty(n)
    for j in range(n):
        total = 0.0
        for k in range(av.shape[0]):
            total += av[k, j] * av[k, j]
        sigma[j] = math.sqrt(total)
    return sigma


@_njit
def dls(jac: Array, xi: Array, z: Array, threshold: float, max_damping: float,
        out: Array) -> tuple[float, float]:
    """
    Write the damped least-squares solution (plus null-space term of ``z``) to ``out``.

    Returns (condition number, lambda^2). ``z``: the posture velocity (zeros for none).
    """
    av = np.empty((6, 6))
    v = np.empty((6, 6))
    sigma = jacobi_svd(jac, av, v)
    s_max = sigma.max()
    s_min = sigma.min()
    kappa = s_max / s_min if s_min > 0.0 else np.inf
    lam2 = 0.0
    if s_min < threshold:
        ratio = s_min / threshold
        lam2 = max_damping * max_damping * (1.0 - ratio * ratio)
    coef = np.empty(6)
    for j in range(6):
        projection = 0.0
        for k in range(6):
            projection += av[k, j] * xi[k]
        denom = sigma[j] * sigma[j] + lam2
        coef[j] = projection / denom if denom > 0.0 else 0.0
        if lam2 > 0.0:
            vz = 0.0
            for k in range(6):
                vz += v[k, j] * z[k]
            coef[j] += lam2 / denom * vz
    for i in range(6):
        total = 0.0
        for j in range(6):
            total += v[i, j] * coef[j]
        out[i] = total
    return kappa, lam2


@_njit
def limit(qd: Array, previous: Array, q: Array, velocity_limits: Array, max_dv: Array,
          acceleration_limits: Array, lower: Array, upper: Array, period: float,
          out: Array) -> tuple[float, int, float]:
    """
    Scale ``qd`` into the velocity, then acceleration limits (common factors) into ``out``.

    Returns (scale, joint that could not stop before its limit or -1, its stopping position).
    """
    ratio = 0.0
    for i in range(6):
        ratio = max(ratio, abs(qd[i]) / velocity_limits[i])
    scale = 1.0 / ratio if ratio > 1.0 else 1.0
    ratio = 0.0
    for i in range(6):
        out[i] = qd[i] * scale
        ratio = max(ratio, abs(out[i] - previous[i]) / max_dv[i])
    if ratio > 1.0:
        scale /= ratio
        for i in range(6):
            out[i] = previous[i] + (out[i] - previous[i]) / ratio
    t_stop = 0.0
    for i in range(6):
        t_stop = max(t_stop, abs(out[i]) / acceleration_limits[i])
    horizon = 2.0 * period + 0.5 * (t_stop + period)
    for i in range(6):
        stop = q[i] + out[i] * horizon
        if (out[i] > 0.0 and stop > upper[i]) or (out[i] < 0.0 and stop < lower[i]):
            return scale, i, stop
    return scale, -1, 0.0


@_njit
def log3(r: Array, out: Array, offset: int) -> None:
    """Write the rotation vector (axis times angle) of rotation ``r`` to ``out[offset:+3]``."""
    cos = 0.5 * (r[0, 0] + r[1, 1] + r[2, 2] - 1.0)
    cos = min(1.0, max(-1.0, cos))
    angle = math.acos(cos)
    wx = r[2, 1] - r[1, 2]
    wy = r[0, 2] - r[2, 0]
    wz = r[1, 0] - r[0, 1]
    if angle < 1e-4:
        k = 0.5 + angle * angle / 12.0          # angle / (2 sin angle), to second order
        out[offset] = k * wx
        out[offset + 1] = k * wy
        out[offset + 2] = k * wz
    elif angle < math.pi - 1e-4:
        k = angle / (2.0 * math.sin(angle))
        out[offset] = k * wx
        out[offset + 1] = k * wy
        out[offset + 2] = k * wz
    else:
        # Near pi: the axis from the diagonal (R + I = 2 n n^T + O(pi - angle)).
        axis = np.empty(3)
        for i in range(3):
            axis[i] = math.sqrt(max(0.0, 0.5 * (r[i, i] + 1.0)))
        j = 0
        if axis[1] > axis[j]:
            j = 1
        if axis[2] > axis[j]:
            j = 2
        for i in range(3):
            if i != j:
                axis[i] = (r[i, j] + r[j, i]) / (4.0 * axis[j])
        w = (wx, wy, wz)
        sign = 1.0 if w[j] * axis[j] >= 0.0 else -1.0
        norm = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
        for i in range(3):
            out[offset + i] = sign * angle * axis[i] / norm


@_njit
def mul_transposed(a: Array, b: Array, out: Array) -> None:
    """Write ``a b^T`` of 3x3 matrices to ``out`` (numba's ``@`` needs SciPy's BLAS)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@_njit
def twist(p_a: Array, r_a: Array, p_b: Array, r_b: Array, p_hat: Array, r_hat: Array,
          period: float, kp: float, ko: float, out: Array) -> None:
    """Write the commanded tool twist: secant feed-forward plus pose-error feedback."""
    rel = np.empty((3, 3))
    mul_transposed(r_b, r_a, rel)
    log3(rel, out, 3)
    err = np.empty(6)
    mul_transposed(r_a, r_hat, rel)
    log3(rel, err, 3)
    for i in range(3):
        out[i] = (p_b[i] - p_a[i]) / period + kp * (p_a[i] - p_hat[i])
        out[3 + i] = out[3 + i] / period + ko * err[3 + i]


@_njit
def exp3(w: Array, out: Array) -> None:
    """Write the rotation matrix exp([w]x) (Rodrigues) to ``out``."""
    angle = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    if angle < 1e-8:
        a = 1.0 - angle * angle / 6.0
        b = 0.5 - angle * angle / 24.0
    else:
        a = math.sin(angle) / angle
        b = (1.0 - math.cos(angle)) / (angle * angle)
    x, y, z = w[0], w[1], w[2]
    out[0, 0] = 1.0 - b * (y * y + z * z)
    out[0, 1] = -a * z + b * x * y
    out[0, 2] = a * y + b * x * z
    out[1, 0] = a * z + b * x * y
    out[1, 1] = 1.0 - b * (x * x + z * z)
    out[1, 2] = -a * x + b * y * z
    out[2, 0] = -a * y + b * x * z
    out[2, 1] = a * x + b * y * z
    out[2, 2] = 1.0 - b * (x * x + y * y)


@_njit
def hermite_pose(times: Array, positions: Array, coeffs: Array, rotations: Array, twists: Array,
                 t: float, p_out: Array, r_out: Array) -> None:
    """Write the pose of a PoseTrajectory at ``t`` (see ``PoseTrajectory.pose``)."""
    n = times.shape[0]
    if t <= 0.0 or n == 1:
        p_out[:] = positions[0]
        r_out[:, :] = rotations[0]
        return
    if t >= times[n - 1]:
        p_out[:] = positions[n - 1]
        r_out[:, :] = rotations[n - 1]
        return
    i = min(np.searchsorted(times, t, side='right') - 1, n - 2)
    s = (t - times[i]) / (times[i + 1] - times[i])
    for k in range(3):
        p_out[k] = coeffs[i, 0, k] + s * (coeffs[i, 1, k] + s * (coeffs[i, 2, k]
                                                                 + s * coeffs[i, 3, k]))
    w = np.empty(3)
    for k in range(3):
        w[k] = s * twists[i, k]
    rot = np.empty((3, 3))
    exp3(w, rot)
    for a in range(3):
        for b in range(3):
            r_out[a, b] = (rot[a, 0] * rotations[i, 0, b] + rot[a, 1] * rotations[i, 1, b]
                           + rot[a, 2] * rotations[i, 2, b])


@_njit
def delay_costs(commands: Array, index: NDArray[np.int64], frac: Array, dq: Array, period: float,
                forgetting: float, costs: Array) -> tuple[float, np.intp]:
    """
    Update the delay candidates' forgetting costs with one measured displacement.

    Returns (squared command change of this step, index of the cheapest candidate).
    """
    for g in range(index.shape[0]):
        i = index[g]
        f = frac[g]
        total = 0.0
        for k in range(6):
            model = period * ((1.0 - f) * commands[i, k] + f * commands[i + 1, k])
            d = model - dq[k]
            total += d * d
        costs[g] = forgetting * costs[g] + total
    change = 0.0
    for k in range(6):
        d = period * (commands[0, k] - commands[1, k])
        change += d * d
    return change, np.argmin(costs)


@_njit
def in_flight(commands: Array, delay: float, period: float, out: Array) -> None:
    """Write the joint motion still to come from sent commands (see DelayEstimator)."""
    for k in range(6):
        out[k] = 0.0
    for m in range(commands.shape[0]):
        overlap = min(delay - m, delay) - max(delay - 1.0 - m, 0.0)
        overlap = min(1.0, max(0.0, overlap))
        if overlap > 0.0:
            for k in range(6):
                out[k] += period * overlap * commands[m, k]


def warm_up() -> None:
    """Compile (or load from the cache) every kernel now, not in the first control step."""
    if not AVAILABLE:
        return
    jac = np.eye(6)
    out = np.zeros(6)
    dls(jac, out, out, 0.1, 0.1, out)
    limit(out, out, out, np.ones(6), np.ones(6), np.ones(6), -np.ones(6), np.ones(6), 0.01,
          out)
    twist(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3), np.zeros(3), np.eye(3), 0.01, 1.0,
          1.0, out)
    times = np.array([0.0, 1.0])
    hermite_pose(times, np.zeros((2, 3)), np.zeros((1, 4, 3)),
                 np.repeat(np.eye(3)[None], 2, axis=0), np.zeros((1, 3)), 0.5, np.zeros(3),
                 np.eye(3))
    commands = np.zeros((4, 6))
    delay_costs(commands, np.zeros(2, dtype=np.int64), np.zeros(2), out, 0.01, 0.9, np.zeros(2))
    mul_transposed(np.eye(3), np.eye(3), np.eye(3))
    in_flight(commands, 0.5, 0.01, out)

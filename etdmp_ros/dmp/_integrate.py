"""
Rollout of the transformation system, batched over starts.

In the virtual situation each dimension obeys (v = tau dx/dt)::

    tau dv/dt = K (g - x) - D v + A s(t) + M f(s(t)) + Omega(x, v) x v
    tau dx/dt = v

``A`` and ``M`` (per start and dimension) express both formulations: Ijspeert uses A = 0 and
M = spatial scale; Hoffmann uses A = -K (g - x0) and M = K. The linear part is integrated exactly
(zero-order hold over a sub-step, with the phase-dependent forcing taken at the sub-step's midpoint
and precomputed for all sub-steps at once); the obstacle coupling, which only turns v, is
applied as an exact rotation of v after each sub-step, so it never adds energy.

Two implementations: a readable numpy reference (the oracle in tests) and a numba step loop (the
fast path, used when numba is importable). Both start from a given state (``x0`` and, optionally,
``v0``), so the same loop serves a whole offline rollout and, with two output samples, one step of
the online rollout (``_online.py``): the DMP equations are written here once.
"""

from __future__ import annotations

import functools

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike

from ._obstacles import steering_axis

#: Longest sub-step of the integrator, as a fraction of tau.
MAX_SUBSTEP = 1e-3

try:  # The fast path is optional: without numba the reference path serves.
    import numba
except ImportError:  # pragma: no cover - numba is pinned in requirements
    numba = None  # type: ignore[assignment]

#: The obstacle coupling's gains as the rollouts take them: (gamma, beta, gamma2, k), ``k``
#: (1/length) one per system (B,) or one for all.
Gains = tuple[float, float, float, ArrayLike]
#: The exact step of :func:`discretize`: (Phi (2, 2), Gamma (2,)).
Step = tuple[Array, Array]
#: Positions, velocities and accelerations, each (B, n, d) (or (N, d) for :func:`chain`).
Samples = tuple[Array, Array, Array]


def _expm(a: Array) -> Array:
    """Matrix exponential of a small matrix by scaling and squaring of a Taylor series."""
    norm = np.abs(a).sum(axis=1).max()
    squarings = max(0, int(np.ceil(np.log2(norm))) + 1) if norm > 0.5 else 0
    a = a / 2.0 ** squarings
    result = np.eye(len(a))
    term = np.eye(len(a))
    for i in range(1, 20):
        term = term @ a / i
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


@functools.lru_cache(maxsize=64)
def _discretized(K: float, D: float, tau: float, h: float) -> Step:
    phi, gam = _discretize(K, D, tau, h)
    phi.flags.writeable = gam.flags.writeable = False
    return phi, gam


def discretize(K: float, D: float, tau: float, h: float) -> Step:
    """Exact zero-order-hold step (Phi (2, 2), Gamma (2,)) of ``z = (x, v)`` over ``h`` seconds."""
    return _discretized(float(K), float(D), float(tau), float(h))


def _discretize(K: float, D: float, tau: float, h: float) -> Step:
    aug = np.zeros((3, 3))
    aug[:2, :2] = np.array([[0.0, 1.0], [-K, -D]]) / tau
    aug[1, 2] = 1.0 / tau
    e = _expm(aug * h)
    return e[:2, :2].copy(), e[:2, 2].copy()


def _rotate(v: Array, omega: Array, angle_scale: float) -> Array:
    """Rotate each v (B, d) about omega (B, 3) by |omega| * angle_scale (Rodrigues)."""
    d = v.shape[1]
    v3 = v if d == 3 else np.concatenate([v, np.zeros((len(v), 1))], axis=1)
    norm = np.linalg.norm(omega, axis=1, keepdims=True)
    k = omega / np.maximum(norm, 1e-300)
    angle = norm * angle_scale
    kxv = np.cross(k, v3)
    out = v3 * np.cos(angle) + kxv * np.sin(angle) + k * (k * v3).sum(1, keepdims=True) * (
        1.0 - np.cos(angle))
    return out[:, :d]


def rollout_reference(x0: Array, goal: Array, A: Array, M: Array, s_mid: Array, f_mid: Array,
                      s_out: Array, f_out: Array, obstacles: Array, gains: Gains, K: float,
                      D: float, tau: float, h: float, substeps: int, R: Array,
                      v0: ArrayLike | None = None) -> Samples:
    """
    Numpy reference rollout in the virtual situation, returned in the real one.

    Shapes: x0 (virtual start), goal, A, M (B, d); s_mid (n_sub,); f_mid (n_sub, d); s_out (n,);
    f_out (n, d); obstacles (B, n_obs, d), virtual; gains (gamma, beta, gamma2, k (B,));
    R (B, d, d) the Euclidean transform; v0 (B, d) the virtual scaled velocity ``tau dx'/dt`` at
    the start (None: at rest). Returns positions, velocities dx/dt and accelerations, each
    (B, n, d), mapped back with ``x = R^T (x' - g) + g`` (Eq. 13-14).
    """
    phi, gam = discretize(K, D, tau, h)
    B, d = x0.shape
    n = len(s_out)
    X, V, Acc = (np.empty((B, n, d)) for _ in range(3))
    x = x0.copy()
    v = np.zeros((B, d)) if v0 is None else np.array(v0, dtype=float)
    have_obstacles = obstacles.shape[1] > 0
    gamma, beta, gamma2, k = gains
    k = np.asarray(k, dtype=float)[:, None]

    def omega_at(x: Array, v: Array) -> Array:
        return steering_axis(x, v, obstacles, goal, gamma, beta, gamma2, k)

    for i in range(n):
        lam: float | Array = 0.0
        if have_obstacles:
            lam = np.cross(omega_at(x, v), v if d == 3 else np.c_[v, np.zeros(B)])[:, :d]
        X[:, i], V[:, i] = x, v / tau
        Acc[:, i] = (K * (goal - x) - D * v + A * s_out[i] + M * f_out[i] + lam) / tau ** 2
        if i == n - 1:
            break
        for j in range(i * substeps, (i + 1) * substeps):
            u = K * goal + A * s_mid[j] + M * f_mid[j]
            x, v = (phi[0, 0] * x + phi[0, 1] * v + gam[0] * u,
                    phi[1, 0] * x + phi[1, 1] * v + gam[1] * u)
            if have_obstacles:
                v = _rotate(v, omega_at(x, v), h / tau)
    g = goal[:, None]
    return (X - g) @ R + g, V @ R, Acc @ R


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _omega_nb(x: Array, v: Array, obs: Array, g: Array, gamma: float, beta: float,
                  gamma2: float, k: float, d: int, out: Array) -> None:
        """Steering axis Omega (3,) for one state; mirrors _obstacles.steering_axis."""
        out[0] = out[1] = out[2] = 0.0
        x2 = x[2] if d == 3 else 0.0
        v2 = v[2] if d == 3 else 0.0
        g2 = g[2] if d == 3 else 0.0
        speed = np.sqrt(v[0] ** 2 + v[1] ** 2 + v2 ** 2)
        to_goal = np.sqrt((x[0] - g[0]) ** 2 + (x[1] - g[1]) ** 2 + (x2 - g2) ** 2)
        if speed <= 0.0:
            return
        for j in range(obs.shape[0]):
            o0 = obs[j, 0] - x[0]
            o1 = obs[j, 1] - x[1]
            o2 = (obs[j, 2] - x2) if d == 3 else 0.0
            dist = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
            if not (dist < to_goal) or dist <= 0.0:
                continue
            c = (o0 * v[0] + o1 * v[1] + o2 * v2) / (dist * speed)
            phi = np.arccos(min(1.0, max(-1.0, c)))
            r0 = o1 * v2 - o2 * v[1]
            r1 = o2 * v[0] - o0 * v2
            r2 = o0 * v[1] - o1 * v[0]
            rn = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            if rn <= 1e-12 * speed * dist:
                if d == 2:
                    r0, r1, r2 = 0.0, 0.0, 1.0
                else:
                    # e x v for the axis e least aligned with v.
                    a0, a1, a2 = abs(v[0]), abs(v[1]), abs(v2)
                    if a0 <= a1 and a0 <= a2:
                        r0, r1, r2 = 0.0, -v2, v[1]
                    elif a1 <= a2:
                        r0, r1, r2 = v2, 0.0, -v[0]
                    else:
                        r0, r1, r2 = -v[1], v[0], 0.0
                rn = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            w = (gamma * phi * np.exp(-beta * abs(phi)) + gamma2 * np.exp(-k * dist)) / rn
            out[0] += w * r0
            out[1] += w * r1
            out[2] += w * r2

    @numba.njit(cache=True, fastmath=False)
    def _turn_nb(x: Array, v: Array, obstacles: Array, g: Array, gamma: float, beta: float,
                 gamma2: float, k: float, angle_scale: float, d: int, om: Array) -> None:
        """Turn v in place by the obstacle coupling's rotation over one sub-step."""
        _omega_nb(x, v, obstacles, g, gamma, beta, gamma2, k, d, om)
        norm = np.sqrt(om[0] ** 2 + om[1] ** 2 + om[2] ** 2)
        if norm > 0.0:
            k0, k1, k2 = om[0] / norm, om[1] / norm, om[2] / norm
            ang = norm * angle_scale
            ca, sa = np.cos(ang), np.sin(ang)
            v0, v1 = v[0], v[1]
            v2 = v[2] if d == 3 else 0.0
            kv = k0 * v0 + k1 * v1 + k2 * v2
            v[0] = v0 * ca + (k1 * v2 - k2 * v1) * sa + k0 * kv * (1.0 - ca)
            v[1] = v1 * ca + (k2 * v0 - k0 * v2) * sa + k1 * kv * (1.0 - ca)
            if d == 3:
                v[2] = v2 * ca + (k0 * v1 - k1 * v0) * sa + k2 * kv * (1.0 - ca)

    @numba.njit(cache=True, fastmath=False)
    def _substep_nb(x: Array, v: Array, g: Array, A: Array, M: Array, s: float, f: Array,
                    obstacles: Array, gamma: float, beta: float, gamma2: float, k: float, K: float,
                    phi: Array, gam: Array, angle_scale: float, d: int, om: Array) -> None:
        """One sub-step of one system in place: the exact linear update, then the turn of v."""
        for i in range(d):
            u = K * g[i] + A[i] * s + M[i] * f[i]
            xi = x[i]
            x[i] = phi[0, 0] * xi + phi[0, 1] * v[i] + gam[0] * u
            v[i] = phi[1, 0] * xi + phi[1, 1] * v[i] + gam[1] * u
        if obstacles.shape[0] > 0:
            _turn_nb(x, v, obstacles, g, gamma, beta, gamma2, k, angle_scale, d, om)

    @numba.njit(cache=True, fastmath=False)
    def _rollout_nb(x0: Array, goal: Array, A: Array, M: Array, s_mid: Array, f_mid: Array,
                    s_out: Array, f_out: Array, obstacles: Array, gamma: float, beta: float,
                    gamma2: float, k: Array, K: float, D: float, tau: float, phi: Array,
                    gam: Array, angle_scale: float, substeps: int, R: Array, vel0: Array, X: Array,
                    V: Array, Acc: Array) -> None:
        # Scalars and indices only in the loops: an array view per sub-step (goal[b], f_mid[j])
        # costs more than the sub-step's arithmetic (the batch ran 4x slower per system).
        B, d = x0.shape
        n = s_out.shape[0]
        n_obs = obstacles.shape[1]
        x = np.empty(d)
        v = np.empty(d)
        acc = np.empty(d)
        om = np.zeros(3)
        p00, p01, p10, p11 = phi[0, 0], phi[0, 1], phi[1, 0], phi[1, 1]
        g0, g1 = gam[0], gam[1]
        tau2 = tau * tau
        for b in range(B):
            for i in range(d):
                x[i] = x0[b, i]
                v[i] = vel0[b, i]
            for step in range(n):
                lam0 = lam1 = lam2 = 0.0
                if n_obs > 0:
                    _omega_nb(x, v, obstacles[b], goal[b], gamma, beta, gamma2, k[b], d, om)
                    v2 = v[2] if d == 3 else 0.0
                    lam0 = om[1] * v2 - om[2] * v[1]
                    lam1 = om[2] * v[0] - om[0] * v2
                    lam2 = om[0] * v[1] - om[1] * v[0]
                for i in range(d):
                    lam = lam0 if i == 0 else (lam1 if i == 1 else lam2)
                    acc[i] = (K * (goal[b, i] - x[i]) - D * v[i] + A[b, i] * s_out[step]
                              + M[b, i] * f_out[step, i] + lam) / tau2
                for j in range(d):
                    # Back to the real situation: x = R^T (x' - g) + g (Eq. 13-14).
                    xj = goal[b, j]
                    vj = 0.0
                    aj = 0.0
                    for i in range(d):
                        xj += R[b, i, j] * (x[i] - goal[b, i])
                        vj += R[b, i, j] * v[i] / tau
                        aj += R[b, i, j] * acc[i]
                    X[b, step, j] = xj
                    V[b, step, j] = vj
                    Acc[b, step, j] = aj
                if step == n - 1:
                    break
                for jj in range(step * substeps, (step + 1) * substeps):
                    sm = s_mid[jj]
                    for i in range(d):
                        u = K * goal[b, i] + A[b, i] * sm + M[b, i] * f_mid[jj, i]
                        xi = x[i]
                        x[i] = p00 * xi + p01 * v[i] + g0 * u
                        v[i] = p10 * xi + p11 * v[i] + g1 * u
                    if n_obs > 0:
                        _turn_nb(x, v, obstacles[b], goal[b], gamma, beta, gamma2, k[b],
                                 angle_scale, d, om)

    @numba.njit(cache=True, fastmath=False)
    def _chain_nb(x_real: Array, xd_real: Array, goal: Array, A: Array, M: Array, R: Array,
                  k: Array, s_mid: Array, f_mid: Array, s_out: Array, f_out: Array,
                  obstacles: Array, gamma: float, beta: float, gamma2: float, K: float, D: float,
                  tau: float, phi: Array, gam: Array, angle_scale: float, substeps: int, X: Array,
                  Xd: Array, Acc: Array) -> None:
        N, d = goal.shape
        n_obs = obstacles.shape[0]
        x = np.empty(d)
        v = np.empty(d)
        xr = x_real.copy()
        vr = xd_real * tau
        obs = np.empty((max(n_obs, 1), d))
        om = np.zeros(3)
        for n in range(N):
            g = goal[n]
            # Into the virtual situation of this step's placement: x' = R (x - g) + g, v' = R v.
            for i in range(d):
                x[i] = g[i]
                v[i] = 0.0
                for j in range(d):
                    x[i] += R[n, i, j] * (xr[j] - g[j])
                    v[i] += R[n, i, j] * vr[j]
            for m in range(n_obs):
                for i in range(d):
                    obs[m, i] = g[i]
                    for j in range(d):
                        obs[m, i] += R[n, i, j] * (obstacles[m, j] - g[j])
            for jj in range(n * substeps, (n + 1) * substeps):
                _substep_nb(x, v, g, A[n], M[n], s_mid[jj], f_mid[jj], obs[:n_obs], gamma, beta,
                            gamma2, k[n], K, phi, gam, angle_scale, d, om)
            lam0 = lam1 = lam2 = 0.0
            if n_obs > 0:
                _omega_nb(x, v, obs[:n_obs], g, gamma, beta, gamma2, k[n], d, om)
                v2 = v[2] if d == 3 else 0.0
                lam0 = om[1] * v2 - om[2] * v[1]
                lam1 = om[2] * v[0] - om[0] * v2
                lam2 = om[0] * v[1] - om[1] * v[0]
            for j in range(d):
                X[n, j] = g[j]
                Xd[n, j] = 0.0
                Acc[n, j] = 0.0
            for i in range(d):
                lam = lam0 if i == 0 else (lam1 if i == 1 else lam2)
                acc = (K * (g[i] - x[i]) - D * v[i] + A[n, i] * s_out[n]
                       + M[n, i] * f_out[n, i] + lam) / (tau * tau)
                for j in range(d):     # back to the real situation: x = R^T (x' - g) + g
                    X[n, j] += R[n, i, j] * (x[i] - g[i])
                    Xd[n, j] += R[n, i, j] * v[i] / tau
                    Acc[n, j] += R[n, i, j] * acc
            for j in range(d):
                xr[j] = X[n, j]
                vr[j] = Xd[n, j] * tau


def chain(x: ArrayLike, xd: ArrayLike, goal: Array, A: ArrayLike, M: ArrayLike, R: ArrayLike,
          k: ArrayLike, s_mid: ArrayLike, f_mid: ArrayLike, s_out: ArrayLike, f_out: ArrayLike,
          obstacles: ArrayLike, gains: tuple[float, float, float, object], K: float, D: float,
          tau: float, h: float, substeps: int, step: Step | None = None) -> Samples:
    """
    Advance one system N output steps, each in the virtual situation of its own placement.

    Step ``n`` maps the real state (``x``, ``xd = dx/dt`` at the start) into the virtual
    situation of (``goal[n]``, ``R[n]``, ``A[n]``, ``M[n]``, obstacle decay ``k[n]``), integrates
    one output step of ``substeps`` sub-steps (forcing at the midpoints ``s_mid``, ``f_mid``:
    N * substeps rows) and maps the new sample (forcing ``s_out[n]``, ``f_out[n]``) back: what
    N calls of :func:`rollout` with two output samples do, in one numba loop (the online
    rollout's remainder, ``OnlineRun.run``). ``obstacles`` (n_obs, d) in the real situation;
    ``gains`` as :func:`rollout` takes them, whose ``k`` is not used here. Returns X, Xd, Acc
    (N, d): the samples after each step. Needs numba. ``step`` may give
    ``discretize(K, D, tau, h)`` already computed.
    """
    phi, gam = discretize(K, D, tau, h) if step is None else step
    N, d = goal.shape
    X, Xd, Acc = (np.empty((N, d)) for _ in range(3))
    gamma, beta, gamma2, _ = gains
    f64 = np.ascontiguousarray
    _chain_nb(f64(x, float), f64(xd, float), f64(goal, float), f64(A, float), f64(M, float),
              f64(R, float), f64(k, float), f64(s_mid, float), f64(f_mid, float),
              f64(s_out, float), f64(f_out, float), f64(obstacles, float).reshape(-1, d),
              float(gamma), float(beta), float(gamma2), float(K), float(D), float(tau), phi,
              gam, h / tau, int(substeps), X, Xd, Acc)
    return X, Xd, Acc


def rollout(x0: Array, goal: Array, A: Array, M: Array, s_mid: Array, f_mid: Array, s_out: Array,
            f_out: Array, obstacles: Array, gains: Gains, K: float, D: float, tau: float, h: float,
            substeps: int, R: Array, fast: bool = True, v0: ArrayLike | None = None,
            step: Step | None = None) -> Samples:
    """
    Roll out B systems; same arguments and results as :func:`rollout_reference`.

    ``fast`` selects the numba step loop when numba is available. ``step`` may give
    ``discretize(K, D, tau, h)`` already computed (the online rollout caches it).
    """
    if not fast or numba is None:
        return rollout_reference(x0, goal, A, M, s_mid, f_mid, s_out, f_out, obstacles, gains,
                                 K, D, tau, h, substeps, R, v0)
    phi, gam = discretize(K, D, tau, h) if step is None else step
    B, d = x0.shape
    n = len(s_out)
    # One block for the three outputs: above 4 MiB numpy asks the kernel for huge pages, and
    # first touching 12 MB of 4 kB pages (a batch of 256 x 1000 steps) cost more than the loop.
    X, V, Acc = np.empty((3, B, n, d))
    gamma, beta, gamma2, k = gains
    f64 = np.ascontiguousarray
    _rollout_nb(f64(x0, float), f64(goal, float), f64(A, float), f64(M, float), f64(s_mid),
                f64(f_mid), f64(s_out), f64(f_out), f64(obstacles, float), float(gamma),
                float(beta), float(gamma2), f64(np.broadcast_to(k, (B,)), float), float(K),
                float(D), float(tau), phi, gam, h / tau, int(substeps), f64(R, float),
                np.zeros((B, d)) if v0 is None else f64(v0, float), X, V, Acc)
    return X, V, Acc

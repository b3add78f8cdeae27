"""
Canonical system and forcing term (paper Eq. 3-5, with the factor s and a gate).

The mathematics: docs/design.md#canonical-system-and-forcing-term and
docs/design.md#coming-to-rest.

The phase decays as ``tau ds/dt = -alpha s`` so ``s(t) = exp(-alpha t / tau)``. The forcing term is
``f(s) = s G(s) sum_i psi_i(s) w_i / sum_i psi_i(s)`` with Gaussian kernels
``psi_i(s) = exp(-h_i (s - c_i)^2)`` whose centres are spaced evenly in time (hence
exponentially in s) and whose widths follow from the spacing of neighbours. The gate ``G`` is 1
until ``(1 - GATE_WIDTH) tau`` and falls smoothly to 0 at ``t = tau``, where ``s = exp(-alpha)``:
the forcing vanishes at tau and stays 0 after it. Hoffmann's term ``-K (g - x0) s`` is made to end
at tau too (:func:`hoffmann_term`), so past tau every plan is the spring alone, at rest at its
goal.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from functools import lru_cache

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike

#: Timings whose forcing tables a ForcingTerm keeps (least recently made dropped first).
TABLE_CACHE_SIZE = 8
#: The gate's width, as a fraction of tau: it is 1 until (1 - GATE_WIDTH) tau and 0 from tau on.
GATE_WIDTH = 0.05
#: Hoffmann's term is its own until (1 - HOFFMANN_WIDTH) tau, and ends at tau.
HOFFMANN_WIDTH = 0.3
#: Steps of the normalised time on which Hoffmann's term is tabulated.
HOFFMANN_STEPS = 4000
#: Steps of the normalised time on which the fit's end condition is computed.
END_STEPS = 1000
#: A rollout's forcing table: (phase term at the sub-steps' midpoints, f there, phase term at
#: the samples, f there).
_Table = tuple[Array, Array, Array,
               Array]


def phase(t: ArrayLike, tau: float, alpha: float) -> Array:
    """Phase ``s(t) = exp(-alpha t / tau)`` (paper Eq. 5 integrated, s(0) = 1)."""
    return np.exp(-alpha * np.asarray(t, dtype=float) / tau)


def _smootherstep(x: ArrayLike) -> tuple[Array, Array, Array]:
    """Return S(x) = 6 x^5 - 15 x^4 + 10 x^3 on [0, 1] (0 below, 1 above) and S', S''."""
    x = np.clip(x, 0.0, 1.0)
    return (x ** 3 * (10.0 + x * (6.0 * x - 15.0)), 30.0 * x ** 2 * (1.0 - x) ** 2,
            60.0 * x * (1.0 - x) * (1.0 - 2.0 * x))


def _time(s: ArrayLike, alpha: float) -> Array:
    """Normalised time ``t / tau = -ln(s) / alpha`` of phases ``s`` (inf for s <= 0)."""
    with np.errstate(divide='ignore'):
        return -np.log(np.maximum(np.asarray(s, dtype=float), 0.0)) / alpha


def gate(s: ArrayLike, alpha: float, width: float = GATE_WIDTH) -> Array:
    """
    Return the gate ``G(s)``: 1 until ``(1 - width) tau``, 0 from ``t = tau`` (s = exp(-alpha)).

    In between it is the smootherstep ``S(x) = 6 x^5 - 15 x^4 + 10 x^3`` of
    ``x = (1 - t/tau) / width`` (the time read from the phase), so the gated forcing has a
    continuous second derivative and the plan's jerk stays continuous at tau.
    """
    x = np.clip((1.0 - _time(s, alpha)) / width, 0.0, 1.0)
    return x * x * x * (10.0 + x * (6.0 * x - 15.0))      # S(x) alone: rollouts call this


@lru_cache(maxsize=16)
def _hoffmann_table(K: float, D: float, alpha: float) -> tuple[Array, Array]:
    """Tabulate :func:`hoffmann_term` over the normalised time u in [0, 1]: (u, rho / K)."""
    from ._integrate import discretize      # the integrator's exact step (no import cycle)
    n = HOFFMANN_STEPS
    u = np.linspace(0.0, 1.0, n + 1)
    s = np.exp(-alpha * u)
    # Hoffmann's offset response y: y'' + D y' + K y = K s (u = t/tau), y(0) = 1, y'(0) = 0,
    # by the exact step with the input at each step's midpoint.
    phi, gam = discretize(K, D, 1.0, 1.0 / n)
    inputs = K * np.exp(-alpha * (u[:-1] + 0.5 / n))
    y, yd = np.empty(n + 1), np.empty(n + 1)
    y[0], yd[0] = 1.0, 0.0
    for k in range(n):
        y[k + 1] = phi[0, 0] * y[k] + phi[0, 1] * yd[k] + gam[0] * inputs[k]
        yd[k + 1] = phi[1, 0] * y[k] + phi[1, 1] * yd[k] + gam[1] * inputs[k]
    # The response made to end at u = 1: h = y G_h, G_h = 1 - S((u - 1 + w) / w); rho is the
    # input whose response is h: rho = K h + D h' + h'' = G_h K s + D y G_h' + 2 y' G_h' + y G_h''.
    w = HOFFMANN_WIDTH
    S, S1, S2 = _smootherstep((u - 1.0 + w) / w)
    G, G1, G2 = 1.0 - S, -S1 / w, -S2 / (w * w)
    rho = G * K * s + D * y * G1 + 2.0 * yd * G1 + y * G2
    rho[-1] = 0.0
    return u, rho / K


def hoffmann_term(s: ArrayLike, K: float, D: float, alpha: float) -> Array:
    """
    Return Hoffmann's phase term ``rho(s) / K``, with ``tau dv = ... - (g - x0) rho(s) + ...``.

    Hoffmann et al. (2009) use ``rho = K s``: it cancels the spring's pull at the start, and the
    learned forcing cancels it for the demonstration's own start. From another start, the offset
    ``delta = x0 - x0_D`` decays as the response ``y(t)`` of the spring to ``s`` (rho's
    response), which is still 4 % of ``delta`` at tau (decaying as s). Here rho is ``K s`` until
    ``(1 - HOFFMANN_WIDTH) tau``; then it is the input whose response is ``y G_h``, ``G_h`` a
    smootherstep from 1 to 0 at tau: the offset is carried to 0 at tau, the plan up to then is
    Hoffmann's own, and from tau on the term is 0 (docs/design.md#coming-to-rest).
    """
    return ForcingTerm(2, alpha, K, D).phase_term(s)


@lru_cache(maxsize=16)
def _end_condition(n_basis: int, alpha: float, K: float, D: float) -> tuple[
        Array, Array, Array, Array]:
    """
    Return (C (2, N), G (n, 2), P (2, 2), s (n,)): how the state at t = tau follows from F.

    For ``z'' + D z' + K z = F`` (in u = t/tau), ``z(0) = z0`` at rest, with ``F`` held over
    END_STEPS equal steps (the integrator's exact step, ``F_k`` at the phase ``s_k`` of step k's
    midpoint): ``(z, z')(1) = P (z0, 0) + sum_k G_k F_k``; for ``F = f(s)`` that sum is ``C w``.
    Cached: it depends on the basis and the spring only.
    """
    from ._integrate import discretize      # the integrator's exact step (no import cycle)
    n = END_STEPS
    phi, gam = discretize(K, D, 1.0, 1.0 / n)
    G = np.empty((n, 2))
    g = gam.copy()
    for k in range(n - 1, -1, -1):
        G[k] = g
        g = phi @ g
    s = np.exp(-alpha * (np.arange(n) + 0.5) / n)
    C = G.T @ ForcingTerm(n_basis, alpha, K, D).design_matrix(s)
    for array in (C, G, s):
        array.flags.writeable = False
    return C, G, np.linalg.matrix_power(phi, n), s


class ForcingTerm:
    """
    Normalised radial basis functions of the phase and their weights.

    ``weights`` has shape (n_basis, d); ``__call__`` evaluates f(s) for many phases at once,
    which is how rollouts precompute the forcing (the phase does not depend on the state).
    """

    def __init__(self, n_basis: int, alpha: float, K: float = 156.25, D: float = 25.0) -> None:
        if int(n_basis) < 2:
            raise ValueError(f'n_basis must be >= 2, got {n_basis}')
        self.n_basis = int(n_basis)
        self.alpha = float(alpha)
        self.K, self.D = float(K), float(D)     # the spring's, for Hoffmann's term
        # Centres evenly spaced in normalised time t/tau in [0, 1].
        self.centres = np.exp(-self.alpha * np.linspace(0.0, 1.0, self.n_basis))
        gaps = -np.diff(self.centres)
        # A kernel drops to exp(-1) at its neighbour's centre: enough overlap for a smooth fit.
        self.widths = 1.0 / np.append(gaps, gaps[-1]) ** 2
        self.weights = np.zeros((self.n_basis, 0))
        # timing -> (s_mid, f(s_mid), s_out, f(s_out))
        self._tables: OrderedDict[tuple[float, float, int, int], _Table] = OrderedDict()
        # (u, rho / K) of Hoffmann's term, made when first used
        self._hoffmann: tuple[Array, Array] | None = None
        # Phases above these: the gate is 1, Hoffmann's term is his own (K s).
        self._s_gate = float(np.exp(-self.alpha * (1.0 - GATE_WIDTH)))
        self._s_hoffmann = float(np.exp(-self.alpha * (1.0 - HOFFMANN_WIDTH)))

    def phase_term(self, s: ArrayLike) -> Array:
        """Return Hoffmann's phase term ``rho(s) / K`` (:func:`hoffmann_term`), shape (n,)."""
        s = np.asarray(s, dtype=float)
        if s.size and s.min() >= self._s_hoffmann:     # Hoffmann's own: an online step's case
            return s
        if self._hoffmann is None:
            self._hoffmann = _hoffmann_table(self.K, self.D, self.alpha)
        u, rho = self._hoffmann
        return np.where(s >= self._s_hoffmann, s, np.interp(_time(s, self.alpha), u, rho,
                                                            right=0.0))

    def design_matrix(self, s: ArrayLike) -> Array:
        """Regressors ``s G(s) psi_i(s) / sum_j psi_j(s)`` for phases ``s`` (shape (n, N))."""
        s = np.asarray(s, dtype=float)
        psi = np.exp(-self.widths * (s[:, None] - self.centres) ** 2)
        # Before the gate closes (an online step's case) it is 1: skip it.
        gated = s if s.size and s.min() >= self._s_gate else s * gate(s, self.alpha)
        # Kernels never all vanish inside [exp(-alpha), 1]; the floor guards phases far past it
        # (where the gate is 0 anyway).
        return gated[:, None] * psi / np.maximum(psi.sum(axis=1, keepdims=True), 1e-300)

    def fit(self, s: ArrayLike, f_target: Array, regularization: float = 1e-8,
            end: tuple[ArrayLike, float, Callable[[Array], Array] | None] | None = None) -> Array:
        """
        Fit the weights to ``f_target`` (shape (n, d)) by ridge-regularised least squares.

        One global least-squares problem fits overlapping kernels better than the paper's locally
        weighted regression; the small ridge keeps kernels that the data barely excite bounded.
        ``end = (z0, scale, extra)`` adds the end condition (docs/design.md#coming-to-rest):
        the system ``tau^2 z'' = -K z - D tau z' + scale f(s) + extra(s)`` (``z = x - g``,
        ``extra`` a callable of s returning (n, d), or None) started at rest from ``z0`` (d,)
        is at rest at ``z = 0`` at t = tau: two linear constraints per dimension on the
        weights, met exactly (Lagrange multipliers), so the reproduction ends at its goal at rest
        whatever the fit's residual there.
        """
        phi = self.design_matrix(s)
        gram = phi.T @ phi
        ridge = regularization * np.trace(gram) / self.n_basis
        matrix = gram + ridge * np.eye(self.n_basis)
        rhs = phi.T @ f_target
        if end is None:
            self.weights = np.linalg.solve(matrix, rhs)
        else:
            z0, scale, extra = end
            C, G, P, s_end = _end_condition(self.n_basis, self.alpha, self.K, self.D)
            C = scale * C
            free = np.outer(P[:, 0], np.asarray(z0, dtype=float))      # (2, d): without f
            if extra is not None:
                free = free + G.T @ extra(s_end)
            kkt = np.block([[matrix, C.T], [C, np.zeros((2, 2))]])
            self.weights = np.linalg.solve(kkt, np.vstack([rhs, -free]))[:self.n_basis]
        self._tables = OrderedDict()
        return self.weights

    def table(self, tau: float, dt: float, n_out: int, substeps: int) -> _Table:
        """
        Return (s_mid, f(s_mid), s_out, f(s_out)) of a rollout's timing, cached per timing.

        ``s_mid``: Hoffmann's phase term (:meth:`phase_term`, what multiplies ``A`` in the
        rollout) at the midpoints of the ``(n_out - 1) * substeps`` sub-steps of
        ``dt / substeps``; ``s_out``: at the ``n_out`` samples, ``dt`` apart, from t = 0. Refit
        weights clear the cache.
        """
        key = (tau, dt, n_out, substeps)
        tables = self._tables
        table = tables.get(key)
        if table is None:
            h = dt / substeps
            s_mid = phase((np.arange((n_out - 1) * substeps) + 0.5) * h, tau, self.alpha)
            s_out = phase(np.arange(n_out) * dt, tau, self.alpha)
            table = (self.phase_term(s_mid), self(s_mid), self.phase_term(s_out), self(s_out))
            tables[key] = table
            if len(tables) > TABLE_CACHE_SIZE:
                tables.popitem(last=False)
        return table

    def __call__(self, s: ArrayLike) -> Array:
        """Evaluate f(s) for phases ``s`` (shape (n,)); returns shape (n, d)."""
        return self.design_matrix(s) @ self.weights

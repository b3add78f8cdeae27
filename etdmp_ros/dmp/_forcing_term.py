"""
Canonical system and forcing term (paper Eq. 3-5, with the factor s and a gate).

The mathematics: docs/design.md#canonical-system-and-forcing-term and
docs/design.md#coming-to-rest.

The phase decays as ``tau ds/dt = -alpha s`` so ``s(t) = exp(-alpha t / tau)``. The forcing term is
``f(s) = s G(s) sum_i psi_i(s) w_i / sum_i psi_i(s)`` with Gaussian kernels
``psi_i(s) = exp(-h_i (s - c_i)^2)`` whose centres are spaced evenly in time (hence
exponentially in s) and whose widths follow from the spacing of neighbours. The gate ``G`` is 1
until ``(1 - GATE_WIDTH) tau`` and falls smoothly to 0 at ``t = tau``, where ``s = exp(-alpha)``:
the forcing, and Hoffmann's term ``-K (g - x0) s G(s)``, vanish at tau and stay 0 after it, so
past tau every plan is the spring alone and comes to rest at its goal.
"""

from collections import OrderedDict

import numpy as np

#: Timings whose forcing tables a ForcingTerm keeps (least recently made dropped first).
TABLE_CACHE_SIZE = 8
#: The gate's width, as a fraction of tau: it is 1 until (1 - GATE_WIDTH) tau and 0 from tau on.
GATE_WIDTH = 0.05


def phase(t, tau, alpha):
    """Phase ``s(t) = exp(-alpha t / tau)`` (paper Eq. 5 integrated, s(0) = 1)."""
    return np.exp(-alpha * np.asarray(t, dtype=float) / tau)


def gate(s, alpha, width=GATE_WIDTH):
    """
    Return the gate ``G(s)``: 1 until ``(1 - width) tau``, 0 from ``t = tau`` (s = exp(-alpha)).

    In between it is the smootherstep ``6 u^5 - 15 u^4 + 10 u^3`` of ``u = (1 - t/tau) / width``
    (the time read from the phase, ``t/tau = -ln(s) / alpha``), so the gated forcing has a
    continuous second derivative and the plan's jerk stays continuous at tau.
    """
    s = np.asarray(s, dtype=float)
    with np.errstate(divide='ignore'):
        u = (alpha + np.log(np.maximum(s, 0.0))) / (alpha * width)
    u = np.clip(u, 0.0, 1.0)
    return u * u * u * (10.0 + u * (6.0 * u - 15.0))


class ForcingTerm:
    """
    Normalised radial basis functions of the phase and their weights.

    ``weights`` has shape (n_basis, d); ``__call__`` evaluates f(s) for many phases at once,
    which is how rollouts precompute the forcing (the phase does not depend on the state).
    """

    def __init__(self, n_basis, alpha):
        if int(n_basis) < 2:
            raise ValueError(f'n_basis must be >= 2, got {n_basis}')
        self.n_basis = int(n_basis)
        self.alpha = float(alpha)
        # Centres evenly spaced in normalised time t/tau in [0, 1].
        self.centres = np.exp(-self.alpha * np.linspace(0.0, 1.0, self.n_basis))
        gaps = -np.diff(self.centres)
        # A kernel drops to exp(-1) at its neighbour's centre: enough overlap for a smooth fit.
        self.widths = 1.0 / np.append(gaps, gaps[-1]) ** 2
        self.weights = np.zeros((self.n_basis, 0))
        self._tables = OrderedDict()    # timing -> (s_mid, f(s_mid), s_out, f(s_out))

    def drive(self, s):
        """Return the gated phase ``s G(s)`` (shape (n,)): what scales the forcing's basis."""
        s = np.asarray(s, dtype=float)
        return s * gate(s, self.alpha)

    def design_matrix(self, s):
        """Regressors ``s G(s) psi_i(s) / sum_j psi_j(s)`` for phases ``s`` (shape (n, N))."""
        s = np.asarray(s, dtype=float)
        psi = np.exp(-self.widths * (s[:, None] - self.centres) ** 2)
        # Kernels never all vanish inside [exp(-alpha), 1]; the floor guards phases far past it
        # (where the gate is 0 anyway).
        return self.drive(s)[:, None] * psi / np.maximum(psi.sum(axis=1, keepdims=True), 1e-300)

    def fit(self, s, f_target, regularization=1e-8):
        """
        Fit the weights to ``f_target`` (shape (n, d)) by ridge-regularised least squares.

        One global least-squares problem fits overlapping kernels better than the paper's locally
        weighted regression; the small ridge keeps kernels that the data barely excite bounded.
        """
        phi = self.design_matrix(s)
        gram = phi.T @ phi
        ridge = regularization * np.trace(gram) / self.n_basis
        self.weights = np.linalg.solve(gram + ridge * np.eye(self.n_basis), phi.T @ f_target)
        self._tables = OrderedDict()
        return self.weights

    def table(self, tau, dt, n_out, substeps):
        """
        Return (s_mid, f(s_mid), s_out, f(s_out)) of a rollout's timing, cached per timing.

        ``s_mid``: the gated phase ``s G(s)`` (:meth:`drive`, the factor of Hoffmann's term ``A``
        in the rollout) at the midpoints of the ``(n_out - 1) * substeps`` sub-steps of
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
            table = (self.drive(s_mid), self(s_mid), self.drive(s_out), self(s_out))
            tables[key] = table
            if len(tables) > TABLE_CACHE_SIZE:
                tables.popitem(last=False)
        return table

    def __call__(self, s):
        """Evaluate f(s) for phases ``s`` (shape (n,)); returns shape (n, d)."""
        return self.design_matrix(s) @ self.weights

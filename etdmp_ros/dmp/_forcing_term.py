"""
Canonical system and forcing term (paper Eq. 3-5, with the factor s).

The mathematics: docs/design.md#canonical-system-and-forcing-term.

The phase decays as ``tau ds/dt = -alpha s`` so ``s(t) = exp(-alpha t / tau)``. The forcing term is
``f(s) = s * sum_i psi_i(s) w_i / sum_i psi_i(s)`` with Gaussian kernels
``psi_i(s) = exp(-h_i (s - c_i)^2)`` whose centres are spaced evenly in time (hence
exponentially in s) and whose widths follow from the spacing of neighbours.
"""

import numpy as np


def phase(t, tau, alpha):
    """Phase ``s(t) = exp(-alpha t / tau)`` (paper Eq. 5 integrated, s(0) = 1)."""
    return np.exp(-alpha * np.asarray(t, dtype=float) / tau)


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

    def design_matrix(self, s):
        """Regressors ``s * psi_i(s) / sum_j psi_j(s)`` for phases ``s`` (shape (n, n_basis))."""
        s = np.asarray(s, dtype=float)[:, None]
        psi = np.exp(-self.widths * (s - self.centres) ** 2)
        # Kernels never all vanish inside [exp(-alpha), 1]; the floor guards phases far past it.
        return s * psi / np.maximum(psi.sum(axis=1, keepdims=True), 1e-300)

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
        return self.weights

    def __call__(self, s):
        """Evaluate f(s) for phases ``s`` (shape (n,)); returns shape (n, d)."""
        return self.design_matrix(s) @ self.weights

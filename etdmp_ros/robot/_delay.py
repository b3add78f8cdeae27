"""
The actuation delay of a velocity-commanded arm, estimated online from how its joints moved.

The controller (:mod:`etdmp_ros.robot._controller`) predicts where the commands already sent
take the joints before its next one acts (a Smith predictor); :class:`DelayEstimator` tells it
how long that is, and :meth:`DelayEstimator.in_flight` how far.
"""

from __future__ import annotations

from etdmp_ros.robot import _ik_fast
from etdmp_ros.robot._ur10 import Joints
import numpy as np


class DelayEstimator:
    """
    Estimate the actuation delay, in control periods, from how the joints actually moved.

    Between two measurements one control period apart, the joints move by ``T u`` where ``u``
    is the command in force. With a delay of ``d = i + f`` periods that is the blend
    ``(1 - f) u_(k-1-i) + f u_(k-2-i)`` of the commands sent before; the delay (0 to 2 periods,
    steps of 1/8, refined by a parabola) is the one whose predicted displacements matched best,
    with exponential forgetting. A fractional delay also absorbs the lag of the joints' velocity
    servos. Until the commands have changed enough to tell delays apart, ``prior`` is used.
    """

    GRID = np.linspace(0.0, 2.0, 17)
    #: Accumulated squared command change (rad^2, times T^2) needed before estimates count.
    MIN_EXCITATION = 1e-10

    def __init__(self, prior: float, period: float, forgetting: float = 0.98,
                 fast: bool | None = None) -> None:
        """Start from ``prior`` periods; ``forgetting`` per step (0.98: about 50 steps)."""
        self.fast = _ik_fast.AVAILABLE if fast is None else fast
        self.period = float(period)
        self.prior = float(prior)
        self.delay = float(prior)
        self.forgetting = float(forgetting)
        self._index = np.floor(self.GRID).astype(np.int64)
        self._frac = self.GRID - self._index
        self.reset()

    def reset(self) -> None:
        """Forget the history (not the current estimate)."""
        self._commands = np.zeros((4, 6))        # newest first: u_(k-1), u_(k-2), ...
        self._costs = np.zeros(len(self.GRID))
        self._excitation = 0.0
        self._q: Joints | None = None
        self._t = 0.0

    def update(self, q: Joints, t: float) -> float:
        """Take the measurement ``q`` at ``t``; return the delay estimate in periods."""
        T = self.period
        if self._q is not None and abs(t - self._t - T) < 0.25 * T:
            u = self._commands
            if self.fast:
                change, best = _ik_fast.delay_costs(u, self._index, self._frac, q - self._q, T,
                                                    self.forgetting, self._costs)
            else:
                f = self._frac[:, None]
                models = T * ((1.0 - f) * u[self._index] + f * u[self._index + 1])
                residual = np.sum((models - (q - self._q)) ** 2, axis=1)
                self._costs = self.forgetting * self._costs + residual
                change = float(np.sum((T * (u[0] - u[1])) ** 2))
                best = np.argmin(self._costs)
            self._excitation = self.forgetting * self._excitation + change
            if self._excitation > self.MIN_EXCITATION:
                self.delay = self._refine(int(best))
        self._q, self._t = q, t
        return self.delay

    def _refine(self, k: int) -> float:
        if k == 0 or k == len(self.GRID) - 1:
            return float(self.GRID[k])
        c0, c1, c2 = self._costs[k - 1:k + 2]
        curvature = c0 - 2.0 * c1 + c2
        shift = 0.5 * (c0 - c2) / curvature if curvature > 0.0 else 0.0
        return float(self.GRID[k] + np.clip(shift, -0.5, 0.5) * (self.GRID[1] - self.GRID[0]))

    def in_flight(self, delay: float) -> Joints:
        """
        Return the joint motion still to come from commands already sent, until the next one acts.

        With a delay of ``delay`` periods, command ``u_(k-1-m)`` acts over ``[(delay - 1 - m) T,
        (delay - m) T]`` after the measurement; the part of it before ``delay T`` counts.
        """
        if self.fast:
            out = np.empty(6)
            _ik_fast.in_flight(self._commands, float(delay), self.period, out)
            return out
        m = np.arange(len(self._commands))
        overlap = np.clip(np.minimum(delay - m, delay) - np.maximum(delay - 1.0 - m, 0.0), 0.0,
                          1.0)
        return self.period * (overlap @ self._commands)

    def record(self, command: Joints) -> None:
        """Note the command sent after the latest measurement."""
        self._commands[1:] = self._commands[:-1].copy()
        self._commands[0] = command

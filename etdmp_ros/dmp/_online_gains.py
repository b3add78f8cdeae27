"""
Gains of the online rollout (:class:`OnlineRun`): the goal filter, phase stopping, when it is done.

The method and the scan behind the defaults: docs/design.md#online-gains.
"""

from dataclasses import dataclass
import math


@dataclass(frozen=True)
class OnlineGains:
    """
    Gains of the online rollout (docs/design.md#online-goal).

    ``alpha_goal``: rate of the goal filter, ``tau dg_f/dt = alpha_goal (g - g_f)``; ``inf``
    turns the filter off (the goal jumps, as in the plain DMP's goal change). ``alpha_err``:
    phase stopping, the rate of the whole system (phase and transformation system) is divided
    by ``1 + alpha_err e^2`` with ``e`` the distance from the measured position to the plan
    relative to the size ``l`` of the placed movement (its largest distance from the goal); 0
    turns it off. ``done_tolerance``: the run is done when the phase has ended (phase time
    ``>= tau``) and both ``|x - g|`` and the DMP's own ``|v|`` (``tau |dx/dt|`` at full rate)
    are below this fraction of ``l``.

    The defaults: alpha_goal = 25 = D makes the filter twice as fast as the critically damped
    spring (whose rate is sqrt(K) = 12.5), so it adds little lag to the spring's own while it
    spreads the acceleration of a goal jump over about tau / 25 (docs/design.md#online-goal has
    the scan behind this choice); alpha_err = 1000 halves the rate at a tracking error of 3 % of
    the movement's size and leaves it above 97 % below 0.5 %, and a plan waiting for a held
    tool creeps ahead by at most ``(3 V T / (alpha_err l))^(1/3) l`` in a hold of ``T`` seconds
    (V: the plan's top speed), 24 % of the letter G's size in 1 s.
    """

    alpha_goal: float = 25.0
    alpha_err: float = 1000.0
    done_tolerance: float = 1e-3

    def validate(self) -> None:
        """Raise ValueError unless the gains are usable (alpha_goal may be inf)."""
        values = {}
        for name in ('alpha_goal', 'alpha_err', 'done_tolerance'):
            try:
                values[name] = float(getattr(self, name))
            except (TypeError, ValueError):
                raise ValueError(f'{name} must be a number, got {getattr(self, name)!r}') from None
        if not values['alpha_goal'] > 0.0:      # also refuses NaN
            raise ValueError(f'alpha_goal must be > 0 (inf: no goal filter), got '
                             f'{self.alpha_goal!r}')
        if not (math.isfinite(values['alpha_err']) and values['alpha_err'] >= 0.0):
            raise ValueError(f'alpha_err must be finite and >= 0, got {self.alpha_err!r}')
        tolerance = values['done_tolerance']
        if not (math.isfinite(tolerance) and tolerance > 0.0):
            raise ValueError(f'done_tolerance must be finite and > 0, got '
                             f'{self.done_tolerance!r}')

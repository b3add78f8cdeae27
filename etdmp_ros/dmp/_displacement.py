"""
A detour's displacement ``delta(t)``, a function of time: bumps along directions, and a blend.

``delta(t) = H(t) + sum_e A_e b_e(t) n_e`` (:mod:`etdmp_ros.dmp._detour` plans it;
docs/design.md#obstacles-with-a-size): per encounter ``e`` a bump ``b_e`` in time (0, rising
along the quintic smoothstep to 1, 1 over a plateau, falling back to 0: C2), an amplitude
``A_e`` and a unit direction ``n_e``; ``H(t)`` the displacement an online run had at a re-plan,
blended out to zero along a quintic Hermite curve.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike

try:  # The fast path is optional: without numba the numpy reference serves.
    import numba
except ImportError:  # pragma: no cover - numba is pinned in requirements
    numba = None  # type: ignore[assignment]

#: A displacement's values at the samples: delta, delta', delta'', each (n, d).
Values = list[Array]


def smoothstep(u: ArrayLike) -> tuple[Array, Array, Array]:
    """Return the quintic smoothstep S(u) and its first two derivatives (u clipped to [0, 1])."""
    u = np.clip(u, 0.0, 1.0)
    u2 = u * u
    return (u2 * u * (10.0 + u * (-15.0 + 6.0 * u)), 30.0 * u2 * (1.0 - u) ** 2,
            60.0 * u * (1.0 - u) * (1.0 - 2.0 * u))


def _hermite_out(u: ArrayLike) -> tuple[Array, Array, Array]:
    """Quintic Hermite basis from (1, 0, 0), (0, 1, 0), (0, 0, 1) at u = 0 to 0 at u = 1."""
    u = np.clip(u, 0.0, 1.0)
    h0 = 1.0 - u ** 3 * (10.0 - 15.0 * u + 6.0 * u * u)
    h1 = u - u ** 3 * (6.0 - 8.0 * u + 3.0 * u * u)
    h2 = 0.5 * (u ** 2 - 3.0 * u ** 3 + 3.0 * u ** 4 - u ** 5)
    d0 = -30.0 * u * u * (1.0 - u) ** 2
    d1 = 1.0 - 18.0 * u * u + 32.0 * u ** 3 - 15.0 * u ** 4
    d2 = 0.5 * (2.0 * u - 9.0 * u * u + 12.0 * u ** 3 - 5.0 * u ** 4)
    e0 = -60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    e1 = -36.0 * u + 96.0 * u * u - 60.0 * u ** 3
    e2 = 0.5 * (2.0 - 18.0 * u + 36.0 * u * u - 20.0 * u ** 3)
    return np.stack([h0, h1, h2]), np.stack([d0, d1, d2]), np.stack([e0, e1, e2])


def bump(t: ArrayLike, ts: float, ta: float, tb: float, te: float,
         fast: bool = True) -> tuple[Array, Array, Array]:
    """
    Return the bump b(t) and its first two time derivatives at times ``t`` (n,).

    0 before ``ts``, rising along the smoothstep to 1 at ``ta``, 1 until ``tb``, falling to 0
    at ``te``, 0 after. A ramp of zero length is a step (only used where no sample lies on it).
    ``fast``: one numba loop (the detour evaluates bumps many times per plan), else the numpy
    reference.
    """
    t = np.asarray(t, dtype=float)
    if fast and numba is not None and t.ndim == 1:
        return _bump_nb(t, float(ts), float(ta), float(tb), float(te))
    b, b1, b2 = np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
    rise = ta - ts
    fall = te - tb
    if rise > 0.0:
        on = (t > ts) & (t < ta)
        s, s1, s2 = smoothstep((t[on] - ts) / rise)
        b[on], b1[on], b2[on] = s, s1 / rise, s2 / rise ** 2
    if fall > 0.0:
        on = (t > tb) & (t < te)
        s, s1, s2 = smoothstep((te - t[on]) / fall)
        b[on], b1[on], b2[on] = s, -s1 / fall, s2 / fall ** 2
    b[(t >= ta) & (t <= tb)] = 1.0
    return b, b1, b2


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _bump_nb(t: Array, ts: float, ta: float, tb: float,
                 te: float) -> tuple[Array, Array, Array]:  # pragma: no cover - numba
        """Compute :func:`bump`'s numpy reference in one loop (the same operations)."""
        n = len(t)
        b, b1, b2 = np.zeros(n), np.zeros(n), np.zeros(n)
        rise, fall = ta - ts, te - tb
        for i in range(n):
            if t[i] >= ta and t[i] <= tb:
                b[i] = 1.0
            elif rise > 0.0 and t[i] > ts and t[i] < ta:
                u = (t[i] - ts) / rise
                u2 = u * u
                b[i] = u2 * u * (10.0 + u * (-15.0 + 6.0 * u))
                b1[i] = 30.0 * u2 * (1.0 - u) ** 2 / rise
                b2[i] = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / rise ** 2
            elif fall > 0.0 and t[i] > tb and t[i] < te:
                u = (te - t[i]) / fall
                u2 = u * u
                b[i] = u2 * u * (10.0 + u * (-15.0 + 6.0 * u))
                b1[i] = -30.0 * u2 * (1.0 - u) ** 2 / fall
                b2[i] = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / fall ** 2
        return b, b1, b2


@dataclass(frozen=True)
class Displacement:
    """
    A detour's displacement ``delta(t)`` as a function of time (see the module docstring).

    Encounter arrays: ``ts``, ``ta``, ``tb``, ``te`` (E,) the bump's corners, ``amplitude``
    (E,), ``direction`` (E, d). The carried part: ``t0``, ``blend`` (its duration, 0 for none)
    and ``carry`` (3, d): the displacement, its velocity and acceleration at ``t0``.
    """

    ts: Array
    ta: Array
    tb: Array
    te: Array
    amplitude: Array
    direction: Array
    t0: float = 0.0
    blend: float = 0.0
    carry: Array | None = field(default=None)

    @property
    def end(self) -> float:
        """Return the time after which the displacement is zero."""
        ends = [self.t0 + self.blend] + [float(t) for t in self.te]
        return max(ends)

    def __call__(self, t: ArrayLike) -> Values:
        """Return delta, delta', delta'' at times ``t`` (n,), sorted, each (n, d)."""
        t = np.asarray(t, dtype=float)
        d = self.direction.shape[1]
        out: Values = [np.zeros((len(t), d)) for _ in range(3)]
        for e in range(len(self.amplitude)):
            if self.amplitude[e] == 0.0:
                continue
            # Only the samples inside the bump's window: it is zero elsewhere.
            lo, hi = np.searchsorted(t, [self.ts[e], self.te[e]], side='right')
            parts = bump(t[lo:hi], self.ts[e], self.ta[e], self.tb[e], self.te[e])
            for o, part in zip(out, parts):
                o[lo:hi] += (self.amplitude[e] * part)[:, None] * self.direction[e]
        if self.blend > 0.0 and self.carry is not None:
            T = self.blend
            lo, hi = np.searchsorted(t, [self.t0, self.t0 + T], side='left')
            h, h1, h2 = _hermite_out((t[lo:hi] - self.t0) / T)
            coeff = self.carry * np.array([1.0, T, T * T])[:, None]    # in units of u
            out[0][lo:hi] += h.T @ coeff
            out[1][lo:hi] += h1.T @ coeff / T
            out[2][lo:hi] += h2.T @ coeff / T ** 2
        return out

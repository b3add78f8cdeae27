"""
Obstacles with a size, avoided by a local detour of the obstacle-free plan (the default).

The mathematics and the measurements behind the choices: docs/design.md#obstacles-with-a-size.
In short, obstacle ``j`` is a ball (a disk in 2D) of centre ``c_j`` and radius ``r_j``, the
clearance the plan must keep. The DMP is rolled out without obstacles, ``x_free(t)``; where that
plan comes within ``rho_j = r_j + m`` of ``c_j`` (``m``: the margin, a fraction of the movement's
size) the plan is displaced::

    x(t) = x_free(t) + delta(t),      delta(t) = H(t) + sum_e A_e b_e(t) n_e

with one term per *encounter* ``e`` (a stretch of consecutive samples within ``rho_j``):

- ``b_e(t)``: a bump in time, 1 over a plateau in the encounter, rising before it and falling
  after it along the quintic smoothstep ``S(u) = 10 u^3 - 15 u^4 + 6 u^5`` (C2: value, slope
  and curvature are continuous), each ramp at least as long as the plan takes to travel
  ``ramp * rho_j`` of arc length and long enough in time to bound the acceleration it adds, 0
  elsewhere, and 0 at the plan's start and end; encounters whose bumps overlap are one;
- ``n_e``: a unit direction of a fixed set (72 in 2D, 162 in 3D, fixed in the virtual
  situation), and the plateau, chosen for the least squared displacement along the plan;
- ``A_e >= 0``: the smallest amplitude for which every sample keeps ``|x - c_j| >= rho_j`` from
  every obstacle ``j`` (found exactly: each sample and obstacle forbid an interval of amplitudes,
  a quadratic's roots);
- ``H(t)``: zero offline; online, after a re-plan, the displacement the run had, blended out to
  zero along a quintic Hermite curve (C2 at the switch).

Velocities and accelerations follow from ``delta``'s derivatives. Since ``R`` is orthogonal
about the goal, the detour commutes with the Euclidean transform (Eq. 23); the plan's timing is
the obstacle-free plan's. The result is checked (:func:`keep_clear`): a sample, or the straight
segment between two samples, closer to an obstacle's centre than its radius raises
GeneralizationError; such a plan is never returned.
"""

from dataclasses import dataclass, field
from functools import lru_cache
import math

import numpy as np

from ._errors import GeneralizationError

try:  # The fast path is optional: without numba the numpy reference serves.
    import numba
except ImportError:  # pragma: no cover - numba is pinned in requirements
    numba = None

#: Candidate directions of a detour in 2D (evenly spaced angles).
DIRECTIONS_2D = 72
#: Candidate directions of a detour in 3D (subdivided icosahedron: 162 points on the sphere).
_ICOSPHERE_LEVEL = 2
#: Options within this relative amount of each other are equally good: the first candidate
#: direction wins (a deterministic choice where two sides are equally good, e.g. a path through
#: a centre, whatever the round-off).
TIE = 1e-6
#: Candidate directions (the best by their inside samples' push) tried in full per encounter.
TOP_DIRECTIONS = 8
#: Points per segment between two samples held clear where a segment cut into an obstacle.
REFINE = 3
#: Bump shapes tried per direction: the plateau covers the samples that need at least this
#: fraction of the largest push (1: a peak; 0: every sample inside a ball).
PLATEAUS = (1.0, 0.5, 0.0)
_PLATEAUS = np.array(PLATEAUS)


@dataclass(frozen=True)
class Obstacles:
    """Obstacles with a size: ``centres`` (m, d) and ``radii`` (m,), both real situation."""

    centres: np.ndarray
    radii: np.ndarray

    def __len__(self):
        """Return the number of obstacles."""
        return len(self.centres)


def _icosphere(level):
    """Return unit vectors (n, 3): the vertices of an icosahedron subdivided ``level`` times."""
    p = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [(-1, p, 0), (1, p, 0), (-1, -p, 0), (1, -p, 0), (0, -1, p), (0, 1, p),
             (0, -1, -p), (0, 1, -p), (p, 0, -1), (p, 0, 1), (-p, 0, -1), (-p, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(v, dtype=float) / np.linalg.norm(v) for v in verts]
    for _ in range(level):
        cache, new_faces = {}, []

        def middle(i, j):
            key = (min(i, j), max(i, j))
            if key not in cache:
                m = verts[i] + verts[j]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]

        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    return np.array(verts)


@lru_cache(maxsize=None)
def _directions(d):
    if d == 2:
        angle = 2.0 * np.pi * np.arange(DIRECTIONS_2D) / DIRECTIONS_2D
        directions = np.column_stack([np.cos(angle), np.sin(angle)])
    else:
        directions = _icosphere(_ICOSPHERE_LEVEL)
    directions.flags.writeable = False
    return directions


def candidate_directions(d):
    """Return the detour's candidate unit directions (n, d) in the virtual situation."""
    if d not in (2, 3):
        raise GeneralizationError(f'obstacles with a size need 2 or 3 dimensions, not {d}')
    return _directions(d)


# -- the displacement ------------------------------------------------------------------------

def smoothstep(u):
    """Return the quintic smoothstep S(u) and its first two derivatives (u clipped to [0, 1])."""
    u = np.clip(u, 0.0, 1.0)
    u2 = u * u
    return (u2 * u * (10.0 + u * (-15.0 + 6.0 * u)), 30.0 * u2 * (1.0 - u) ** 2,
            60.0 * u * (1.0 - u) * (1.0 - 2.0 * u))


def _hermite_out(u):
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


def bump(t, ts, ta, tb, te):
    """
    Return the bump b(t) and its first two time derivatives at times ``t`` (n,).

    0 before ``ts``, rising along the smoothstep to 1 at ``ta``, 1 until ``tb``, falling to 0
    at ``te``, 0 after. A ramp of zero length is a step (only used where no sample lies on it).
    """
    t = np.asarray(t, dtype=float)
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


@dataclass(frozen=True)
class Displacement:
    """
    A detour's displacement ``delta(t)`` as a function of time (see the module docstring).

    Encounter arrays: ``ts``, ``ta``, ``tb``, ``te`` (E,) the bump's corners, ``amplitude``
    (E,), ``direction`` (E, d). The carried part: ``t0``, ``blend`` (its duration, 0 for none)
    and ``carry`` (3, d): the displacement, its velocity and acceleration at ``t0``.
    """

    ts: np.ndarray
    ta: np.ndarray
    tb: np.ndarray
    te: np.ndarray
    amplitude: np.ndarray
    direction: np.ndarray
    t0: float = 0.0
    blend: float = 0.0
    carry: np.ndarray = field(default=None)

    @property
    def end(self):
        """Return the time after which the displacement is zero."""
        ends = [self.t0 + self.blend] + [float(t) for t in self.te]
        return max(ends)

    def __call__(self, t):
        """Return delta, delta', delta'' at times ``t`` (n,), sorted, each (n, d)."""
        t = np.asarray(t, dtype=float)
        d = self.direction.shape[1]
        out = [np.zeros((len(t), d)) for _ in range(3)]
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


def no_displacement(d):
    """Return the zero displacement in ``d`` dimensions."""
    empty = np.zeros(0)
    return Displacement(empty, empty, empty, empty, empty, np.zeros((0, d)))


# -- planning a detour -----------------------------------------------------------------------

def _runs(mask):
    """Return (first, last) index pairs of the runs of True in a 1D boolean array."""
    if not mask.any():
        return []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def amplitudes(W, q, N, b, own, at_least=0.0):
    """
    Return, per direction, the smallest amplitude >= ``at_least`` that keeps samples clear.

    ``W`` (k, m, d): window samples minus the obstacles' centres; ``q`` (m,): target radii;
    ``N`` (n_dir, d): unit directions; ``b`` (k,) > 0: the bump at the samples; ``own`` (m,)
    bool: the encounter's obstacles. A sample moved by ``s n`` is inside obstacle j while
    ``|W + s n|^2 < q_j^2``, i.e. for ``s`` between the roots of a quadratic, which with
    ``s = A b`` forbids an open interval of A. The answer is the smallest A outside all of
    them: from ``at_least``, jump past every interval that contains A until none does. A
    sample inside an obstacle not the encounter's own is not this encounter's to clear (the
    final check catches it): it forbids nothing here. Returns (n_dir,) amplitudes. The numpy
    reference of :func:`amplitude`'s numba loop.
    """
    p = np.einsum('kmi,ni->kmn', W, N)
    c = np.einsum('kmi,kmi->km', W, W) - q * q
    disc = p * p - c[..., None]
    ok = (disc > 0.0) & ~(~own & (c < 0.0))[..., None]
    root = np.sqrt(np.where(ok, disc, 0.0))
    lo = (-p - root) / b[:, None, None]
    hi = (-p + root) / b[:, None, None]
    ok &= hi > 0.0
    lo, hi = lo[ok], hi[ok]
    which = np.nonzero(ok)[2]
    A = np.full(len(N), float(at_least))
    for _ in range(len(lo) + 1):
        contains = (lo < A[which]) & (hi > A[which])
        if not contains.any():
            break
        jump = np.full(len(N), -np.inf)
        np.maximum.at(jump, which[contains], hi[contains])
        A = np.maximum(A, jump)
    return A


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _amplitude_nb(W, c, n, b, own, at_least):  # pragma: no cover - numba
        k, m, d = W.shape
        A = at_least
        while True:
            jump = A
            for i in range(k):
                for j in range(m):
                    if c[i, j] < 0.0 and not own[j]:
                        continue
                    p = 0.0
                    for e in range(d):
                        p += W[i, j, e] * n[e]
                    disc = p * p - c[i, j]
                    if disc <= 0.0:
                        continue
                    root = math.sqrt(disc)
                    hi = (-p + root) / b[i]
                    if hi <= A:
                        continue
                    if (-p - root) / b[i] < A and hi > jump:
                        jump = hi
            if jump == A:
                return A
            A = jump


def amplitude(W, q, n, b, own, at_least=0.0, fast=True):
    """Return :func:`amplitudes` for one direction ``n`` (d,): numba loop, or the reference."""
    if not fast or numba is None:
        return float(amplitudes(W, q, n[None], b, own, at_least)[0])
    c = np.einsum('kmi,kmi->km', W, W) - q * q
    return float(_amplitude_nb(np.ascontiguousarray(W), c, np.ascontiguousarray(n), b, own,
                               float(at_least)))


def _arc_time(s, t, target):
    """Return the first sample time at which the arc length ``s`` reaches ``target``."""
    i = int(np.searchsorted(s, target, side='left'))
    return float(t[min(max(i, 0), len(t) - 1)])


def _pushes(W, q, n):
    """Return, per sample, the push along ``n`` that takes it out of every ball it is in."""
    p = W @ n
    c = np.einsum('kmi,kmi->km', W, W) - q * q
    return np.max(np.where(c < 0.0, -p + np.sqrt(np.maximum(p * p - c, 0.0)), 0.0), axis=1)


def chords(values, refine):
    """
    Append to ``values`` (k, ...) the points at ``i / (refine + 1)`` along each chord.

    The displacement is linear in the samples, so a chord point of the moved polyline is the
    chord point of the base moved by the chord point of the bump: constraints on these points
    keep the straight segments between samples clear, not only the samples.
    """
    if refine <= 0 or len(values) < 2:
        return values
    u = np.arange(1, refine + 1) / (refine + 1.0)
    shape = (-1,) + (1,) * (values.ndim - 1)
    inner = (1.0 - u.reshape(shape)) * values[:-1, None] + u.reshape(shape) * values[1:, None]
    return np.concatenate([values, inner.reshape((-1,) + values.shape[1:])])


def _encounter(t, ds, base, C, q, own, span, directions, size, fast, refine=0):
    """
    Return the best (amplitude, direction, ts, ta, tb, te) for one encounter, or None.

    ``span`` = [ts, ta, tb, te, obstacles, need]: the window, the stretch inside the
    encounter's balls, and per direction the push its inside samples need (:func:`_needs`).
    The directions are ranked by that need; for the best
    TOP_DIRECTIONS (all of them if none of those can pass), each bump shape of PLATEAUS (the
    plateau over the samples needing at least that fraction of the largest push) gets its
    exact amplitude (:func:`amplitude`); the option with the least squared displacement along
    the plan (by arc length) wins. ``fast``: one numba loop, else the numpy reference.
    """
    ts, ta, tb, te, _, need = span
    window = np.arange(*np.searchsorted(t, [ts, te], side='right'))
    window = window[t[window] < te]
    W = base[window][:, None] - C[None]                                    # (k, m, d)
    # The best few directions by need, then (where none of them can pass) all others; within
    # each set in the fixed order of the candidates, and a later option must beat an earlier
    # one by more than TIE: two sides equally good (a path through a centre) go the same way
    # whatever the round-off (the online run re-plans on a remainder computed differently).
    cut = np.sort(need)[min(TOP_DIRECTIONS, len(need)) - 1] * (1.0 + TIE) + 1e-300
    tw, dsw = t[window], ds[window]
    Wc = chords(W, refine)
    for candidates in (np.flatnonzero(need <= cut), np.flatnonzero(need > cut)):
        if fast and numba is not None:
            cw = np.einsum('kmi,kmi->km', Wc, Wc) - q * q
            i, A, lo_t, hi_t = _encounter_nb(tw, dsw, np.ascontiguousarray(W), own, q,
                                             directions, candidates, _PLATEAUS, ts,
                                             ta, te, size, TIE, np.ascontiguousarray(Wc), cw,
                                             refine)
            best = None if i < 0 else (0.0, A, directions[i], ts, lo_t, hi_t, te)
        else:
            best = _options(tw, dsw, W, q, own, directions, candidates, ts, ta, te, size,
                            refine)
        if best is not None:
            return best[1:]
    return None


def _options(tw, dsw, W, q, own, directions, candidates, ts, ta, te, size, refine=0):
    """Return the best (cost, A, n, ts, ta, tb, te) of the candidates: the numpy reference."""
    best = None
    for i in candidates:
        n = directions[i]
        push = _pushes(W[:, own], q[own], n)
        for fraction in PLATEAUS:
            top = np.flatnonzero(push >= fraction * push.max()) if fraction > 0.0 else \
                np.flatnonzero(push > 0.0)
            lo_t = max(float(tw[top[0]]), ta)
            hi_t = max(float(tw[top[-1]]), lo_t)
            b = bump(tw, ts, lo_t, hi_t, te)[0]
            A = amplitude(chords(W, refine), q, n, chords(b, refine), own, 0.0, fast=False)
            cost = A * A * float(np.sum(b * b * dsw))
            if A <= size and (best is None or cost < best[0] * (1.0 - TIE)):
                best = (cost, A, n, ts, lo_t, hi_t, te)
    return best


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _bump_nb(t, ts, ta, tb, te):  # pragma: no cover - numba
        """Scalar :func:`bump` value."""
        if t >= ta and t <= tb:
            return 1.0
        if t > ts and t < ta:
            u = (t - ts) / (ta - ts)
        elif t > tb and t < te:
            u = (te - t) / (te - tb)
        else:
            return 0.0
        return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))

    @numba.njit(cache=True, fastmath=False)
    def _encounter_nb(tw, dsw, W, own, q, D, candidates, fractions, ts, ta, te, size, tie,
                      Wc, cc, refine):  # pragma: no cover - numba
        """Run :func:`_options`' loop over directions and bump shapes."""
        k, m, d = W.shape
        push = np.zeros(k)
        b = np.empty(len(Wc))
        c = cc[:k]
        best_i, best_cost, best_A, best_lo, best_hi = -1, np.inf, 0.0, 0.0, 0.0
        for i in candidates:
            n = D[i]
            largest = 0.0
            for kk in range(k):
                push[kk] = 0.0
                for j in range(m):
                    if own[j] and c[kk, j] < 0.0:
                        p = 0.0
                        for e in range(d):
                            p += W[kk, j, e] * n[e]
                        out = -p + math.sqrt(max(p * p - c[kk, j], 0.0))
                        if out > push[kk]:
                            push[kk] = out
                if push[kk] > largest:
                    largest = push[kk]
            for fraction in fractions:
                first, last = -1, -1
                for kk in range(k):
                    if (push[kk] >= fraction * largest) if fraction > 0.0 else (push[kk] > 0.0):
                        if first < 0:
                            first = kk
                        last = kk
                lo_t = max(tw[first], ta)
                hi_t = max(tw[last], lo_t)
                for kk in range(k):
                    b[kk] = _bump_nb(tw[kk], ts, lo_t, hi_t, te)
                for r in range(refine):         # the chord points, as chords() orders them
                    u = (r + 1.0) / (refine + 1.0)
                    for kk in range(k - 1):
                        b[k + kk * refine + r] = (1.0 - u) * b[kk] + u * b[kk + 1]
                A = _amplitude_nb(Wc, cc, n, b, own, 0.0)
                cost = 0.0
                for kk in range(k):
                    cost += b[kk] * b[kk] * dsw[kk]
                cost *= A * A
                if A <= size and (best_i < 0 or cost < best_cost * (1.0 - tie)):
                    best_i, best_cost, best_A, best_lo, best_hi = i, cost, A, lo_t, hi_t
        return best_i, best_A, best_lo, best_hi


def detour(t, x, obstacles, margin, ramp, directions, size, displacement=None, t0=None,
           blend_length=None, fast=True, acceleration=None, refine=0):
    """
    Plan the detour of the plan ``x`` (n, d) sampled at ``t`` (n,) around ``obstacles``.

    ``obstacles``: :class:`Obstacles`; ``margin``: the extra clearance ``m`` the detour aims
    for (length); ``ramp``: the ramps' arc length in units of ``rho_j``; ``directions``: the
    candidate unit directions (n_dir, d) in the situation of ``x``; ``size``: the movement's
    size (a detour larger than it is refused). Online re-plans give the ``displacement`` in
    force, to be blended out from ``t0`` = ``t[0]`` over the time the plan takes to travel
    ``blend_length``. Returns a :class:`Displacement`, or None when no obstacle comes within
    ``r_j + margin`` of the plan and there is nothing to carry (the plan stays as it is, bit
    for bit). ``acceleration``: the acceleration a ramp may add, at most (None: no bound); a
    ramp is made long enough in time for the least translation that clears its stretch to stay
    below it, and a joined encounter's ramps are lengthened again for its amplitude, as far as
    the time around it allows. ``refine``: chord points per segment that must be
    clear too (:func:`chords`). Raises GeneralizationError when no detour can pass; the
    result is not checked here (:func:`keep_clear` does).
    """
    n, d = x.shape
    C, r = obstacles.centres, obstacles.radii
    t0 = float(t[0]) if t0 is None else float(t0)
    carry = None
    blend = 0.0
    base = x
    if displacement is not None:
        now = displacement(np.array([t0]))
        carry = np.stack([now[0][0], now[1][0], now[2][0]])
        if not np.any(carry):
            carry = None
    if len(C) == 0 and carry is None:
        return None
    step = np.diff(x, axis=0)
    ds = np.sqrt(np.einsum('ki,ki->k', step, step))
    s = np.concatenate([[0.0], np.cumsum(ds)])
    ds = np.concatenate([[0.0], ds])                # arc length before each sample
    if carry is not None:
        blend = max(_arc_time(s, t, min(blend_length, s[-1])) - t0, 0.0)
        if blend <= 0.0:
            blend = float(t[-1] - t0)
        carry_only = Displacement(*(np.zeros(0),) * 5, np.zeros((0, d)), t0, blend, carry)
        base = x + carry_only(t)[0]
    if len(C) == 0:
        return carry_only
    dist = np.linalg.norm(base[:, None, :] - C[None], axis=2)          # (n, m)
    # The target radius: r + margin, lowered to what the ends of the plan allow (> r).
    ends = np.minimum(dist[0], dist[-1])
    for j in np.flatnonzero(ends < r):
        end = 0 if dist[0, j] < r[j] else -1
        raise GeneralizationError(
            f"obstacle #{j} (centre {_fmt(C[j])}, radius {r[j]:.4g}) contains the plan's "
            f"{'start' if end == 0 else 'end'} ({dist[end, j]:.4g} from its centre): the "
            'clearance cannot be kept')
    q = np.minimum(r + margin, ends)
    inside = dist < q
    if not inside.any():
        return carry_only if carry is not None else None
    spans = []              # [ts, ta, tb, te, obstacles]
    t_last = float(t[-1])
    for j in range(len(C)):
        length = ramp * q[j]
        for a, b in _runs(inside[:, j]):
            ta, tb = float(t[a]), float(t[b])
            ts = _arc_time(s, t, s[a] - length)
            te = _arc_time(s, t, s[b] + length)
            need = _needs(base[a:b + 1] - C[j], q[j], directions)
            if acceleration:
                # Long enough for the least translation that clears the stretch.
                least = _ramp_time(float(need.min()), acceleration)
                ts, te = min(ts, ta - least), max(te, tb + least)
            ts, te = max(ts, t0), min(te, t_last)
            if carry is not None and ts <= t0:
                # Rising from the switch as the carried displacement fades: together smooth.
                ta = max(ta, t0 + blend)
                tb, te = max(tb, ta), max(te, ta)
            spans.append([ts, ta, tb, te, {j}, need])
    # Stretches whose bumps overlap in time become one encounter (one direction, one bump):
    # bumps of their own, raised together, were measured to bend the shape more
    # (docs/design.md#obstacles-with-a-size). The encounters' windows are then disjoint, and
    # each amplitude is found on its own.
    found = []
    joined = _joined(spans)
    for e, span in enumerate(joined):
        own = np.zeros(len(C), dtype=bool)
        own[sorted(span[4])] = True
        best = _encounter(t, ds, base, C, q, own, span, directions, size, fast, refine)
        if best is None:
            j = min(span[4])
            raise GeneralizationError(
                f'passing obstacle #{j} (centre {_fmt(C[j])}, radius {r[j]:.4g}) needs a '
                f"detour larger than the movement's size {size:.4g}: no detour keeps the shape")
        if acceleration:
            # A joined encounter may need more than its stretches' least pushes: lengthen its
            # ramps into the free time around it (windows stay disjoint) and solve again.
            room = (found[-1][5] if found else t0,
                    joined[e + 1][0] if e + 1 < len(joined) else t_last)
            best = _slower(t, base, C, q, own, best, room, acceleration, size, fast, refine)
        found.append(best)
    A = np.array([f[0] for f in found])
    N = np.array([f[1] for f in found]).reshape(-1, d)
    corners = np.array([f[2:] for f in found], dtype=float).reshape(-1, 4)
    return Displacement(corners[:, 0], corners[:, 1], corners[:, 2], corners[:, 3], A, N, t0,
                        blend, carry)


def _needs(W, q, directions):
    """
    Return, per direction, the translation that takes every sample of ``W`` (k, d) out.

    ``W``: samples minus a centre, ``q``: the target radius; a sample ``w`` inside leaves
    along ``n`` at the larger root of ``|w + s n| = q``.
    """
    p = W @ directions.T
    c = np.einsum('ki,ki->k', W, W) - q * q
    out = np.where(c[:, None] < 0.0, -p + np.sqrt(np.maximum(p * p - c[:, None], 0.0)), 0.0)
    return np.max(out, axis=0)


def _ramp_time(amplitude, acceleration):
    """Return the ramp duration whose smoothstep keeps ``amplitude`` under ``acceleration``."""
    # The quintic smoothstep's second derivative peaks at 10 / sqrt(3) (at u = 1/2 -+ 1/sqrt(12)).
    return math.sqrt(10.0 / math.sqrt(3.0) * amplitude / acceleration)


def _slower(t, base, C, q, own, best, room, acceleration, size, fast, refine=0):
    """Return ``best`` with ramps lengthened (within ``room``) to keep the acceleration bound."""
    A, n, ts, ta, tb, te = best
    least = _ramp_time(A, acceleration)
    new_ts = max(min(ts, ta - least), room[0])
    new_te = min(max(te, tb + least), room[1])
    if new_ts == ts and new_te == te:
        return best
    window = np.flatnonzero((t > new_ts) & (t < new_te))
    b = bump(t[window], new_ts, ta, tb, new_te)[0]
    A2 = amplitude(chords(base[window][:, None] - C[None], refine), q, n, chords(b, refine), own,
                   0.0, fast)
    return (A2, n, new_ts, ta, tb, new_te) if A2 <= size else best


def _joined(spans):
    """Join spans ``[ts, ta, tb, te, balls, need]`` whose windows ``(ts, te)`` overlap."""
    out = []
    for span in sorted(spans, key=lambda span: span[0]):
        if out and span[0] <= out[-1][3]:
            last = out[-1]
            last[1], last[2] = min(last[1], span[1]), max(last[2], span[2])
            last[3] = max(last[3], span[3])
            last[4] = last[4] | span[4]
            last[5] = np.maximum(last[5], span[5])
        else:
            out.append(list(span))
    return out


def keep_clear(t, x, obstacles, *args, where='the plan', **kwargs):
    """
    Return :func:`detour`'s displacement for ``x`` and its values at ``t``, checked clear.

    Arguments as :func:`detour`. Returns ``(displacement, (delta, delta', delta''))``, or
    ``(None, None)`` where nothing moves. Where a straight segment between two samples of the
    moved plan cuts into an obstacle (a large, fast detour), the detour is planned again with
    REFINE points per segment held clear. Raises GeneralizationError when the moved plan is
    still not clear (:func:`check_clearance`): never a plan that enters an obstacle.
    """
    for refine in (0, REFINE):
        shift = detour(t, x, obstacles, *args, refine=refine, **kwargs)
        values = None if shift is None else shift(t)
        try:
            check_clearance(x if shift is None else x + values[0], obstacles, where)
            return shift, values
        except GeneralizationError as err:
            error = err
    raise error


def check_clearance(x, obstacles, where='the plan'):
    """
    Raise GeneralizationError unless the polyline ``x`` (n, d) keeps out of every obstacle.

    A sample closer to a centre than its radius, or a straight segment between two samples
    that passes closer, fails.
    """
    C, r = obstacles.centres, obstacles.radii
    if len(C) == 0:
        return
    if numba is not None and len(x) >= 2:
        gap = _gaps_nb(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(C, float))
    else:
        gap = segment_gaps(x, C)
    j = int(np.argmin(gap - r))
    if gap[j] < r[j]:
        raise GeneralizationError(
            f'{where} passes {gap[j]:.4g} from the centre of obstacle #{j} ({_fmt(C[j])}), '
            f'inside its radius {r[j]:.4g}: refused')


def segment_gaps(x, C):
    """Return the smallest distance of the polyline ``x`` (n, d) to each centre (m,)."""
    if len(x) < 2:
        return np.linalg.norm(x[:, None] - C[None], axis=2).min(axis=0)
    a, ab = x[:-1, None], np.diff(x, axis=0)[:, None]                    # (k, 1, d)
    ac = C[None] - a                                                      # (k, m, d)
    length2 = np.maximum(np.sum(ab * ab, axis=2), 1e-300)                 # (k, 1)
    u = np.clip(np.sum(ac * ab, axis=2) / length2, 0.0, 1.0)              # (k, m)
    return np.linalg.norm(ac - u[..., None] * ab, axis=2).min(axis=0)


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _gaps_nb(x, C):  # pragma: no cover - numba
        """Compute :func:`segment_gaps` in one loop."""
        n, d = x.shape
        m = C.shape[0]
        out = np.full(m, np.inf)
        for k in range(n - 1):
            for j in range(m):
                ab2 = 0.0
                acab = 0.0
                for i in range(d):
                    ab = x[k + 1, i] - x[k, i]
                    ab2 += ab * ab
                    acab += (C[j, i] - x[k, i]) * ab
                u = min(max(acab / max(ab2, 1e-300), 0.0), 1.0)
                gap2 = 0.0
                for i in range(d):
                    e = C[j, i] - x[k, i] - u * (x[k + 1, i] - x[k, i])
                    gap2 += e * e
                gap = math.sqrt(gap2)
                if gap < out[j]:
                    out[j] = gap
        return out


def _fmt(point):
    return '(' + ', '.join(f'{c:.4g}' for c in point) + ')'

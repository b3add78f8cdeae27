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

from __future__ import annotations

from collections.abc import Iterable, Sequence
from functools import lru_cache
import math
from typing import Any

from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import NDArray

from ._clearance import check_clearance, distances, format_point, least_pushes, Obstacles
from ._displacement import bump, Displacement, Values
from ._errors import GeneralizationError

try:  # The fast path is optional: without numba the numpy reference serves.
    import numba
except ImportError:  # pragma: no cover - numba is pinned in requirements
    numba = None  # type: ignore[assignment]

#: An encounter's detour: (amplitude, direction (d,), ts, ta, tb, te), the bump's corners.
Encounter = tuple[float, Array, float, float, float, float]

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


def _icosphere(level: int) -> Array:
    """Return unit vectors (n, 3): the vertices of an icosahedron subdivided ``level`` times."""
    p = (1.0 + math.sqrt(5.0)) / 2.0
    corners = [(-1, p, 0), (1, p, 0), (-1, -p, 0), (1, -p, 0), (0, -1, p), (0, 1, p),
               (0, -1, -p), (0, 1, -p), (p, 0, -1), (p, 0, 1), (-p, 0, -1), (-p, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(v, dtype=float) / np.linalg.norm(v) for v in corners]
    for _ in range(level):
        cache: dict[tuple[int, int], int]
        new_faces: list[tuple[int, int, int]]
        cache, new_faces = {}, []

        def middle(i: int, j: int) -> int:
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
def _directions(d: int) -> Array:
    if d == 2:
        angle = 2.0 * np.pi * np.arange(DIRECTIONS_2D) / DIRECTIONS_2D
        directions = np.column_stack([np.cos(angle), np.sin(angle)])
    else:
        directions = _icosphere(_ICOSPHERE_LEVEL)
    directions.flags.writeable = False
    return directions


def candidate_directions(d: int) -> Array:
    """Return the detour's candidate unit directions (n, d) in the virtual situation."""
    if d not in (2, 3):
        raise GeneralizationError(f'obstacles with a size need 2 or 3 dimensions, not {d}')
    return _directions(d)


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Return (first, last) index pairs of the runs of True in a 1D boolean array."""
    if not mask.any():
        return []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), ends.tolist()))


def amplitudes(W: Array, q: Array, N: Array, b: Array, own: NDArray[np.bool_],
               at_least: float = 0.0) -> Array:
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
    def _amplitude_nb(W: Array, c: Array, n: Array,
                      b: Array, own: NDArray[np.bool_],
                      at_least: float) -> float:  # pragma: no cover - numba
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


def amplitude(W: Array, q: Array, n: Array, b: Array, own: NDArray[np.bool_],
              at_least: float = 0.0, fast: bool = True) -> float:
    """Return :func:`amplitudes` for one direction ``n`` (d,): numba loop, or the reference."""
    if not fast or numba is None:
        return float(amplitudes(W, q, n[None], b, own, at_least)[0])
    c = np.einsum('kmi,kmi->km', W, W) - q * q
    return float(_amplitude_nb(np.ascontiguousarray(W), c, np.ascontiguousarray(n), b, own,
                               float(at_least)))


def _arc_time(s: Array, t: Array, target: float) -> float:
    """Return the first sample time at which the arc length ``s`` reaches ``target``."""
    i = int(np.searchsorted(s, target, side='left'))
    return float(t[min(max(i, 0), len(t) - 1)])


def _pushes(W: Array, q: Array, n: Array) -> Array:
    """Return, per sample, the push along ``n`` that takes it out of every ball it is in."""
    p = W @ n
    c = np.einsum('kmi,kmi->km', W, W) - q * q
    return np.max(np.where(c < 0.0, -p + np.sqrt(np.maximum(p * p - c, 0.0)), 0.0), axis=1)


def chords(values: Array, refine: int) -> Array:
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


def _encounter(t: Array, ds: Array, base: Array,
               C: Array, q: Array, own: NDArray[np.bool_],
               span: Sequence[Any], directions: Array, size: float, fast: bool,
               refine: int = 0) -> Encounter | None:
    """
    Return the best (amplitude, direction, ts, ta, tb, te) for one encounter, or None.

    ``span`` = [ts, ta, tb, te, obstacles, need]: the window, the stretch inside the
    encounter's balls, and per direction the push its inside samples need
    (:func:`~etdmp_ros.dmp._clearance.least_pushes`).
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


def _options(tw: Array, dsw: Array, W: Array, q: Array, own: NDArray[np.bool_], directions: Array,
             candidates: Iterable[int], ts: float, ta: float, te: float, size: float,
             refine: int = 0) -> tuple[float, float, Array, float, float, float, float] | None:
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
            b = bump(tw, ts, lo_t, hi_t, te, fast=False)[0]
            A = amplitude(chords(W, refine), q, n, chords(b, refine), own, 0.0, fast=False)
            cost = A * A * float(np.sum(b * b * dsw))
            if A <= size and (best is None or cost < best[0] * (1.0 - TIE)):
                best = (cost, A, n, ts, lo_t, hi_t, te)
    return best


if numba is not None:
    @numba.njit(cache=True, fastmath=False)
    def _bump_nb(t: float, ts: float, ta: float, tb: float,
                 te: float) -> float:  # pragma: no cover - numba
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
    def _encounter_nb(tw: Array, dsw: Array,
                      W: Array, own: NDArray[np.bool_], q: Array,
                      D: Array, candidates: NDArray[np.intp],
                      fractions: Array, ts: float, ta: float, te: float,
                      size: float, tie: float, Wc: Array,
                      cc: Array, refine: int) -> tuple[
                          int, float, float, float]:  # pragma: no cover - numba
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


def detour(t: Array, x: Array, obstacles: Obstacles, margin: float, ramp: float, directions: Array,
           size: float, displacement: Displacement | None = None, t0: float | None = None,
           blend_length: float | None = None, fast: bool = True, acceleration: float | None = None,
           refine: int = 0) -> Displacement | None:
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
    C = obstacles.centres
    t0 = float(t[0]) if t0 is None else float(t0)
    carry = None if displacement is None else _carry(displacement, t0)
    if len(C) == 0 and carry is None:
        return None
    step = np.diff(x, axis=0)
    ds = np.sqrt(np.einsum('ki,ki->k', step, step))
    s = np.concatenate([[0.0], np.cumsum(ds)])
    ds = np.concatenate([[0.0], ds])                # arc length before each sample
    blend = 0.0
    base = x
    if carry is not None:
        blend = max(_arc_time(s, t, min(blend_length, s[-1])) - t0, 0.0)
        if blend <= 0.0:
            blend = float(t[-1] - t0)
        carry_only = Displacement(*(np.zeros(0),) * 5, np.zeros((0, d)), t0, blend, carry)
        base = x + carry_only(t)[0]
        if len(C) == 0:
            return carry_only
    q, inside = _target_radii(base, obstacles, margin, fast)
    if not inside.any():
        return carry_only if carry is not None else None
    spans = _spans(t, s, base, C, q, inside, ramp, directions, acceleration, t0,
                   None if carry is None else blend, fast)
    found = _encounters(t, ds, base, obstacles, q, _joined(spans), directions, size, fast,
                        refine, acceleration, t0)
    A = np.array([f[0] for f in found])
    N = np.array([f[1] for f in found]).reshape(-1, d)
    corners = np.array([f[2:] for f in found], dtype=float).reshape(-1, 4)
    return Displacement(corners[:, 0], corners[:, 1], corners[:, 2], corners[:, 3], A, N, t0,
                        blend, carry)


def _carry(displacement: Displacement, t0: float) -> Array | None:
    """Return the displacement in force at ``t0`` and its derivatives (3, d), or None if 0."""
    now = displacement(np.array([t0]))
    carry = np.stack([now[0][0], now[1][0], now[2][0]])
    return carry if np.any(carry) else None


def _target_radii(base: Array, obstacles: Obstacles, margin: float,
                  fast: bool = True) -> tuple[Array, NDArray[np.bool_]]:
    """
    Return the target radii ``q`` (m,) and which samples of ``base`` (n, d) are within (n, m).

    ``q`` is ``r + margin``, lowered to what the ends of the plan allow (> r); an obstacle that
    holds the plan's start or end raises GeneralizationError.
    """
    C, r = obstacles.centres, obstacles.radii
    dist = distances(base, C, fast)                                       # (n, m)
    ends = np.minimum(dist[0], dist[-1])
    for j in np.flatnonzero(ends < r):
        end = 0 if dist[0, j] < r[j] else -1
        raise GeneralizationError(
            f'obstacle #{j} (centre {format_point(C[j])}, radius {r[j]:.4g}) contains the '
            f"plan's {'start' if end == 0 else 'end'} ({dist[end, j]:.4g} from its centre): the "
            'clearance cannot be kept')
    q = np.minimum(r + margin, ends)
    return q, dist < q


def _spans(t: Array, s: Array, base: Array, C: Array, q: Array, inside: NDArray[np.bool_],
           ramp: float, directions: Array, acceleration: float | None, t0: float,
           blend: float | None, fast: bool = True) -> list[list[Any]]:
    """
    Return the stretches of samples ``inside`` an obstacle: ``[ts, ta, tb, te, {j}, need]``.

    ``s`` (n,): the arc length at the samples; ``blend``: the carried displacement's blend
    time, or None without one; ``need``: per direction, the least translation that clears it.
    ``fast``: numba loops, else the numpy references.
    """
    spans = []
    t_last = float(t[-1])
    for j in range(len(C)):
        length = ramp * q[j]
        for a, b in _runs(inside[:, j]):
            ta, tb = float(t[a]), float(t[b])
            ts = _arc_time(s, t, s[a] - length)
            te = _arc_time(s, t, s[b] + length)
            need = least_pushes(base[a:b + 1] - C[j], q[j], directions, fast)
            if acceleration:
                # Long enough for the least translation that clears the stretch.
                least = _ramp_time(float(need.min()), acceleration)
                ts, te = min(ts, ta - least), max(te, tb + least)
            ts, te = max(ts, t0), min(te, t_last)
            if blend is not None and ts <= t0:
                # Rising from the switch as the carried displacement fades: together smooth.
                ta = max(ta, t0 + blend)
                tb, te = max(tb, ta), max(te, ta)
            spans.append([ts, ta, tb, te, {j}, need])
    return spans


def _encounters(t: Array, ds: Array, base: Array, obstacles: Obstacles, q: Array,
                joined: list[list[Any]], directions: Array, size: float, fast: bool,
                refine: int, acceleration: float | None, t0: float) -> list[Encounter]:
    """
    Return the best detour of each encounter: ``joined`` spans (:func:`_joined`) in time order.

    Stretches whose bumps overlap in time are one encounter (one direction, one bump): bumps
    of their own, raised together, were measured to bend the shape more
    (docs/design.md#obstacles-with-a-size). The encounters' windows are then disjoint, and
    each amplitude is found on its own.
    """
    C, r = obstacles.centres, obstacles.radii
    t_last = float(t[-1])
    found: list[Encounter] = []
    for e, span in enumerate(joined):
        own = np.zeros(len(C), dtype=bool)
        own[sorted(span[4])] = True
        best = _encounter(t, ds, base, C, q, own, span, directions, size, fast, refine)
        if best is None:
            j = min(span[4])
            raise GeneralizationError(
                f'passing obstacle #{j} (centre {format_point(C[j])}, radius {r[j]:.4g}) needs '
                f"a detour larger than the movement's size {size:.4g}: no detour keeps the "
                'shape')
        if acceleration:
            # A joined encounter may need more than its stretches' least pushes: lengthen its
            # ramps into the free time around it (windows stay disjoint) and solve again.
            room = (found[-1][5] if found else t0,
                    joined[e + 1][0] if e + 1 < len(joined) else t_last)
            best = _slower(t, base, C, q, own, best, room, acceleration, size, fast, refine)
        found.append(best)
    return found


def _ramp_time(amplitude: float, acceleration: float) -> float:
    """Return the ramp duration whose smoothstep keeps ``amplitude`` under ``acceleration``."""
    # The quintic smoothstep's second derivative peaks at 10 / sqrt(3) (at u = 1/2 -+ 1/sqrt(12)).
    return math.sqrt(10.0 / math.sqrt(3.0) * amplitude / acceleration)


def _slower(t: Array, base: Array, C: Array, q: Array, own: NDArray[np.bool_], best: Encounter,
            room: tuple[float, float], acceleration: float, size: float, fast: bool,
            refine: int = 0) -> Encounter:
    """Return ``best`` with ramps lengthened (within ``room``) to keep the acceleration bound."""
    A, n, ts, ta, tb, te = best
    least = _ramp_time(A, acceleration)
    new_ts = max(min(ts, ta - least), room[0])
    new_te = min(max(te, tb + least), room[1])
    if new_ts == ts and new_te == te:
        return best
    window = np.flatnonzero((t > new_ts) & (t < new_te))
    b = bump(t[window], new_ts, ta, tb, new_te, fast)[0]
    A2 = amplitude(chords(base[window][:, None] - C[None], refine), q, n, chords(b, refine), own,
                   0.0, fast)
    return (A2, n, new_ts, ta, tb, new_te) if A2 <= size else best


def _joined(spans: list[list[Any]]) -> list[list[Any]]:
    """Join spans ``[ts, ta, tb, te, balls, need]`` whose windows ``(ts, te)`` overlap."""
    out: list[list[Any]] = []
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


def keep_clear(t: Array, x: Array, obstacles: Obstacles, *args: Any, where: str = 'the plan',
               **kwargs: Any) -> tuple[Displacement | None, Values | None]:
    """
    Return :func:`detour`'s displacement for ``x`` and its values at ``t``, checked clear.

    Arguments as :func:`detour`. Returns ``(displacement, (delta, delta', delta''))``, or
    ``(None, None)`` where nothing moves. Where a straight segment between two samples of the
    moved plan cuts into an obstacle (a large, fast detour), the detour is planned again with
    REFINE points per segment held clear. Raises GeneralizationError when the moved plan is
    still not clear (:func:`check_clearance`): never a plan that enters an obstacle.
    """
    for refine in (0, REFINE):
        shift = detour(t, x, obstacles, *args, refine=refine, **kwargs)  # type: ignore[misc]
        values = None if shift is None else shift(t)
        try:
            check_clearance(x if shift is None or values is None else x + values[0], obstacles,
                            where)
            return shift, values
        except GeneralizationError as err:
            error = err
    raise error

"""
Unit quaternions in ROS order ``(x, y, z, w)``, numpy only, batched over leading axes.

The mathematics: docs/orientation.md. A unit quaternion ``q = (sin(a/2) n, cos(a/2))`` is the
rotation by the angle ``a`` about the unit axis ``n``; ``q`` and ``-q`` are the same rotation.
The rotation vector of a rotation is ``r = a n`` and ``exp(r / 2)`` its quaternion;
``rotation_vector`` returns the shortest one (``|r| <= pi``), ``unwrap`` makes a sequence of
them continuous by choosing, for each, the one of its lifts ``(a + 2 pi m) n`` nearest to its
neighbour. Products are Hamilton products: ``multiply(p, q)`` is the rotation q followed by p.
"""

from __future__ import annotations

from etdmp_ros.geometry.arrays import Array, Quaternions, Rotations, RotationVectors
import numpy as np
from numpy.typing import ArrayLike

#: Norm below which a quaternion counts as zero (no rotation can be read from it).
MIN_NORM = 1e-9
#: Below this rotation angle (rad) the series expansions replace the closed forms.
SMALL_ANGLE = 1e-4
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def unit_and_norm(v: ArrayLike) -> tuple[Array, Array]:
    """
    Return ``(v / |v|, |v|)`` of vectors (..., k) without overflow; a zero vector stays zero.

    ``np.linalg.norm`` squares the components: one of 1e308 gives inf (or FloatingPointError
    under ``np.errstate(over='raise')``, "overflow encountered in dot"), and ``v / inf`` is the
    zero vector. Here ``v`` is divided by its largest component first. ``|v|`` itself is inf
    where it exceeds the largest float (components of 1.7e308), which the caller may refuse.
    """
    v = np.asarray(v, dtype=float)
    scale = np.max(np.abs(v), axis=-1, keepdims=True)
    scaled = v / np.where(scale > 0.0, scale, 1.0)
    length = np.linalg.norm(scaled, axis=-1, keepdims=True)
    with np.errstate(over='ignore'):
        norm = (scale * length)[..., 0]
    return scaled / np.where(length > 0.0, length, 1.0), norm


def multiply(p: ArrayLike, q: ArrayLike) -> Quaternions:
    """Return the Hamilton products ``p q`` of quaternions (..., 4) (broadcast)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    px, py, pz, pw = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw,
                     pw * qw - px * qx - py * qy - pz * qz], axis=-1)


def left_matrix(p: ArrayLike) -> Array:
    """Return the matrices L (..., 4, 4) with ``p q = L q`` for quaternions ``p`` (..., 4)."""
    p = np.asarray(p, dtype=float)
    x, y, z, w = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    return np.stack([np.stack([w, -z, y, x], -1), np.stack([z, w, -x, y], -1),
                     np.stack([-y, x, w, z], -1), np.stack([-x, -y, -z, w], -1)], axis=-2)


def right_matrix(q: ArrayLike) -> Array:
    """Return the matrices M (..., 4, 4) with ``p q = M p`` for quaternions ``q`` (..., 4)."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([np.stack([w, z, -y, x], -1), np.stack([-z, w, x, y], -1),
                     np.stack([y, -x, w, z], -1), np.stack([-x, -y, -z, w], -1)], axis=-2)


def conjugate(q: ArrayLike) -> Quaternions:
    """Return the conjugates (the inverses, for unit quaternions) of ``q`` (..., 4)."""
    q = np.asarray(q, dtype=float)
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def about_axis(axis: ArrayLike, angle: ArrayLike) -> Quaternions:
    """Return the quaternions (..., 4) of rotations by ``angle`` (...) about unit ``axis``."""
    half = 0.5 * np.asarray(angle, dtype=float)
    axis = np.asarray(axis, dtype=float)
    return np.concatenate([np.sin(half)[..., None] * axis, np.cos(half)[..., None]], axis=-1)


def exp_map(r: ArrayLike) -> Quaternions:
    """Return the unit quaternions ``exp(r / 2)`` (..., 4) of rotation vectors ``r`` (..., 3)."""
    r = np.asarray(r, dtype=float)
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    # sin(angle/2) / angle, finite at 0 (numpy's sinc is sin(pi x) / (pi x)).
    factor = 0.5 * np.sinc(angle / (2.0 * np.pi))
    return np.concatenate([factor * r, np.cos(0.5 * angle)], axis=-1)


def canonical(q: ArrayLike) -> Quaternions:
    """
    Return ``q`` or ``-q`` (..., 4), whichever has ``w > 0``.

    For ``w == 0`` (a half turn) the sign makes the first non-zero vector component positive,
    so that ``q`` and ``-q`` always give the same result.
    """
    q = np.asarray(q, dtype=float)
    key = q[..., 3].copy()
    for i in (0, 1, 2):
        key = np.where(key == 0.0, q[..., i], key)
    return np.where((key < 0.0)[..., None], -q, q)


def rotation_vector(q: ArrayLike) -> RotationVectors:
    """Return the shortest rotation vectors ``r`` (``|r| <= pi``, (..., 3)) of quaternions."""
    return log_map(canonical(q))     # w >= 0: the shorter way round


def log_map(q: ArrayLike) -> RotationVectors:
    """
    Return the rotation vectors ``r`` with ``exp(r / 2) = q`` (..., 3), ``|r|`` in [0, 2 pi].

    Unlike :func:`rotation_vector` the sign of ``q`` counts: ``-q`` gives the rotation the other
    way round, so a sign-continuous path of quaternions gives a continuous path of rotation
    vectors (up to 2 pi from the identity).
    """
    q = np.asarray(q, dtype=float)
    v, w = q[..., :3], q[..., 3:]
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(norm, w)
    with np.errstate(divide='ignore', invalid='ignore'):
        # angle / |v|; near the identity its series 2/w (1 - |v|^2 / (3 w^2)) is exact enough.
        exact = angle / norm
        series = 2.0 / w * (1.0 - norm ** 2 / (3.0 * w ** 2))
    return np.where((norm > SMALL_ANGLE) | (w <= 0.0), exact, series) * v


def nearest_lift(r: ArrayLike, reference: ArrayLike) -> RotationVectors:
    """
    Return the lift ``(a + 2 pi m) n`` of rotation vectors ``r`` nearest to ``reference``.

    ``r`` and ``reference`` are (..., 3). All lifts lie on the line of the axis ``n``; the
    nearest is found by rounding. A rotation vector near zero has lifts ``2 pi m u`` for every
    unit ``u``: the nearest is taken along ``reference``. Ties (a reference exactly half way)
    round to even.
    """
    r = np.asarray(r, dtype=float)
    reference = np.asarray(reference, dtype=float)
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    ref_norm = np.linalg.norm(reference, axis=-1, keepdims=True)
    tiny = angle <= SMALL_ANGLE
    with np.errstate(divide='ignore', invalid='ignore'):
        axis = np.where(tiny, reference / np.where(ref_norm > 0.0, ref_norm, 1.0), r / angle)
    along = np.sum(axis * reference, axis=-1, keepdims=True)
    m = np.round((along - angle) / (2.0 * np.pi))
    lift = r + 2.0 * np.pi * m * axis
    return np.where(tiny & (m == 0.0), r, lift)


def unwrap(r: ArrayLike, backward: bool = False) -> RotationVectors:
    """
    Make a sequence of rotation vectors ``r`` (T, 3) continuous (each nearest to the previous).

    ``backward`` keeps the last one and walks to the first (a path anchored at its end).
    """
    r = np.array(r, dtype=float)
    steps = np.linalg.norm(np.diff(r, axis=0), axis=1)
    jumps = np.flatnonzero(steps > 0.5 * np.pi)     # a smooth path has none: nothing to do
    if not jumps.size:
        return r
    order = range(jumps[-1], -1, -1) if backward else range(jumps[0] + 1, len(r))
    for k in order:
        r[k] = nearest_lift(r[k], r[k + 1] if backward else r[k - 1])
    return r


def angle_between(p: ArrayLike, q: ArrayLike) -> Array:
    """Return the rotation angles (rad, in [0, pi]) between quaternions ``p`` and ``q``."""
    d = multiply(conjugate(p), q)
    return 2.0 * np.arctan2(np.linalg.norm(d[..., :3], axis=-1), np.abs(d[..., 3]))


def continuous(q: ArrayLike) -> Quaternions:
    """Flip the signs of quaternions ``q`` (T, 4) so that neighbours have dot product >= 0."""
    q = np.asarray(q, dtype=float)
    flips = np.where(np.sum(q[1:] * q[:-1], axis=1) < 0.0, -1.0, 1.0)
    return q * np.cumprod(np.r_[1.0, flips])[:, None]


def left_jacobian(r: ArrayLike, r_dot: ArrayLike) -> Array:
    """
    Return ``omega = J(r) dr/dt`` (..., 3): the angular velocity of ``exp(r(t) / 2)``.

    ``J(r) = I + (1 - cos a)/a^2 [r]x + (a - sin a)/a^3 [r]x^2`` (``a = |r|``) is the left
    Jacobian of the rotation group: ``d/dt exp(r/2) = 1/2 omega exp(r/2)``, omega in the
    fixed frame.
    """
    r = np.asarray(r, dtype=float)
    r_dot = np.asarray(r_dot, dtype=float)
    a = np.linalg.norm(r, axis=-1, keepdims=True)
    a2 = a * a
    small = a <= SMALL_ANGLE
    with np.errstate(divide='ignore', invalid='ignore'):
        c1 = np.where(small, 0.5 - a2 / 24.0, (1.0 - np.cos(a)) / a2)
        c2 = np.where(small, 1.0 / 6.0 - a2 / 120.0, (a - np.sin(a)) / (a2 * a))
    rxd = np.cross(r, r_dot)
    return r_dot + c1 * rxd + c2 * np.cross(r, rxd)


def normalized(q: ArrayLike) -> Quaternions:
    """
    Return quaternions (..., 4) scaled to unit length; ValueError for a zero or non-finite one.

    For quaternions from outside (parameters, messages, files); the other functions here take
    unit quaternions as they are.
    """
    q = np.asarray(q, dtype=float)
    if q.shape[-1:] != (4,):
        raise ValueError(f'quaternions [x, y, z, w] must have 4 values, got shape {q.shape}')
    unit, n = unit_and_norm(q)      # (1e308, 1e308, 0, 1) is a rotation too
    bad = ~np.isfinite(n) | (n < MIN_NORM) | ~np.all(np.isfinite(q), axis=-1)
    if np.any(bad):
        raise ValueError(f'not a rotation quaternion [x, y, z, w]: '
                         f'{q.reshape(-1, 4)[int(np.argmax(bad.ravel()))].tolist()}')
    return unit


def from_rpy(roll: float, pitch: float, yaw: float) -> Quaternions:
    """Return the quaternion of URDF's roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.array([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


def to_matrix(q: ArrayLike) -> Rotations:
    """Return the rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def from_matrix(R: ArrayLike) -> Quaternions:
    """
    Return unit quaternions (..., 4), ``w >= 0``, of rotation matrices ``R`` (..., 3, 3).

    Shepperd's method, vectorised: each matrix uses the largest of the four candidate
    denominators, so no division is by a small number.
    """
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    candidates = np.stack([1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22,
                           1 + m00 + m11 + m22], axis=-1)
    best = np.argmax(candidates, axis=-1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(candidates, best[..., None], -1), 1e-300))
    s = s[..., 0]
    d21, d02, d10 = R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], \
        R[..., 1, 0] - R[..., 0, 1]
    s01, s02, s12 = R[..., 0, 1] + R[..., 1, 0], R[..., 0, 2] + R[..., 2, 0], \
        R[..., 1, 2] + R[..., 2, 1]
    rows = [np.stack([s / 4, s01 / s, s02 / s, d21 / s], -1),
            np.stack([s01 / s, s / 4, s12 / s, d02 / s], -1),
            np.stack([s02 / s, s12 / s, s / 4, d10 / s], -1),
            np.stack([d21 / s, d02 / s, d10 / s, s / 4], -1)]
    q = np.choose(best[..., None], rows)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:] < 0.0, -q, q)

"""
Tool pose trajectories that the controller follows: time-stamped paths and minimum-jerk moves.

Both kinds answer ``pose(t) -> (p, R)`` for any ``t`` (clamped to ``[0, duration]``): ``p`` is the
tool tip position (3,) and ``R`` the tool rotation (3, 3), both in base_link. The controller needs
nothing else: its feed-forward velocity is the secant of ``pose`` over one control period.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Sequence


from etdmp_ros import limits
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Array, Points3, Rotations
from etdmp_ros.robot import _ik_fast

import numpy as np
from numpy.typing import ArrayLike
import pinocchio as pin

#: Smallest step between two time stamps (s); closer stamps are a malformed path.
MIN_STAMP_STEP = 1e-6


class TrajectoryError(ValueError):
    """A trajectory that cannot be followed (malformed input); the message says why."""


def _as_rotations(rotations: ArrayLike, n: int) -> Rotations:
    rot = np.asarray(rotations, dtype=float)
    if rot.shape != (n, 3, 3):
        raise TrajectoryError(f'rotations must have shape ({n}, 3, 3), got {rot.shape}')
    if not np.all(np.isfinite(rot)):
        raise TrajectoryError('rotations contain NaN or inf')
    gram = np.einsum('nij,nkj->nik', rot, rot) - np.eye(3)
    if np.max(np.abs(gram)) > 1e-6 or np.any(np.linalg.det(rot) < 0.0):
        raise TrajectoryError('rotations must be proper rotation matrices')
    return rot


def quaternions_to_rotations(quaternions: ArrayLike) -> Rotations:
    """
    Convert (n, 4) quaternions ``(x, y, z, w)`` (ROS order) to (n, 3, 3) rotation matrices.

    Quaternions are normalised; a zero or non-finite one raises TrajectoryError.
    """
    try:
        return quat.to_matrix(quat.normalized(np.asarray(quaternions, dtype=float).reshape(-1, 4)))
    except ValueError as exc:
        raise TrajectoryError(f'bad orientation: {exc}') from None


class PoseTrajectory:
    """
    A path of time-stamped tool poses, interpolated in time.

    Positions: C1 cubic Hermite spline through the samples, tangents by second-order finite
    differences (a path that starts or ends at rest keeps zero velocity there). Rotations: the
    geodesic between neighbouring samples (``R(t) = exp(s log(R_i+1 R_i^T)) R_i``). Times are
    relative to the first sample: ``pose(0)`` is the first pose whatever the stamps' origin.
    A single pose is a trajectory of duration 0.
    """

    def __init__(self, t: ArrayLike, positions: ArrayLike, rotations: ArrayLike) -> None:
        """Check and store samples: ``t`` (n,) strictly increasing, (n, 3), (n, 3, 3)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        n = len(t)
        if n == 0:
            raise TrajectoryError('the path is empty')
        if not np.all(np.isfinite(t)):
            raise TrajectoryError('time stamps contain NaN or inf')
        steps = np.diff(t)
        if np.any(steps < MIN_STAMP_STEP):
            k = int(np.argmax(steps < MIN_STAMP_STEP))
            raise TrajectoryError(
                f'time stamps must increase strictly: pose #{k + 1} is at {t[k + 1]:.6f} s, '
                f'pose #{k} at {t[k]:.6f} s')
        p = np.asarray(positions, dtype=float)
        if p.shape != (n, 3):
            raise TrajectoryError(f'positions must have shape ({n}, 3), got {p.shape}')
        if not np.all(np.isfinite(p)):
            raise TrajectoryError('positions contain NaN or inf')
        self.t = t - t[0]
        self.positions = p.copy()
        self.rotations = _as_rotations(rotations, n).copy()
        self.duration = float(self.t[-1])
        self._times = self.t.tolist()
        if n == 1:
            self._coeffs = np.zeros((0, 4, 3))
            self._twists = np.zeros((0, 3))
            return
        h = steps[:, None]
        m = np.gradient(p, self.t, axis=0, edge_order=2 if n >= 3 else 1)
        p0, p1, m0, m1 = p[:-1], p[1:], h * m[:-1], h * m[1:]
        # p(s) = c0 + c1 s + c2 s^2 + c3 s^3 on each segment, s in [0, 1].
        self._coeffs = np.stack(
            [p0, m0, 3.0 * (p1 - p0) - 2.0 * m0 - m1, 2.0 * (p0 - p1) + m0 + m1], axis=1)
        self._twists = np.array([pin.log3(r1 @ r0.T) for r0, r1 in
                                 zip(self.rotations[:-1], self.rotations[1:])])

    @classmethod
    def from_quaternions(cls, t: ArrayLike, positions: ArrayLike,
                         quaternions: ArrayLike) -> PoseTrajectory:
        """Build from ``(x, y, z, w)`` quaternions (ROS order)."""
        return cls(t, positions, quaternions_to_rotations(quaternions))

    @classmethod
    def timed_by_speed(cls, positions: ArrayLike, rotations: ArrayLike, speed: float,
                       angular_speed: float, min_duration: float = 0.1) -> PoseTrajectory:
        """
        Time an untimed path: a minimum-jerk speed profile along its length.

        The path's arc length ``L`` (and total rotation angle) is covered in
        ``T = max(1.875 L / speed, 1.875 angle / angular_speed, min_duration)``, the duration at
        which a minimum-jerk profile peaks at ``speed``; it starts and ends at rest.
        """
        p = np.asarray(positions, dtype=float)
        rot = np.asarray(rotations, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
            raise TrajectoryError(f'positions must have shape (n, 3), got {p.shape}')
        if len(p) == 1:
            return cls([0.0], p, rot.reshape(1, 3, 3))
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        ang = np.array([np.linalg.norm(pin.log3(r1 @ r0.T)) for r0, r1 in zip(rot[:-1], rot[1:])])
        # Progress along the path: length and angle, each as a fraction of its total.
        total, total_ang = seg.sum(), ang.sum()
        progress = np.zeros(len(p))
        if total > 0.0 or total_ang > 0.0:
            weight_lin = total / speed
            weight_ang = total_ang / angular_speed
            step = (seg * weight_lin / max(total, 1e-12)
                    + ang * weight_ang / max(total_ang, 1e-12))
            progress[1:] = np.cumsum(step) / step.sum()
        keep = np.r_[True, np.diff(progress) > 1e-9]
        if not np.all(keep):
            p, rot, progress = p[keep], rot[keep], progress[keep]
        duration = max(1.875 * total / speed, 1.875 * total_ang / angular_speed, min_duration)
        if len(p) == 1:
            return cls([0.0], p, rot)
        return cls(duration * _inverse_minimum_jerk(progress), p, rot)

    def _segment(self, t: float) -> tuple[int | None, float]:
        if t <= 0.0 or len(self._times) == 1:
            return None, 0
        if t >= self.duration:
            return None, len(self._times) - 1
        i = min(bisect_right(self._times, t) - 1, len(self._times) - 2)
        return i, (t - self._times[i]) / (self._times[i + 1] - self._times[i])

    def pose(self, t: float, fast: bool | None = None) -> tuple[Points3, Rotations]:
        """
        Return (p (3,), R (3, 3)) at time ``t`` (s, clamped to the path's span).

        ``fast``: the numba kernel (default when numba is there) or this numpy code (the oracle).
        """
        if _ik_fast.AVAILABLE if fast is None else fast:
            p, rot = np.empty(3), np.empty((3, 3))
            _ik_fast.hermite_pose(self.t, self.positions, self._coeffs, self.rotations,
                                  self._twists, float(t), p, rot)
            return p, rot
        i, s = self._segment(t)
        if i is None:
            return self.positions[int(s)].copy(), self.rotations[int(s)].copy()
        c = self._coeffs[i]
        p = c[0] + s * (c[1] + s * (c[2] + s * c[3]))
        return p, pin.exp3(s * self._twists[i]) @ self.rotations[i]

    def velocity(self, t: float) -> Points3:
        """Return the tool tip velocity in m/s, shape (3,), at ``t`` (zero outside the span)."""
        i, s = self._segment(t)
        if i is None:
            return np.zeros(3)
        c = self._coeffs[i]
        h = self._times[i + 1] - self._times[i]
        return (c[1] + s * (2.0 * c[2] + s * 3.0 * c[3])) / h


def _inverse_minimum_jerk(progress: Array) -> Array:
    """Return u in [0, 1] with 10u^3 - 15u^4 + 6u^5 = progress (monotone; bisection)."""
    lo, hi = np.zeros_like(progress), np.ones_like(progress)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        below = mid ** 3 * (10.0 - 15.0 * mid + 6.0 * mid ** 2) < progress
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    u = 0.5 * (lo + hi)
    u[0], u[-1] = 0.0, 1.0
    return u


def _quintic(s: float | Array) -> tuple[tuple[float | Array, ...], tuple[float | Array, ...]]:
    """Return the quintic Hermite basis (h00, h01, h10, h11) and its s-derivative at s."""
    s2, s3 = s * s, s * s * s
    basis = (1.0 - s3 * (10.0 - 15.0 * s + 6.0 * s2),     # start position
             s3 * (10.0 - 15.0 * s + 6.0 * s2),           # end position
             s - s3 * (6.0 - 8.0 * s + 3.0 * s2),         # start velocity (times T)
             -s3 * (4.0 - 7.0 * s + 3.0 * s2))            # end velocity (times T)
    d01 = 30.0 * s2 * (1.0 - s) ** 2
    deriv = (-d01, d01, 1.0 - s2 * (18.0 - 32.0 * s + 15.0 * s2),
             -s2 * (12.0 - 28.0 * s + 15.0 * s2))
    return basis, deriv


class MinimumJerkMove:
    """
    A smooth move from the tool's current pose and velocity to a pose at rest.

    Position and rotation vector (relative to the start rotation, in base_link axes) each follow
    a quintic with the given start velocity, zero start acceleration and zero end velocity and
    acceleration: from rest, the minimum-jerk profile ``10 s^3 - 15 s^4 + 6 s^5``.
    """

    def __init__(self, p0: ArrayLike, rotation0: ArrayLike, p1: ArrayLike, rotation1: ArrayLike,
                 duration: float, v0: ArrayLike = (0.0, 0.0, 0.0),
                 w0: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        """Plan over ``duration`` seconds; ``v0`` (m/s) and ``w0`` (rad/s) are start velocities."""
        if not (np.isfinite(duration) and duration > 0.0):
            raise TrajectoryError(f'duration must be positive, got {duration!r}')
        self.duration = float(duration)
        self.p0 = np.asarray(p0, dtype=float).copy()
        self.p1 = np.asarray(p1, dtype=float).copy()
        self.rotation0 = np.asarray(rotation0, dtype=float).copy()
        self.rotation1 = np.asarray(rotation1, dtype=float).copy()
        self.v0 = np.asarray(v0, dtype=float).copy()
        self.w0 = np.asarray(w0, dtype=float).copy()
        self.angle = pin.log3(self.rotation1 @ self.rotation0.T)

    @classmethod
    def plan(cls, p0: ArrayLike, rotation0: ArrayLike, p1: ArrayLike, rotation1: ArrayLike,
             speed: float, angular_speed: float, acceleration: float,
             v0: ArrayLike = (0.0, 0.0, 0.0), w0: ArrayLike = (0.0, 0.0, 0.0),
             min_duration: float = 0.2) -> MinimumJerkMove:
        """
        Choose the shortest duration that keeps the move safe and return the move.

        From rest, peak speed ``1.875 d / T`` and peak acceleration ``5.77 d / T^2`` give the
        start value; the duration then grows until sampled peaks respect ``speed`` (or the start
        speed, if higher), ``angular_speed`` and ``acceleration`` (m/s^2).
        """
        dist = float(np.linalg.norm(np.asarray(p1, float) - np.asarray(p0, float)))
        angle = float(np.linalg.norm(pin.log3(np.asarray(rotation1) @ np.asarray(rotation0).T)))
        duration = max(min_duration, 1.875 * dist / speed, 1.875 * angle / angular_speed,
                       np.sqrt(5.7735 * dist / acceleration))
        speed_cap = max(speed, float(np.linalg.norm(v0)))
        ang_cap = max(angular_speed, float(np.linalg.norm(w0)))
        s = np.linspace(0.0, 1.0, 41)
        for _ in range(100):
            move = cls(p0, rotation0, p1, rotation1, duration, v0, w0)
            v, w, a = move._profile(s)
            if (v.max() <= speed_cap * (1 + 1e-6) and w.max() <= ang_cap * (1 + 1e-6)
                    and a.max() <= acceleration * (1 + 1e-6)):
                return move
            duration *= 1.1
        return move

    def _profile(self, s: Array) -> tuple[Array, Array, Array]:
        """Return sampled |velocity|, |angular rate| and |acceleration| at phases ``s``."""
        _, (_, d01, d10, _) = _quintic(s[:, None])
        T = self.duration
        vel = d01 * (self.p1 - self.p0) / T + d10 * self.v0
        rate = d01 * self.angle / T + d10 * self.w0
        acc = np.gradient(vel, s * T, axis=0)
        return (np.linalg.norm(vel, axis=1), np.linalg.norm(rate, axis=1),
                np.linalg.norm(acc, axis=1))

    def pose(self, t: float) -> tuple[Points3, Rotations]:
        """Return (p (3,), R (3, 3)) at time ``t`` (s, clamped to ``[0, duration]``)."""
        if t >= self.duration:
            return self.p1.copy(), self.rotation1.copy()
        s = max(t, 0.0) / self.duration
        (h00, h01, h10, _), _ = _quintic(s)
        T = self.duration
        p = h00 * self.p0 + h01 * self.p1 + h10 * T * self.v0
        r = h01 * self.angle + h10 * T * self.w0
        return p, pin.exp3(r) @ self.rotation0

    def velocity(self, t: float) -> Points3:
        """Return the tool tip velocity in m/s, shape (3,), at time ``t``."""
        if t >= self.duration or t < 0.0:
            return np.zeros(3) if t >= self.duration else self.v0.copy()
        _, (_, d01, d10, _) = _quintic(t / self.duration)
        return d01 * (self.p1 - self.p0) / self.duration + d10 * self.v0


def trajectory_from_path(stamps_ns: Sequence[int] | None, positions: ArrayLike,
                         quaternions: ArrayLike | None, tool_rotation: Rotations,
                         speed: float = 0.05, angular_speed: float = 0.5) -> PoseTrajectory:
    """
    Return the PoseTrajectory of a received path (the rules of the controller's /etdmp/path).

    - Timing: pose ``k`` is at ``(stamps_ns[k] - stamps_ns[0]) * 1e-9`` s; only differences
      count (the path starts when it is received, or after the approach). If every stamp is the
      same (e.g. all zero: an untimed path), the path is timed by its length: a minimum-jerk
      profile peaking at ``speed`` m/s (``angular_speed`` rad/s for rotations).
    - Orientation: ``quaternions`` (n, 4) (x, y, z, w); if all are zero (unset), the tool keeps
      ``tool_rotation`` (its current one) along the whole path.

    Raises TrajectoryError with the reason for anything else that is malformed.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    positions = np.asarray(positions, dtype=float)
    quat = np.asarray(quaternions, dtype=float).reshape(-1, 4)
    n = len(stamps)
    if n == 0:
        raise TrajectoryError('the path is empty')
    if positions.shape != (n, 3) or quat.shape != (n, 4):
        raise TrajectoryError('positions and orientations must match the stamps in number')
    if not np.all(np.isfinite(positions)) or not np.all(np.isfinite(quat)):
        raise TrajectoryError('the path contains NaN or inf')
    far = float(np.abs(positions).max())
    if far > limits.MAX_REQUEST_COORDINATE:
        # A finite 1e308 overflowed: a timed path raised LinAlgError in the checking thread (a
        # traceback, the path dropped unsaid); an untimed one passed the check with duration 0.
        raise TrajectoryError(f'the path has a coordinate of {far:.3g} m, beyond '
                              f'{limits.MAX_REQUEST_COORDINATE:g} m (MAX_REQUEST_COORDINATE): no '
                              'place of the workcell')
    if not np.any(quat):
        rotations = np.repeat(np.asarray(tool_rotation, dtype=float)[None], n, axis=0)
    else:
        rotations = quaternions_to_rotations(quat)
    t = (stamps - stamps[0]) * 1e-9
    if n > 1 and not np.any(t):
        return PoseTrajectory.timed_by_speed(positions, rotations, speed, angular_speed)
    return PoseTrajectory(t, positions, rotations)

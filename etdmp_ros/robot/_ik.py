"""
Differential inverse kinematics of the UR10 tool tip, with every limit of a velocity command.

One :meth:`DifferentialIK.solve` maps a desired tool twist ``xi = (v, w)`` (m/s, rad/s, base_link
axes) to joint velocities ``qd`` (rad/s) in this order:

1. Damped least squares from one SVD ``J = U S V^T``: ``qd = V diag(s_i / (s_i^2 + lambda^2))
   U^T xi``. The damping is zero while the smallest singular value ``s_min`` is above
   ``singular_value_threshold`` (exact inverse: no tracking error in the normal workspace) and
   grows as ``lambda^2 = max_damping^2 (1 - (s_min / threshold)^2)`` below it (Nakamura and
   Hanafusa 1986; Chiaverini 1997), so ``|qd| <= |xi| / (2 lambda)`` stays bounded through a
   singularity. MoveIt Servo uses an undamped pseudo-inverse there.
2. Optional posture term in the damped null space ``N = V diag(lambda^2 / (s_i^2 + lambda^2))
   V^T`` (zero away from singularities on this 6-joint arm with a 6D task; near one it moves
   the arm along the directions the damped task leaves free, towards ``posture``).
3. Condition number ``kappa = s_max / s_min``: when ``kappa`` is above ``condition_slowdown``
   and the command makes it grow (``kappa`` one period ahead is larger), the command is scaled
   by ``(condition_halt - kappa) / (condition_halt - condition_slowdown)``; at
   ``condition_halt`` the IK asks for a halt. Moving away from a singularity is never slowed.
4. One common factor so that every ``|qd_i| <= velocity_limits_i`` (the direction is kept).
5. Acceleration: one common factor on the change ``qd - qd_prev`` so that every
   ``|qd_i - qd_prev_i| <= acceleration_limits_i * period``.
6. Joint position limits: if a joint moving towards a limit could not stop (braking at the
   acceleration limits, see :meth:`brake`) before ``limit -/+ joint_limit_margin``, the IK asks
   for a halt instead of sending the command.

A halt is carried out by :meth:`brake`: the previous command scaled down by one common factor per
period (decelerating every joint within its acceleration limit, tool direction kept) until zero.

Steps 1, 2 and 4-6 run as numba kernels (:mod:`._ik_fast`) when numba is there; the numpy code
below is the same computation, kept as the oracle of the tests (``solve(..., fast=False)``).
"""

from __future__ import annotations

from dataclasses import dataclass

from etdmp_ros.geometry.arrays import Array, Points3, Rotations
from etdmp_ros.robot import _ik_fast
from etdmp_ros.robot._ur10 import JOINT_NAMES, Joints, UR10Model
import numpy as np
from numpy.typing import ArrayLike

#: Default joint acceleration limits (rad/s^2), shoulder pan ... wrist 3. UR publishes no
#: acceleration limits (only torques: 330, 330, 150, 56, 56, 56 N m on the UR10); these are
#: below what those torques give the arm with a light tool, and above the 20 rad/s^2 (elbow) that
#: following letter G, 0.2 m tall, in its nominal 2 s needs.
DEFAULT_ACCELERATION_LIMITS = (25.0, 25.0, 35.0, 40.0, 40.0, 40.0)

HALT_SINGULARITY = 'singularity'
HALT_JOINT_LIMIT = 'joint-limit'


@dataclass(slots=True)
class IKResult:
    """
    One IK solution.

    ``qd``: the joint velocity command (rad/s), already within every limit; when ``halt`` is
    set (``'singularity'`` or ``'joint-limit'``) it is the first braking step instead and
    ``reason`` says why. ``condition``: Jacobian condition number; ``damping``: lambda;
    ``scale``: the product of the singularity, velocity and acceleration factors (1 = none);
    ``singularity_scale``: the singularity factor alone.
    """

    qd: Joints
    condition: float
    damping: float
    scale: float
    halt: str | None = None
    reason: str = ''
    singularity_scale: float = 1.0


class DifferentialIK:
    """Damped least-squares velocity IK with singularity, velocity, acceleration, joint limits."""

    def __init__(self, model: UR10Model, period: float, velocity_limits: ArrayLike | None = None,
                 acceleration_limits: ArrayLike = DEFAULT_ACCELERATION_LIMITS,
                 joint_limit_margin: float = 0.05, singular_value_threshold: float = 0.08,
                 max_damping: float = 0.08, condition_slowdown: float = 20.0,
                 condition_halt: float = 50.0, posture: ArrayLike | None = None,
                 posture_gain: float = 0.0) -> None:
        """
        Set up the IK for a :class:`UR10Model` stepping every ``period`` seconds.

        ``velocity_limits`` default to the model's (stricter of URDF and official UR10 values);
        values above the model's are clipped to them.
        """
        self.model = model
        self.period = float(period)
        limits = model.velocity_limits
        if velocity_limits is not None:
            limits = np.minimum(np.asarray(velocity_limits, dtype=float), limits)
        self.velocity_limits = np.array(limits, dtype=float)
        self.acceleration_limits = np.broadcast_to(
            np.asarray(acceleration_limits, dtype=float), (6,)).copy()
        self.lower = model.lower + joint_limit_margin
        self.upper = model.upper - joint_limit_margin
        self.joint_limit_margin = float(joint_limit_margin)
        self.singular_value_threshold = float(singular_value_threshold)
        self.max_damping = float(max_damping)
        self.condition_slowdown = float(condition_slowdown)
        self.condition_halt = float(condition_halt)
        self.posture: Array | None = (None if posture is None
                                      else np.asarray(posture, dtype=float).copy())
        self.posture_gain = float(posture_gain)
        self._max_dv = self.acceleration_limits * self.period
        self._no_posture = np.zeros(6)
        self.validate()
        _ik_fast.warm_up()

    def validate(self) -> None:
        """Raise ValueError if a setting is out of range."""
        checks = [
            ('period', self.period > 0.0),
            ('velocity_limits', np.all(self.velocity_limits > 0.0)),
            ('acceleration_limits', np.all(self.acceleration_limits > 0.0)),
            ('joint_limit_margin', 0.0 <= self.joint_limit_margin < 0.5),
            ('singular_value_threshold', self.singular_value_threshold >= 0.0),
            ('max_damping', self.max_damping >= 0.0),
            ('condition_slowdown', self.condition_slowdown >= 1.0),
            ('condition_halt', self.condition_halt > self.condition_slowdown),
            ('posture_gain', self.posture_gain >= 0.0),
        ]
        for name, ok in checks:
            if not ok:
                raise ValueError(f'{name} is out of range')
        if self.posture is not None and (self.posture.shape != (6,)
                                         or not np.all(np.isfinite(self.posture))):
            raise ValueError('posture must be 6 finite joint positions')

    def kinematics(self, q: ArrayLike) -> tuple[Points3, Rotations, Array]:
        """Return the tool tip (position, rotation, Jacobian) at ``q``: the model's kinematics."""
        return self.model.kinematics(q)

    def jacobian(self, q: ArrayLike) -> Array:
        """Return the tool tip Jacobian (6, 6) at ``q``: the model's :meth:`tool_jacobian`."""
        return self.model.tool_jacobian(q)

    def condition(self, q: ArrayLike) -> float:
        """Return the Jacobian condition number at ``q`` (inf when singular)."""
        s = np.linalg.svd(self.kinematics(q)[2], compute_uv=False)
        return s[0] / s[-1] if s[-1] > 0.0 else np.inf

    def solve(self, q: Joints, jacobian: Array, twist: Array, previous: Joints,
              fast: bool | None = None) -> IKResult:
        """
        Return the :class:`IKResult` for the twist ``(v, w)`` at joint positions ``q``.

        ``previous`` is the last command sent (rad/s), the base of the acceleration limit.
        ``fast``: numba kernels (default when numba is there) or numpy (the oracle in tests).
        """
        fast = _ik_fast.AVAILABLE if fast is None else fast
        qd, kappa, lam2 = self._damped(q, jacobian, twist, fast)
        scale = 1.0
        if kappa > self.condition_slowdown:
            ahead = self.condition(q + qd * self.period)
            if ahead > kappa:
                if kappa >= self.condition_halt:
                    return self._halt(previous, kappa, lam2, HALT_SINGULARITY,
                                      f'Jacobian condition number {kappa:.1f} reached the halt '
                                      f'threshold {self.condition_halt:g} and the path leads '
                                      'further into the singularity')
                scale = (self.condition_halt - kappa) / (self.condition_halt
                                                         - self.condition_slowdown)
                qd = qd * scale
        singularity_scale = scale
        qd, scale, joint = self._limited(q, qd, previous, scale, fast)
        if joint is not None:
            j, stop = joint
            if qd[j] > 0:
                side, limit = 'upper', self.model.upper[j]
            else:
                side, limit = 'lower', self.model.lower[j]
            return self._halt(previous, kappa, lam2, HALT_JOINT_LIMIT,
                              f'{JOINT_NAMES[j]} at {q[j]:+.3f} rad moving {qd[j]:+.2f} rad/s '
                              f'would pass {stop:+.3f} rad, inside the {self.joint_limit_margin:g}'
                              f' rad margin of its {side} limit {limit:+.3f} rad')
        return IKResult(qd, float(kappa), float(np.sqrt(lam2)), float(scale),
                        singularity_scale=float(singularity_scale))

    def _damped(self, q: Joints, jacobian: Array, twist: Array,
                fast: bool) -> tuple[Joints, float, float]:
        """Return steps 1 and 2 (module docstring): ``qd``, the condition number, ``lambda^2``."""
        posture = self.posture if self.posture_gain > 0.0 else None
        if fast:
            z = self.posture_gain * (posture - q) if posture is not None else self._no_posture
            qd = np.empty(6)
            kappa, lam2 = _ik_fast.dls(jacobian, twist, z, self.singular_value_threshold,
                                       self.max_damping, qd)
            return qd, kappa, lam2
        u_svd, s, vt = np.linalg.svd(jacobian)
        s_min = s[-1]
        kappa = s[0] / s_min if s_min > 0.0 else np.inf
        lam2 = 0.0
        if s_min < self.singular_value_threshold:
            lam2 = self.max_damping ** 2 * (1.0 - (s_min / self.singular_value_threshold) ** 2)
        denom = s * s + lam2
        qd = vt.T @ (s / denom * (u_svd.T @ twist))
        if posture is not None and lam2 > 0.0:
            qd += vt.T @ (lam2 / denom * (vt @ (self.posture_gain * (posture - q))))
        return qd, kappa, lam2

    def _limited(self, q: Joints, qd: Joints, previous: Joints, scale: float,
                 fast: bool) -> tuple[Joints, float, tuple[int, float] | None]:
        """
        Return steps 4 to 6 (module docstring): ``qd`` limited, ``scale`` times the factors.

        The third result is (joint, stopping position) of a joint that could not stop before
        its limit, or None.
        """
        if fast:
            out = np.empty(6)
            factor, j, stop = _ik_fast.limit(qd, previous, q, self.velocity_limits, self._max_dv,
                                             self.acceleration_limits, self.lower, self.upper,
                                             self.period, out)
            return out, scale * factor, (None if j < 0 else (j, stop))
        ratio = np.max(np.abs(qd) / self.velocity_limits)
        if ratio > 1.0:
            qd = qd / ratio
            scale /= ratio
        change = qd - previous
        ratio = np.max(np.abs(change) / self._max_dv)
        if ratio > 1.0:
            qd = previous + change / ratio
            scale /= ratio
        return qd, scale, self._joint_limit_violation(q, qd)

    def _joint_limit_violation(self, q: Joints, qd: Joints) -> tuple[int, float] | None:
        """Return (joint, stopping position) of the first joint that could not stop in time."""
        # Braking by common factor takes t_s = max |qd_i| / a_i; joint i then travels
        # |qd_i| t_s / 2, after this period and one more of command delay.
        t_stop = np.max(np.abs(qd) / self.acceleration_limits)
        stop = q + qd * (2.0 * self.period + 0.5 * (t_stop + self.period))
        bad = ((qd > 0.0) & (stop > self.upper)) | ((qd < 0.0) & (stop < self.lower))
        if not np.any(bad):
            return None
        j = int(np.argmax(bad))
        return j, float(stop[j])

    def _halt(self, previous: Joints, kappa: float, lam2: float, kind: str,
              reason: str) -> IKResult:
        return IKResult(self.brake(previous), float(kappa), float(np.sqrt(lam2)), 0.0, kind,
                        reason)

    def brake(self, previous: ArrayLike) -> Joints:
        """Return the next command of a controlled stop from ``previous`` (zeros once stopped)."""
        previous = np.asarray(previous, dtype=float)
        ratio = np.max(np.abs(previous) / self._max_dv)
        if ratio <= 1.0:
            return np.zeros(6)
        return previous * (1.0 - 1.0 / ratio)

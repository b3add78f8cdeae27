"""
The orientation part of a skill: a DMP on the unit quaternion, in the positions' phase.

The mathematics: docs/orientation.md. In short, with ``q_g`` the goal orientation and
``e = 2 log(q q_g^-1)`` (the rotation vector from the goal to ``q``, in the fixed frame), the
orientation obeys the DMP of Koutras & Doulgeri (2019) on ``e``, without their per-axis scaling::

    tau dz/dt = K (0 - e) - D z + f_q(s)        tau de/dt = z        q = exp(e / 2) q_g

with the positions' ``K``, ``D`` and phase ``s``; ``f_q`` is learned from the demonstration's
``e(t)`` (made continuous: no quaternion sign flips, rotation vectors unwrapped). The Euclidean
transform turns the orientation with the motion: the DMP runs in the virtual situation, where the
demonstration's frame is kept, and its output is turned back by the rotation part ``Q`` of
``R^T``, ``q(t) = Q q'(t)``, ``omega(t) = R_Q omega'(t)``. A requested goal orientation
``q_g`` becomes the virtual goal ``Q^-1 q_g``.
"""

from __future__ import annotations

from collections import OrderedDict

from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Array, Quaternions, Rotations, RotationVectors
import numpy as np
from numpy.typing import ArrayLike

from ._errors import GeneralizationError
from ._forcing_term import ForcingTerm, phase
from ._integrate import rollout

#: How a plan's tool orientation is chosen (docs/orientation.md#modes): "demo", the
#: demonstrated orientations turned with the motion (``goal_orientation=None``); "goal", converge
#: to a given goal orientation (``goal_orientation=q``); "tool", the skill's orientations are not
#: used and the tool keeps one orientation (dmp_server's ``tool_orientation``; position-only
#: skills, such as the letters). Default: "demo" for a skill with orientations, else "tool".
ORIENTATION_MODES = ('demo', 'goal', 'tool')
#: Timings (forcing tables, virtual reproductions) cached per skill.
_CACHE_SIZE = 8


def check_goal_orientation(orientation: OrientationDMP | None, goal_orientation: ArrayLike | None,
                           batch: int) -> Quaternions | None:
    """
    Validate ``goal_orientation`` of a request with ``batch`` starts; return (B, 4) or None.

    ``orientation`` is the skill's :class:`OrientationDMP` or None (a position-only skill, which
    refuses a goal orientation). Accepts (4,) for every start or (B, 4); quaternions in ROS order
    (x, y, z, w), normalised here. Raises GeneralizationError.
    """
    if goal_orientation is None:
        return None
    if orientation is None:
        raise GeneralizationError('goal_orientation given, but this skill was learned without '
                                  'orientations (a position-only skill); learn it with '
                                  'learn(positions, orientations) or leave goal_orientation None')
    try:
        q = np.asarray(goal_orientation, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GeneralizationError(f'goal_orientation must be numeric: {exc}') from None
    if q.shape == (4,):
        q = np.repeat(q[None], batch, axis=0)
    elif q.shape != (batch, 4):
        raise GeneralizationError(f'goal_orientation must be a quaternion (x, y, z, w) of shape '
                                  f'(4,) or ({batch}, 4), got {q.shape}')
    if not np.all(np.isfinite(q)):
        raise GeneralizationError('goal_orientation contains NaN or inf')
    unit, norm = quat.unit_and_norm(q)
    if np.any(norm < quat.MIN_NORM):
        raise GeneralizationError('goal_orientation is the zero quaternion, which is no '
                                  'rotation; give a unit quaternion (x, y, z, w) or None')
    return unit


def turn_quaternions(R: Rotations, method: str, mode: int,
                     independent_axis: int) -> Quaternions:
    """
    Return the quaternions Q (B, 4) by which the orientation is turned: the rotation part of R^T.

    ``R`` (B, d, d) is the Euclidean transform (virtual = R real). In 2D it is a rotation in the
    task plane, lifted to the rotation about the plane's normal (z); in 3D mode 1 it is a
    rotation; in 3D mode 2 only its block about the independent axis turns the orientation (the
    sign flip along that axis is a mirror, not a rotation). The plain DMP does not turn.
    """
    B, d = R.shape[0], R.shape[1]
    if method != 'etdmp':
        return np.repeat(quat.IDENTITY[None], B, axis=0)
    if d == 2:
        angle = np.arctan2(R[:, 0, 1], R[:, 0, 0])   # R^T = [[c, s], [-s, c]]: R turns by -angle
        return quat.about_axis(np.array([0.0, 0.0, 1.0]), angle)
    Rt = np.swapaxes(R, 1, 2).copy()
    if mode == 2:
        a = int(independent_axis)
        Rt[:, a, :] = 0.0
        Rt[:, :, a] = 0.0
        Rt[:, a, a] = 1.0
    return quat.from_matrix(Rt)


class OrientationDMP:
    """
    The orientation DMP of one demonstration: ``q`` (T, 4) unit quaternions at times ``t``.

    ``tau``, ``K``, ``D``, ``alpha``, ``n_basis`` and ``regularization`` are the skill's. The
    quaternions are made sign-continuous (``demo``), their rotation vectors from the goal
    unwrapped from the end backwards (``e_demo``).
    """

    def __init__(self, q: ArrayLike, t: Array, tau: float, K: float, D: float,
                 alpha: float, n_basis: int, regularization: float) -> None:
        self.demo = quat.continuous(q)
        self.K, self.D, self.alpha = K, D, alpha
        self.start, self.goal = self.demo[0].copy(), self.demo[-1].copy()
        relative = quat.multiply(self.demo, quat.conjugate(self.goal))
        self.e_demo = quat.unwrap(quat.log_map(relative), backward=True)
        self.e_start = self.e_demo[0].copy()
        #: Largest rotation (rad) of the demonstration away from its goal orientation.
        self.extent = float(np.max(np.linalg.norm(self.e_demo, axis=1)))
        e = self.e_demo
        ed = np.gradient(e, t, axis=0, edge_order=2)
        edd = np.gradient(ed, t, axis=0, edge_order=2)
        s = phase(t, tau, alpha)
        target = tau ** 2 * edd + D * tau * ed + K * e
        self.forcing = ForcingTerm(n_basis, alpha, K, D)
        with np.errstate(all='ignore'):
            # The reproduction ends at its goal orientation, at rest (design.md#coming-to-rest).
            self.forcing.fit(s, target, regularization, end=(self.e_start, 1.0, None))
        self._reproductions: OrderedDict[tuple[float, float, int, int], tuple[
            Array, Array]] = OrderedDict()

    # -- rollout in the virtual situation ---------------------------------------------------

    def _table(self, tau: float, dt: float, n_out: int, substeps: int) -> tuple[
            Array, Array, Array, Array]:
        """Phase and f_q(s) at every sub-step midpoint and output sample, cached per timing."""
        return self.forcing.table(tau, dt, n_out, substeps)

    def _rollout(self, e0: Array, tau: float, dt: float, n_out: int,
                 substeps: int, fast: bool) -> tuple[Array, Array]:
        """Integrate the DMP on ``e`` from ``e0`` (B, 3) at rest; return e, de/dt (B, n, 3)."""
        B = len(e0)
        s_mid, f_mid, s_out, f_out = self._table(tau, dt, n_out, substeps)
        zeros = np.zeros((B, 3))
        e, e_dot, _ = rollout(e0, zeros, zeros, np.ones((B, 3)), s_mid, f_mid, s_out, f_out,
                              np.zeros((B, 0, 3)), (0.0, 0.0, 0.0, np.zeros(B)), self.K, self.D,
                              tau, dt / substeps, substeps, np.broadcast_to(np.eye(3), (B, 3, 3)),
                              fast=fast)
        return e, e_dot

    def _reproduction(self, tau: float, dt: float, n_out: int, substeps: int,
                      fast: bool) -> tuple[Array, Array]:
        """Return the virtual orientation path to the demonstration's goal (cached per timing)."""
        key = (tau, dt, n_out, substeps)
        found = self._reproductions.get(key)
        if found is None:
            e, e_dot = self._rollout(self.e_start[None], tau, dt, n_out, substeps, fast)
            found = (quat.multiply(quat.exp_map(e[0]), self.goal),
                     quat.left_jacobian(e[0], e_dot[0]))
            for array in found:
                array.flags.writeable = False
            self._reproductions[key] = found
            if len(self._reproductions) > _CACHE_SIZE:
                self._reproductions.popitem(last=False)
        return found

    def virtual_start(self, goals: Quaternions) -> RotationVectors:
        """
        Return the start ``e0'`` (B, 3) of the DMP toward virtual goal orientations (B, 4).

        ``e0' = 2 log(q_D0 g'^-1)``, the lift nearest the demonstration's own ``e0``: a goal
        that is the demonstration's (either sign) gives exactly its ``e0``, and a goal close to
        it a start close to it (the DMP never takes the long way round because of a lift).
        """
        relative = quat.multiply(self.start[None], quat.conjugate(goals))
        return quat.nearest_lift(quat.rotation_vector(relative), self.e_start[None])

    # -- generalization -----------------------------------------------------------------------

    def generalize(self, turn: Quaternions, goal_orientation: Quaternions | None,
                   tau: float, dt: float, n_out: int, substeps: int,
                   fast: bool = True) -> tuple[Quaternions, Array]:
        """
        Return orientations q (B, n, 4) and angular velocities omega (B, n, 3), real situation.

        ``turn`` (B, 4) is :func:`turn_quaternions`; ``goal_orientation`` (B, 4) (checked by
        :func:`check_goal_orientation`) or None: keep the demonstration's orientations turned
        with the motion.
        """
        # Products with a fixed quaternion are 4 x 4 matrices: one matmul per output.
        turn_t = np.swapaxes(quat.to_matrix(turn), 1, 2)
        if goal_orientation is None:
            q_virtual, omega_virtual = self._reproduction(tau, dt, n_out, substeps, fast)
            q = q_virtual @ np.swapaxes(quat.left_matrix(turn), 1, 2)
            return q, omega_virtual @ turn_t
        goals = quat.multiply(quat.conjugate(turn), goal_orientation)
        e, e_dot = self._rollout(self.virtual_start(goals), tau, dt, n_out, substeps, fast)
        # q = Q exp(e/2) g', g' = Q^-1 q_g the virtual goal.
        product = quat.left_matrix(turn) @ quat.right_matrix(goals)
        q = quat.exp_map(e) @ np.swapaxes(product, 1, 2)
        return q, quat.left_jacobian(e, e_dot) @ turn_t

"""
Timing feasibility of a planned tool path: can the UR10's joints follow it within their limits.

:func:`timing_violation` solves the arm's pose IK (the controller's model,
:meth:`UR10Model.solve_pose`, warm-started along the path from the current joints) at poses
evenly spaced in time, and compares the joint velocities and accelerations between them (finite
differences) with the limits the controller commands within (``UR10Model.velocity_limits``,
``DEFAULT_ACCELERATION_LIMITS``). A path whose timing needs more is refused with the factor by
which it must be slowed down: joint velocities scale as 1 / duration and accelerations as
1 / duration^2 when a path is stretched in time, as a DMP's is by its tau.

Accelerations are estimated over the spacing of the solved poses, so a peak shorter than that is
underestimated: the check is necessary, not sufficient (the controller's tracking has the last
word). The module needs no ROS.
"""

from __future__ import annotations

from dataclasses import dataclass

from etdmp_ros.robot._ur10 import JOINT_NAMES, Joints, UR10Model
import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Pose error (m and rad) above which a pose counts as out of reach of the IK.
IK_RESIDUAL = 1e-4


@dataclass(frozen=True)
class TimingViolation:
    """Why a path's timing is infeasible: what is exceeded, where, and the slow-down needed."""

    reason: str
    slowdown: float


def plan_joints(model: UR10Model, positions: ArrayLike, rotation: ArrayLike, t: ArrayLike,
                q_seed: ArrayLike, samples: int = 64,
                iterations: int = 1) -> tuple[NDArray[np.intp], Joints, TimingViolation | None]:
    """
    Return ``(idx, joints, violation)``: the arm's joints at poses of a path, by pose IK.

    ``positions`` (n, 3) tool tip positions in base_link, all with ``rotation`` (3, 3) or each
    with its own (``rotation`` (n, 3, 3)); ``t`` (n,) seconds; ``q_seed`` (6,) joints to start
    the IK from (the current ones). IK is solved at up to ``samples`` poses evenly spaced in
    time, ``idx`` their indices (``iterations`` Newton steps each after the first,
    warm-started); ``joints`` (len(idx), 6). ``violation``: a TimingViolation for a path of
    fewer than 3 poses or a pose out of reach (the reason says where; ``joints`` then holds
    the poses solved before it), else None.
    """
    positions = np.asarray(positions, dtype=float)
    t = np.asarray(t, dtype=float)
    n = len(t)
    if n < 3:
        return (np.zeros(0, int), np.zeros((0, 6)),
                TimingViolation(f'the plan has {n} pose(s): too short to be followed', np.inf))
    idx = np.unique(np.linspace(0, n - 1, min(n, max(3, int(samples)))).round().astype(int))
    q = np.asarray(q_seed, dtype=float)
    rotation = np.asarray(rotation, dtype=float)
    rotations = rotation if rotation.ndim == 3 else np.broadcast_to(rotation, (n, 3, 3))
    joints = np.empty((len(idx), 6))
    for k, i in enumerate(idx):
        q, error = model.solve_pose(positions[i], rotations[i], q,
                                    iterations=60 if k == 0 else iterations)
        residual = float(np.linalg.norm(error))
        if residual > IK_RESIDUAL and k > 0:   # a jump: give Newton its full budget
            q, error = model.solve_pose(positions[i], rotations[i], q)
            residual = float(np.linalg.norm(error))
        if residual > IK_RESIDUAL:
            p = positions[i]
            what = '' if rotation.ndim == 2 else ' with its orientation'
            return idx[:k], joints[:k], TimingViolation(
                f'pose at t = {t[i]:.2f} s, ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m{what}, is out '
                f'of reach of the arm (IK misses it by {residual * 1000:.1f} mm)', np.inf)
        joints[k] = q
    return idx, joints, None


def joint_timing_violation(times: ArrayLike, joints: Joints, velocity_limits: ArrayLike,
                           acceleration_limits: ArrayLike) -> TimingViolation | None:
    """
    Return a TimingViolation if joints (k, 6) at ``times`` (k,) exceed the limits, or None.

    Velocities and accelerations are finite differences between the rows.
    """
    times = np.asarray(times, dtype=float)
    velocity_limits = np.asarray(velocity_limits, dtype=float)
    acceleration_limits = np.asarray(acceleration_limits, dtype=float)
    qd = np.diff(joints, axis=0) / np.diff(times)[:, None]
    qdd = np.diff(qd, axis=0) / (0.5 * (times[2:] - times[:-2]))[:, None]
    v_ratio = np.abs(qd) / velocity_limits
    a_ratio = np.abs(qdd) / acceleration_limits
    rv, ra = float(v_ratio.max()), float(a_ratio.max())
    if rv <= 1.0 and ra <= 1.0:
        return None
    if rv >= np.sqrt(ra):
        k, j = np.unravel_index(np.argmax(v_ratio), v_ratio.shape)
        what = (f'{JOINT_NAMES[j]} velocity {abs(qd[k, j]):.2f} rad/s at t = '
                f'{0.5 * (times[k] + times[k + 1]):.2f} s, {rv:.2f} x its limit '
                f'{velocity_limits[j]:.2f} rad/s')
    else:
        k, j = np.unravel_index(np.argmax(a_ratio), a_ratio.shape)
        what = (f'{JOINT_NAMES[j]} acceleration {abs(qdd[k, j]):.1f} rad/s^2 at t = '
                f'{times[k + 1]:.2f} s, {ra:.2f} x its limit {acceleration_limits[j]:.1f} '
                'rad/s^2')
    return TimingViolation(f'the arm cannot follow the plan in time: it needs {what}',
                           max(rv, float(np.sqrt(ra))))


def timing_violation(model: UR10Model, positions: ArrayLike, rotation: ArrayLike, t: ArrayLike,
                     q_seed: ArrayLike, velocity_limits: ArrayLike, acceleration_limits: ArrayLike,
                     samples: int = 64, iterations: int = 1) -> TimingViolation | None:
    """
    Return a TimingViolation if the joints cannot follow ``positions`` at times ``t``, or None.

    ``positions`` (n, 3) tool tip positions in base_link, all with ``rotation`` (3, 3) or each
    with its own (``rotation`` (n, 3, 3)); ``t``
    (n,) seconds; ``q_seed`` (6,) joints to start the IK from (the current ones); the limits
    (6,) in rad/s and rad/s^2. IK is solved at up to ``samples`` poses (``iterations`` Newton
    steps each after the first, warm-started: :func:`plan_joints`). A path of fewer than 3
    poses has no timing to follow and is refused. Unreachable poses are refused too (the reason
    says where).
    """
    idx, joints, violation = plan_joints(model, positions, rotation, t, q_seed, samples,
                                         iterations)
    if violation is not None:
        return violation
    return joint_timing_violation(np.asarray(t, dtype=float)[idx], joints, velocity_limits,
                                  acceleration_limits)

"""
Trajectory following for the UR10 tool tip: closed-loop differential IK with a state machine.

:class:`TrajectoryController` is stepped once per control period with the measured joint
positions ``q`` and their measurement time ``t`` and returns a :class:`Command`. The joint
velocity command is

    xi = ( (p_d(t_b) - p_d(t_a)) / T + K_p (p_d(t_a) - p_hat),
           log(R_d(t_b) R_d(t_a)^T) / T + K_o log(R_d(t_a) R_hat^T) )
    qd = DifferentialIK.solve(q_hat, J(q_hat + qd_prev T / 2), xi, qd_prev)

with ``T`` the control period, ``d`` the actuation delay, ``t_a = t + age + d`` the time the
command starts to act and ``t_b = t_a + T`` the time the next one replaces it. The feed-forward
is the reference's secant over exactly the period the command acts, and the Jacobian is taken
halfway through that period (midpoint rule), so a kinematic plant follows the reference to
second order. ``q_hat`` is where the commands already sent take the joints by ``t_a`` (a Smith
predictor: the delay of a velocity-commanded robot is compensated, not fought by the feedback).
``(p_hat, R_hat)`` is the tool pose at ``q_hat``.

The delay ``d`` is estimated online by :class:`DelayEstimator` (0 to 2 periods, fractional: it
also absorbs the lag of the joints' velocity servos) from how the joints actually moved after
each command; ``actuation_delay`` is its starting value (one period by default, what a
ros2_control velocity interface does).

States (``Command.status``): ``idle``, ``approaching`` (a minimum-jerk move from the tool to the
path's first pose at a safe speed), ``tracking``, ``holding`` (the last pose, for ``hold_time``),
``paused``, ``halted-singularity``, ``halted-joint-limit``, ``unreachable`` (a path that fails
:meth:`TrajectoryController.check`, or a tracking error above ``max_tracking_error``) and
``stale-input``. Halts and the end of a path brake at the acceleration limits to zero; pause and
lost input send zero at once. Pausing freezes the path clock; resuming approaches the pose where
the path was paused and goes on, the path clock ramping back to full speed (minimum-jerk rate).

Missed control steps. The controller steps when a measurement arrives; one that comes more than
:data:`MISSED_STEPS` periods after the previous step (the controller's process was not
scheduled, or joint states were held back) means the arm went on without it: on its last
command (a velocity interface applies it until a watchdog stops it), not along the path. The
path clock, though, kept running on the measurements' time, so the reference is as far ahead
as the gap is long: 0.25 s at the 0.27 m/s of the letter W written in its own 2 s is 50 mm,
beyond ``max_tracking_error``, for an arm that only coasted. Such a gap therefore re-synchronises
the path clock to the arm (:meth:`TrajectoryController.missed_steps`): the path goes on from the
path time, between the last step's and now, whose pose is nearest to the tool, so the arm is
not asked to catch up with time it did not have. A tracking error that still stops the arm
after a gap says so in its reason.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
import math

from etdmp_ros.geometry.arrays import Array, Points3, Rotations
from etdmp_ros.robot import _ik_fast
from etdmp_ros.robot._delay import DelayEstimator
from etdmp_ros.robot._ik import (DEFAULT_ACCELERATION_LIMITS, DifferentialIK, HALT_SINGULARITY,
                                 IKResult)
from etdmp_ros.robot._trajectory import MinimumJerkMove, PoseTrajectory
from etdmp_ros.robot._ur10 import JOINT_NAMES, Joints, UR10Model
import numpy as np
from numpy.typing import ArrayLike
import pinocchio as pin

IDLE = 'idle'
APPROACHING = 'approaching'
TRACKING = 'tracking'
HOLDING = 'holding'
PAUSED = 'paused'
HALTED_SINGULARITY = 'halted-singularity'
HALTED_JOINT_LIMIT = 'halted-joint-limit'
UNREACHABLE = 'unreachable'
STALE_INPUT = 'stale-input'
STATUSES = (IDLE, APPROACHING, TRACKING, HOLDING, PAUSED, HALTED_SINGULARITY,
            HALTED_JOINT_LIMIT, UNREACHABLE, STALE_INPUT)
#: States in which the controller commands motion along a reference.
MOVING = (APPROACHING, TRACKING, HOLDING)

#: A measurement this many control periods or more after the previous step means missed steps:
#: the path clock is re-synchronised to the arm (module docstring).
MISSED_STEPS = 2.5
#: Path time step (s) of the search for the pose nearest to the tool after missed steps.
RESYNC_STEP = 0.001
#: A tracking-error stop this long (s) after missed steps names them in its reason.
GAP_MEMORY = 1.0

#: Tool speeds below these count as "at rest" when a path starts (m/s, rad/s).
REST_SPEED = 1e-3
REST_ANGULAR_SPEED = 1e-2


@dataclass
class ControllerConfig:
    """
    Settings of :class:`TrajectoryController` (units: s, m, rad).

    Gains are in 1/s: an error decays as ``exp(-gain t)``. ``actuation_delay`` ``None`` means one
    control period (a ros2_control velocity interface applies a command at its next update);
    with ``estimate_delay`` it is only the starting value of :class:`DelayEstimator`.
    ``velocity_scale`` multiplies the UR10 velocity limits (<= 1).
    """

    rate: float = 125.0
    position_gain: float = 50.0
    orientation_gain: float = 50.0
    actuation_delay: float | None = None
    velocity_scale: float = 1.0
    acceleration_limits: tuple[float, ...] = DEFAULT_ACCELERATION_LIMITS
    joint_limit_margin: float = 0.05
    singular_value_threshold: float = 0.08
    max_damping: float = 0.08
    condition_slowdown: float = 20.0
    condition_halt: float = 50.0
    posture: tuple[float, ...] | None = None
    posture_gain: float = 0.0
    approach_speed: float = 0.1
    approach_angular_speed: float = 0.5
    approach_acceleration: float = 0.5
    approach_tolerance: float = 0.002
    approach_angle_tolerance: float = 0.02
    resume_ramp_time: float = 0.5
    hold_time: float = 0.5
    max_tracking_error: float = 0.05
    estimate_delay: bool = True

    def validate(self) -> None:
        """Raise ValueError naming the first setting out of range."""
        positive = ('rate', 'position_gain', 'orientation_gain', 'approach_speed',
                    'approach_angular_speed', 'approach_acceleration', 'max_tracking_error')
        non_negative = ('approach_tolerance', 'approach_angle_tolerance', 'resume_ramp_time',
                        'hold_time', 'posture_gain')
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in positive and not (np.isfinite(value) and value > 0.0):
                raise ValueError(f'{f.name} must be a positive number, got {value!r}')
            if f.name in non_negative and not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f'{f.name} must be >= 0, got {value!r}')
        if not 0.0 < self.velocity_scale <= 1.0:
            raise ValueError(f'velocity_scale must be in (0, 1], got {self.velocity_scale!r}')
        if self.actuation_delay is not None and not 0.0 <= self.actuation_delay < 1.0:
            raise ValueError(f'actuation_delay must be in [0, 1) s, got {self.actuation_delay!r}')
        if self.position_gain * self.period > 1.0 or self.orientation_gain * self.period > 1.0:
            raise ValueError('position_gain and orientation_gain must not exceed the control rate '
                             f'{self.rate:g} Hz (gain * period > 1 is unstable)')

    @property
    def period(self) -> float:
        """Return the control period in seconds."""
        return 1.0 / self.rate


@dataclass(slots=True)
class Command:
    """
    What one control step returns.

    ``qd``: joint velocities to send (rad/s, UR joint order). ``status``/``reason``: the state
    and, for halts and rejections, why. ``tool_position``/``tool_rotation``: forward kinematics
    of the measured joints. ``reference_position``/``reference_rotation``: where the tool should
    be now (``None`` when not following a reference); ``tracking_error``: the distance from the
    reference position to the tool tip (m, NaN without reference).
    """

    qd: Joints
    status: str
    reason: str
    tool_position: Points3
    tool_rotation: Rotations
    reference_position: Points3 | None = None
    reference_rotation: Rotations | None = None
    tracking_error: float = float('nan')
    condition: float = float('nan')
    extra: dict[str, float] | None = None


def _ramp_integral(u: float, ramp: float) -> float:
    """Return path time elapsed after ``u`` s of a clock whose rate ramps 0 -> 1 in ``ramp`` s."""
    if ramp <= 0.0 or u >= ramp:
        return u - 0.5 * ramp if ramp > 0.0 else u
    x = u / ramp
    # Integral of the minimum-jerk rate 10x^3 - 15x^4 + 6x^5.
    return ramp * x ** 4 * (2.5 - 3.0 * x + x * x)


class TrajectoryController:
    """
    Follow tool pose trajectories with the UR10 (ROS-free; one instance per robot).

    Not thread-safe: a node calls :meth:`step`, :meth:`follow`, :meth:`set_paused` and the other
    state changes under one lock. :meth:`check` uses its own model and may run concurrently.
    """

    def __init__(self, model: UR10Model, config: ControllerConfig | None = None,
                 fast: bool | None = None) -> None:
        """
        Build the controller for a :class:`UR10Model` (its tool offset defines the tool tip).

        ``fast``: numba kernels for the step (default when numba is there), or numpy only.
        """
        self.fast = _ik_fast.AVAILABLE if fast is None else bool(fast)
        self.config = ControllerConfig() if config is None else config
        self.config.validate()
        c = self.config
        self.period = c.period
        self.delay = self.period if c.actuation_delay is None else float(c.actuation_delay)
        self.delay_estimator = DelayEstimator(self.delay / self.period, self.period,
                                              fast=self.fast)
        self.ik = self._make_ik(model)
        self._check_ik = self._make_ik(UR10Model(tool_offset=model.tool_offset))
        self._previous: Joints = np.zeros(6)
        self._status, self._reason = IDLE, ''
        self._path: PoseTrajectory | None = None       # the path being executed
        self._approach: MinimumJerkMove | None = None  # the move to the path (None: none needed)
        self._path_start = 0.0       # path time at which the schedule enters the path
        self._ramp = 0.0             # duration of the path clock's ramp-in (resume)
        self._t_start = 0.0          # measurement time of the schedule's start
        # (path, path time, start stamp) to start at the next step
        self._pending: tuple[PoseTrajectory, float, float | None] | None = None
        self._path_stamp: float | None = None      # stamp (s) of the path's first pose, if any
        #: Paths spliced in so far (continuations of the tracked one, taken without an approach).
        self.splices = 0
        self._paused = False
        self._last_theta = 0.0
        self._t_last: float | None = None
        self._slowed: float | None = None    # condition number while slowing for a singularity
        #: Times the path clock was re-synchronised after missed steps, and the last such gap
        #: as (measurement time, gap s, path time before, path time after).
        self.resyncs = 0
        self.last_gap: tuple[float, float, float, float] | None = None

    def _make_ik(self, model: UR10Model) -> DifferentialIK:
        c = self.config
        return DifferentialIK(
            model, self.period, velocity_limits=model.velocity_limits * c.velocity_scale,
            acceleration_limits=c.acceleration_limits, joint_limit_margin=c.joint_limit_margin,
            singular_value_threshold=c.singular_value_threshold, max_damping=c.max_damping,
            condition_slowdown=c.condition_slowdown, condition_halt=c.condition_halt,
            posture=c.posture, posture_gain=c.posture_gain)

    # -- state changes ---------------------------------------------------------------------------

    @property
    def status(self) -> str:
        """Return the current state (one of STATUSES)."""
        return self._status

    @property
    def reason(self) -> str:
        """Return why the controller halted or rejected a path ('' otherwise)."""
        return self._reason

    @property
    def previous_command(self) -> Joints:
        """Return a copy of the last joint velocity command (rad/s)."""
        return self._previous.copy()

    def follow(self, path: PoseTrajectory, stamp: float | None = None) -> None:
        """
        Execute ``path`` (a PoseTrajectory) from the next step on, replacing any other.

        ``stamp`` (s): the time its first pose is stamped with, on the clock of the path it
        replaces. A path that continues the one being tracked (a re-plan of its remainder,
        stamped on the same clock) is spliced in without an approach: at the next step the
        controller moves on the new path from the same time, when the new path is within
        ``approach_tolerance`` of the current reference there (:meth:`_splice`).
        """
        self._pending = (path, 0.0, stamp)

    def cancel(self, reason: str = '') -> None:
        """Stop following (brake to zero at the acceleration limits) and become idle."""
        self._pending = None
        self._path = None
        if self._status != PAUSED:
            self._set(IDLE, reason)

    def reject(self, reason: str) -> None:
        """Refuse the path just received (``reason`` says why): brake to zero, ``unreachable``."""
        self._pending = None
        self._path = None
        self._set(UNREACHABLE, reason)

    def set_paused(self, paused: bool) -> None:
        """Pause (zero command at once, path clock frozen) or resume (approach back, go on)."""
        if paused and not self._paused:
            self._paused = True
            if self._pending is None and self._path is not None:
                tau = 0.0
                if self._approach is None or self._last_theta >= self._approach.duration:
                    tau = min(self._path_time(self._last_theta), self._path.duration)
                self._pending = (self._path, tau, self._path_stamp)
            self._path = None
            self._previous = np.zeros(6)
            self._set(PAUSED)
        elif not paused and self._paused:
            self._paused = False
            # The next step starts the schedule and reports its real phase.
            self._set(APPROACHING if self._pending is not None else IDLE)

    @property
    def paused(self) -> bool:
        """Return True while paused."""
        return self._paused

    def input_lost(self, reason: str) -> None:
        """Joint states went stale: zero command at once, drop the path, ``stale-input``."""
        self.delay_estimator.reset()
        self._pending = None
        self._path = None
        self._previous = np.zeros(6)
        self._set(STALE_INPUT, reason)

    def shutdown(self) -> Joints:
        """Return the zero command to send before exiting (and forget everything)."""
        self._pending = None
        self._path = None
        self._previous = np.zeros(6)
        self._set(IDLE, 'shutdown')
        return np.zeros(6)

    def _set(self, status: str, reason: str = '') -> None:
        self._status, self._reason = status, reason

    # -- the schedule: approach, then the path (with a ramp-in on resume), then hold --------------

    def _path_time(self, theta: float) -> float:
        t_app = self._approach.duration if self._approach is not None else 0.0
        return self._path_start + _ramp_integral(max(theta - t_app, 0.0), self._ramp)

    def _reference(self, theta: float) -> tuple[Points3, Rotations, str, float]:
        """Return (p, R, phase, path time) of the schedule at ``theta`` s after its start."""
        if self._approach is not None and theta < self._approach.duration:
            p, rot = self._approach.pose(theta)
            return p, rot, APPROACHING, self._path_start
        tau = self._path_time(theta)
        assert self._path is not None        # called while a path is tracked
        p, rot = self._path.pose(tau, self.fast)
        return p, rot, TRACKING if tau < self._path.duration else HOLDING, tau

    def continues(self, path: PoseTrajectory, stamp: float | None) -> bool:
        """
        Return whether ``path`` stamped ``stamp`` would be spliced in now (see :meth:`follow`).

        A node may hand such a path over at once and check it afterwards: it differs from the
        tracked one only ahead of the current path time (a re-plan's switch lies ahead).
        """
        return self._t_last is not None and self._splice_time(self._t_last, path,
                                                              stamp) is not None

    def _splice_time(self, t: float, path: PoseTrajectory, stamp: float | None) -> float | None:
        """
        Return the path time of ``path`` at which it continues the current path at ``t``, or None.

        It does when both have stamps, the schedule is on the path (not approaching, not in a
        ramp-in, not holding its end), the new path covers the current time on the common
        clock, and its pose then is within ``approach_tolerance`` (and
        ``approach_angle_tolerance``) of the current reference.
        """
        c = self.config
        if stamp is None or self._path_stamp is None or self._path is None or self._paused:
            return None
        theta = t - self._t_start
        t_app = self._approach.duration if self._approach is not None else 0.0
        if theta < t_app + self._ramp:
            return None
        tau_old = self._path_time(theta)
        if tau_old >= self._path.duration:
            return None             # holding the end: a new path starts as any other
        tau_new = tau_old - (stamp - self._path_stamp)
        if not 0.0 <= tau_new < path.duration:
            return None
        p_old, rot_old = self._path.pose(tau_old)
        p_new, rot_new = path.pose(tau_new)
        if (np.linalg.norm(p_new - p_old) > c.approach_tolerance
                or np.linalg.norm(pin.log3(rot_new @ rot_old.T)) > c.approach_angle_tolerance):
            return None
        return tau_new

    def _splice(self, t: float, path: PoseTrajectory, stamp: float | None) -> bool:
        """Continue on ``path`` from the current path time if it continues the current path."""
        tau_new = self._splice_time(t, path, stamp)
        if tau_new is None:
            return False
        self._path, self._path_start, self._t_start = path, tau_new, t
        self._path_stamp = stamp
        self._approach, self._ramp = None, 0.0
        self._last_theta = 0.0
        self.splices += 1
        return True

    def _start(self, t: float, p: Points3, rot: Rotations, jac: Array) -> None:
        assert self._pending is not None     # called when a path is pending
        path, tau0, stamp = self._pending
        self._pending = None
        if self._splice(t, path, stamp):
            return
        self._path_stamp = stamp
        c = self.config
        p1, rot1 = path.pose(tau0)
        twist = jac @ self._previous
        v0, w0 = twist[:3], twist[3:]
        moving = np.linalg.norm(v0) > REST_SPEED or np.linalg.norm(w0) > REST_ANGULAR_SPEED
        far = (np.linalg.norm(p1 - p) > c.approach_tolerance
               or np.linalg.norm(pin.log3(rot1 @ rot.T)) > c.approach_angle_tolerance)
        self._approach = None
        if far or moving:
            self._approach = MinimumJerkMove.plan(
                p, rot, p1, rot1, c.approach_speed, c.approach_angular_speed,
                c.approach_acceleration, v0=v0, w0=w0)
        # A path entered while it moves (a resume mid-path) starts with its clock ramping in.
        starts_moving = tau0 < path.duration and np.linalg.norm(path.velocity(tau0)) > REST_SPEED
        self._ramp = c.resume_ramp_time if starts_moving else 0.0
        self._path, self._path_start, self._t_start = path, tau0, t
        self._last_theta = 0.0
        self._slowed = None

    # -- one control period ----------------------------------------------------------------------

    def step(self, q: ArrayLike, t: float, age: float = 0.0) -> Command:
        """
        Return the :class:`Command` for joints ``q`` (rad) measured at time ``t`` (s).

        ``age``: how long ago (s) the measurement was taken when this step runs (0 in a loop
        that measures and commands at once); it adds to the look-ahead.
        """
        q = np.asarray(q, dtype=float)
        if self.config.estimate_delay:
            self.delay = self.delay_estimator.update(q, t) * self.period
        command = self._step(q, t, age)
        self.delay_estimator.record(self._previous)
        return command

    def _step(self, q: Joints, t: float, age: float) -> Command:
        """Compute the command (see :meth:`step`)."""
        if self._t_last is not None and t < self._t_last - 1e-9:
            self.input_lost(f'joint state time went back from {self._t_last:.3f} to {t:.3f} s')
        gap = t - self._t_last if self._t_last is not None else 0.0
        self._t_last = t
        if self._status == STALE_INPUT:
            self._set(IDLE)
        p, rot, jac = self.ik.kinematics(q)
        if self._paused:
            self._previous = np.zeros(6)
            self._set(PAUSED)
            return Command(np.zeros(6), PAUSED, '', p, rot)
        if self._pending is not None:
            self._start(t, p, rot, jac)
        if self._path is None:
            self._previous = self.ik.brake(self._previous)
            return Command(self._previous.copy(), self._status, self._reason, p, rot)

        c = self.config
        if gap >= MISSED_STEPS * self.period and t > self._t_start:
            self.missed_steps(t, gap, p)
        theta = t - self._t_start
        self._last_theta = theta
        p_ref, rot_ref, phase, tau = self._reference(theta)
        d = p_ref - p
        error = math.sqrt(d @ d)
        if phase == HOLDING and tau >= self._path.duration + c.hold_time:
            return self._stop(IDLE, '', p, rot, p_ref, rot_ref, error)
        if error > c.max_tracking_error:
            return self._lost(t, tau, p, rot, p_ref, rot_ref, error)
        result = self._solve(q, theta, age)
        self._previous = result.qd
        self._slowed = result.condition if result.singularity_scale < 1.0 else None
        if result.halt is not None:
            self._path = None
            self._set(HALTED_SINGULARITY if result.halt == HALT_SINGULARITY
                      else HALTED_JOINT_LIMIT, result.reason)
        else:
            self._set(phase)
        return Command(result.qd.copy(), self._status, self._reason, p, rot, p_ref, rot_ref,
                       error, result.condition,
                       {'scale': result.scale, 'damping': result.damping})

    def _lost(self, t: float, tau: float, p: Points3, rot: Rotations, p_ref: Points3,
              rot_ref: Rotations, error: float) -> Command:
        """Stop for a tracking ``error`` (m) above max_tracking_error at path time ``tau``."""
        c = self.config
        too_far = (f'tracking error {error * 1000:.0f} mm exceeds max_tracking_error '
                   f'{c.max_tracking_error * 1000:.0f} mm (at path time {tau:.2f} s)')
        if self.last_gap is not None and t - self.last_gap[0] <= GAP_MEMORY:
            too_far += (f', {t - self.last_gap[0]:.2f} s after {self.last_gap[1] * 1e3:.0f} '
                        'ms without a control step (the arm moved on its last command '
                        'meanwhile)')
        if self._slowed is not None:    # the lag is the singularity slow-down's doing
            return self._stop(HALTED_SINGULARITY, f'slowed down near a singularity (Jacobian'
                              f' condition number {self._slowed:.1f} > '
                              f'{c.condition_slowdown:g}): {too_far}', p, rot, p_ref, rot_ref,
                              error)
        return self._stop(UNREACHABLE, too_far, p, rot, p_ref, rot_ref, error)

    def _solve(self, q: Joints, theta: float, age: float) -> IKResult:
        """Return the IK's command for joints ``q``, ``theta`` s into the schedule (see above)."""
        c = self.config
        age = min(max(age, 0.0), 0.5)
        lookahead = age + self.delay
        # Smith predictor: where the commands already sent take the joints before this one acts.
        q_hat = q + self.delay_estimator.in_flight(self.delay / self.period)
        if age > 0.0:
            q_hat += self._previous * age
        p_hat, rot_hat, _ = self.ik.kinematics(q_hat)
        # The Jacobian halfway through the period the command acts (midpoint rule): the
        # secant of the reference is matched to second order, not just first.
        jac = self.ik.jacobian(q_hat + (0.5 * self.period) * self._previous)
        p_a, rot_a, _, _ = self._reference(theta + lookahead)
        p_b, rot_b, _, _ = self._reference(theta + lookahead + self.period)
        xi = np.empty(6)
        if self.fast:
            _ik_fast.twist(p_a, rot_a, p_b, rot_b, p_hat, rot_hat, self.period, c.position_gain,
                           c.orientation_gain, xi)
        else:
            xi[:3] = (p_b - p_a) / self.period + c.position_gain * (p_a - p_hat)
            xi[3:] = (pin.log3(rot_b @ rot_a.T) / self.period
                      + c.orientation_gain * pin.log3(rot_a @ rot_hat.T))
        return self.ik.solve(q_hat, jac, xi, self._previous, self.fast)

    def missed_steps(self, t: float, gap: float, p: Points3) -> None:
        """
        Re-synchronise the path clock after ``gap`` s without a step (see the module docstring).

        ``t``: the measurement time now, ``p``: the tool position measured. While the schedule
        is on the path (not approaching, ramping in or holding its end), the path goes on from
        the path time, between the previous step's and now, whose pose is nearest to ``p``
        (searched every :data:`RESYNC_STEP` s). Elsewhere nothing changes (an approach is slow;
        holding is at rest). Noted in :attr:`last_gap` and :attr:`resyncs` either way.
        """
        assert self._path is not None        # called while a path is tracked
        theta_then, theta_now = self._last_theta, t - self._t_start
        t_app = self._approach.duration if self._approach is not None else 0.0
        tau_then, tau_now = self._path_time(theta_then), self._path_time(theta_now)
        tau = tau_now
        if theta_then >= t_app + self._ramp and tau_then < self._path.duration:
            end = min(tau_now, self._path.duration)
            taus = np.linspace(tau_then, end, max(2, int(math.ceil((end - tau_then)
                                                                   / RESYNC_STEP)) + 1))
            gaps = [np.sum((self._path.pose(x, self.fast)[0] - p) ** 2) for x in taus]
            tau = float(taus[int(np.argmin(gaps))])
            self._path_start, self._t_start = tau, t
            self._approach, self._ramp = None, 0.0
            self._last_theta = 0.0
            self.resyncs += 1
        self.last_gap = (t, gap, tau_now, tau)

    def _stop(self, status: str, reason: str, p: Points3, rot: Rotations, p_ref: Points3,
              rot_ref: Rotations, error: float) -> Command:
        self._path = None
        self._set(status, reason)
        self._previous = self.ik.brake(self._previous)
        return Command(self._previous.copy(), status, reason, p, rot, p_ref, rot_ref, error)

    # -- feasibility of a path before it is executed ----------------------------------------------

    def check(self, path: PoseTrajectory, q: ArrayLike, max_samples: int = 200) -> str:
        """
        Return why ``path`` cannot be executed from joints ``q``, or '' if it can.

        Solves position IK (damped Newton, warm-started along the way) for the straight approach
        from the tool to the first pose and for up to ``max_samples`` poses of the path; fails on
        a pose out of reach, beyond a joint limit (with margin) or at a singularity (condition
        number at the halt threshold). Uses its own model: safe beside :meth:`step`.
        """
        ik = self._check_ik
        q = np.array(q, dtype=float)
        p0, rot0, _ = ik.kinematics(q)
        p1, rot1 = path.pose(0.0)
        n_app = int(np.ceil(np.linalg.norm(p1 - p0) / 0.02))
        angle = pin.log3(rot1 @ rot0.T)
        targets = [(f'approach point {k}/{n_app}', p0 + (p1 - p0) * k / n_app,
                    pin.exp3(angle * k / n_app) @ rot0) for k in range(1, n_app)]
        idx = np.arange(len(path.t))
        if len(idx) > max_samples:
            idx = np.unique(np.linspace(0, len(idx) - 1, max_samples).round().astype(int))
        targets += [(f'pose #{i} (t = {path.t[i]:.2f} s)', path.positions[i], path.rotations[i])
                    for i in idx]
        for name, p, rot in targets:
            q, error = ik.model.solve_pose(p, rot, q)
            residual = float(np.linalg.norm(error))
            where = f'{name} at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m'
            if residual > 1e-4:
                return (f'{where} is out of reach: the closest the UR10 gets is '
                        f'{residual * 1000:.1f} mm away')
            bad = np.flatnonzero((q < ik.lower) | (q > ik.upper))
            if len(bad):
                j = int(bad[0])
                return (f'{where} needs {JOINT_NAMES[j]} at {q[j]:+.3f} rad, within '
                        f'{ik.joint_limit_margin:g} rad of its limits [{ik.model.lower[j]:+.3f}, '
                        f'{ik.model.upper[j]:+.3f}]')
            kappa = ik.condition(q)
            if kappa >= ik.condition_halt:
                return (f'{where} is at a singular configuration (Jacobian condition number '
                        f'{kappa:.0f} >= {ik.condition_halt:g})')
        return ''

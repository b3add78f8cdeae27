"""
The ROS-free controller: trajectories, differential IK and its limits, the state machine.

Closed-loop tests run against a kinematic plant (``q += qd_cmd T``, commands one period late)
and assert tracking errors, limits and states against ground truth.
"""

from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.robot import _ik_fast
from etdmp_ros.robot import (ControllerConfig, DelayEstimator, DifferentialIK, JOINT_NAMES,
                             MinimumJerkMove, PoseTrajectory, quaternions_to_rotations,
                             TrajectoryController, TrajectoryError, UR10Model)
import numpy as np
import pinocchio as pin
import pytest
from support.controller_plans import (g_plan, Q_INITIAL, run_kinematic, stir_plan, tool_down,
                                      TOOL_OFFSET)


@pytest.fixture(scope='module')
def ur10():
    return UR10Model(tool_offset=TOOL_OFFSET)


@pytest.fixture(scope='module')
def letter_g():
    return g_plan()[0]


def assert_within_limits(controller, log, skip_steps=()):
    """Every command within the velocity limits, every change within the acceleration ones."""
    qd = np.array(log.qd)
    ik = controller.ik
    assert np.all(np.abs(qd) <= ik.velocity_limits * (1 + 1e-9))
    change = np.abs(np.diff(np.vstack([np.zeros(6), qd]), axis=0)) / controller.period
    keep = np.ones(len(change), dtype=bool)
    keep[list(skip_steps)] = False
    assert np.all(change[keep] <= ik.acceleration_limits * (1 + 1e-9)), \
        f'acceleration {change[keep].max(axis=0)} > {ik.acceleration_limits}'
    q = np.array(log.q)
    assert np.all(q >= ik.model.lower) and np.all(q <= ik.model.upper)


# -- trajectories ---------------------------------------------------------------------------------

def test_pose_trajectory_interpolates_a_smooth_path():
    t = np.linspace(0.0, 2.0, 201)
    p = np.c_[0.1 * np.cos(t), 0.1 * np.sin(t), 0.05 * t]
    rot = np.array([pin.exp3(np.array([0.0, 0.0, 0.3 * s])) for s in t])
    path = PoseTrajectory(t + 100.0, p, rot)          # stamps' origin does not matter
    assert path.duration == pytest.approx(2.0)
    for k in (0, 57, 200):
        pk, rk = path.pose(t[k])
        np.testing.assert_allclose(pk, p[k], atol=1e-12)
        np.testing.assert_allclose(rk, rot[k], atol=1e-12)
    s = 1.2345
    pk, rk = path.pose(s)
    np.testing.assert_allclose(pk, [0.1 * np.cos(s), 0.1 * np.sin(s), 0.05 * s], atol=1e-7)
    np.testing.assert_allclose(rk, pin.exp3(np.array([0.0, 0.0, 0.3 * s])), atol=1e-12)
    np.testing.assert_allclose(path.velocity(s), [-0.1 * np.sin(s), 0.1 * np.cos(s), 0.05],
                               atol=1e-5)
    # Clamped outside the span.
    np.testing.assert_allclose(path.pose(-1.0)[0], p[0])
    np.testing.assert_allclose(path.pose(5.0)[0], p[-1])
    np.testing.assert_allclose(path.velocity(5.0), 0.0)


def test_pose_trajectory_keeps_rest_at_the_ends(letter_g):
    # A DMP starts and ends at rest; second-order end tangents keep that.
    assert np.linalg.norm(letter_g.velocity(0.0)) < 0.01 * np.linalg.norm(letter_g.velocity(0.5))
    assert np.linalg.norm(letter_g.velocity(letter_g.duration - 1e-9)) < 0.01


@pytest.mark.parametrize('t, match', [([0.0, 0.0, 1.0], 'increase'), ([0.0, np.nan, 1.0], 'NaN'),
                                      ([], 'empty')])
def test_pose_trajectory_rejects_bad_stamps(t, match):
    n = len(t)
    with pytest.raises(TrajectoryError, match=match):
        PoseTrajectory(t, np.zeros((n, 3)), np.repeat(np.eye(3)[None], n, axis=0))


def test_pose_trajectory_rejects_bad_poses():
    with pytest.raises(TrajectoryError, match='NaN'):
        PoseTrajectory([0, 1], [[0, 0, 0], [0, np.inf, 0]], [np.eye(3)] * 2)
    with pytest.raises(TrajectoryError, match='rotation'):
        PoseTrajectory([0, 1], np.zeros((2, 3)), [np.eye(3), 2 * np.eye(3)])
    with pytest.raises(TrajectoryError, match='not a rotation quaternion'):
        PoseTrajectory.from_quaternions([0, 1], np.zeros((2, 3)), [[0, 0, 0, 1], [0, 0, 0, 0]])


def test_quaternions_match_the_geometry_module():
    rng = np.random.default_rng(3)
    rot = np.array([pin.exp3(rng.normal(size=3)) for _ in range(20)])
    quats = np.array([quat.from_matrix(r) for r in rot])
    np.testing.assert_allclose(quaternions_to_rotations(quats), rot, atol=1e-12)


def test_untimed_path_gets_a_minimum_jerk_profile():
    p = np.c_[np.linspace(0.0, 0.3, 31), np.zeros(31), np.zeros(31)]
    path = PoseTrajectory.timed_by_speed(p, np.repeat(np.eye(3)[None], 31, axis=0), speed=0.05,
                                         angular_speed=0.5)
    assert path.duration == pytest.approx(1.875 * 0.3 / 0.05)
    speeds = [np.linalg.norm(path.velocity(s)) for s in np.linspace(0, path.duration, 301)]
    assert max(speeds) == pytest.approx(0.05, rel=0.02)
    assert speeds[0] < 1e-3 and speeds[-1] < 1e-3


def test_minimum_jerk_move_boundary_conditions():
    p0, p1 = np.array([0.5, 0.0, 0.3]), np.array([0.6, 0.1, 0.2])
    r0, r1 = np.eye(3), pin.exp3(np.array([0.0, 0.0, 0.4]))
    v0 = np.array([0.2, 0.0, 0.0])
    move = MinimumJerkMove.plan(p0, r0, p1, r1, speed=0.1, angular_speed=0.5, acceleration=0.5,
                                v0=v0)
    np.testing.assert_allclose(move.pose(0.0)[0], p0)
    np.testing.assert_allclose(move.pose(move.duration)[0], p1)
    np.testing.assert_allclose(move.pose(move.duration)[1], r1, atol=1e-12)
    np.testing.assert_allclose(move.velocity(0.0), v0, atol=1e-12)
    np.testing.assert_allclose(move.velocity(move.duration - 1e-9), 0.0, atol=1e-6)
    t = np.linspace(0.0, move.duration, 401)
    speed = np.array([np.linalg.norm(move.velocity(s)) for s in t])
    assert speed.max() <= 0.2 * (1 + 1e-6)           # the start speed is the highest allowed
    acc = np.abs(np.diff(speed)) / np.diff(t)
    assert acc.max() <= 0.5 * 1.05
    # From rest: the classic minimum-jerk duration 1.875 d / v_max (here speed-bound).
    rest = MinimumJerkMove.plan(p0, r0, p1, r0, 0.1, 0.5, 10.0)
    assert rest.duration == pytest.approx(1.875 * np.linalg.norm(p1 - p0) / 0.1)


# -- differential IK ------------------------------------------------------------------------------

def make_ik(ur10, **kw):
    return DifferentialIK(ur10, 1 / 125, **kw)


def test_no_damping_in_the_normal_workspace(ur10):
    ik = make_ik(ur10, acceleration_limits=1e6)
    q = Q_INITIAL
    _, _, jac = ik.kinematics(q)
    xi = np.array([0.05, -0.02, 0.01, 0.0, 0.1, 0.0])
    result = ik.solve(q, jac, xi, np.zeros(6))
    assert result.damping == 0.0 and result.scale == 1.0 and result.halt is None
    np.testing.assert_allclose(jac @ result.qd, xi, atol=1e-12)
    assert result.condition == pytest.approx(np.linalg.cond(jac))


def test_damping_grows_near_a_singularity_and_bounds_velocities(ur10):
    ik = make_ik(ur10, acceleration_limits=1e6, condition_halt=1e9, condition_slowdown=1e8)
    damping, norms, pinv_norms = [], [], []
    for wrist2 in (-0.3, -0.05, -0.01, -0.001):     # wrist singularity at wrist_2 = 0
        q = Q_INITIAL.copy()
        q[4] = wrist2
        _, _, jac = ik.kinematics(q)
        xi = 0.2 * np.linalg.svd(jac)[0][:, -1]      # the direction the arm is losing
        result = ik.solve(q, jac, xi, np.zeros(6))
        damping.append(result.damping)
        norms.append(np.linalg.norm(result.qd))
        pinv_norms.append(np.linalg.norm(np.linalg.pinv(jac) @ xi))
        assert np.linalg.norm(result.qd) <= np.linalg.norm(xi) / (2 * max(result.damping, 1e-12)) \
            or result.damping == 0.0
    assert damping[0] == 0.0
    assert damping[1] < damping[2] < damping[3] <= ik.max_damping
    assert pinv_norms[-1] > 100.0 > max(norms)      # the pseudo-inverse explodes, DLS does not
    assert np.all(np.abs(norms) <= 1.01 * ur10.velocity_limits.max() * np.sqrt(6))


def test_velocity_limit_keeps_the_direction(ur10):
    ik = make_ik(ur10, acceleration_limits=1e6)
    q = Q_INITIAL
    _, _, jac = ik.kinematics(q)
    xi = np.array([3.0, -1.0, 2.0, 0.0, 0.0, 1.0])       # far too fast
    result = ik.solve(q, jac, xi, np.zeros(6))
    exact = np.linalg.solve(jac, xi)
    assert np.max(np.abs(result.qd) / ik.velocity_limits) == pytest.approx(1.0)
    np.testing.assert_allclose(result.qd / np.linalg.norm(result.qd),
                               exact / np.linalg.norm(exact), atol=1e-12)
    assert result.scale == pytest.approx(np.linalg.norm(result.qd) / np.linalg.norm(exact))


def test_acceleration_limit_bounds_the_change(ur10):
    ik = make_ik(ur10)
    q = Q_INITIAL
    _, _, jac = ik.kinematics(q)
    previous = np.array([0.1, 0.0, -0.1, 0.0, 0.0, 0.0])
    result = ik.solve(q, jac, np.array([0.5, 0.5, 0.0, 0.0, 0.0, 0.0]), previous)
    change = np.abs(result.qd - previous) / ik.period
    assert np.max(change / ik.acceleration_limits) == pytest.approx(1.0)
    # A stop decelerates every joint within its limit and keeps the direction.
    braked = ik.brake(np.array([2.0, -1.0, 0.5, 0.0, 0.0, 0.0]))
    assert np.all(np.abs(braked - [2.0, -1.0, 0.5, 0, 0, 0]) <= ik.acceleration_limits * ik.period
                  + 1e-12)
    np.testing.assert_allclose(braked / braked[0], [1.0, -0.5, 0.25, 0, 0, 0])
    assert not np.any(ik.brake(np.full(6, 1e-3)))


def test_posture_term_acts_only_where_damping_frees_the_task(ur10):
    posture = Q_INITIAL.copy()
    ik = make_ik(ur10, acceleration_limits=1e6, posture=posture, posture_gain=2.0,
                 condition_halt=1e9, condition_slowdown=1e8)
    plain = make_ik(ur10, acceleration_limits=1e6, condition_halt=1e9, condition_slowdown=1e8)
    xi = np.array([0.02, 0.0, 0.0, 0.0, 0.0, 0.0])
    q = Q_INITIAL + 0.1
    jac = ik.kinematics(q)[2]
    np.testing.assert_allclose(ik.solve(q, jac, xi, np.zeros(6)).qd,
                               plain.solve(q, jac, xi, np.zeros(6)).qd, atol=1e-15)
    q = Q_INITIAL.copy()
    q[4] = -0.01                                         # near the wrist singularity
    jac = ik.kinematics(q)[2]
    extra = ik.solve(q, jac, np.zeros(6), np.zeros(6)).qd
    assert extra @ (posture - q) > 0.0                   # moves towards the posture
    assert extra[4] < 0.0                                # wrist 2 away from the singularity


# -- the controller on a kinematic plant ---------------------------------------------------------

@pytest.mark.parametrize('rate', [125.0, 500.0])
def test_tracks_letter_g(ur10, letter_g, rate):
    controller = TrajectoryController(ur10, ControllerConfig(rate=rate))
    controller.follow(letter_g)
    log, q = run_kinematic(controller, Q_INITIAL, duration=10.0)
    states = [s for i, s in enumerate(log.status) if i == 0 or s != log.status[i - 1]]
    assert states == ['approaching', 'tracking', 'holding', 'idle']
    errors = log.errors('tracking')
    assert len(errors) == pytest.approx(letter_g.duration * rate, abs=2)
    rms, worst = np.sqrt(np.mean(errors ** 2)), errors.max()
    assert rms < 0.005e-3 and worst < 0.02e-3, (rms, worst)     # measured 1.4 um, 8 um
    assert_within_limits(controller, log)
    np.testing.assert_allclose(ur10.frame_pose(q)[0], letter_g.positions[-1], atol=1e-4)
    assert not np.any(log.qd[-1])
    # The approach is a minimum-jerk move at no more than the approach speed.
    tool = np.array(log.tool)
    speed = np.linalg.norm(np.diff(tool, axis=0), axis=1) * rate
    approaching = np.array(log.status[1:]) == 'approaching'
    assert speed[approaching].max() <= controller.config.approach_speed * 1.05


def test_tracks_the_stirring_plan(ur10):
    path = stir_plan()[0]
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    controller.follow(path)
    log, q = run_kinematic(controller, Q_INITIAL, duration=15.0)
    errors = log.errors('tracking')
    assert len(errors) == pytest.approx(path.duration * 125, abs=2)
    assert np.sqrt(np.mean(errors ** 2)) < 0.005e-3 and errors.max() < 0.02e-3
    assert_within_limits(controller, log)
    assert log.status[-1] == 'idle'
    p, rot = ur10.frame_pose(q)
    np.testing.assert_allclose(p, path.positions[-1], atol=1e-4)
    assert np.linalg.norm(pin.log3(rot @ tool_down().T)) < 1e-3


def test_holds_the_last_pose_then_sends_zeros(ur10, letter_g):
    config = ControllerConfig(rate=125.0, hold_time=0.4)
    controller = TrajectoryController(ur10, config)
    controller.follow(letter_g)
    log, _ = run_kinematic(controller, Q_INITIAL, duration=10.0, stop_when_idle=False)
    status = np.array(log.status)
    assert np.sum(status == 'holding') == pytest.approx(0.4 * 125, abs=2)
    idle = np.flatnonzero(status == 'idle')
    assert idle[0] == np.flatnonzero(status == 'holding')[-1] + 1
    assert not np.any(np.array(log.qd)[idle])           # explicit zeros from then on
    holding = np.array(log.error)[status == 'holding']
    assert holding.max() < 0.1e-3


def test_path_switch_mid_execution_is_smooth(ur10, letter_g):
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    other = PoseTrajectory(letter_g.t, letter_g.positions + [0.0, 0.05, 0.02],
                           letter_g.rotations)
    controller.follow(letter_g)
    switch = 2.5                                         # during the G (approach ends ~1.7 s)
    log, q = run_kinematic(controller, Q_INITIAL, duration=15.0,
                           events=[(switch, lambda c: c.follow(other))])
    k = int(np.searchsorted(log.t, switch - 1e-9))
    assert log.status[k - 1] == 'tracking' and log.status[k] == 'approaching'
    assert_within_limits(controller, log)               # no jump in the command
    tool = np.array(log.tool)
    speed = np.linalg.norm(np.diff(tool, axis=0), axis=1) * 125
    speed_at_switch = speed[k - 3:k + 1].max()
    assert speed[k:][np.array(log.status[k + 1:]) == 'approaching'].max() <= \
        max(controller.config.approach_speed, speed_at_switch) * 1.05
    errors = np.array(log.error[k:])[np.array(log.status[k:]) == 'tracking']
    assert len(errors) > 200 and errors.max() < 0.1e-3
    np.testing.assert_allclose(ur10.frame_pose(q)[0], other.positions[-1], atol=1e-4)


def test_pause_sends_zeros_and_resume_finishes_the_path(ur10, letter_g):
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    controller.follow(letter_g)
    pause, resume = 2.5, 3.5
    log, q = run_kinematic(controller, Q_INITIAL, duration=15.0,
                           events=[(pause, lambda c: c.set_paused(True)),
                                   (resume, lambda c: c.set_paused(False))])
    k0, k1 = np.searchsorted(log.t, [pause - 1e-9, resume - 1e-9])
    assert set(log.status[k0:k1]) == {'paused'}
    assert not np.any(np.array(log.qd[k0:k1]))
    after = log.status[k1:]
    assert after[0] == 'approaching' and 'tracking' in after and after[-1] == 'idle'
    # The path goes on from where it was paused (not from its start): the remaining tracking
    # time is what was left, plus the ramp-in of the path clock.
    remaining = letter_g.duration - (pause - (log.status.index('tracking')) / 125)
    tracking_after = after.count('tracking') / 125
    assert tracking_after == pytest.approx(remaining + 0.5 * controller.config.resume_ramp_time,
                                           abs=0.05)
    assert_within_limits(controller, log, skip_steps=[k0])   # pause stops at once
    errors = np.array(log.error[k1:])[np.array(after) == 'tracking']
    assert errors.max() < 0.2e-3
    np.testing.assert_allclose(ur10.frame_pose(q)[0], letter_g.positions[-1], atol=1e-4)


def test_stale_input_sends_zeros_at_once_and_drops_the_path(ur10, letter_g):
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    controller.follow(letter_g)
    log, q = run_kinematic(controller, Q_INITIAL, duration=2.5)
    assert log.status[-1] == 'tracking' and np.any(log.qd[-1])
    controller.input_lost('no joint states for 0.1 s')
    assert controller.status == 'stale-input'
    assert not np.any(controller.previous_command)
    command = controller.step(q, 2.6)                     # input is back
    assert command.status == 'idle' and not np.any(command.qd)


def test_drive_into_singularity_halts_bounded(ur10):
    # A path whose joint-space twin crosses the wrist singularity (wrist_2 = 0).
    q_a = Q_INITIAL.copy()
    q_a[4] = -0.8
    q_b = q_a.copy()
    q_b[4] = 0.4
    t = np.linspace(0.0, 4.0, 401)
    joints = q_a + (q_b - q_a) * (t / t[-1])[:, None]
    poses = [ur10.frame_pose(qk) for qk in joints]
    path = PoseTrajectory(t, [p for p, _ in poses], [r for _, r in poses])
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    controller.follow(path)
    log, q = run_kinematic(controller, q_a, duration=6.0)
    assert log.status[-1] == 'halted-singularity'
    assert 'condition number' in log.reason[-1]
    assert_within_limits(controller, log)
    condition = np.array(log.condition)
    assert np.nanmax(condition) <= controller.config.condition_halt * 1.1
    assert not np.any(log.qd[-1])
    # The slow-down zone scaled the command down before the halt.
    first_halt = log.status.index('halted-singularity')
    assert np.max(np.abs(log.qd[first_halt - 1])) < 0.2 * np.max(np.abs(log.qd[first_halt - 60]))
    assert q[4] < -0.05                                  # stopped short of wrist_2 = 0


def test_joint_limit_halts_before_the_limit(ur10):
    # Turning the tool about its own axis winds wrist 3 towards its +2 pi limit.
    q0 = Q_INITIAL.copy()
    q0[5] = 6.0
    p0, r0 = ur10.frame_pose(q0)
    t = np.linspace(0.0, 3.0, 301)
    rotations = [r0 @ pin.exp3(np.array([0.0, 0.0, -0.6 * s / 3.0])) for s in t]
    # Which sign winds wrist_3 up depends on the frame: pick the one that does.
    q_test = q0.copy()
    q_test[5] += 0.1
    if np.linalg.norm(pin.log3(ur10.frame_pose(q_test)[1] @ rotations[-1].T)) > 0.6:
        rotations = [r0 @ pin.exp3(np.array([0.0, 0.0, 0.6 * s / 3.0])) for s in t]
    path = PoseTrajectory(t, np.repeat(p0[None], len(t), axis=0), rotations)
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    assert 'wrist_3_joint' in controller.check(path, q0)
    controller.follow(path)
    log, q = run_kinematic(controller, q0, duration=5.0)
    assert log.status[-1] == 'halted-joint-limit'
    assert 'wrist_3_joint' in log.reason[-1] and 'upper limit' in log.reason[-1]
    assert_within_limits(controller, log)
    wrist3 = np.array(log.q)[:, 5]
    assert wrist3.max() > 6.1                             # it did move towards the limit
    assert wrist3.max() <= ur10.upper[5] - 0.5 * controller.config.joint_limit_margin


def test_unreachable_path_is_rejected_with_the_reason(ur10, letter_g):
    controller = TrajectoryController(ur10)
    far = PoseTrajectory(letter_g.t, letter_g.positions + [1.5, 0.0, 0.0], letter_g.rotations)
    reason = controller.check(far, Q_INITIAL)
    assert 'out of reach' in reason
    assert controller.check(letter_g, Q_INITIAL) == ''
    controller.reject(reason)
    command = controller.step(Q_INITIAL, 0.0)
    assert command.status == 'unreachable' and command.reason == reason
    assert not np.any(command.qd)


def test_too_fast_path_stops_on_tracking_error(ur10, letter_g):
    # The G in 0.1 s needs more than the joints can give: the error grows, the arm stops.
    fast = PoseTrajectory(letter_g.t / 20.0, letter_g.positions, letter_g.rotations)
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    controller.follow(fast)
    log, _ = run_kinematic(controller, Q_INITIAL, duration=5.0)
    assert log.status[-1] == 'unreachable' and 'tracking error' in log.reason[-1]
    assert_within_limits(controller, log)
    assert not np.any(log.qd[-1])


def test_single_pose_path_moves_there_and_holds(ur10):
    p0, r0 = ur10.frame_pose(Q_INITIAL)
    target = p0 + [0.05, -0.03, 0.02]
    controller = TrajectoryController(ur10)
    controller.follow(PoseTrajectory([0.0], [target], [r0]))
    log, q = run_kinematic(controller, Q_INITIAL, duration=5.0)
    assert 'holding' in log.status and log.status[-1] == 'idle'
    np.testing.assert_allclose(ur10.frame_pose(q)[0], target, atol=1e-4)


@pytest.mark.parametrize('field, value', [('rate', 0.0), ('position_gain', -1.0),
                                          ('velocity_scale', 1.5), ('hold_time', np.nan),
                                          ('position_gain', 200.0)])
def test_config_is_validated(ur10, field, value):
    with pytest.raises(ValueError, match=field.split('_')[0]):
        TrajectoryController(ur10, ControllerConfig(**{field: value}))


def test_joint_names_order():
    assert JOINT_NAMES[5] == 'wrist_3_joint'


# -- the numba fast path against the numpy oracle ------------------------------------------------

needs_numba = pytest.mark.skipif(not _ik_fast.AVAILABLE, reason='numba is not installed')


@needs_numba
def test_fast_solve_matches_numpy(ur10):
    rng = np.random.default_rng(7)
    ik = DifferentialIK(ur10, 1 / 125, posture=Q_INITIAL, posture_gain=1.5)
    for k in range(300):
        q = rng.uniform(-3.0, 3.0, 6)
        if k % 3 == 0:
            q[4] = rng.uniform(-0.05, 0.05)             # near the wrist singularity
        if k % 5 == 0:
            q[5] = ur10.upper[5] - rng.uniform(0.0, 0.1)  # near a joint limit
        jac = ik.kinematics(q)[2]
        xi = rng.normal(scale=0.3, size=6)
        previous = rng.normal(scale=0.5, size=6)
        slow = ik.solve(q, jac, xi, previous, fast=False)
        fast = ik.solve(q, jac, xi, previous, fast=True)
        assert fast.halt == slow.halt and fast.reason == slow.reason
        np.testing.assert_allclose(fast.qd, slow.qd, atol=1e-9)
        assert fast.condition == pytest.approx(slow.condition, rel=1e-8)
        assert fast.damping == pytest.approx(slow.damping, abs=1e-12)


@needs_numba
def test_fast_rotation_log_and_trajectory_match(letter_g):
    rng = np.random.default_rng(8)
    out = np.empty(6)
    for angle in np.r_[0.0, 1e-9, 1e-5, rng.uniform(0.0, np.pi, 50), np.pi - 1e-6, np.pi]:
        axis = rng.normal(size=3)
        w = angle * axis / np.linalg.norm(axis)
        rot = pin.exp3(w)
        _ik_fast.log3(rot, out, 3)
        expected = pin.log3(rot)
        if angle > np.pi - 1e-3:                          # +-w are the same rotation
            assert np.allclose(out[3:], expected, atol=1e-6) or \
                np.allclose(out[3:], -expected, atol=1e-6)
            np.testing.assert_allclose(pin.exp3(out[3:]), rot, atol=1e-9)
        else:
            np.testing.assert_allclose(out[3:], expected, atol=1e-10)
    t = np.linspace(0.0, 1.0, 11)
    twisted = PoseTrajectory(t, np.c_[t, t ** 2, 0 * t],
                             [pin.exp3(np.array([0.2, -0.1, 1.0]) * s) for s in t])
    for path in (letter_g, twisted):
        for s in np.r_[-1.0, 0.0, rng.uniform(0.0, path.duration, 100), path.duration, 9.0]:
            p_fast, r_fast = path.pose(s, fast=True)
            p_slow, r_slow = path.pose(s, fast=False)
            np.testing.assert_allclose(p_fast, p_slow, atol=1e-12)
            np.testing.assert_allclose(r_fast, r_slow, atol=1e-12)


@needs_numba
def test_fast_controller_matches_numpy_in_closed_loop(ur10, letter_g):
    logs = []
    for fast in (False, True):
        controller = TrajectoryController(ur10, ControllerConfig(rate=125.0), fast=fast)
        controller.follow(letter_g)
        logs.append(run_kinematic(controller, Q_INITIAL, duration=6.0)[0])
    assert logs[0].status == logs[1].status
    np.testing.assert_allclose(np.array(logs[1].qd), np.array(logs[0].qd), atol=1e-8)


# -- the actuation delay, estimated online -------------------------------------------------------

@pytest.mark.parametrize('delay', [0, 1, 2])
def test_delay_estimate_converges_to_the_plant_delay(ur10, letter_g, delay):
    # Start from a wrong guess: the estimate must find the plant's delay during the approach.
    wrong = (delay + 1) % 3
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0,
                                                             actuation_delay=wrong / 125.0))
    controller.follow(letter_g)
    log, _ = run_kinematic(controller, Q_INITIAL, duration=10.0, delay_periods=delay)
    assert controller.delay * 125.0 == pytest.approx(delay, abs=0.02)
    errors = log.errors('tracking')
    assert np.sqrt(np.mean(errors ** 2)) < 0.01e-3 and errors.max() < 0.05e-3
    assert_within_limits(controller, log)


def test_delay_estimator_predicts_in_flight_motion():
    estimator = DelayEstimator(prior=1.5, period=0.01, fast=False)
    for u in (np.full(6, 1.0), np.full(6, 2.0), np.full(6, 3.0)):
        estimator.record(u)
    # 1.5 periods: the newest command (3) for one period, the one before (2) for half a period.
    np.testing.assert_allclose(estimator.in_flight(1.5), 0.01 * (3.0 + 0.5 * 2.0))
    np.testing.assert_allclose(estimator.in_flight(0.0), 0.0)
    if _ik_fast.AVAILABLE:
        fast = DelayEstimator(prior=1.5, period=0.01, fast=True)
        fast._commands[:] = estimator._commands
        for d in (0.0, 0.3, 1.0, 1.7, 2.0):
            np.testing.assert_allclose(fast.in_flight(d), estimator.in_flight(d), atol=1e-15)


def test_slow_down_near_a_singularity_is_reported_as_such(ur10):
    # A fast path into the wrist singularity: the slow-down makes the arm lag; the stop is
    # reported as the singularity's doing, not as an unreachable target.
    q_a = Q_INITIAL.copy()
    q_a[4] = -0.8
    q_b = q_a.copy()
    q_b[4] = 0.4
    t = np.linspace(0.0, 1.0, 101)
    poses = [ur10.frame_pose(q_a + (q_b - q_a) * s) for s in t]
    path = PoseTrajectory(t, [p for p, _ in poses], [r for _, r in poses])
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0,
                                                             max_tracking_error=0.01))
    controller.follow(path)
    log, _ = run_kinematic(controller, q_a, duration=4.0)
    assert log.status[-1] == 'halted-singularity'
    assert 'slowed down near a singularity' in log.reason[-1]
    assert_within_limits(controller, log)

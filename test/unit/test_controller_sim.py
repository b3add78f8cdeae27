"""
The controller driving the MuJoCo simulation in-process (no ROS): tracking, limits, halts.

Each control period: read the simulated joints, step the controller, command the velocities,
advance the physics one period (commands act at once, so ``actuation_delay = 0``). The tool
tip is measured independently of the controller: Pinocchio forward kinematics of the simulated
joints (``UR10Sim.tool_tip_position`` is the site before the last physics step, as MuJoCo's
``mj_step`` leaves it), against the plan evaluated at the path time found from the controller's
reference, which must itself be the plan at nominal speed.
"""

from etdmp_ros.robot import _controller
from etdmp_ros.robot import ControllerConfig, PoseTrajectory, TrajectoryController, UR10Model
from etdmp_ros.ros.system import scene_config
from etdmp_ros.sim import UR10Sim
import numpy as np
import pinocchio as pin
import pytest
from support.controller_plans import (g_plan, letter_plan, path_time_offset, Q_INITIAL,
                                      stir_plan, TOOL_OFFSET, turning_plan)


@pytest.fixture(scope='module')
def ur10():
    return UR10Model(tool_offset=TOOL_OFFSET)


@pytest.fixture(scope='module')
def sim():
    with UR10Sim(scene_config(), watchdog_timeout=0.0) as s:
        yield s


def drive(sim, controller, q0, duration, ur10, stall=None):
    """
    Run the closed loop; return a dict of arrays (one row per control period).

    ``stall``: (s after tracking began, s) during which the controller does not step (its
    process not scheduled): the simulation goes on with the last command (and its watchdog).
    """
    sim.reset(q0)
    T = controller.period
    rows = {'t': [], 'q': [], 'qd': [], 'status': [], 'tool': [], 'ref': [], 'reason': []}
    tracking = None
    for _ in range(int(round(duration / T))):
        q, t = sim.q, sim.time
        if stall is not None and tracking is not None and \
                tracking + stall[0] <= t < tracking + stall[0] + stall[1]:
            sim.advance(T)
            continue
        command = controller.step(q, t)
        if command.status == 'tracking' and tracking is None:
            tracking = t
        sim.set_velocity_command(command.qd)
        rows['t'].append(t)
        rows['q'].append(q)
        rows['qd'].append(command.qd)
        rows['status'].append(command.status)
        rows['reason'].append(command.reason)
        rows['tool'].append(ur10.frame_pose(q)[0])
        rows['ref'].append(command.reference_position if command.reference_position is not None
                           else np.full(3, np.nan))
        sim.advance(T)
        if command.status == 'idle' and len(rows['t']) > 3 and not np.any(command.qd):
            break
    return {k: np.array(v) for k, v in rows.items()}


def tracking_errors(path, run):
    """Return the true tool-tip errors (m) over the tracking phase, after checking the timing."""
    tracking = run['status'] == 'tracking'
    t, ref, tool = run['t'][tracking], run['ref'][tracking], run['tool'][tracking]
    t0 = path_time_offset(path, t, ref)
    plan = np.array([path.pose(s - t0)[0] for s in t])
    # The controller's reference is the plan at its nominal speed (no slowed clock hiding lag).
    assert np.max(np.linalg.norm(ref - plan, axis=1)) < 1e-6
    assert t[-1] - t[0] == pytest.approx(path.duration, abs=2 * (t[1] - t[0]))
    return np.linalg.norm(tool - plan, axis=1)


def assert_within_limits(controller, run):
    ik = controller.ik
    qd = run['qd']
    assert np.all(np.abs(qd) <= ik.velocity_limits * (1 + 1e-9))
    change = np.abs(np.diff(np.vstack([np.zeros(6), qd]), axis=0)) / controller.period
    assert np.all(change <= ik.acceleration_limits * (1 + 1e-9))
    assert np.all(run['q'] >= ik.model.lower) and np.all(run['q'] <= ik.model.upper)


@pytest.mark.parametrize('rate', [125.0, 500.0])
def test_letter_g_in_mujoco(sim, ur10, rate):
    path = g_plan()[0]
    controller = TrajectoryController(ur10, ControllerConfig(rate=rate, actuation_delay=0.0))
    controller.follow(path)
    run = drive(sim, controller, Q_INITIAL, 10.0, ur10)
    errors = tracking_errors(path, run)
    rms = np.sqrt(np.mean(errors ** 2))
    print(f'G in MuJoCo at {rate:g} Hz: RMS {rms * 1e3:.3f} mm, max {errors.max() * 1e3:.3f} mm')
    assert rms <= 0.1e-3 and errors.max() <= 0.5e-3
    assert_within_limits(controller, run)
    assert run['status'][-1] == 'idle' and not np.any(run['qd'][-1])
    np.testing.assert_allclose(run['tool'][-1], path.positions[-1], atol=0.1e-3)


def test_stirring_in_mujoco(sim, ur10):
    path = stir_plan()[0]
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0, actuation_delay=0.0))
    controller.follow(path)
    run = drive(sim, controller, Q_INITIAL, 15.0, ur10)
    errors = tracking_errors(path, run)
    rms = np.sqrt(np.mean(errors ** 2))
    print(f'stirring in MuJoCo: RMS {rms * 1e3:.3f} mm, max {errors.max() * 1e3:.3f} mm')
    assert rms <= 0.1e-3 and errors.max() <= 0.5e-3
    assert_within_limits(controller, run)
    np.testing.assert_allclose(run['tool'][-1], path.positions[-1], atol=0.1e-3)


def orientation_errors(path, run, ur10):
    """Return the true tool orientation errors (rad) over the tracking phase vs the plan."""
    tracking = run['status'] == 'tracking'
    t, ref, q = run['t'][tracking], run['ref'][tracking], run['q'][tracking]
    t0 = path_time_offset(path, t, ref)
    return np.array([np.linalg.norm(pin.log3(path.pose(s - t0)[1] @ ur10.frame_pose(qk)[1].T))
                     for s, qk in zip(t, q)])


@pytest.mark.parametrize('name', ['stir', 'wipe'])
def test_the_tool_tilts_and_turns_as_planned_in_mujoco(sim, ur10, name):
    # The stirrer tilts and circles, the sponge turns with the stroke: the true tool
    # orientation (forward kinematics of the simulated joints) follows the plan's.
    path, plan = turning_plan(name)
    turn = np.degrees(max(np.linalg.norm(pin.log3(r @ path.rotations[0].T))
                          for r in path.rotations))
    assert turn > 9.0          # the plan does turn the tool
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0, actuation_delay=0.0))
    assert controller.check(path, Q_INITIAL) == ''
    controller.follow(path)
    run = drive(sim, controller, Q_INITIAL, 15.0, ur10)
    angles = np.degrees(orientation_errors(path, run, ur10))
    rms = np.sqrt(np.mean(angles ** 2))
    errors = tracking_errors(path, run)
    print(f'{name} in MuJoCo: orientation RMS {rms:.3f} deg, max {angles.max():.3f} deg '
          f'(turn {turn:.1f} deg); position RMS {np.sqrt(np.mean(errors ** 2)) * 1e3:.3f} mm')
    assert rms <= 0.5 and angles.max() <= 2.0
    assert np.sqrt(np.mean(errors ** 2)) <= 0.1e-3 and errors.max() <= 0.5e-3
    assert_within_limits(controller, run)
    final = ur10.frame_pose(run['q'][-1])[1]
    assert np.degrees(np.linalg.norm(pin.log3(path.rotations[-1] @ final.T))) < 0.1
    # The measure: the model's tool frame is MuJoCo's tool tip site, orientation included.
    sim.set_joint_positions(run['q'][len(run['q']) // 2])
    site_p, site_rot = sim.site_pose(sim.tool_tip_site)
    p, rot = ur10.frame_pose(run['q'][len(run['q']) // 2])[:2]
    assert np.linalg.norm(site_p - p) < 1e-9
    assert np.linalg.norm(pin.log3(site_rot @ rot.T)) < 1e-9


def test_an_orientation_the_ur10_cannot_reach_is_refused_before_moving(ur10):
    # Stirring far out (1.08 m from the base): reachable with the stirrer's own orientations,
    # but not when it must end pointing back at the base (tool z along -x): the wrist would
    # be beyond the arm's reach. Both pre-checks refuse it, saying where, before anything moves.
    from etdmp_ros.robot import DEFAULT_ACCELERATION_LIMITS
    from etdmp_ros.robot._timing import timing_violation
    goal = np.array([1.08, 0.1, 0.2])
    start = goal + [-0.05, 0.05, 0.25]
    back = (0.0, -np.sqrt(0.5), 0.0, np.sqrt(0.5))
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0))
    own, _ = turning_plan('stir', start=start, goal=goal)
    assert controller.check(own, Q_INITIAL) == ''
    path, plan = turning_plan('stir', start=start, goal=goal, goal_orientation=back)
    reason = controller.check(path, Q_INITIAL)
    assert reason.startswith('pose #') and 'is out of reach' in reason, reason
    violation = timing_violation(ur10, plan.positions, path.rotations, plan.t, Q_INITIAL,
                                 ur10.velocity_limits, DEFAULT_ACCELERATION_LIMITS, 64)
    assert violation is not None and 'with its orientation, is out of reach' in \
        violation.reason, violation


def test_singularity_halt_in_mujoco(sim, ur10):
    q_a = Q_INITIAL.copy()
    q_a[4] = -0.8
    q_b = q_a.copy()
    q_b[4] = 0.4                                     # through wrist_2 = 0: wrist singularity
    t = np.linspace(0.0, 4.0, 401)
    poses = [ur10.frame_pose(q_a + (q_b - q_a) * s / t[-1]) for s in t]
    path = PoseTrajectory(t, [p for p, _ in poses], [r for _, r in poses])
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0, actuation_delay=0.0))
    assert 'singular' in controller.check(path, q_a)  # refused up front by the node ...
    controller.follow(path)                           # ... and halted if executed anyway
    run = drive(sim, controller, q_a, 7.0, ur10)
    assert run['status'][-1] == 'halted-singularity'
    assert 'condition number' in run['reason'][-1]
    assert_within_limits(controller, run)
    assert not np.any(run['qd'][-1])
    assert np.max(np.abs(run['q'][:, 4])) < 0.9 and run['q'][-1, 4] < -0.05
    sim.advance(0.5)                                  # stays put after the halt
    np.testing.assert_allclose(sim.q, run['q'][-1], atol=2e-3)


@pytest.mark.parametrize('resync', [True, False], ids=['resync', 'no-resync'])
def test_a_stalled_controller_goes_on_where_the_arm_is(sim, ur10, monkeypatch, resync):
    # Issue 25, "an unexplained stop": the letter W written in its own 2 s (0.45 m/s at its
    # fastest), the controller not stepping for 0.25 s (its process not scheduled; joint states
    # held back, as the reliable subscription did). The simulation goes on with the last
    # command until its 0.1 s watchdog brakes. The path clock ran on the measurements' time, so
    # the reference is 0.25 s ahead of an arm that coasted: without re-synchronising it the
    # arm is stopped, "tracking error 94 mm exceeds max_tracking_error 50 mm"; with it, the path
    # goes on from the pose nearest to the tool and the W is written to its end.
    path = letter_plan('W', dt=0.01)[0]
    if not resync:
        monkeypatch.setattr(_controller, 'MISSED_STEPS', np.inf)
    monkeypatch.setattr(sim, 'watchdog_timeout', 0.1)
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0, actuation_delay=0.0))
    assert controller.check(path, Q_INITIAL) == ''
    controller.follow(path)
    run = drive(sim, controller, Q_INITIAL, 10.0, ur10, stall=(1.0, 0.25))
    tracked = run['status'] == 'tracking'
    error = np.linalg.norm(run['ref'][tracked] - run['tool'][tracked], axis=1)
    print(f'W stalled 0.25 s, resync {resync}: status {run["status"][-1]} '
          f'{run["reason"][-1]!r}, max error while tracked {error.max() * 1e3:.1f} mm')
    assert_within_limits(controller, run)
    if not resync:
        assert run['status'][-1] == 'unreachable'
        assert 'exceeds max_tracking_error' in run['reason'][-1]
        return
    assert controller.resyncs == 1
    assert controller.last_gap[1] == pytest.approx(0.256, abs=0.005)   # 0.25 s, whole periods
    assert run['status'][-1] == 'idle' and not np.any(run['qd'][-1])
    assert 'holding' in run['status']
    assert error.max() < 0.03     # coasting 0.1 s straight on where the W turns
    np.testing.assert_allclose(run['tool'][-1], path.positions[-1], atol=0.1e-3)
    # Away from the stall the W is tracked as closely as without it.
    after = run['t'][tracked] > run['t'][tracked][0] + 1.0 + 0.25 + 0.3
    assert np.max(error[after]) < 0.5e-3


def _shifted_remainder(path, t, positions, t_from, t_shift, shift):
    """Return the path's remainder from ``t_from`` on, bent smoothly by ``shift`` after t_shift."""
    keep = t >= t_from - 1e-9
    s = np.clip((t[keep] - t_shift) / (t[-1] - t_shift), 0.0, 1.0)
    blend = s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)        # C2, zero slope at both ends
    moved = positions[keep] + blend[:, None] * np.asarray(shift)
    rotations = np.repeat(path.rotations[:1], keep.sum(), axis=0)
    return PoseTrajectory(t[keep] - t[keep][0], moved, rotations), t[keep][0], moved


@pytest.mark.parametrize('stamped', [True, False])
def test_a_replanned_remainder_is_spliced_in_without_an_approach(sim, ur10, stamped):
    # A re-plan of the path being tracked (its remainder from 0.8 s, the goal moved 10 mm from
    # 1.2 s on), stamped on the same clock, is taken over at the same path time: no approach,
    # no stop, the tool ends at the new end. Unstamped, it is a new path: approach from rest.
    path, t, positions = g_plan(dt=0.01)
    controller = TrajectoryController(ur10, ControllerConfig(rate=125.0, actuation_delay=0.0))
    controller.follow(path, 0.0)
    remainder, stamp, moved = _shifted_remainder(path, t, positions, 0.8, 1.2, [0.0, 0.01, 0.0])
    sim.reset(Q_INITIAL)
    T = controller.period
    statuses, qds, tools, began, switched = [], [], [], None, None
    for k in range(int(round(8.0 / T))):
        q, now = sim.q, sim.time
        if switched is None and began is not None and now - began >= 1.0:
            controller.follow(remainder, stamp if stamped else None)
            switched = k
        command = controller.step(q, now)
        if began is None and command.status == 'tracking':
            began = now
        statuses.append(command.status)
        qds.append(command.qd)
        tools.append(ur10.frame_pose(q)[0])
        sim.set_velocity_command(command.qd)
        sim.advance(T)
        if switched is not None and command.status == 'idle':
            break
    assert switched is not None
    after = statuses[switched:]
    assert_within_limits(controller, {'qd': np.array(qds), 'q': np.array([Q_INITIAL])})
    np.testing.assert_allclose(tools[-1], moved[-1], atol=0.2e-3)
    speeds = np.linalg.norm(np.diff(np.array(tools), axis=0), axis=1) / T
    if stamped:
        assert controller.splices == 1
        assert 'approaching' not in after, sorted(set(after))
        # No stop-and-go: the tool keeps its speed through the switch.
        window = speeds[switched - 5:switched + 25]
        assert window.min() > 0.3 * speeds[switched - 6], window
    else:
        assert controller.splices == 0
        assert 'approaching' in after

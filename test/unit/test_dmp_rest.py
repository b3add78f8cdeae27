"""
Every plan comes to rest at its goal, position and orientation, also past tau.

On recordings that are not the built-in ones (test/support/shapes.py: the LASA handwriting data set
and the ways a recording goes wrong; 3D shapes with a tool that turns with the stroke), with both
formulations and both methods, from the recording's own start and from the other quadrants or
octants, rolled out to 2 tau: never farther from the goal after tau than 0.5 % of the plan's
size, within 0.1 % at 2 tau, slower than 1 % of a size per tau there. The reasons and the
remedies (re-timed ends, the gate, Hoffmann's term, the end condition of the fit):
docs/design.md#coming-to-rest; the full set's figures: test/benchmarks/bench_rest.py.
"""

import math

from etdmp_ros.dmp import builtin_demo, GeneralizationError, learn, nrmse, OBSTACLE_MARGIN
from etdmp_ros.dmp._forcing_term import hoffmann_term, phase
from etdmp_ros.dmp._retime import MAX_STRETCH
from etdmp_ros.geometry import quaternion as quat
import numpy as np
import pytest
from support import shapes

#: The issue's bounds, as fractions of the plan's size (speed: sizes per tau).
AFTER_TAU, AT_2TAU, SPEED_2TAU = 0.005, 0.001, 0.01
#: The issue's bound on the last orientation (degrees).
ANGLE_DEG = 0.1
#: LASA shapes of the tests (every fifth; bench_rest.py runs all 30 x 7 recordings).
LASA = shapes.lasa_names()[::5]
#: Output samples per tau of the rollouts here (a LASA recording has 1000).
SAMPLES = 400
VARIANTS = {'as recorded': lambda r: r, 'ends moving': shapes.ends_moving,
            'starts moving': shapes.starts_moving, 'abrupt stop': shapes.abrupt_stop,
            'uneven': shapes.uneven}


def starts_around(start, goal):
    """Return the start and starts in the other quadrants (2D) or octants (3D), (B, d)."""
    offset = np.asarray(start, float) - goal
    if len(offset) == 2:
        turns = [(0.0, 1.0), (90.0, 1.5), (180.0, 0.6), (270.0, 1.2)]
        return np.array([goal + k * np.array([[math.cos(math.radians(a)), -math.sin(
            math.radians(a))], [math.sin(math.radians(a)), math.cos(math.radians(a))]]) @ offset
            for a, k in turns])
    signs = np.array([[x, y, z] for x in (1, -1) for y in (1, -1) for z in (1, -1)])
    return np.vstack([start, goal + np.linalg.norm(offset) * signs / math.sqrt(3.0)])


def rest_figures(traj, goal, tau):
    """Return (farthest after tau, distance at 2 tau, speed at 2 tau), each (B,), in sizes."""
    x = traj.x if traj.x.ndim == 3 else traj.x[None]
    v = traj.v if traj.v.ndim == 3 else traj.v[None]
    k = int(round((len(traj.t) - 1) / 2))        # the sample at tau, with margin 1
    dist = np.linalg.norm(x - goal, axis=2)
    size = dist[:, :k + 1].max(axis=1)
    return (dist[:, k:].max(axis=1) / size, dist[:, -1] / size,
            np.linalg.norm(v[:, -1], axis=1) * tau / size)


def assert_at_rest(skill, starts, goal, method, **kwargs):
    """Generalize to 2 tau and assert the issue's three bounds for every start."""
    traj = skill.generalize(starts, goal, method=method, margin=1.0, dt=skill.tau / SAMPLES,
                            **kwargs)
    after, at_2tau, speed = rest_figures(traj, goal, skill.tau)
    assert np.all(after <= AFTER_TAU), after
    assert np.all(at_2tau <= AT_2TAU), at_2tau
    assert np.all(speed <= SPEED_2TAU), speed
    return traj


@pytest.mark.parametrize('variant', list(VARIANTS))
@pytest.mark.parametrize('formulation', ['ijspeert', 'hoffmann'])
def test_lasa_recordings_come_to_rest_at_their_goal_from_every_quadrant(variant, formulation):
    for name in LASA:
        rec = VARIANTS[variant](shapes.lasa(name, 0))
        skill = learn(rec.positions, t=rec.t, formulation=formulation)
        starts, goal = starts_around(rec.positions[0], rec.positions[-1]), rec.positions[-1]
        assert_at_rest(skill, starts, goal, 'etdmp')
        try:
            assert_at_rest(skill, starts, goal, 'dmp')
        except GeneralizationError as err:      # Ijspeert's division by ~0 (said, not NaN)
            assert 'plain DMP cannot generalize' in str(err)


def test_the_issue_s_reproductions_come_to_rest():
    # The issue's two recordings: cut while moving (was 36 % of the size away after tau) and
    # an abrupt stop just before the end (3.9 %).
    t = np.linspace(0.0, 1.0, 200)
    cut = np.column_stack([np.sin(3 * t), t ** 2])
    s = np.minimum(t / 0.97, 1.0)
    halt = np.column_stack([np.cos(np.pi * s), np.sin(np.pi * s)])
    for y in (cut, halt):
        skill = learn(y, t=t)
        traj = assert_at_rest(skill, y[0], y[-1], 'etdmp')
        assert np.linalg.norm(traj.x[-1] - y[-1]) < 1e-6 * skill.size


@pytest.mark.parametrize('make', [shapes.helix, shapes.figure_eight_3d])
@pytest.mark.parametrize('variant', list(VARIANTS))
def test_3d_shapes_come_to_rest_from_every_octant_both_modes(make, variant):
    rec = VARIANTS[variant](make())
    for formulation in ('ijspeert', 'hoffmann'):
        skill = learn(rec.positions, t=rec.t, formulation=formulation)
        starts, goal = starts_around(rec.positions[0], rec.positions[-1]), rec.positions[-1]
        for mode in (1, 2):
            assert_at_rest(skill, starts, goal, 'etdmp', mode=mode)


def test_a_1d_recording_ending_moving_comes_to_rest():
    t = np.linspace(0.0, 2.0, 300)
    y = np.sin(2.2 * t) + 0.3 * t      # ends moving
    for formulation in ('ijspeert', 'hoffmann'):
        skill = learn(y, t=t, formulation=formulation)
        assert skill.retiming.end > 0.0
        for method in ('etdmp', 'dmp'):
            assert_at_rest(skill, np.array([[y[0]], [2.0 * y[-1] - y[0]], [y[-1] + 3.0]]),
                           np.array([y[-1]]), method)


def test_a_hand_led_stir_as_recorded_comes_to_rest_from_every_octant():
    # The kinesthetic recording's path (etdmp_ros.demo.kinesthetic.hand_stir, trimmed to the motion
    # as dmp_server trims a bag) with 20 um of sensor noise; through the simulation and a bag:
    # test_kinesthetic.py.
    from etdmp_ros.demo.kinesthetic import hand_stir
    from etdmp_ros.skills.recorded import _motion_span
    t, positions = hand_stir([0.75, -0.2, 0.3], [0.7, -0.3, 0.2])
    positions = positions + np.random.default_rng(0).normal(0.0, 2e-5, positions.shape)
    first, last = _motion_span(positions)
    y, t = positions[first:last + 1], t[first:last + 1]
    for formulation in ('ijspeert', 'hoffmann'):
        skill = learn(y, t=t, formulation=formulation)
        starts = starts_around(y[0], y[-1])
        for mode in (1, 2):
            assert_at_rest(skill, starts, y[-1], 'etdmp', mode=mode)
        assert_at_rest(skill, starts, y[-1], 'dmp')


# ---------------------------------------------------------------------- what the fix keeps

def _on_learned_clock(skill, traj):
    """Return the plan at the re-timed time of each recorded sample."""
    return np.stack([np.interp(skill.retiming.times, traj.t, traj.x[:, i])
                     for i in range(traj.x.shape[1])], axis=1)


def test_recordings_at_rest_learn_and_reproduce_as_before():
    # At rest at both ends: nothing is re-timed, the reproduction is as good as before
    # (nRMSE by sample index against the recording; before the change: G 0.00073,
    # stir 0.00018, helix 0.00022, figure eight 0.00021).
    before = {'G': 0.00073, 'P': 0.00082, 'R': 0.00083, 'W': 0.00093, 'stir': 0.00018,
              'helix': 0.00022, 'figure_eight_3d': 0.00021}
    recordings = {name: builtin_demo(name) for name in ('G', 'P', 'R', 'W', 'stir')}
    recordings.update(helix=shapes.helix(), figure_eight_3d=shapes.figure_eight_3d())
    for name, rec in recordings.items():
        skill = learn(rec.positions, t=rec.t)
        assert skill.retiming.start == 0.0 and skill.retiming.end == 0.0, name
        assert skill.tau == rec.t[-1] - rec.t[0]
        assert np.array_equal(skill.demo_t, rec.t - rec.t[0])
        quality = nrmse(skill.reproduce().x, rec.positions)
        assert quality <= 1.1 * before[name] + 2e-5, (name, quality)


def test_lasa_reproduces_its_recordings_on_the_learned_clock():
    # Before the change: median 0.00042 (by sample index: the recordings' own clock). The
    # re-timed recordings reproduced sample by sample on the learned clock: median below 0.0001.
    figures = []
    for name in shapes.lasa_names()[::2]:
        rec = shapes.lasa(name, 0)
        skill = learn(rec.positions, t=rec.t)
        figures.append(nrmse(_on_learned_clock(skill, skill.reproduce(dt=skill.tau / 2000)),
                             rec.positions))
    assert np.median(figures) < 1e-4 and max(figures) < 1e-3, figures


def test_re_timing_keeps_the_path_and_changes_only_the_ends():
    rec = shapes.ends_moving(shapes.starts_moving(shapes.lasa('Sshape', 2)))
    skill = learn(rec.positions, t=rec.t)
    r = skill.retiming
    period = rec.t[-1] / (len(rec.t) - 1)       # stretches are whole sample intervals
    assert 0.0 < r.start <= 0.5 * MAX_STRETCH * rec.t[-1] + period
    assert 0.0 < r.end <= 0.5 * MAX_STRETCH * rec.t[-1] + period
    assert skill.tau == pytest.approx(rec.t[-1] + r.start + r.end, rel=1e-12)
    # Every recorded sample is on the learned demonstration at its re-timed time.
    at = np.stack([np.interp(r.times, skill.demo_t, skill.demo[:, i]) for i in range(2)], axis=1)
    assert np.max(np.linalg.norm(at - rec.positions, axis=1)) < 1e-3 * skill.size
    assert np.all(np.diff(r.times) > 0.0)
    # Only the ends: in between, the recording's own clock (shifted by the start's stretch).
    middle = (rec.t > 0.1 * rec.t[-1]) & (rec.t < 0.85 * rec.t[-1])
    assert np.allclose(r.times[middle], rec.t[middle] + r.start, atol=1e-12)
    # The learned demonstration starts and ends at rest.
    v = np.linalg.norm(np.gradient(skill.demo, skill.demo_t, axis=0), axis=1) * skill.tau
    assert v[0] < 1e-3 * skill.size and v[-1] < 1e-3 * skill.size
    assert v[1] < 0.01 * v.max() and v[-2] < 0.01 * v.max()


def test_a_hold_after_an_abrupt_stop_stays_a_hold():
    rec = shapes.abrupt_stop(shapes.lasa('Angle', 1))
    skill = learn(rec.positions, t=rec.t)
    held = np.flatnonzero(np.all(rec.positions == rec.positions[-1], axis=1))
    assert len(held) > 20 and skill.retiming.end > 0.0
    # The held samples keep their spacing after the slowed stretch.
    assert np.allclose(np.diff(skill.retiming.times[held]), np.diff(rec.t[held]))


# -------------------------------------------------------------- the remedies, one by one

def test_the_reproduction_ends_at_its_goal_at_rest_by_the_end_condition():
    for name in ('Sharpc', 'Leaf_1', 'JShape'):
        rec = shapes.lasa(name, 0)
        for formulation in ('ijspeert', 'hoffmann'):
            skill = learn(rec.positions, t=rec.t, formulation=formulation)
            traj = skill.reproduce()
            assert np.linalg.norm(traj.x[-1] - skill.goal) < 1e-6 * skill.size
            assert np.linalg.norm(traj.v[-1]) * skill.tau < 1e-5 * skill.size


def test_hoffmann_s_term_is_his_until_0_7_tau_and_ends_at_tau():
    K, D, alpha = 156.25, 25.0, 4.0
    t = np.linspace(0.0, 2.0, 2001)
    term = hoffmann_term(phase(t, 1.0, alpha), K, D, alpha)
    early = t <= 0.7
    assert np.allclose(term[early], phase(t[early], 1.0, alpha), atol=1e-12)
    assert np.all(term[t >= 1.0] == 0.0)
    # From another start the plan is Hoffmann's until 0.7 tau and at its goal at tau.
    rec = shapes.lasa('Khamesh', 0)
    skill = learn(rec.positions, t=rec.t, formulation='hoffmann')
    start, goal = rec.positions[0] + [8.0, -5.0], rec.positions[-1]
    traj = skill.generalize(start, goal, method='dmp', margin=1.0)
    k = (len(traj.t) - 1) // 2
    assert np.linalg.norm(traj.x[k] - goal) < 1e-5 * skill.size


def test_online_runs_come_to_rest_at_the_goal_and_say_done():
    for variant in ('ends moving', 'abrupt stop'):
        rec = VARIANTS[variant](shapes.lasa('WShape', 0))
        for formulation in ('ijspeert', 'hoffmann'):
            skill = learn(rec.positions, t=rec.t, formulation=formulation)
            start, goal = starts_around(rec.positions[0], rec.positions[-1])[1], rec.positions[-1]
            offline = skill.generalize(start, goal, margin=1.0, dt=skill.tau / SAMPLES)
            for fast in (True, False):
                run = skill.online(start, goal, fast=fast, dt=skill.tau / SAMPLES)
                _, x, v, _ = run.run(2.0 * skill.tau, fast=fast)
                size = np.max(np.linalg.norm(offline.x - goal, axis=1))
                assert run.done
                assert np.linalg.norm(x[-1] - goal) <= 1e-3 * size
                # The same plan as the offline rollout, sample for sample.
                assert np.allclose(x, offline.x[1:len(x) + 1], atol=1e-9 * size)


def test_with_two_obstacles_the_plan_comes_to_rest_at_its_goal_and_stays():
    rec = shapes.ends_moving(shapes.lasa('GShape', 0))
    skill = learn(rec.positions, t=rec.t)
    start, goal = starts_around(rec.positions[0], rec.positions[-1])[1], rec.positions[-1]
    free = skill.generalize(start, goal)
    size = np.max(np.linalg.norm(free.x - goal, axis=1))
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(free.x, axis=0), axis=1))]
    obstacles = free.x[np.searchsorted(arc, [0.3 * arc[-1], 0.6 * arc[-1]])] + 0.02 * size
    for fast in (True, False):
        traj = skill.generalize(start, goal, obstacles=obstacles, margin=2.0, fast=fast,
                                dt=skill.tau / SAMPLES)
        n_end = int(round((len(traj.t) - 1) * (1.0 + OBSTACLE_MARGIN) / 3.0))  # 1.5 tau
        dist = np.linalg.norm(traj.x - goal, axis=1) / size
        assert dist[n_end] <= AT_2TAU
        assert np.all(dist[n_end:] <= dist[n_end] + 1e-9)    # it stays
        assert np.linalg.norm(traj.v[-1]) * skill.tau / size <= 1e-6


# ---------------------------------------------------------------------------- orientation

def _turned(q, axis, degrees):
    axis = np.asarray(axis, dtype=float)
    return quat.multiply(quat.about_axis(axis / np.linalg.norm(axis), math.radians(degrees)), q)


ORIENTED = [shapes.helix(), shapes.figure_eight_3d()] + [
    shapes.with_turning_tool(shapes.lasa(name, 0)) for name in ('Sine', 'RShape', 'Leaf_1')]


@pytest.mark.parametrize('rec', ORIENTED, ids=[r.name for r in ORIENTED])
@pytest.mark.parametrize('variant', ['as recorded', 'ends moving', 'abrupt stop'])
def test_a_goal_orientation_up_to_a_half_turn_away_is_reached_at_tau_at_rest(rec, variant):
    rec = VARIANTS[variant](rec)
    skill = learn(rec.positions, rec.orientations, t=rec.t)
    starts, goal = starts_around(rec.positions[0], rec.positions[-1])[:3], rec.positions[-1]
    for axis in ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (1.0, 2.0, -2.0)):
        for degrees in (30.0, 90.0, 150.0, 180.0):
            q_goal = _turned(rec.orientations[-1], axis, degrees)
            at_tau = skill.generalize(starts, goal, goal_orientation=q_goal,
                                      dt=skill.tau / SAMPLES)
            angle = np.degrees(quat.angle_between(at_tau.q[:, -1], q_goal[None]))
            assert np.all(angle <= ANGLE_DEG), (axis, degrees, angle)
            later = skill.generalize(starts, goal, goal_orientation=q_goal, margin=1.0,
                                     dt=skill.tau / SAMPLES)
            angles = np.degrees(quat.angle_between(later.q, q_goal[None, None]))
            k = (len(later.t) - 1) // 2
            assert np.all(angles[:, k:] <= ANGLE_DEG)
            assert np.all(np.degrees(np.linalg.norm(later.omega[:, -1], axis=1)) * skill.tau
                          <= 1e-3)
    # Without a goal orientation: the demonstration's last one (turned), reached at tau.
    own = skill.generalize(rec.positions[0], goal, method='dmp')
    assert np.degrees(quat.angle_between(own.q[-1], rec.orientations[-1])) <= 1e-3

"""Orientation: the quaternion DMP, turned with the motion by ET-DMP, and its files (no ROS)."""

import itertools

from etdmp_ros.dmp import (builtin_demo, Demonstration, DemonstrationError, GeneralizationError,
                           learn, load_demo, ORIENTATION_MODES, save_demo)
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.skills.library import (read_mcap_path, recorded_orientations, recorded_path_demo,
                                      SkillLibrary)
import numpy as np
import pytest
from test_skill_library import letter_path, PLANE, TILTED, write_mcap

DEG = np.pi / 180.0
Z = np.array([0.0, 0.0, 1.0])


def min_jerk(n):
    """Return times over 1 s and a minimum-jerk progress from 0 to 1 (rest at both ends)."""
    t = np.linspace(0.0, 1.0, n)
    return t, 10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5


def letter_with_tool(n=200):
    """Make a 2D stroke and a tool that tilts and yaws along it (plane frame, tool z down)."""
    t, s = min_jerk(n)
    x = np.c_[6.0 * np.cos(3.5 * s) + 1.0 - 7.0 * s, 5.0 * np.sin(3.5 * s) + 8.0 * (1.0 - s)]
    down = quat.about_axis([1.0, 0.0, 0.0], np.pi)
    yaw = quat.about_axis(Z, 1.2 * np.sin(2.5 * s))
    tilt = quat.about_axis([0.0, 1.0, 0.0], 0.3 * np.sin(np.pi * s))
    return t, x, quat.multiply(yaw, quat.multiply(tilt, down))


def spiral_with_stirrer(n=300):
    """Make a stirring-like 3D motion with a stirrer whose tilt circles with it."""
    t, s = min_jerk(n)
    r = 0.03 * (1.0 - s) + 0.01
    ang = 6 * np.pi * s
    x = np.c_[r * np.cos(ang) + 0.05 * (1 - s), r * np.sin(ang) - 0.04 * (1 - s),
              0.15 * (1.0 - s)]
    axis = np.c_[-np.sin(ang), np.cos(ang), np.zeros(n)]
    q = quat.multiply(quat.about_axis(axis, 0.3 * (1.0 - s) + 0.1 * np.sin(np.pi * s)),
                      quat.about_axis([1.0, 0.0, 0.0], np.pi))
    return t, x, q


def rotation_error(A, B):
    """Return the angles (rad) between rotation matrices A and B (..., 3, 3), accurate near 0."""
    frobenius = np.linalg.norm(A - B, axis=(-2, -1))
    return 2.0 * np.arcsin(np.minimum(1.0, frobenius / (2.0 * np.sqrt(2.0))))


def lift(R):
    """Return the 3D rotation of a 2D skill's transform: R in the plane, 1 along the normal."""
    out = np.eye(3)
    out[:2, :2] = R
    return out


def numeric_omega(q, t):
    """Angular velocity from finite differences of q: omega = 2 (dq/dt) q^-1 (fixed frame)."""
    return 2.0 * quat.multiply(np.gradient(q, t, axis=0), quat.conjugate(q))[:, :3]


def assert_well_formed(traj):
    """Assert unit quaternions, no sign flips, finite values and a start at rest."""
    q, omega = traj.q, traj.omega
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(omega))
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
    assert np.all(np.sum(q[..., 1:, :] * q[..., :-1, :], axis=-1) > 0.0), 'sign flip'
    np.testing.assert_allclose(omega[..., 0, :], 0.0, atol=1e-12)


@pytest.fixture(scope='module')
def letter():
    t, x, q = letter_with_tool()
    return learn(x, q, t=t)


@pytest.fixture(scope='module')
def spiral():
    t, x, q = spiral_with_stirrer()
    return learn(x, q, t=t)


# ----------------------------------------------------------------------------- quaternion math

def test_quaternion_maps_round_trip():
    rng = np.random.default_rng(1)
    r = rng.normal(size=(200, 3))
    r *= (rng.uniform(0.0, np.pi, 200) / np.linalg.norm(r, axis=1))[:, None]
    r[:3] = [[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0], [0.0, 0.0, np.pi - 1e-12]]
    q = quat.exp_map(r)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(quat.rotation_vector(q)[:-1], r[:-1], atol=1e-12)
    np.testing.assert_allclose(quat.rotation_vector(-q)[:-1], r[:-1], atol=1e-12)
    np.testing.assert_allclose(quat.to_matrix(quat.from_matrix(quat.to_matrix(q))),
                               quat.to_matrix(q), atol=1e-14)
    # A rotation about z by 90 degrees maps x onto y (Hamilton product, ROS order x, y, z, w).
    np.testing.assert_allclose(quat.to_matrix(quat.about_axis(Z, np.pi / 2)) @ [1, 0, 0],
                               [0, 1, 0], atol=1e-15)
    # q1 q2 is "q2, then q1".
    q1, q2 = q[5], q[6]
    np.testing.assert_allclose(quat.to_matrix(quat.multiply(q1, q2)),
                               quat.to_matrix(q1) @ quat.to_matrix(q2), atol=1e-14)


def test_half_turns_and_lifts_are_deterministic():
    half = quat.about_axis([0.0, 1.0, 0.0], np.pi)
    np.testing.assert_allclose(quat.rotation_vector(half), quat.rotation_vector(-half))
    assert np.linalg.norm(quat.rotation_vector(half)) == pytest.approx(np.pi)
    r = np.array([0.0, 0.0, 3.0])
    np.testing.assert_allclose(quat.nearest_lift(r, [0.0, 0.0, 9.0]), [0, 0, 3 + 2 * np.pi])
    np.testing.assert_allclose(quat.nearest_lift(r, [0.0, 0.0, -3.0]), [0, 0, 3 - 2 * np.pi])
    np.testing.assert_allclose(quat.nearest_lift(np.zeros(3), [0.0, 6.0, 0.0]),
                               [0, 2 * np.pi, 0])
    # A rotation about a fixed axis through 3 full turns unwraps to one straight ramp.
    angle = np.linspace(0.0, 6 * np.pi, 400)
    q = quat.continuous(quat.about_axis([0.6, 0.0, 0.8], angle))
    unwrapped = quat.unwrap(quat.rotation_vector(q))
    np.testing.assert_allclose(unwrapped @ [0.6, 0.0, 0.8], angle, atol=1e-9)


def test_left_jacobian_is_the_angular_velocity():
    t = np.linspace(0.0, 1.0, 20001)
    r = np.c_[np.sin(3 * t), 2.0 * t ** 2, np.cos(2 * t) - 1.0] * 1.3
    r_dot = np.gradient(r, t, axis=0, edge_order=2)
    q = quat.exp_map(r)
    omega = quat.left_jacobian(r, r_dot)
    np.testing.assert_allclose(omega[5:-5], numeric_omega(q, t)[5:-5], atol=1e-6)


# ----------------------------------------------------------------------------- learning

def test_position_only_skills_have_no_orientation():
    t, x, _ = letter_with_tool()
    skill = learn(x, t=t)
    assert not skill.has_orientation
    traj = skill.generalize([-5.0, 4.0], [0.0, 0.0])
    assert traj.q is None and traj.omega is None
    with pytest.raises(GeneralizationError, match='learned without orientations'):
        skill.generalize([-5.0, 4.0], [0.0, 0.0], goal_orientation=[0, 0, 0, 1])
    for name in ('G', 'P', 'R', 'W'):
        assert not learn(builtin_demo(name)).has_orientation
    assert ORIENTATION_MODES == ('demo', 'goal', 'tool')


def test_learning_normalises_and_removes_sign_flips(letter):
    t, x, q = letter_with_tool()
    flipped = q * np.where(np.arange(len(q)) % 3 == 0, -2.5, 0.5)[:, None]   # signs, lengths
    skill = learn(x, flipped, t=t)
    assert skill.has_orientation
    # Continuous from the first sample on (here the first one was flipped: all are).
    np.testing.assert_allclose(skill.orientation.demo, -q, atol=1e-15)
    np.testing.assert_allclose(skill.reproduce().q, -letter.reproduce().q, atol=1e-12)


def test_reproduction_follows_the_demonstrated_orientations(letter, spiral):
    for make, skill in ((letter_with_tool, letter), (spiral_with_stirrer, spiral)):
        _, _, q = make()
        rep = skill.reproduce()
        assert_well_formed(rep)
        error = quat.angle_between(rep.q, q)
        assert error.max() < 0.2 * DEG
        assert error[-1] < 0.01 * DEG


@pytest.mark.parametrize('name', ['wipe', 'stir'])
def test_builtin_orientations_are_reproduced(name):
    demo = builtin_demo(name)
    rep = learn(demo).reproduce()
    assert_well_formed(rep)
    error = quat.angle_between(rep.q, demo.orientations)
    assert error.max() < 0.2 * DEG and error[-1] < 0.01 * DEG


@pytest.mark.parametrize('orientations, expected', [
    (np.zeros((200, 3)), 'shape (200, 4)'),
    (np.zeros((199, 4)) + [0, 0, 0, 1], 'shape (200, 4)'),
    (np.where(np.arange(800).reshape(200, 4) == 33, np.nan, 1.0), 'orientations[8]'),
    (np.where(np.arange(200)[:, None] == 17, 0.0, [0.0, 0.0, 0.0, 1.0]), 'orientations[17]'),
    (np.array([['a'] * 4] * 200), 'real numbers'),
])
def test_bad_orientations_are_refused(orientations, expected):
    t, x, _ = letter_with_tool()
    with pytest.raises(DemonstrationError) as err:
        learn(x, orientations, t=t)
    assert expected in str(err.value)


def test_orientations_need_two_or_three_dimensions():
    t, s = min_jerk(50)
    with pytest.raises(DemonstrationError, match='2D .* or 3D'):
        learn(s, np.tile([0.0, 0.0, 0.0, 1.0], (50, 1)), t=t)


# ----------------------------------------------------------------------------- ET-DMP turns it

def quadrant_starts(skill, goal):
    """One start in each quadrant (plus on the axes), 1.3 times as far as the demo's."""
    distance = 1.3 * np.linalg.norm(skill.start - skill.goal)
    angles = np.radians([30, 120, 210, 300, 0, 90, 180, 270])
    return goal + distance * np.c_[np.cos(angles), np.sin(angles)]


def octant_starts(skill, goal):
    """One start in each octant, plus ones anti-parallel and parallel to the demo's."""
    distance = 0.8 * np.linalg.norm(skill.start - skill.goal)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=3))) * [1.0, 0.7, 1.2]
    corners /= np.linalg.norm(corners, axis=1, keepdims=True)
    i_d = (skill.start - skill.goal) / np.linalg.norm(skill.start - skill.goal)
    return goal + distance * np.vstack([corners, -i_d, i_d])


def assert_turned_with_the_motion(skill, traj, start, goal, turn):
    """Assert q = turn R_rep (<= 1e-6 rad) and that the tool sees the reproduction's motion."""
    rep = skill.reproduce()
    expected = turn @ quat.to_matrix(rep.q)
    assert rotation_error(quat.to_matrix(traj.q), expected).max() <= 1e-6
    np.testing.assert_allclose(traj.omega, rep.omega @ turn.T, atol=1e-9)
    # The velocity seen from the tool (its own frame) is the reproduction's, scaled by c.
    c = np.linalg.norm(np.subtract(start, goal)) / np.linalg.norm(skill.start - skill.goal)
    d = skill.dim

    def seen(q, v):
        v3 = v if d == 3 else np.c_[v, np.zeros(len(v))]
        return np.einsum('nji,nj->ni', quat.to_matrix(q), v3)
    np.testing.assert_allclose(seen(traj.q, traj.v), c * seen(rep.q, rep.v),
                               atol=1e-9 * c * np.abs(rep.v).max())


@pytest.mark.parametrize('skill_name', ['letter', 'wipe'])
def test_2d_orientation_is_turned_about_the_plane_normal(skill_name, letter):
    skill = letter if skill_name == 'letter' else learn(builtin_demo('wipe'))
    goal = np.array([2.0, -3.0])
    for start in quadrant_starts(skill, goal):
        traj = skill.generalize(start, goal)
        turn = lift(traj.rotation.T)
        assert_turned_with_the_motion(skill, traj, start, goal, turn)
        assert_well_formed(traj)
        # The turn is about the task plane's normal (z of the plane frame).
        np.testing.assert_allclose(turn @ Z, Z, atol=1e-15)


@pytest.mark.parametrize('skill_name', ['spiral', 'stir'])
def test_3d_orientation_is_turned_by_the_transform(skill_name, spiral):
    skill = spiral if skill_name == 'spiral' else learn(builtin_demo('stir'))
    goal = np.array([0.6, -0.2, 0.3])
    for start in octant_starts(skill, goal):
        traj = skill.generalize(start, goal, mode=1)
        assert np.linalg.det(traj.rotation) == pytest.approx(1.0)
        assert_turned_with_the_motion(skill, traj, start, goal, traj.rotation.T)
        assert_well_formed(traj)


def test_3d_mode_2_turns_the_orientation_about_the_independent_axis_only(spiral):
    goal = np.array([0.6, -0.2, 0.3])
    i_d = spiral.start - spiral.goal
    for sign_z in (1.0, -1.0):       # -1: the movement is mirrored along z, the tool is not
        start = goal + np.array([-i_d[1], i_d[0], sign_z * i_d[2]])
        traj = spiral.generalize(start, goal, mode=2)
        assert traj.rotation[2, 2] == sign_z
        turn = np.eye(3)
        turn[:2, :2] = traj.rotation[:2, :2].T
        rep = spiral.reproduce()
        assert rotation_error(quat.to_matrix(traj.q),
                              turn @ quat.to_matrix(rep.q)).max() <= 1e-6
        assert_well_formed(traj)


def test_plain_dmp_keeps_the_demonstrated_orientations(letter):
    traj = letter.generalize([-6.0, 2.0], [1.0, 1.0], method='dmp')
    assert np.allclose(traj.rotation, np.eye(2))
    np.testing.assert_allclose(traj.q, letter.reproduce().q, atol=1e-15)


def test_orientation_is_sampled_with_the_positions(spiral):
    traj = spiral.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], dt=0.002, tau=2.0)
    assert traj.q.shape == (len(traj.t), 4) and traj.omega.shape == (len(traj.t), 3)
    slow = spiral.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], dt=0.004, tau=4.0)
    # Twice the duration: the same orientations at the same phase, half the angular speed.
    np.testing.assert_allclose(slow.q, traj.q, atol=1e-9)
    np.testing.assert_allclose(slow.omega, traj.omega / 2, atol=1e-9)


def test_angular_velocity_is_continuous_and_matches_the_quaternions(spiral, letter):
    goal_q = quat.about_axis([0.0, 0.6, 0.8], 2.0)
    for traj in (spiral.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], dt=5e-4),
                 spiral.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], dt=5e-4,
                                   goal_orientation=goal_q),
                 letter.generalize([-6.0, -2.0], [1.0, 1.0], dt=5e-4)):
        omega = traj.omega
        peak = np.linalg.norm(omega, axis=1).max()
        # omega is the derivative of q (finite differences agree to their O(dt^2) error).
        np.testing.assert_allclose(omega[2:-2], numeric_omega(traj.q, traj.t)[2:-2],
                                   atol=2e-4 * peak)
        # Continuous: the largest change from one sample to the next halves with the period.
        jump = np.linalg.norm(np.diff(omega, axis=0), axis=1).max()
        coarse = np.linalg.norm(np.diff(omega[::2], axis=0), axis=1).max()
        assert jump < 0.02 * peak and 1.8 < coarse / jump < 2.2


# ----------------------------------------------------------------------------- goal orientation

GOALS = [quat.about_axis([0.0, 0.0, 1.0], 0.5), quat.about_axis([1.0, 0.0, 0.0], 2.5),
         quat.about_axis([0.0, 0.6, 0.8], 3.0), quat.about_axis([0.8, -0.6, 0.0], np.pi - 1e-6)]


@pytest.mark.parametrize('k', range(len(GOALS)))
def test_goal_orientation_is_reached(spiral, letter, k):
    goal_q = GOALS[k]
    for skill, start, goal in ((spiral, [0.3, 0.1, 0.2], [0.0, 0.0, 0.0]),
                               (letter, [-6.0, -2.0], [1.0, 1.0])):
        traj = skill.generalize(start, goal, goal_orientation=goal_q)
        assert_well_formed(traj)
        assert quat.angle_between(traj.q[-1], goal_q) <= 0.1 * DEG
        # It starts where the movement without a goal orientation starts: the demo's start
        # orientation turned with the motion.
        free = skill.generalize(start, goal)
        assert quat.angle_between(traj.q[0], free.q[0]) <= 1e-9
        assert np.linalg.norm(traj.omega[-1]) < 1e-2


def test_goal_orientation_equal_to_the_turned_demo_goal_changes_nothing(spiral):
    start, goal = [0.3, -0.1, 0.2], [0.1, 0.0, 0.0]
    free = spiral.generalize(start, goal)
    turned_goal = quat.multiply(quat.from_matrix(free.rotation.T), spiral.orientation.goal)
    for sign in (1.0, -1.0):         # either quaternion of the same rotation (antipodal)
        same = spiral.generalize(start, goal, goal_orientation=sign * turned_goal)
        assert quat.angle_between(same.q, free.q).max() <= 1e-9
        np.testing.assert_allclose(same.omega, free.omega, atol=1e-9)
        assert_well_formed(same)


def test_goal_a_half_turn_away_and_constant_demos_are_defined():
    t, x, _ = spiral_with_stirrer()
    still = np.tile(quat.about_axis([1.0, 0.0, 0.0], np.pi), (len(t), 1))
    skill = learn(x, still, t=t)
    traj = skill.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0])
    assert_well_formed(traj)
    np.testing.assert_allclose(quat.angle_between(traj.q, traj.q[0]), 0.0, atol=1e-12)
    np.testing.assert_allclose(traj.omega, 0.0, atol=1e-12)
    assert rotation_error(quat.to_matrix(traj.q[0]),
                          traj.rotation.T @ quat.to_matrix(still[0])) <= 1e-9
    for goal_q in (quat.multiply(quat.about_axis(Z, np.pi), traj.q[-1]),   # exactly a half turn
                   -traj.q[-1], [0.0, 0.0, 0.0, -3.0]):
        other = skill.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], goal_orientation=goal_q)
        assert_well_formed(other)
        assert quat.angle_between(other.q[-1], goal_q / np.linalg.norm(goal_q)) <= 0.1 * DEG
    # Deterministic: the same request gives the same path, whatever the goal's sign.
    half = quat.multiply(quat.about_axis(Z, np.pi), traj.q[-1])
    a = skill.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], goal_orientation=half)
    b = skill.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], goal_orientation=-half)
    assert quat.angle_between(a.q, b.q).max() <= 1e-12


@pytest.mark.parametrize('goal_orientation, expected', [
    ([0.0, 0.0, 0.0, 0.0], 'zero quaternion'),
    ([0.0, 0.0, np.nan, 1.0], 'NaN or inf'),
    ([0.0, 0.0, 1.0], 'shape (4,) or (1, 4)'),
    ('up', 'numeric'),
])
def test_bad_goal_orientations_are_refused(spiral, goal_orientation, expected):
    with pytest.raises(GeneralizationError) as err:
        spiral.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], goal_orientation=goal_orientation)
    assert expected in str(err.value)


def test_batches_with_orientation_equal_single_requests(spiral, letter):
    rng = np.random.default_rng(4)
    starts = rng.normal(scale=0.3, size=(6, 3))
    goal = np.array([0.05, 0.0, -0.02])
    goals_q = quat.exp_map(rng.normal(size=(6, 3)))
    for goal_orientation in (None, goals_q, goals_q[0]):
        batch = spiral.generalize(starts, goal, goal_orientation=goal_orientation)
        assert batch.q.shape == (6, len(batch.t), 4) and batch.omega.shape[:2] == (6, len(batch.t))
        assert_well_formed(batch)
        for b in range(6):
            g = None if goal_orientation is None else (
                goal_orientation[b] if goal_orientation.ndim == 2 else goal_orientation)
            single = spiral.generalize(starts[b], goal, goal_orientation=g)
            np.testing.assert_allclose(batch.q[b], single.q, atol=1e-12)
            np.testing.assert_allclose(batch.omega[b], single.omega, atol=1e-12)
    with pytest.raises(GeneralizationError, match=r'\(6, 4\)'):
        spiral.generalize(starts, goal, goal_orientation=goals_q[:4])
    planar = letter.generalize(rng.normal(scale=8.0, size=(5, 2)), [0.0, 0.0], method='dmp')
    assert planar.q.shape == (5, len(planar.t), 4)


def test_numba_and_numpy_rollouts_agree(spiral):
    goal_q = GOALS[1]
    fast = spiral.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], goal_orientation=goal_q)
    slow = spiral.generalize([0.3, 0.1, 0.2], [0.0, 0.0, 0.0], goal_orientation=goal_q,
                             fast=False)
    np.testing.assert_allclose(fast.q, slow.q, atol=1e-12)
    np.testing.assert_allclose(fast.omega, slow.omega, atol=1e-10)


# ----------------------------------------------------------------------------- built-in demos

def test_wipe_keeps_the_sponge_along_the_stroke():
    demo = builtin_demo('wipe')
    v = np.gradient(demo.positions, demo.t, axis=0)
    speed = np.linalg.norm(v, axis=1)
    long_side = quat.to_matrix(demo.orientations)[:, :2, 1]     # the tool's y axis, in plane
    np.testing.assert_allclose(quat.to_matrix(demo.orientations)[:, :, 2] @ Z, -1.0, atol=1e-8)
    fast = speed > 0.97 * speed.max()            # mid-stroke, away from the turnarounds
    direction = v[fast] / speed[fast, None]
    sine = np.abs(long_side[fast, 0] * direction[:, 1] - long_side[fast, 1] * direction[:, 0])
    assert np.count_nonzero(fast) > 100 and sine.max() < np.sin(4 * DEG)
    # The sponge never turns round at a turnaround: at most the stroke's change of angle.
    assert np.degrees(quat.angle_between(demo.orientations, demo.orientations[0]).max()) < 45


def test_stir_tilts_and_circles_with_the_spiral():
    demo = builtin_demo('stir')
    x = demo.positions
    shaft = quat.to_matrix(demo.orientations)[:, :, 2]          # tool z: down the stirrer
    tilt = np.degrees(np.arccos(np.clip(-shaft[:, 2], -1.0, 1.0)))
    stirring = (x[:, 2] < -0.03) & (np.hypot(x[:, 0], x[:, 1]) > 0.02)
    assert 8.0 < tilt[stirring].min() and tilt[stirring].max() < 13.0
    assert tilt[-1] < 0.01 and 30.0 < tilt[0] < 40.0
    # The tilt points the way the tip is off the axis, and so circles with it.
    cosine = np.sum(shaft[stirring, :2] * x[stirring, :2], axis=1) / (
        np.linalg.norm(shaft[stirring, :2], axis=1) * np.hypot(x[stirring, 0], x[stirring, 1]))
    assert cosine.min() > 0.999
    np.testing.assert_allclose(demo.orientations[-1], [-np.sqrt(0.5), np.sqrt(0.5), 0, 0],
                               atol=1e-8)


# ----------------------------------------------------------------------------- files

def demo_with_orientation(n=40, dim=3):
    rng = np.random.default_rng(dim)
    t = np.cumsum(rng.uniform(0.01, 0.1, n))
    return Demonstration('orig', rng.normal(size=(n, dim)), t,
                         quat.exp_map(rng.normal(size=(n, 3))))


@pytest.mark.parametrize('suffix', ['.csv', '.npz'])
@pytest.mark.parametrize('dim', [2, 3])
def test_orientations_round_trip_through_files(tmp_path, suffix, dim):
    demo = demo_with_orientation(dim=dim)
    save_demo(tmp_path / f'd{suffix}', demo)
    back = load_demo(tmp_path / f'd{suffix}')
    assert back.has_orientation and 'with orientations' in repr(back)
    np.testing.assert_array_equal(back.positions, demo.positions)
    np.testing.assert_allclose(back.orientations, demo.orientations, atol=1e-15)
    if suffix == '.csv':
        header = (tmp_path / 'd.csv').read_text().splitlines()[0]
        assert header == 't,' + ','.join('xyz'[:dim]) + ',qx,qy,qz,qw'
    save_demo(tmp_path / 'd.npy', demo)                     # positions only, as documented
    assert not load_demo(tmp_path / 'd.npy').has_orientation


def test_csv_orientation_columns_are_found_by_name_and_normalised(tmp_path):
    rows = ''.join(f'{k * 0.1},{k},{k * k},0,0,{2 * np.sin(k / 20)},{2 * np.cos(k / 20)}\n'
                   for k in range(12))
    (tmp_path / 'a.csv').write_text('t,x,y,QX,qy,qz,qw\n' + rows)
    demo = load_demo(tmp_path / 'a.csv')
    assert demo.dim == 2 and demo.has_orientation
    np.testing.assert_allclose(demo.orientations[:, 2], np.sin(np.arange(12) / 20), atol=1e-15)
    reordered = ''.join(f'{2 * np.cos(k / 20)},{k * 0.1},0,{k},0,{2 * np.sin(k / 20)},{k * k}\n'
                        for k in range(12))
    (tmp_path / 'b.csv').write_text('qw,t,qx,x,qy,qz,y\n' + reordered)
    np.testing.assert_allclose(load_demo(tmp_path / 'b.csv').orientations, demo.orientations)
    # Files without the columns are what they always were.
    (tmp_path / 'c.csv').write_text('t,x,y\n' + ''.join(f'{k},{k},{-k}\n' for k in range(12)))
    assert not load_demo(tmp_path / 'c.csv').has_orientation


def _rows(bad_line=None, value=None):
    out = []
    for k in range(12):
        q = ['0', '0', '0', '1']
        if k + 2 == bad_line:
            q = value
        out.append(','.join([str(k * 0.1), str(k), str(-k)] + q))
    return '\n'.join(out) + '\n'


@pytest.mark.parametrize('header, rows, expected', [
    ('t,x,y,qx,qy,qz,qw', _rows(7, ['0', '0', '0', '0']), ['line 7', 'zero quaternion']),
    ('t,x,y,qx,qy,qz,qw', _rows(5, ['0', 'nan', '0', '1']), ['line 5', 'finite']),
    ('t,x,y,qx,qy,qz,qw', _rows(9, ['0', 'inf', '0', '1']), ['line 9', 'finite']),
    ('t,x,y,qx,qy,qz,qw', _rows(4, ['0', 'x', '0', '1']), ['line 4', "column 'qy'"]),
    ('t,x,y,qx,qy,qz,w', _rows(), ['qx, qy, qz', 'all of qx, qy, qz, qw']),
])
def test_bad_csv_orientations_are_refused_with_the_line(tmp_path, header, rows, expected):
    path = tmp_path / 'bad.csv'
    path.write_text(header + '\n' + rows)
    with pytest.raises(DemonstrationError) as err:
        load_demo(path)
    for part in [str(path)] + expected:
        assert part in str(err.value)


def test_bad_npz_quaternions_are_refused(tmp_path):
    positions = np.c_[np.arange(12.0), np.arange(12.0) ** 2]
    np.savez(tmp_path / 'a.npz', positions=positions, quaternions=np.zeros((12, 4)))
    with pytest.raises(DemonstrationError, match=r'quaternions\[0\].*zero quaternion'):
        load_demo(tmp_path / 'a.npz')
    np.savez(tmp_path / 'b.npz', positions=positions, quaternions=np.ones((12, 3)))
    with pytest.raises(DemonstrationError, match=r'shape \(12, 4\)'):
        load_demo(tmp_path / 'b.npz')


def _stamped(p, q, stamp_ns):
    return {'header': {'stamp': {'sec': stamp_ns // 10**9, 'nanosec': stamp_ns % 10**9},
                       'frame_id': 'base_link'},
            'pose': {'position': dict(zip('xyz', (float(c) for c in p))),
                     'orientation': dict(zip('xyzw', (float(c) for c in q)))}}


def test_mcap_pose_and_path_orientations_are_read(tmp_path):
    path = letter_path(40)
    q = quat.multiply(quat.about_axis(Z, np.linspace(0.0, 0.8, 40)),
                      quat.about_axis([1.0, 0.0, 0.0], np.pi))
    stamps = (10**9 * np.linspace(10.0, 11.95, 40)).astype(np.int64)
    poses = [_stamped(p, r, int(s)) for p, r, s in zip(path, q, stamps)]
    path_msg = {'header': {'stamp': {'sec': 1, 'nanosec': 0}, 'frame_id': 'base_link'},
                'poses': [_stamped(p, -2.0 * r, int(s)) for p, r, s in zip(path, q, stamps)]}
    write_mcap(tmp_path / 'rec.mcap', {'/tool_pose': ('pose', [(int(s), m) for s, m in
                                                               zip(stamps, poses)]),
                                       '/plan': ('path', [(1, path_msg)])})
    for topic in ('/tool_pose', '/plan'):
        recorded = read_mcap_path(tmp_path / 'rec.mcap', topic)
        assert quat.angle_between(recorded.orientations, q).max() < 1e-12
    library = SkillLibrary()
    added, errors = library.add_files([tmp_path / 'rec.mcap'], PLANE, mcap_topic='/tool_pose')
    assert errors == [] and library.get('rec').demo.has_orientation
    assert library.skill('rec').has_orientation
    # Bad orientations are reported with the pose.
    poses[7] = _stamped(path[7], [0.0, 0.0, 0.0, 0.0], int(stamps[7]))
    write_mcap(tmp_path / 'bad.mcap', {'/tool_pose': ('pose', [(int(s), m) for s, m in
                                                               zip(stamps, poses)])})
    with pytest.raises(DemonstrationError, match='pose 7.*zero quaternion'):
        read_mcap_path(tmp_path / 'bad.mcap')


def test_unset_recorded_orientations_mean_none():
    assert recorded_orientations(np.zeros((20, 4))) is None
    assert recorded_orientations(np.tile([0.0, 0.0, 0.0, 1.0], (20, 1))) is None
    q = recorded_orientations(np.tile([0.0, 0.0, 0.0, 2.0], (20, 1)))
    np.testing.assert_allclose(q, np.tile([0.0, 0.0, 0.0, 1.0], (20, 1)))
    with pytest.raises(DemonstrationError, match='pose 3'):
        recorded_orientations(np.r_[np.tile([0.0, 0.0, 1.0, 0.0], (3, 1)), np.zeros((5, 4))])


def test_recorded_2d_orientations_are_kept_in_the_plane_frame():
    on_plane = TILTED.from_plane(np.column_stack([np.linspace(0, 9, 30),
                                                  np.sin(np.linspace(0, 3, 30))]))
    in_plane = quat.multiply(quat.about_axis(Z, np.linspace(0.0, 1.0, 30)),
                             quat.about_axis([1.0, 0.0, 0.0], np.pi))
    in_base = TILTED.orientation_from_plane(in_plane)
    # The tool's z axis points into the tilted plane in base_link.
    np.testing.assert_allclose(quat.to_matrix(in_base)[:, :, 2] @ TILTED.normal, -1.0,
                               atol=1e-12)
    demo = recorded_path_demo('t', on_plane, None, TILTED, orientations=in_base)
    assert demo.dim == 2
    assert quat.angle_between(demo.orientations, in_plane).max() < 1e-12
    renamed = SkillLibrary().add('other', demo, 'taught').demo
    np.testing.assert_array_equal(renamed.orientations, demo.orientations)
    np.testing.assert_allclose(TILTED.rotation.T @ TILTED.rotation, np.eye(3), atol=1e-15)

"""Learning and generalizing skills: DMP vs ET-DMP, formulations, batches, bad input."""

from etdmp_ros import limits
from etdmp_ros.dmp import (builtin_demo, DemonstrationError, GeneralizationError, learn, nrmse,
                           OBSTACLE_MARGIN, ObstacleGains)
import numpy as np
import pytest


def cross2(a, b):
    """Return the z component of the cross product of two 2D vectors."""
    return a[0] * b[1] - a[1] * b[0]


def letter_like(n=200):
    """Make a smooth 2D stroke whose start and goal differ in both dimensions (no ~0 offsets)."""
    t = np.linspace(0.0, 1.0, n)
    s = 10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5          # minimum-jerk: starts and ends at rest
    x = 6.0 * np.cos(3.5 * s) + 1.0 - 7.0 * s
    y = 5.0 * np.sin(3.5 * s) + 8.0 * (1.0 - s)
    return np.c_[x, y]


def spiral_3d(n=300):
    """Make a stirring-like 3D motion that circles while descending to a goal on the axis."""
    t = np.linspace(0.0, 1.0, n)
    s = 10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5
    r = 0.03 * (1.0 - s) + 0.01
    ang = 6 * np.pi * s
    return np.c_[r * np.cos(ang) + 0.05 * (1 - s), r * np.sin(ang) - 0.04 * (1 - s),
                 0.15 * (1.0 - s)]


def similarity_residual(skill, traj, start, goal):
    """Largest distance between an ET-DMP path and the demo reproduction rotated and scaled."""
    rep = skill.reproduce(dt=traj.t[1] - traj.t[0])
    i_d = skill.start - skill.goal
    c = np.linalg.norm(np.subtract(start, goal)) / np.linalg.norm(i_d)
    expected = c * (rep.x - skill.goal) @ traj.rotation + goal
    return np.max(np.linalg.norm(expected - traj.x, axis=-1)) / (c * skill.size)


def test_reproduction_follows_the_demonstration():
    demo = letter_like()
    skill = learn(demo, dt=1 / 199)
    rep = skill.reproduce()
    assert rep.x.shape == demo.shape
    assert np.max(np.linalg.norm(rep.x - demo, axis=1)) < 0.01 * skill.size
    assert nrmse(rep.x, demo) < 0.005
    np.testing.assert_allclose(rep.x[0], demo[0])
    assert np.linalg.norm(rep.x[-1] - demo[-1]) < 1e-3 * skill.size


@pytest.mark.parametrize('angle', np.linspace(-np.pi, np.pi, 9))
def test_2d_etdmp_is_the_reproduction_rotated_and_scaled(angle):
    skill = learn(letter_like(), dt=1 / 199)
    goal = np.array([3.0, -2.0])
    direction = np.array([np.cos(angle), np.sin(angle)])
    i_c = 1.7 * np.linalg.norm(skill.start - skill.goal) * direction
    traj = skill.generalize(goal + i_c, goal, method='etdmp')
    assert similarity_residual(skill, traj, goal + i_c, goal) < 1e-9
    np.testing.assert_allclose(traj.x[0], goal + i_c, atol=1e-12)
    # The rotation is proper and turns I_C onto the direction of I_D (signed angle:
    # docs/design.md, corrections to the paper).
    R = traj.rotation
    assert np.linalg.det(R) == pytest.approx(1.0)
    i_d = skill.start - skill.goal
    turned = R @ i_c
    assert cross2(turned, i_d) == pytest.approx(0.0, abs=1e-9 * np.linalg.norm(i_c))
    assert turned @ i_d > 0.0
    # The 2D rule is the planar rotation by theta = atan2(I_C x I_D, I_C . I_D) (Eq. 8, 10).
    theta = np.arctan2(cross2(i_c, i_d), i_c @ i_d)
    np.testing.assert_allclose(R, [[np.cos(theta), -np.sin(theta)],
                                   [np.sin(theta), np.cos(theta)]], atol=1e-12)


def test_2d_generalization_is_equivariant():
    skill = learn(letter_like(), dt=1 / 199)
    start, goal = np.array([-4.0, 6.0]), np.array([1.0, 1.0])
    base = skill.generalize(start, goal)
    shift = np.array([10.0, -3.0])
    np.testing.assert_allclose(skill.generalize(start + shift, goal + shift).x, base.x + shift,
                               atol=1e-9)
    q = np.array([[np.cos(0.7), -np.sin(0.7)], [np.sin(0.7), np.cos(0.7)]])
    rotated = skill.generalize(q @ (start - goal) + goal, goal)
    np.testing.assert_allclose(rotated.x, (base.x - goal) @ q.T + goal, atol=1e-9)
    scaled = skill.generalize(2.5 * (start - goal) + goal, goal)
    np.testing.assert_allclose(scaled.x, 2.5 * (base.x - goal) + goal, atol=1e-9)


def test_plain_dmp_loses_the_shape_in_another_quadrant():
    demo = letter_like()
    skill = learn(demo, dt=1 / 199)
    goal = skill.goal
    other = goal - (skill.start - skill.goal) * np.array([1.0, -1.0])   # mirrored quadrant
    et = skill.generalize(other, goal, method='etdmp')
    dmp = skill.generalize(other, goal, method='dmp')
    assert nrmse(et.x, demo) < 0.005
    assert nrmse(dmp.x, demo) > 10 * nrmse(et.x, demo)
    np.testing.assert_allclose(dmp.rotation, np.eye(2))
    for traj in (et, dmp):
        assert np.linalg.norm(traj.x[-1] - goal) < 2e-3 * skill.size


def test_1d_reflection_about_the_goal():
    t = np.linspace(0.0, 1.0, 150)
    demo = 2.0 + 3.0 * np.cos(np.pi * (10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5)) + np.sin(7 * t)
    skill = learn(demo, dt=1 / 149)
    goal = 0.5
    i_d = skill.start[0] - skill.goal[0]
    for start in (goal + 2 * i_d, goal - 2 * i_d):
        traj = skill.generalize([start], [goal])
        assert traj.rotation[0, 0] == np.sign(i_d) * np.sign(start - goal)
        assert similarity_residual(skill, traj, [start], [goal]) < 1e-9
        assert traj.x[0, 0] == pytest.approx(start)
    mirrored = skill.generalize([goal - 2 * i_d], [goal]).x
    same_side = skill.generalize([goal + 2 * i_d], [goal]).x
    np.testing.assert_allclose(mirrored - goal, -(same_side - goal), atol=1e-9)


@pytest.mark.parametrize('seed', range(5))
def test_3d_mode1_rodrigues_similarity(seed):
    rng = np.random.default_rng(seed)
    skill = learn(spiral_3d(), dt=0.01)
    goal = rng.normal(size=3)
    i_c = rng.normal(size=3) * 0.2
    traj = skill.generalize(goal + i_c, goal, mode=1)
    assert similarity_residual(skill, traj, goal + i_c, goal) < 1e-9
    R = traj.rotation
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    i_d = skill.start - skill.goal
    # Rodrigues (Eq. 9) about k = I_C x I_D by the angle between them.
    k = np.cross(i_c, i_d)
    k /= np.linalg.norm(k)
    theta = np.arccos(i_c @ i_d / np.linalg.norm(i_c) / np.linalg.norm(i_d))
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    np.testing.assert_allclose(R, np.eye(3) + np.sin(theta) * kx
                               + (1 - np.cos(theta)) * kx @ kx, atol=1e-12)


def test_3d_antiparallel_start_has_a_defined_rotation():
    skill = learn(spiral_3d(), dt=0.01)
    goal = np.zeros(3)
    i_d = skill.start - skill.goal
    traj = skill.generalize(goal - 0.5 * i_d, goal, mode=1)
    assert np.all(np.isfinite(traj.x))
    R = traj.rotation
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(R @ (-i_d), i_d, atol=1e-12)
    # The documented choice: pi about an axis perpendicular to I_D and to the coordinate axis
    # least aligned with I_D.
    least = np.zeros(3)
    least[np.argmin(np.abs(i_d))] = 1.0
    axis = np.cross(i_d, least)
    np.testing.assert_allclose(R @ axis, axis, atol=1e-12)
    assert similarity_residual(skill, traj, goal - 0.5 * i_d, goal) < 1e-9
    again = skill.generalize(goal - 0.5 * i_d, goal, mode=1)
    np.testing.assert_array_equal(again.x, traj.x)


def test_3d_mode2_keeps_the_independent_axis():
    skill = learn(spiral_3d(), dt=0.01)
    goal = np.array([0.5, 0.1, 0.2])
    i_d = skill.start - skill.goal
    for sz in (1.0, -1.0):
        i_c = np.array([-0.08, 0.06, sz * 0.3])
        traj = skill.generalize(goal + i_c, goal, mode=2, independent_axis=2)
        R = traj.rotation
        assert R[2, 2] == np.sign(i_d[2]) * np.sign(i_c[2])
        np.testing.assert_allclose(R[2, :2], 0.0)
        np.testing.assert_allclose(R[:2, 2], 0.0)
        turned = R[:2, :2] @ i_c[:2]
        assert cross2(turned, i_d[:2]) == pytest.approx(0.0, abs=1e-12)
        assert turned @ i_d[:2] > 0
        assert np.all(np.isfinite(traj.x))
        np.testing.assert_allclose(traj.x[0], goal + i_c, atol=1e-12)
        # z follows the 1D rule with its own scale: the height profile is the demo's, scaled.
        rep = skill.reproduce(dt=0.01)
        cz = abs(i_c[2]) / abs(i_d[2])
        np.testing.assert_allclose(traj.x[:, 2] - goal[2],
                                   R[2, 2] * cz * (rep.x[:, 2] - skill.goal[2]), atol=1e-9)
        assert np.linalg.norm(traj.x[-1] - goal) < 5e-3 * np.linalg.norm(i_c)


def test_other_independent_axis():
    skill = learn(spiral_3d(), dt=0.01)
    traj = skill.generalize([0.1, -0.2, 0.05], [0.0, 0.0, 0.0], mode=2, independent_axis=0)
    assert abs(traj.rotation[0, 0]) == 1.0
    np.testing.assert_allclose(traj.rotation[0, 1:], 0.0)


def closed_o(n=200):
    """Make a closed letter O: a full turn, ending just inside its start (same x)."""
    t = np.linspace(0.0, 1.0, n)
    s = 10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5
    ang = np.pi / 2 + 2 * np.pi * s
    r = 1.0 - 0.3 * s
    return np.c_[r * np.cos(ang), r * np.sin(ang)]


def letter_b(n=300):
    """Make a B as one stroke: up the spine, two bowls, ending next to where it started."""
    pts = [(0, 0), (0, 1), (0, 2), (0.8, 1.9), (0.8, 1.1), (0, 1), (1.0, 0.8), (0.9, 0.1),
           (0.0, 0.1)]
    pts = np.array(pts, dtype=float)
    seg = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
    t = np.linspace(0.0, 1.0, n)
    s = (10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5) * seg[-1]
    raw = np.c_[np.interp(s, seg, pts[:, 0]), np.interp(s, seg, pts[:, 1])]
    kernel = np.exp(-0.5 * (np.arange(-15, 16) / 5.0) ** 2)
    kernel /= kernel.sum()
    padded = np.pad(raw, ((15, 15), (0, 0)), mode='edge')
    return np.c_[np.convolve(padded[:, 0], kernel, 'valid'),
                 np.convolve(padded[:, 1], kernel, 'valid')]


def vertical_stroke(n=150):
    """Make a vertical stroke with a slight wiggle: start and goal share x exactly."""
    t = np.linspace(0.0, 1.0, n)
    s = 10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5
    return np.c_[0.15 * np.sin(2 * np.pi * s), 1.0 - s]


@pytest.mark.parametrize('make', [closed_o, letter_b, vertical_stroke])
def test_demos_with_coinciding_dimension(make):
    demo = make()
    skill = learn(demo)
    assert np.min(np.abs(skill.goal - skill.start)) < 1e-3 * skill.size
    # ET-DMP: same quality as any other demonstration, from every quadrant.
    rep_quality = nrmse(skill.generalize(skill.start, skill.goal, method='etdmp').x, demo)
    assert rep_quality < 0.005
    goal = np.array([2.0, -1.0])
    for angle in np.linspace(0.0, 2 * np.pi, 8, endpoint=False):
        start = goal + 3.0 * np.array([np.cos(angle), np.sin(angle)])
        traj = skill.generalize(start, goal, method='etdmp')
        assert np.all(np.isfinite(traj.x))
        assert nrmse(traj.x, demo) == pytest.approx(rep_quality, abs=1e-6)
        assert np.linalg.norm(traj.x[-1] - goal) < 5e-3 * 3.0
    # Plain Ijspeert DMP: a clear error, never NaN.
    with pytest.raises(GeneralizationError, match='coincide'):
        skill.generalize(goal + [3.0, 1.0], goal, method='dmp')
    # The Hoffmann formulation is well posed there.
    hoff = learn(demo, formulation='hoffmann')
    traj = hoff.generalize(goal + [3.0, 1.0], goal, method='dmp')
    assert np.all(np.isfinite(traj.x))
    assert nrmse(hoff.reproduce().x, demo) < 0.01


def test_hoffmann_formulation():
    demo = letter_like()
    skill = learn(demo, dt=1 / 199, formulation='hoffmann')
    assert nrmse(skill.reproduce().x, demo) < 0.005
    goal = np.array([0.0, 0.0])
    start = goal - (skill.start - skill.goal)
    et = skill.generalize(start, goal, method='etdmp')
    dmp = skill.generalize(start, goal, method='dmp')
    assert np.linalg.norm(et.x[-1] - goal) < 2e-3 * skill.size
    assert nrmse(et.x, demo) < nrmse(dmp.x, demo)


def test_batch_equals_single_rollouts():
    skill = learn(letter_like(), dt=1 / 199)
    rng = np.random.default_rng(3)
    starts = rng.uniform(-10, 10, (7, 2))
    goals = rng.uniform(-1, 1, (7, 2))
    obstacles = [[1.0, 2.0], [-2.0, 0.5]]
    for method in ('etdmp', 'dmp'):
        batch = skill.generalize(starts, goals, obstacles=obstacles, method=method)
        assert batch.x.shape == (7, len(batch.t), 2)
        for b in range(7):
            one = skill.generalize(starts[b], goals[b], obstacles=obstacles, method=method)
            np.testing.assert_allclose(batch.x[b], one.x, atol=1e-12)
            np.testing.assert_allclose(batch.a[b], one.a, atol=1e-9)


@pytest.mark.parametrize('dim', [2, 3])
def test_fast_path_agrees_with_reference(dim):
    demo = letter_like() if dim == 2 else spiral_3d()
    skill = learn(demo, dt=0.005)
    rng = np.random.default_rng(dim)
    starts = skill.goal + rng.normal(size=(5, dim)) * skill.size
    plain = skill.generalize(starts, skill.goal)
    obstacles = plain.x[0, [40, 90]]
    for method in ('etdmp', 'dmp'):
        fast = skill.generalize(starts, skill.goal, obstacles=obstacles, method=method)
        ref = skill.generalize(starts, skill.goal, obstacles=obstacles, method=method, fast=False)
        for a, b in ((fast.x, ref.x), (fast.v, ref.v), (fast.a, ref.a)):
            scale = np.abs(b).max()
            np.testing.assert_allclose(a, b, atol=1e-9 * scale)


def test_derivatives_are_consistent():
    skill = learn(letter_like(), dt=1 / 199)
    traj = skill.generalize([5.0, 5.0], [0.0, 0.0], dt=0.001)
    dxdt = np.gradient(traj.x, traj.t, axis=0)
    dvdt = np.gradient(traj.v, traj.t, axis=0)
    assert np.max(np.abs(dxdt - traj.v)[2:-2]) < 1e-3 * np.abs(traj.v).max()
    assert np.max(np.abs(dvdt - traj.a)[2:-2]) < 5e-3 * np.abs(traj.a).max()
    np.testing.assert_allclose(traj.v[0], 0.0)


def test_non_uniform_timestamps():
    demo = letter_like(400)
    t_uniform = np.linspace(0.0, 1.0, 400)
    rng = np.random.default_rng(0)
    t_jittered = np.sort(np.r_[0.0, rng.uniform(0.0, 1.0, 398), 1.0])
    jittered = np.c_[np.interp(t_jittered, t_uniform, demo[:, 0]),
                     np.interp(t_jittered, t_uniform, demo[:, 1])]
    skill = learn(jittered, t=t_jittered + 5.0)     # offsets in time are irrelevant
    assert skill.tau == pytest.approx(1.0)
    rep = skill.generalize(skill.start, skill.goal, method='dmp', dt=1 / 399)
    assert nrmse(rep.x, demo) < 0.01


def test_duration_output_period_and_margin():
    skill = learn(letter_like(), dt=1 / 199)
    traj = skill.generalize([5.0, 5.0], [0.0, 0.0], tau=2.0, dt=0.01, margin=0.25)
    assert traj.t[-1] == pytest.approx(2.5)
    assert len(traj.t) == 251
    slow = skill.generalize([5.0, 5.0], [0.0, 0.0], tau=2.0, dt=0.01)
    fast = skill.generalize([5.0, 5.0], [0.0, 0.0], tau=1.0, dt=0.005)
    np.testing.assert_allclose(slow.x, fast.x, atol=1e-6 * skill.size)
    np.testing.assert_allclose(slow.v, fast.v / 2.0, atol=1e-4 * np.abs(fast.v).max())


def test_builtin_demos_generalize():
    for name in ('G', 'P', 'R', 'W', 'wipe'):
        demo = builtin_demo(name)
        skill = learn(demo)
        assert nrmse(skill.reproduce().x, demo.positions) < 0.01
        goal = np.zeros(2)
        start = goal - 1.3 * (skill.start - skill.goal)
        traj = skill.generalize(start, goal)
        assert np.linalg.norm(traj.x[-1] - goal) < 5e-3 * skill.size
    stir = learn(builtin_demo('stir'))
    for mode in (1, 2):
        traj = stir.generalize([0.1, -0.1, 0.2], [0.0, 0.0, 0.0], mode=mode)
        assert np.linalg.norm(traj.x[-1]) < 5e-3 * stir.size


@pytest.mark.parametrize('kwargs, message', [
    ({'start': [np.nan, 1.0], 'goal': [0.0, 0.0]}, 'NaN'),
    ({'start': [1.0, 1.0, 1.0], 'goal': [0.0, 0.0]}, 'shape'),
    ({'start': [1.0, 1.0], 'goal': [0.0]}, 'shape'),
    ({'start': [1.0, 1.0], 'goal': [1.0, 1.0]}, 'start equals goal'),
    ({'start': [1.0, 1.0], 'goal': [0.0, 0.0], 'method': 'spline'}, 'method'),
    ({'start': [1.0, 1.0], 'goal': [0.0, 0.0], 'dt': -1.0}, 'dt'),
    ({'start': [1.0, 1.0], 'goal': [0.0, 0.0], 'tau': np.inf}, 'tau'),
    ({'start': [1.0, 1.0], 'goal': [0.0, 0.0], 'obstacles': [[0.0, 0.0]]}, 'obstacle'),
    ({'start': [1.0, 1.0], 'goal': [0.0, 0.0], 'obstacles': [[0.0, 0.0, 1.0]]}, 'obstacles'),
    ({'start': [1.0, 1.0], 'goal': [0.0, 0.0], 'obstacles': [['a', 1]]}, 'numeric'),
    ({'start': [1.0, 1.0], 'goal': [0.0, 0.0], 'dt': 1e-9}, 'samples'),
    ({'start': [1.0, 1.0, 0.0], 'goal': [0.0, 0.0, 0.0], 'mode': 3}, 'shape'),
])
def test_bad_generalization_requests(kwargs, message):
    skill = learn(letter_like(), dt=1 / 199)
    with pytest.raises(GeneralizationError, match=message):
        skill.generalize(**kwargs)
    assert np.all(np.isfinite(skill.generalize([1.0, 1.0], [0.0, 0.0]).x))


def test_checked_request_is_batched_with_defaults():
    skill = learn(letter_like(), dt=1 / 199)
    one = skill._check_request([1.0, 1.0], [0.0, 0.0], (), 'etdmp', None, None, None, None)
    assert one.single and one.starts.shape == (1, 2) and one.goals.shape == (1, 2)
    assert one.obstacles.shape == (0, 2)
    assert (one.tau, one.dt, one.n_out) == (skill.tau, skill.dt, len(skill.demo))
    assert one.gains == ObstacleGains()
    batch = skill._check_request([[1.0, 1.0], [2.0, 0.0]], [0.0, 0.0], [3.0, 3.0], 'dmp', 0.01,
                                 2.0, None, None)
    assert not batch.single and batch.starts.shape == batch.goals.shape == (2, 2)
    np.testing.assert_array_equal(batch.goals, 0.0)
    assert batch.obstacles.shape == (1, 2)
    assert batch.n_out == round(2.0 * (1.0 + OBSTACLE_MARGIN) / 0.01) + 1
    # The first problem found is the one reported: shapes before the method name.
    with pytest.raises(GeneralizationError, match='obstacles must have shape'):
        skill._check_request([1.0, 1.0], [0.0, 0.0], [[1.0, 2.0, 3.0]], 'spline', None, None,
                             None, None)


def test_bad_mode_in_3d():
    skill = learn(spiral_3d(), dt=0.01)
    with pytest.raises(GeneralizationError, match='mode'):
        skill.generalize([0.1, 0.1, 0.1], [0.0, 0.0, 0.0], mode=3)
    with pytest.raises(GeneralizationError, match='axis'):
        skill.generalize([0.1, 0.1, 0.1], [0.0, 0.0, 0.0], mode=2, independent_axis=5)


def test_demo_that_starts_at_its_goal():
    t = np.linspace(0.0, 2 * np.pi, 100)
    loop = np.c_[np.sin(t), 1.0 - np.cos(t)]          # closes exactly on itself
    skill = learn(loop)
    with pytest.raises(GeneralizationError, match='starts at its goal'):
        skill.generalize([1.0, 1.0], [0.0, 0.0])
    hoff = learn(loop, formulation='hoffmann')
    traj = hoff.generalize([1.0, 1.0], [0.0, 0.0], method='dmp')
    assert np.all(np.isfinite(traj.x))


@pytest.mark.parametrize('positions, kwargs, message', [
    (np.zeros((5, 2)), {}, 'at least'),
    (np.full((50, 2), np.nan), {}, 'finite'),
    (np.ones((50, 2)), {}, 'does not move'),
    (np.zeros((50, 2, 2)), {}, 'T, d'),
    (np.random.default_rng(0).normal(size=(50, 2)), {'dt': 0.0}, 'dt'),
    (np.random.default_rng(0).normal(size=(50, 2)), {'t': np.ones(50)}, 'increasing'),
    (np.random.default_rng(0).normal(size=(50, 2)), {'t': np.arange(49.0)}, 'shape'),
    (np.random.default_rng(0).normal(size=(50, 2)), {'formulation': 'x'}, 'formulation'),
    (np.random.default_rng(0).normal(size=(50, 2)), {'K': -1.0}, 'K'),
    ('not numbers', {}, 'real numbers'),
])
def test_bad_demonstrations(positions, kwargs, message):
    with pytest.raises(DemonstrationError, match=message):
        learn(positions, **kwargs)


_WAVE = np.column_stack([np.linspace(0.0, 8.0, 80), np.sin(np.linspace(0.0, 6.0, 80))])


@pytest.mark.parametrize('positions, kwargs, message', [
    # Found by attacks: stamps spanning 1.975e9 s (the plan would need 2e11 samples)
    (_WAVE, {'t': np.linspace(0.0, 1.975e9, 80)}, 'MAX_DEMO_DURATION'),
    # coordinates x 1e300: every later product overflowed ('start equals goal' at generalize)
    (_WAVE * 1e300, {}, 'MAX_DEMO_COORDINATE'),
    (_WAVE * 1e-9, {}, 'MIN_DEMO_EXTENT'),
    (_WAVE, {'t': np.r_[0.0, 1e-9, np.linspace(0.1, 1.0, 78)]}, 'MIN_DEMO_SAMPLE_INTERVAL'),
    (np.tile(_WAVE, (limits.MAX_DEMO_SAMPLES // 80 + 1, 1)), {}, 'MAX_DEMO_SAMPLES'),
])
def test_demonstrations_beyond_the_limits_are_refused(positions, kwargs, message):
    with pytest.raises(DemonstrationError, match=message):
        learn(positions, **kwargs)


def test_limits_leave_usable_demonstrations_alone():
    # At the limits themselves: 600 s, MAX_DEMO_SAMPLES samples, coordinates of MAX_COORDINATE.
    n = limits.MAX_DEMO_SAMPLES
    wave = np.column_stack([np.linspace(0.0, 8.0, n), np.sin(np.linspace(0.0, 6.0, n))])
    skill = learn(wave, t=np.linspace(0.0, limits.MAX_DEMO_DURATION, n))
    # The wave starts and ends moving: it is learned as slowing to rest (docs/design.md
    # #coming-to-rest), which adds the re-timing's seconds to its duration.
    assert skill.retiming.start > 0.0 and skill.retiming.end > 0.0
    assert skill.tau == pytest.approx(limits.MAX_DEMO_DURATION + skill.retiming.start
                                      + skill.retiming.end, rel=1e-12)
    big = learn(_WAVE / 8.0 * limits.MAX_DEMO_COORDINATE)
    traj = big.generalize(big.start, big.goal + 1.0)
    assert np.all(np.isfinite(traj.x))


@pytest.mark.parametrize('tau, dt, n', [(0.005, 0.01, 1), (0.001, 0.01, 1)])
def test_a_movement_of_fewer_than_two_samples_is_refused(tau, dt, n):
    # Found by attacks: duration 0.005 gave a 1-pose "plan" at the start, as a success.
    skill = learn(builtin_demo('G'))
    with pytest.raises(GeneralizationError, match=f'would have {n} sample'):
        skill.generalize(skill.start + 1.0, skill.goal, tau=tau, dt=dt)
    assert len(skill.generalize(skill.start + 1.0, skill.goal, tau=0.02, dt=0.01).t) == 3

"""
Obstacles with a size, avoided by the detour (docs/design.md#obstacles-with-a-size).

Held-out shapes (LASA, random scribbles in 2D and 3D: ``test/support/shapes.py``), disks and balls
of radius 3-15 % of the plan's size on and near the obstacle-free plan. What must hold: no sample
and no segment between samples closer to a centre than its radius; far obstacles change nothing,
bit for bit; the goal is reached and kept; ET-DMP and the plain DMP, 2D and 3D, batches and the
online run with an obstacle that moves; a clearance that cannot be kept is refused, never
returned; the numba loop agrees with its numpy reference.
"""

from etdmp_ros.dmp import AVOIDANCES, builtin_demo, GeneralizationError, learn, ObstacleGains
from etdmp_ros.dmp._clearance import distances, least_pushes
from etdmp_ros.dmp._detour import (amplitude, amplitudes, bump, candidate_directions,
                                   check_clearance, Displacement, Obstacles)
import numpy as np
import pytest
from support import shapes


def _size(x, goal):
    return float(np.max(np.linalg.norm(x - goal, axis=1)))


def _gaps(x, centres, radii):
    """Smallest distance of the polyline ``x`` to each centre, minus its radius (m,)."""
    a, b = x[:-1], x[1:]
    ab = b - a
    out = []
    for c, r in zip(centres, radii):
        u = np.clip(np.einsum('ki,ki->k', c - a, ab) / np.maximum(
            np.einsum('ki,ki->k', ab, ab), 1e-300), 0.0, 1.0)
        out.append(np.min(np.linalg.norm(a + u[:, None] * ab - c, axis=1)) - r)
    return np.array(out)


def _turn(d, angle):
    if d == 2:
        return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0],
                     [0.0, 0.0, 1.0]])


def _held_out():
    """Skills learned from shapes nothing was tuned on: 6 LASA shapes, 2D and 3D scribbles."""
    recs = [shapes.lasa(name) for name in shapes.lasa_names()[2::5]]
    recs += [shapes.scribble(40 + seed, 2) for seed in range(3)]
    recs += [shapes.scribble(60 + seed, 3) for seed in range(3)] + [shapes.helix()]
    return [(rec.name, learn(rec.positions, t=rec.t)) for rec in recs]


@pytest.fixture(scope='module')
def cases():
    """(name, skill, method, start, goal, centres, radii, far centres, far radii) tuples."""
    rng = np.random.default_rng(7)
    out = []
    for name, skill in _held_out():
        for turn, factor, method in ((2.0, 1.1, 'etdmp'), (4.0, 0.9, 'etdmp'), (0.0, 1.0, 'dmp')):
            goal = skill.goal
            start = goal + factor * _turn(skill.dim, turn) @ (skill.start - skill.goal)
            try:
                free = skill.generalize(start, goal, method=method)
            except GeneralizationError:
                continue            # the plain DMP cannot place every shape (docs)
            for count in (1, 2, 3):
                centres, radii = shapes.obstacles_on_path(free.x, rng, count,
                                                          keep_clear=(start, goal))
                far, far_radii = shapes.obstacles_on_path(free.x, rng, count, far=True,
                                                          keep_clear=(start, goal))
                out.append((name, skill, method, start, goal, centres, radii, far, far_radii))
    return out


def test_held_out_shapes_never_enter_an_obstacle_and_keep_their_shape(cases):
    deviations = []
    methods, dims = set(), set()
    for name, skill, method, start, goal, centres, radii, *_ in cases:
        free = skill.generalize(start, goal, method=method)
        plan = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii,
                                method=method)
        size = _size(free.x, goal)
        assert np.all(_gaps(plan.x, centres, radii) >= 0.0), name
        assert np.linalg.norm(plan.x[-1] - goal) <= 1e-3 * size, name     # 0.1 % of the size
        # The timing is the obstacle-free plan's, and where the plan is clear it is that plan.
        assert len(plan.t) == len(free.t)
        deviations.append(shapes.shape_deviation(plan.x, free.x, size))
        methods.add(method)
        dims.add(skill.dim)
    assert methods == {'etdmp', 'dmp'} and dims == {2, 3}
    assert len(deviations) >= 60
    # targets (median <= 0.04, p90 <= 0.15; the paper's coupling: 0.21 / 0.48).
    assert np.median(deviations) <= 0.04
    assert np.percentile(deviations, 90) <= 0.15
    assert max(deviations) < 0.5


def test_far_obstacles_change_nothing_bit_for_bit(cases):
    for name, skill, method, start, goal, _, _, far, far_radii in cases:
        free = skill.generalize(start, goal, method=method)
        plan = skill.generalize(start, goal, obstacles=far, obstacle_radii=far_radii,
                                method=method)
        for field in ('t', 'x', 'v', 'a'):
            assert np.array_equal(getattr(plan, field), getattr(free, field)), name


def test_the_goal_is_kept_past_tau():
    """
    The detour ends before the plan does: past tau the plan is the obstacle-free one.

    (Whether the obstacle-free plan itself stays at its goal past tau is the DMP's business
    (test_dmp_rest.py); these recordings end at rest, and their plans do.)
    """
    for rec in (shapes.scribble(3, 2), shapes.scribble(4, 3), shapes.helix()):
        skill = learn(rec.positions, t=rec.t)
        goal = skill.goal
        start = goal + _turn(skill.dim, 2.5) @ (skill.start - skill.goal)
        free = skill.generalize(start, goal, margin=1.0)
        centres, radii = shapes.obstacles_on_path(free.x, np.random.default_rng(1), 2,
                                                  span=(0.6, 0.9), keep_clear=(start, goal))
        plan = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii, margin=1.0)
        size = _size(free.x, goal)
        after = plan.t >= skill.tau
        assert np.max(np.abs(plan.x[after] - free.x[after])) <= 1e-3 * size
        for field in ('x', 'v', 'a'):
            assert np.array_equal(getattr(plan, field)[-1], getattr(free, field)[-1])
        assert np.max(np.linalg.norm(free.x[after] - goal, axis=1)) <= 5e-3 * size
        assert np.max(np.abs(plan.x - free.x)) > 0.01 * size     # the obstacles were in the way


def test_a_batch_is_its_starts_one_by_one():
    skill = learn(builtin_demo('W'))
    goal = skill.goal
    starts = np.array([goal + f * _turn(2, a) @ (skill.start - goal)
                       for a, f in ((0.3, 1.0), (1.9, 0.8), (3.5, 1.2), (5.0, 1.0))])
    free = skill.generalize(starts[0], goal)
    centres = free.x[[70, 130]]
    radii = np.array([0.05, 0.1]) * _size(free.x, goal)
    batch = skill.generalize(starts, goal, obstacles=centres, obstacle_radii=radii)
    for b, start in enumerate(starts):
        one = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii)
        np.testing.assert_array_equal(batch.x[b], one.x)
        np.testing.assert_array_equal(batch.a[b], one.a)
    assert np.max(np.abs(batch.x[0] - free.x)) > 0.01 * _size(free.x, goal)


@pytest.mark.parametrize('name, mode', [('G', 1), ('stir', 2)])
def test_the_detour_turns_with_the_start(name, mode):
    """
    ET-DMP: start and obstacles turned about the goal give the plan turned (Eq. 23).

    (In 3D mode 1 the transform of a turned start is not the turned transform.)
    """
    skill = learn(builtin_demo(name))
    goal = skill.goal
    start = goal + 1.1 * (skill.start - goal)
    free = skill.generalize(start, goal, mode=mode)
    centres = free.x[[len(free.x) // 3, len(free.x) // 2]]      # on the path: a tie of sides
    radii = np.array([0.06, 0.08]) * _size(free.x, goal)
    base = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii, mode=mode)
    q = _turn(skill.dim, 1.3)
    turned = skill.generalize(goal + q @ (start - goal), goal, mode=mode,
                              obstacles=goal + (centres - goal) @ q.T, obstacle_radii=radii)
    np.testing.assert_allclose(turned.x, goal + (base.x - goal) @ q.T,
                               atol=1e-9 * skill.size)


@pytest.mark.parametrize('name', ['G', 'stir'])
def test_numba_and_the_numpy_reference_agree(name):
    skill = learn(builtin_demo(name))
    goal = skill.goal
    start = goal + _turn(skill.dim, 2.0) @ (skill.start - goal)
    free = skill.generalize(start, goal)
    centres, radii = shapes.obstacles_on_path(free.x, np.random.default_rng(3), 3,
                                              keep_clear=(start, goal))
    fast = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii)
    slow = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii, fast=False)
    np.testing.assert_allclose(fast.x, slow.x, atol=1e-9 * skill.size)
    np.testing.assert_allclose(fast.a, slow.a, atol=1e-9 * np.abs(slow.a).max())
    assert np.max(np.abs(fast.x - free.x)) > 0.01 * skill.size


def test_the_amplitude_loop_is_its_reference():
    rng = np.random.default_rng(11)
    for _ in range(200):
        d = rng.choice([2, 3])
        k, m = rng.integers(5, 40), rng.integers(1, 4)
        W = rng.normal(size=(k, m, d))
        q = rng.uniform(0.2, 1.5, m)
        b = rng.uniform(0.01, 1.0, k)
        own = rng.random(m) < 0.7
        n = candidate_directions(d)[rng.integers(len(candidate_directions(d)))]
        A = amplitude(W, q, n, b, own, 0.1)
        assert A == pytest.approx(amplitudes(W, q, n[None], b, own, 0.1)[0], rel=1e-12)
        # What it promises: every own sample, and every sample outside the other balls,
        # is clear of every ball once moved by A b n.
        moved = W + (A * b)[:, None, None] * n
        clear = np.linalg.norm(moved, axis=2) >= q * (1.0 - 1e-9)
        counted = own | (np.linalg.norm(W, axis=2) >= q)
        assert np.all(clear | ~counted)


def test_the_bump_is_smooth_and_its_derivatives_are_exact():
    t = np.linspace(0.0, 1.0, 20001)
    b, b1, b2 = bump(t, 0.2, 0.35, 0.5, 0.8)
    assert b.min() == 0.0 and b.max() == 1.0
    h = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(b, h)[1:-1], b1[1:-1], atol=2e-3)
    np.testing.assert_allclose(np.gradient(b1, h)[2:-2], b2[2:-2], atol=0.5)
    # C2: no jump in the second derivative anywhere (the quintic's ends are flat).
    assert np.max(np.abs(np.diff(b2))) < 1e-2 * np.abs(b2).max()


def test_the_numba_loops_agree_with_their_numpy_references():
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, 1.0, 500))
    for corners in ((0.2, 0.35, 0.5, 0.8), (0.1, 0.1, 0.4, 0.9), (0.3, 0.6, 0.6, 0.6)):
        for fast, slow in zip(bump(t, *corners), bump(t, *corners, fast=False)):
            np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=1e-12)
    for d in (2, 3):
        x = rng.normal(size=(4, 60, d))
        C = rng.normal(size=(3, d))
        np.testing.assert_allclose(distances(x, C), distances(x, C, fast=False), rtol=1e-12)
        assert distances(x, C).shape == (4, 60, 3)
        W = rng.normal(scale=0.5, size=(40, d))
        directions = candidate_directions(d)
        fast, slow = least_pushes(W, 0.8, directions), least_pushes(W, 0.8, directions, False)
        np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=1e-15)
        assert fast.min() > 0.0                   # some samples are inside: every way needs a push


def test_a_carried_displacement_starts_where_it_was_and_fades():
    carry = np.array([[0.3, -0.2], [1.5, 0.4], [-8.0, 6.0]])      # delta, delta', delta''
    empty = np.zeros(0)
    shift = Displacement(empty, empty, empty, empty, empty, np.zeros((0, 2)), 1.0, 0.5, carry)
    at = shift(np.array([1.0]))
    for k in range(3):
        np.testing.assert_allclose(at[k][0], carry[k], atol=1e-12)
    assert all(np.all(part == 0.0) for part in shift(np.array([0.5, 1.5, 2.0])))
    t = np.linspace(1.0, 1.5, 50001)
    delta, delta_v, delta_a = shift(t)
    h = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(delta, h, axis=0)[1:-1], delta_v[1:-1], atol=1e-3)
    np.testing.assert_allclose(np.gradient(delta_v, h, axis=0)[2:-2], delta_a[2:-2], atol=2e-2)
    assert shift.end == 1.5


@pytest.mark.parametrize('name', ['G', 'stir'])
def test_online_with_an_obstacle_that_moves(name):
    skill = learn(builtin_demo(name))
    goal = skill.goal
    start = goal + 1.1 * _turn(skill.dim, 0.4) @ (skill.start - goal)
    free = skill.generalize(start, goal)
    size = _size(free.x, goal)
    centres = free.x[[len(free.x) // 3, 2 * len(free.x) // 3]]
    radii = np.array([0.06, 0.08]) * size
    offline = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii)
    run = skill.online(start, goal, obstacles=centres, obstacle_radii=radii)
    x = [run.x] + [run.step()[0] for _ in range(len(offline.t) - 1)]
    np.testing.assert_allclose(x, offline.x, atol=1e-9 * size)     # nothing moves: generalize
    # The second obstacle slides sideways across the path while the plan runs.
    run = skill.online(start, goal, obstacles=centres, obstacle_radii=radii)
    side = np.zeros(skill.dim)
    side[1] = 1.0
    samples, where = [(run.x, run.v)], []
    for i in range(3 * len(offline.t)):
        moved = centres.copy()
        moved[1] += 0.3 * size * side * min(i, 60) / 60
        x, v, _ = run.step(obstacles=moved)
        samples.append((x, v))
        where.append(moved.copy())
        if run.done:
            break
    x, v = (np.array(c) for c in zip(*samples))
    for k in range(1, len(x)):
        assert np.all(np.linalg.norm(where[k - 1] - x[k], axis=1) >= radii)
    assert run.done and np.linalg.norm(x[-1] - goal) <= 1e-3 * size
    # Continuous: no step changes the velocity more than the offline plan's largest step does.
    largest = np.max(np.linalg.norm(np.diff(offline.v, axis=0), axis=1))
    assert np.max(np.linalg.norm(np.diff(v, axis=0), axis=1)) <= 1.5 * largest


def test_refusals_say_why_and_change_nothing():
    skill = learn(builtin_demo('G'))
    goal = skill.goal
    start = skill.start
    free = skill.generalize(start, goal)
    size = _size(free.x, goal)
    with pytest.raises(GeneralizationError, match='start lies inside obstacle #0'):
        skill.generalize(start, goal, obstacles=[start + 0.01 * size],
                         obstacle_radii=[0.05 * size])
    with pytest.raises(GeneralizationError, match='goal lies inside obstacle #1'):
        skill.generalize(start, goal, obstacles=[free.x[50], goal + 0.02 * size],
                         obstacle_radii=[0.01 * size, 0.05 * size])
    # Two balls that close the way between the start and the rest of the path.
    wall = [start + 0.12 * size * np.array([np.cos(a), np.sin(a)])
            for a in np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)]
    with pytest.raises(GeneralizationError, match='detour larger than|inside obstacle'):
        skill.generalize(start, goal, obstacles=wall, obstacle_radii=np.full(12, 0.06 * size))
    run = skill.online(start, goal, obstacles=[free.x[120]], obstacle_radii=[0.05 * size])
    for _ in range(40):
        run.step()
    before = (run.x, run.t, run.obstacles)
    with pytest.raises(GeneralizationError, match='contains the plan'):
        run.step(obstacles=[run.x + 0.001 * size])              # onto the current position
    assert np.array_equal(run.x, before[0]) and run.t == before[1]
    assert np.array_equal(run.obstacles, before[2])
    with pytest.raises(GeneralizationError, match='give their radii'):
        run.step(obstacles=[free.x[120], free.x[150]])


@pytest.mark.parametrize('kwargs, message', [
    ({'obstacle_radii': [1.0, 2.0]}, r'one radius per obstacle'),
    ({'obstacle_radii': [-1.0]}, '>= 0'),
    ({'obstacle_radii': [np.nan]}, 'NaN'),
    ({'obstacle_radii': [0.1], 'avoidance': 'magic'}, 'avoidance must be one of'),
])
def test_bad_radii_are_refused(kwargs, message):
    skill = learn(builtin_demo('P'))
    with pytest.raises(GeneralizationError, match=message):
        skill.generalize([9.0, 9.0], skill.goal, obstacles=[[3.0, 3.0]], **kwargs)


def test_without_radii_the_paper_coupling_is_kept():
    skill = learn(builtin_demo('R'))
    goal = skill.goal
    start = goal + _turn(2, 1.0) @ (skill.start - goal)
    free = skill.generalize(start, goal)
    centres = free.x[[60, 110]]
    default = skill.generalize(start, goal, obstacles=centres)
    paper = skill.generalize(start, goal, obstacles=centres, avoidance='paper')
    assert AVOIDANCES == ('detour', 'paper')
    for field in ('t', 'x', 'v', 'a'):
        np.testing.assert_array_equal(getattr(default, field), getattr(paper, field))
    # The paper's timing: OBSTACLE_MARGIN more, and its coupling bends the path.
    assert len(paper.t) > len(free.t)
    with_radii = skill.generalize(start, goal, obstacles=centres, obstacle_radii=[0.0, 0.0])
    assert len(with_radii.t) == len(free.t)                     # the detour, around points


def test_the_margin_and_the_acceleration_bound():
    skill = learn(builtin_demo('G'))
    goal = skill.goal
    start = goal + _turn(2, 2.0) @ (skill.start - goal)
    free = skill.generalize(start, goal)
    size = _size(free.x, goal)
    centres = free.x[[70]]
    radii = np.array([0.05 * size])
    for margin in (0.005, 0.02):
        plan = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii,
                                gains=ObstacleGains(clearance_margin=margin))
        gap = np.min(np.linalg.norm(plan.x - centres[0], axis=1)) - radii[0]
        assert gap == pytest.approx(margin * size, rel=0.05)
    gentle = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii)
    sharp = skill.generalize(start, goal, obstacles=centres, obstacle_radii=radii,
                             gains=ObstacleGains(detour_acceleration=100.0))
    peak = np.max(np.linalg.norm(free.a, axis=1))
    assert np.max(np.linalg.norm(gentle.a, axis=1)) <= 2.0 * peak
    assert np.max(np.linalg.norm(sharp.a, axis=1)) > np.max(np.linalg.norm(gentle.a, axis=1))


def test_check_clearance_looks_between_samples():
    x = np.array([[-1.0, 0.0], [1.0, 0.0]])
    check_clearance(x, Obstacles(np.array([[0.0, 0.5]]), np.array([0.4])))
    with pytest.raises(GeneralizationError, match='inside its radius'):
        check_clearance(x, Obstacles(np.array([[0.0, 0.3]]), np.array([0.4])))

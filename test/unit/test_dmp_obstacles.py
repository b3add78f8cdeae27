"""Obstacle coupling (paper Eq. 22-27): steering, safe region, clearance, convergence."""

from pathlib import Path

from etdmp_ros.dmp import (builtin_demo, clearance, learn, load_demo, nrmse, obstacle_coupling,
                           ObstacleGains)
import numpy as np
import pytest


def test_coupling_is_perpendicular_to_the_velocity_and_steers_away():
    rng = np.random.default_rng(0)
    for _ in range(200):
        dim = rng.choice([2, 3])
        x, v = rng.normal(size=dim), rng.normal(size=dim)
        goal = x + 10.0 * rng.normal(size=dim)
        obstacle = x + 0.5 * v / np.linalg.norm(v) + 0.2 * rng.normal(size=dim)
        lam = obstacle_coupling(x, v, obstacle[None], goal)
        assert lam.shape == (dim,)
        assert abs(lam @ v) < 1e-9 * np.linalg.norm(lam) * np.linalg.norm(v)
        # Steering away: the coupling does not point towards the obstacle's side of v.
        to_obs = obstacle - x
        side = to_obs - (to_obs @ v) / (v @ v) * v
        assert lam @ side <= 1e-9 * np.linalg.norm(lam) * np.linalg.norm(side)


def test_2d_coupling_turns_right_obstacle_to_the_left():
    lam = obstacle_coupling(np.zeros(2), np.array([1.0, 0.0]), np.array([[1.0, -0.2]]),
                            np.array([10.0, 0.0]))
    assert lam[1] > 0.0 and abs(lam[0]) < 1e-12


def test_safe_region_switches_the_obstacle_off():
    x, v, goal = np.zeros(2), np.array([1.0, 0.0]), np.array([1.0, 0.0])
    near_goal = obstacle_coupling(x, v, np.array([[2.0, 0.1]]), goal)
    assert np.all(near_goal == 0.0)       # |o - x| > |x - g|: the goal dominates (Eq. 25)
    assert np.linalg.norm(obstacle_coupling(x, v, np.array([[0.5, 0.1]]), goal)) > 0.0


@pytest.mark.parametrize('dim', [2, 3])
def test_heading_straight_at_an_obstacle_still_pushes_sideways(dim):
    x, v = np.zeros(dim), np.eye(dim)[0]
    goal = 10.0 * np.eye(dim)[0]
    lam = obstacle_coupling(x, v, 1.0 * np.eye(dim)[0][None], goal)
    assert np.all(np.isfinite(lam))
    assert np.linalg.norm(lam) > 0.0
    assert abs(lam @ v) < 1e-12
    at_rest = obstacle_coupling(x, np.zeros(dim), np.eye(dim)[0][None], goal)
    assert np.all(at_rest == 0.0)


def test_distance_term_decays_with_k():
    x, v, goal = np.zeros(2), np.array([1.0, 0.0]), np.array([10.0, 0.0])
    gains = ObstacleGains(gamma=0.0, gamma2=100.0, k=2.0)
    near = np.linalg.norm(obstacle_coupling(x, v, np.array([[1.0, 0.0]]), goal, gains))
    far = np.linalg.norm(obstacle_coupling(x, v, np.array([[3.0, 0.0]]), goal, gains))
    assert near == pytest.approx(100.0 * np.exp(-2.0))
    assert far == pytest.approx(100.0 * np.exp(-6.0))


PAPER_LETTERS = Path(__file__).resolve().parents[2].parent / 'shared' / 'data' / 'pbdlib_2Dletters'


def letters():
    """Yield the built-in letters plus, when present, the paper's letter data."""
    for name in ('G', 'P', 'R', 'W'):
        yield 'builtin ' + name, builtin_demo(name).positions, builtin_demo(name).t
    for name in ('G', 'P', 'R', 'W'):
        path = PAPER_LETTERS / f'{name}_00.csv'
        if path.is_file():
            demo = load_demo(path)
            yield 'paper ' + name, demo.positions, demo.t


@pytest.mark.parametrize('name, positions, t', list(letters()))
def test_obstacles_on_the_path_are_cleared_and_the_goal_reached(name, positions, t):
    skill = learn(positions, t=t)
    goal = np.array([1.0, -2.0])
    # A start in another quadrant than the demonstration's.
    start = goal + (skill.start - skill.goal) * np.array([-1.2, 0.9])
    free = skill.generalize(start, goal)
    size = np.ptp(free.x, axis=0).max()
    n = len(free.x)
    for fractions in ([0.35], [0.65], [0.35, 0.65]):
        obstacles = free.x[[int(f * n) for f in fractions]]
        assert clearance(free.x, obstacles) < 1e-9    # they sit on the obstacle-free path
        avoided = skill.generalize(start, goal, obstacles=obstacles)
        assert np.all(np.isfinite(avoided.x))
        assert clearance(avoided.x, obstacles) > 0.05 * size, name
        assert np.linalg.norm(avoided.x[-1] - goal) < 0.01 * size, name
        assert np.linalg.norm(avoided.v[-1]) < 0.05 * np.abs(free.v).max()
        # The shape stays close: measured on the demo's phase span.
        span = avoided.t <= skill.tau + 1e-9
        assert nrmse(avoided.x[span], positions) < 0.5, name


def test_obstacles_are_transformed_with_the_start():
    """ET-DMP avoidance is the same in every quadrant: rotate start and obstacles, rotate path."""
    demo = builtin_demo('G')
    skill = learn(demo)
    goal = np.zeros(2)
    start = goal + 1.1 * (skill.start - skill.goal)
    free = skill.generalize(start, goal)
    obstacles = free.x[[len(free.x) // 3]]
    base = skill.generalize(start, goal, obstacles=obstacles)
    q = np.array([[0.0, -1.0], [1.0, 0.0]])
    turned = skill.generalize(q @ start, goal, obstacles=obstacles @ q.T)
    np.testing.assert_allclose(turned.x, base.x @ q.T, atol=1e-9 * skill.size)

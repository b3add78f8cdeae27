"""
Kinesthetic teaching in the simulation: the scripted hand and the stir it makes.

:class:`etdmp_ros.robot.GuidedMotion` leads the MuJoCo UR10's tool along a script as a hand in
freedrive would; :func:`etdmp_ros.demo.kinesthetic.hand_stir` is the default script. Checked
against the simulation's true tool tip: it follows the script, stays in the bottle, and scripts the
arm cannot follow are refused before it moves.
"""

from etdmp_ros.demo.kinesthetic import hand_stir, REST
from etdmp_ros.demo.scenario import Scenario, stir_start, stir_start_joints
from etdmp_ros.robot import GuidedMotion, GuideError, SceneConfig
from etdmp_ros.sim import UR10Sim
import numpy as np
import pytest


@pytest.fixture(scope='module')
def stir():
    """Return (scenario, sim at the stir start, script t, script positions)."""
    scenario = Scenario(None, 'stir')
    sim = UR10Sim(SceneConfig.from_parameters(scenario.scene))
    sim.reset(stir_start_joints(scenario, scenario.tool_rotation))   # the hand: upright
    t, positions = hand_stir(stir_start(scenario), scenario.bottle_mouth)
    yield scenario, sim, t, positions
    sim.close()


def test_the_hand_stir_rests_then_circles_down_inside_the_bottle(stir):
    scenario, sim, t, p = stir
    np.testing.assert_allclose(p[0], stir_start(scenario), atol=1e-12)
    rest = int(REST * 100)
    assert np.ptp(p[:rest + 1], axis=0).max() < 1e-12 and np.ptp(p[-rest:], axis=0).max() < 1e-12
    v = np.gradient(p, t, axis=0)
    a = np.gradient(v, t, axis=0)
    assert np.abs(a).max() < 5.0        # m/s^2: smooth (a corner at this speed is ~30 m/s^2)
    mouth = scenario.bottle_mouth
    r = np.hypot(*(p[:, :2] - mouth[:2]).T)
    inside = p[:, 2] < mouth[2]
    assert r[inside].max() < scenario.scene['bottle.radius'] - 0.015
    assert np.linalg.norm(p[-1] - (mouth + [0.0, 0.0, -0.13])) < 1e-9
    circling = inside & (r > 0.005)
    turns = np.unwrap(np.arctan2(*(p[circling, 1::-1] - mouth[1::-1]).T))
    assert abs(turns[-1] - turns[0]) > 1.5 * 2 * np.pi      # it stirs: 1.5 turns in the bottle


def test_the_guided_tool_follows_the_script_in_the_simulation(stir):
    scenario, sim, t, p = stir
    guide = GuidedMotion(sim.ur10, sim.q, t, p, 0.008, sim.velocity_limits)
    assert guide.duration == pytest.approx(t[-1])
    tips = []
    while not guide.done:
        qd = guide.command(sim.q)
        assert np.all(np.abs(qd) <= sim.velocity_limits)
        sim.set_velocity_command(qd)
        sim.step(4)
        tips.append(sim.tool_tip_position.copy())
    tips = np.array(tips)
    led = np.array([sim.ur10.tool_position(q) for q in guide.joints[1:]])   # the script's poses
    at_samples = np.searchsorted(t, np.arange(1, len(led) + 1) * 0.008 - 1e-9)
    exact = np.isclose(t[np.minimum(at_samples, len(t) - 1)], np.arange(1, len(led) + 1) * 0.008)
    np.testing.assert_allclose(led[exact], p[at_samples[exact]], atol=1e-6)
    assert np.linalg.norm(tips - led, axis=1).max() < 0.5e-3
    assert np.linalg.norm(tips[-1] - p[-1]) < 3e-4
    np.testing.assert_array_equal(guide.command(sim.q), np.zeros(6))     # done: holds still


def test_scripts_the_arm_cannot_follow_are_refused_before_it_moves(stir):
    _, sim, t, p = stir
    with pytest.raises(GuideError, match='at least 2 positions of 3 coordinates'):
        GuidedMotion(sim.ur10, sim.q, t[:1], p[:1], 0.008)
    with pytest.raises(GuideError, match='slow it down'):
        GuidedMotion(sim.ur10, sim.q, t * 0.05, p, 0.008)
    with pytest.raises(GuideError, match='time stamps must increase'):
        GuidedMotion(sim.ur10, sim.q, t[::-1], p, 0.008)
    with pytest.raises(GuideError, match='MAX_DURATION'):
        GuidedMotion(sim.ur10, sim.q, t * 100, p, 0.008)
    with pytest.raises(GuideError, match='NaN'):
        GuidedMotion(sim.ur10, sim.q, t, np.where(p > 0.5, np.nan, p), 0.008)

"""
Online ET-DMP (docs/design.md#online-goal): a goal that moves while the movement runs.

Checked against what must hold by construction: with a goal that never changes the online run
is the offline rollout; a goal jump leaves position and velocity continuous and the acceleration
within the bound derived in the design document; afterwards the movement converges to the
demonstration placed at the new goal (the error's Lyapunov function never grows once the goal
stands still); phase stopping lets the plan wait for a held tool and then finish the shape.
"""

import math

from etdmp_ros.dmp import (builtin_demo, compare_goal_jump, GeneralizationError, goal_jump_case,
                           GOAL_JUMP_WAYS, learn, nrmse, OnlineGains, OnlineRun)
import numpy as np
import pytest


def roll(run, steps, goals=None, **kwargs):
    """Step ``run`` ``steps`` times (``goals``: {step index: goal}); return x, v, a with t=0."""
    goals = goals or {}
    samples = [(run.x, run.v, run.a)]
    for i in range(steps):
        samples.append(run.step(goal=goals.get(i), **kwargs))
    return tuple(np.array(column) for column in zip(*samples))


@pytest.fixture(scope='module')
def skills():
    return {name: learn(builtin_demo(name)) for name in ('G', 'W', 'stir')}


def _lyapunov(K, tau, e, e_dot):
    """``V = K |e|^2 / 2 + |tau e_dot|^2 / 2`` (Eq. 28 for the error), per sample."""
    return 0.5 * K * np.sum(e ** 2, axis=1) + 0.5 * tau ** 2 * np.sum(e_dot ** 2, axis=1)


# ----------------------------------------------------------------- a goal that does not move
@pytest.mark.parametrize('name, method, mode, kwargs', [
    ('G', 'etdmp', 1, {}),
    ('G', 'dmp', 1, {}),
    ('W', 'etdmp', 1, {'dt': 0.001, 'tau': 1.0}),        # several sub-steps per step
    ('stir', 'etdmp', 1, {}),
    ('stir', 'etdmp', 2, {}),
    ('stir', 'dmp', 1, {}),
    ('G', 'etdmp', 1, {'obstacles': 'path'}),
    ('stir', 'etdmp', 2, {'obstacles': 'path'}),
    ('G', 'dmp', 1, {'obstacles': 'path'}),
])
def test_a_goal_that_never_changes_reproduces_generalize(skills, name, method, mode, kwargs):
    skill = skills[name]
    start, goal, _ = goal_jump_case(skill)
    if kwargs.get('obstacles') == 'path':
        free = skill.generalize(start, goal, method=method, mode=mode).x
        side = np.zeros(skill.dim)
        side[1] = 0.02 * skill.size
        kwargs = dict(kwargs, obstacles=free[[60, 120]] + side)
    offline = skill.generalize(start, goal, method=method, mode=mode, **kwargs)
    run = skill.online(start, goal, method=method, mode=mode, **kwargs)
    x, v, a = roll(run, len(offline.t) - 1)
    assert np.max(np.abs(x - offline.x)) <= 1e-9 * skill.size
    assert np.max(np.abs(v - offline.v)) <= 1e-9 * np.abs(offline.v).max()
    assert np.max(np.abs(a - offline.a)) <= 1e-9 * np.abs(offline.a).max()
    assert run.t == pytest.approx(offline.t[-1])
    np.testing.assert_allclose(run.rotation, offline.rotation, atol=1e-15)
    np.testing.assert_allclose(run.virtual_start, offline.virtual_start, atol=1e-12)


def test_perfect_tracking_and_the_numpy_path_change_nothing(skills):
    skill = skills['G']
    start, goal, _ = goal_jump_case(skill)
    offline = skill.generalize(start, goal)
    tracked = skill.online(start, goal)
    samples = [tracked.x]
    for _ in range(len(offline.t) - 1):
        samples.append(tracked.step(actual=tracked.x)[0])   # the tool is where the plan is
    assert tracked.rate == 1.0
    assert np.max(np.abs(np.array(samples) - offline.x)) <= 1e-9 * skill.size
    reference = skill.online(start, goal, fast=False)
    x, _, _ = roll(reference, len(offline.t) - 1)
    assert np.max(np.abs(x - offline.x)) <= 1e-9 * skill.size


def test_hoffmann_formulation_online():
    demo = builtin_demo('G')
    skill = learn(demo, formulation='hoffmann')
    start, goal, new_goal = goal_jump_case(skill)
    offline = skill.generalize(start, goal)
    x, _, _ = roll(skill.online(start, goal), len(offline.t) - 1)
    assert np.max(np.abs(x - offline.x)) <= 1e-9 * skill.size
    run = skill.online(start, goal)
    roll(run, 3 * (len(offline.t) - 1), goals={80: new_goal})
    assert run.done and np.linalg.norm(run.x - new_goal) <= 1e-3 * skill.size


# ---------------------------------------------------------------------------- a goal that jumps
def test_goal_jump_is_continuous_with_bounded_acceleration(skills):
    """
    Check the bounds of docs/design.md#online-goal, for G with a jump at 40 %.

    With B = (K + Lambda) |g_new - g| (Lambda: the forcing's Lipschitz constant in g), the
    acceleration differs from the unperturbed one by at most (2 + 4/E) B / tau^2 (E = exp(1)),
    and over the
    first sample after the jump it changes by at most (1 - exp(-alpha_goal dt / tau)) B / tau^2
    (the goal filter's first step) beyond the unperturbed change.
    """
    skill = skills['G']
    start, goal, new_goal = goal_jump_case(skill)
    base = skill.generalize(start, goal)
    n = len(base.t) - 1
    k = int(0.4 * n)
    x, v, a = roll(skill.online(start, goal), n, goals={k: new_goal})
    tau, dt, K = skill.tau, base.t[1], skill.K
    jump = np.linalg.norm(new_goal - goal)
    f_max = np.max(np.linalg.norm(skill.forcing(np.exp(-np.linspace(0.0, 6.0, 4000))), axis=1))
    n_demo = np.linalg.norm(skill.start - skill.goal)
    along = goal + np.linspace(0.0, 1.0, 1001)[:, None] * (new_goal - goal)
    gap_min = np.min(np.linalg.norm(start - along, axis=1))
    c_max = max(np.linalg.norm(start - goal), np.linalg.norm(start - new_goal)) / n_demo
    lipschitz = skill.size * f_max * (1.0 / n_demo + c_max / gap_min)
    B = (K + lipschitz) * jump
    # Before the jump: the offline movement.
    np.testing.assert_allclose(x[:k + 1], base.x[:k + 1], atol=1e-9 * skill.size)
    # Position and velocity continuous: one sample changes them no more than the unperturbed
    # movement does, plus what the bounded extra acceleration adds over dt.
    extra_dx = np.linalg.norm(np.diff(x[k:k + 4], axis=0) - np.diff(base.x[k:k + 4], axis=0),
                              axis=1)
    extra_dv = np.linalg.norm(np.diff(v[k:k + 4], axis=0) - np.diff(base.v[k:k + 4], axis=0),
                              axis=1)
    assert np.all(extra_dx <= B / tau ** 2 * dt ** 2)
    assert np.all(extra_dv <= (2 + 4 / math.e) * B / tau ** 2 * dt)
    assert extra_dv[0] <= 0.02 * np.abs(base.v).max()
    # Acceleration: the first-step bound (the filter) and the global bound.
    first = np.linalg.norm((a[k + 1] - a[k]) - (base.a[k + 1] - base.a[k]))
    filter_step = 1.0 - math.exp(-OnlineGains().alpha_goal * dt / tau)
    assert first <= filter_step * B / tau ** 2
    assert np.max(np.linalg.norm(a - base.a, axis=1)) <= (2 + 4 / math.e) * B / tau ** 2
    # Without the filter the same jump steps the acceleration by about K |dg| / tau^2 at once.
    x_nf, _, a_nf = roll(skill.online(start, goal, online=OnlineGains(alpha_goal=math.inf)), n,
                         goals={k: new_goal})
    first_nf = np.linalg.norm((a_nf[k + 1] - a_nf[k]) - (base.a[k + 1] - base.a[k]))
    assert first_nf >= 0.5 * K * jump / tau ** 2
    assert first <= 0.2 * first_nf


def test_after_a_jump_the_shape_is_placed_at_the_new_goal_and_converges(skills):
    skill = skills['G']
    start, goal, new_goal = goal_jump_case(skill)
    reference = skill.generalize(start, new_goal, margin=1.0)     # placed at the new goal
    n = int(round(skill.tau / skill.dt))
    k = int(0.4 * n)
    run = skill.online(start, goal)
    x, v, _ = roll(run, 2 * n, goals={k: new_goal})
    error = np.linalg.norm(x - reference.x, axis=1)
    V = _lyapunov(skill.K, skill.tau, x - reference.x, v - reference.v)
    # The error to the placed shape decays: at t = tau it is below 1 % of the size (it was 30 %
    # at the jump), at 1.5 tau below 1e-4, and the run is done by then.
    assert error[k + 1] > 0.1 * skill.size
    assert error[n] <= 0.01 * skill.size
    assert error[int(1.5 * n)] <= 1e-4 * skill.size
    assert V[int(1.5 * n)] <= 1e-8 * V.max()
    assert run.done
    assert np.linalg.norm(run.filtered_goal - new_goal) == 0.0
    np.testing.assert_allclose(run.rotation, reference.rotation, atol=1e-12)
    # Without the filter the error obeys the homogeneous spring from the jump on: its
    # Lyapunov function (Eq. 28 for the error) never grows (Eq. 29: dV/dt = -D |e_dot|^2).
    x_nf, v_nf, _ = roll(skill.online(start, goal, online=OnlineGains(alpha_goal=math.inf)),
                         2 * n, goals={k: new_goal})
    V_nf = _lyapunov(skill.K, skill.tau, x_nf - reference.x, v_nf - reference.v)
    assert np.all(np.diff(V_nf[k + 1:]) <= 1e-9 * V_nf[k + 1])
    assert V_nf[n] <= 1e-3 * V_nf[k + 1]


@pytest.mark.parametrize('name, mode', [('stir', 1), ('stir', 2), ('W', 1)])
def test_goal_jumps_end_at_the_new_goal(skills, name, mode):
    skill = skills[name]
    start, goal, new_goal = goal_jump_case(skill)
    n = int(round(skill.tau / skill.dt))
    run = skill.online(start, goal, mode=mode)
    x, v, _ = roll(run, 3 * n, goals={int(0.3 * n): new_goal, int(0.6 * n): goal + 0.5 * (
        new_goal - goal)})
    final = goal + 0.5 * (new_goal - goal)
    assert run.done
    assert np.linalg.norm(x[-1] - final) <= 1e-3 * skill.size
    reference = skill.generalize(start, final, mode=mode, margin=2.0)
    assert np.max(np.linalg.norm(x[2 * n:] - reference.x[2 * n:], axis=1)) <= 1e-4 * skill.size
    # No sample changes the velocity more than the unperturbed movement's largest change does.
    base = skill.generalize(start, goal, mode=mode)
    assert (np.max(np.linalg.norm(np.diff(v, axis=0), axis=1))
            <= 1.1 * np.max(np.linalg.norm(np.diff(base.v, axis=0), axis=1)))


def test_a_goal_moving_all_the_time(skills):
    skill = skills['G']
    start, goal, _ = goal_jump_case(skill)
    base = skill.generalize(start, goal)
    n = len(base.t) - 1
    run = skill.online(start, goal)
    radius = 0.2 * np.linalg.norm(start - goal)
    samples = [(run.x, run.v, run.a)]
    for i in range(n):
        angle = 2 * np.pi * i / n
        target = goal + radius * np.array([np.cos(angle) - 1.0, np.sin(angle)])
        samples.append(run.step(goal=target))
    while not run.done and run.t < 3 * skill.tau:
        samples.append(run.step())
    x, v, a = (np.array(column) for column in zip(*samples))
    assert run.done
    assert np.linalg.norm(x[-1] - run.goal) <= 1e-3 * skill.size
    # Smooth throughout: no sample changes the velocity or the acceleration by more than the
    # unperturbed movement's largest change, with a margin.
    assert (np.max(np.linalg.norm(np.diff(v, axis=0), axis=1))
            <= 1.5 * np.max(np.linalg.norm(np.diff(base.v, axis=0), axis=1)))
    assert (np.max(np.linalg.norm(np.diff(a, axis=0), axis=1))
            <= 1.5 * np.max(np.linalg.norm(np.diff(base.a, axis=0), axis=1)))


def test_obstacles_may_appear_during_the_run(skills):
    skill = skills['G']
    start, goal, new_goal = goal_jump_case(skill)
    free = skill.generalize(start, new_goal, margin=0.5)
    n = int(round(skill.tau / skill.dt))
    obstacle = free.x[int(0.7 * n)] + np.array([0.0, 0.02 * skill.size])
    run = skill.online(start, goal)
    samples = [(run.x, run.v, run.a)]
    for i in range(3 * n):
        samples.append(run.step(goal=new_goal if i >= int(0.3 * n) else None,
                                obstacles=[obstacle] if i == int(0.5 * n) else None))
        if run.done:
            break
    x, v, _ = (np.array(column) for column in zip(*samples))
    assert run.done and len(run.obstacles) == 1
    assert np.linalg.norm(x[-1] - new_goal) <= 1e-3 * skill.size
    closest = np.min(np.linalg.norm(x - obstacle, axis=1))
    assert closest >= 0.05 * skill.size
    assert np.min(np.linalg.norm(free.x - obstacle, axis=1)) <= 0.03 * skill.size
    base = skill.generalize(start, goal)
    assert (np.max(np.linalg.norm(np.diff(v, axis=0), axis=1))
            <= 1.1 * np.max(np.linalg.norm(np.diff(base.v, axis=0), axis=1)))


def test_done_and_phase(skills):
    skill = skills['stir']
    start, goal, new_goal = goal_jump_case(skill)
    run = skill.online(start, goal)
    assert run.phase == 1.0 and run.t == 0.0 and not run.done
    n = int(round(skill.tau / skill.dt))
    roll(run, n - 1)
    assert not run.done                      # the phase has not ended yet
    while not run.done:
        run.step()
    assert run.phase <= math.exp(-skill.alpha) * (1 + 1e-9)
    assert run.t < 1.5 * skill.tau
    run.step(goal=new_goal)                  # a goal after the end starts it moving again
    assert not run.done
    while not run.done and run.t < 4 * skill.tau:
        run.step()
    assert run.done and np.linalg.norm(run.x - new_goal) <= 1e-3 * skill.size
    # Giving the same goal at every step is the same as giving it once.
    once, again = skill.online(start, goal), skill.online(start, goal)
    x1, _, _ = roll(once, 50, goals={10: new_goal})
    x2 = [again.x] + [again.step(goal=new_goal if i >= 10 else goal)[0] for i in range(50)]
    np.testing.assert_array_equal(x1, np.array(x2))


# ------------------------------------------------------------------------------ phase stopping
def _track(skill, start, goal, gains, hold, kp=50.0):
    """
    Follow the online plan with a P tracker (feed-forward + kp feedback), held during ``hold``.

    Returns the tool's path, the plan's path and the phase per sample, the samples ``(i0, i1)``
    at which the hold began and ended, and the run.
    """
    run = skill.online(start, goal, online=gains)
    tool, held = run.x, []
    tools, plans, phases = [tool], [run.x], [run.phase]
    while not (run.done and run.t > skill.tau) and run.t < 4 * skill.tau:
        holding = hold[0] * skill.tau <= run.t < hold[1] * skill.tau
        if holding:
            held.append(len(tools) - 1)
        x, v, _ = run.step(actual=tool)
        if not holding:
            tool = tool + run.dt * (v + kp * (x - tool))
        tools.append(tool)
        plans.append(x)
        phases.append(run.phase)
    return np.array(tools), np.array(plans), np.array(phases), (held[0], held[-1] + 1), run


@pytest.mark.parametrize('name', ['G', 'stir'])
def test_phase_stopping_waits_for_a_held_tool_and_then_finishes_the_shape(skills, name):
    skill = skills[name]
    start, goal = skill.start, skill.goal
    nominal = skill.generalize(start, goal)
    gains = OnlineGains()
    tool, plan, phase, (i0, i1), run = _track(skill, start, goal, gains, (0.3, 0.8))
    hold_time = (i1 - i0) * run.dt
    assert hold_time == pytest.approx(0.5 * skill.tau, abs=1.5 * run.dt)
    np.testing.assert_array_equal(tool[i0:i1 + 1], np.repeat(tool[i0][None], i1 + 1 - i0, 0))
    # The phase waits: while held, its time advances by less than 20 % of the hold.
    assert np.log(phase[i0] / phase[i1]) * skill.tau / skill.alpha <= 0.2 * hold_time
    # The plan does not run away: it creeps away from the held tool by no more than the bound of
    # docs/design.md#online-goal, (3 V T / (alpha_err l))^(1/3) l (V: top speed, T: the hold).
    length = skill.size          # the demonstration's own start and goal: l = L
    speed = np.max(np.linalg.norm(nominal.v, axis=1))
    creep = (3 * speed * hold_time / (gains.alpha_err * length)) ** (1 / 3) * length
    lead = np.linalg.norm(plan[i0:i1 + 1] - tool[i0], axis=1)
    assert lead.max() <= lead[0] + creep
    # Released, it finishes the shape: the tool's path stays close to the demonstrated path
    # (no corner cut) and ends at the goal.
    assert run.done and np.linalg.norm(tool[-1] - goal) <= 2e-3 * skill.size
    path = np.array([np.min(np.linalg.norm(nominal.x - p, axis=1)) for p in tool])
    assert path.max() <= 0.06 * skill.size
    # Without phase stopping the plan runs on, and the released tool cuts the corner.
    tool_off, plan_off, _, (j0, j1), _ = _track(skill, start, goal, OnlineGains(alpha_err=0.0),
                                                (0.3, 0.8))
    cut = np.array([np.min(np.linalg.norm(nominal.x - p, axis=1)) for p in tool_off])
    assert cut.max() >= 1.5 * path.max()
    assert np.max(np.linalg.norm(plan_off[j0:j1 + 1] - tool_off[j0], axis=1)) >= 2 * lead.max()
    assert nrmse(np.r_[tool[:i0], tool[i1:]], nominal.x) < nrmse(
        np.r_[tool_off[:j0], tool_off[j1:]], nominal.x)


def test_phase_stopping_rate(skills):
    skill = skills['G']
    run = skill.online(skill.start, skill.goal)
    length = skill.size          # the demonstration's own placement: l = L
    run.step(actual=run.x + np.array([0.03 * length, 0.0]))
    assert run.rate == pytest.approx(1.0 / (1.0 + 1000.0 * 0.03 ** 2))
    run.step(actual=run.x)
    assert run.rate == 1.0
    far = skill.online(skill.start, skill.goal)
    far.step(actual=far.x + 1e200)
    assert 0.0 < far.rate <= 1e-9 and np.all(np.isfinite(far.x))


# ------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize('kwargs, message', [
    ({'goal': [np.nan, 0.0]}, 'NaN'),
    ({'goal': [0.0, 0.0, 0.0]}, 'shape'),
    ({'goal': 'here'}, 'numeric'),
    ({'goal': 'start'}, "movement's start"),
    ({'obstacles': [[np.inf, 0.0]]}, 'NaN'),
    ({'obstacles': [[1.0, 2.0, 3.0]]}, 'shape'),
    ({'obstacles': 'goal'}, 'obstacle lies on the goal'),
    ({'goal': 'obstacle', 'obstacles': [[5.0, 5.0]]}, 'obstacle lies on the goal'),
    ({'actual': [0.0, np.nan]}, 'NaN'),
    ({'actual': [[0.0, 1.0]]}, 'shape'),
])
def test_bad_step_input_is_refused_and_nothing_is_lost(skills, kwargs, message):
    skill = skills['G']
    start, goal, new_goal = goal_jump_case(skill)
    run, twin = skill.online(start, goal), skill.online(start, goal)
    roll(run, 30, goals={10: new_goal})
    roll(twin, 30, goals={10: new_goal})
    before = (run.t, run.x, run.v, run.a, run.goal, run.filtered_goal, run.phase)
    resolved = {key: (start if value == 'start' else [run.goal] if value == 'goal' else
                      [5.0, 5.0] if value == 'obstacle' else value)
                for key, value in kwargs.items()}
    with pytest.raises(GeneralizationError, match=message):
        run.step(**resolved)
    after = (run.t, run.x, run.v, run.a, run.goal, run.filtered_goal, run.phase)
    for a, b in zip(before, after):
        np.testing.assert_array_equal(a, b)
    # It goes on exactly as a run that never saw the bad call.
    np.testing.assert_array_equal(roll(run, 20)[0], roll(twin, 20)[0])


def test_plain_dmp_goal_that_divides_by_zero_is_refused():
    t = np.linspace(0.0, 1.0, 150)
    s = 10 * t ** 3 - 15 * t ** 4 + 6 * t ** 5
    skill = learn(np.c_[0.15 * np.sin(2 * np.pi * s), 1.0 - s])     # start and goal share x
    run = skill.online(skill.start, skill.goal, method='dmp')
    run.step()
    with pytest.raises(GeneralizationError, match='coincide'):
        run.step(goal=skill.goal + np.array([0.5, 0.0]))
    etdmp = skill.online(skill.start, skill.goal)
    roll(etdmp, 400, goals={20: skill.goal + np.array([0.5, 0.0])})
    assert etdmp.done and np.linalg.norm(etdmp.x - etdmp.goal) <= 1e-3 * skill.size


@pytest.mark.parametrize('kwargs, message', [
    ({'start': [[1.0, 1.0], [2.0, 2.0]]}, 'one movement'),
    ({'goal': [[0.0, 0.0], [1.0, 1.0]]}, 'one movement'),
    ({'start': [np.nan, 1.0]}, 'NaN'),
    ({'start': [0.0, 0.0]}, 'start equals goal'),
    ({'method': 'spline'}, 'method'),
    ({'dt': 0.0}, 'dt'),
    ({'tau': -1.0}, 'tau'),
    ({'online': OnlineGains(alpha_goal=0.0)}, 'alpha_goal'),
    ({'online': OnlineGains(alpha_goal=np.nan)}, 'alpha_goal'),
    ({'online': OnlineGains(alpha_err=-1.0)}, 'alpha_err'),
    ({'online': OnlineGains(alpha_err=np.inf)}, 'alpha_err'),
    ({'online': OnlineGains(done_tolerance=0.0)}, 'done_tolerance'),
    ({'online': OnlineGains(alpha_goal='fast')}, 'alpha_goal'),
    ({'online': {'alpha_goal': 1.0}}, 'OnlineGains'),
])
def test_bad_online_requests(skills, kwargs, message):
    skill = skills['G']
    request = dict({'start': [3.0, 3.0], 'goal': [0.0, 0.0]}, **kwargs)
    with pytest.raises(GeneralizationError, match=message):
        skill.online(**request)
    assert isinstance(skill.online([3.0, 3.0], [0.0, 0.0]), OnlineRun)


# ------------------------------------------------------------------ three ways to handle a jump
@pytest.mark.parametrize('name', ['G', 'W', 'stir'])
def test_online_is_best_on_continuity_and_no_worse_than_replanning_on_shape(skills, name):
    """Compare as docs/design.md#online-goal does: a goal jump at 40 % of the movement."""
    skill = skills[name]
    start, goal, new_goal = goal_jump_case(skill)
    results, reference = compare_goal_jump(skill, start, goal, new_goal)
    assert list(results) == list(GOAL_JUMP_WAYS)
    online, replan, plain = (results[way] for way in ('online', 'replan', 'dmp'))
    top_speed = np.abs(reference.v).max()
    # Continuity: (a) has the smallest velocity and acceleration steps.
    assert online.velocity_step < min(replan.velocity_step, plain.velocity_step)
    assert online.acceleration_step < min(replan.acceleration_step, plain.acceleration_step)
    assert online.velocity_step <= 0.02 * top_speed        # (b) jumps by most of the speed
    assert replan.velocity_step >= 0.5 * top_speed
    assert online.acceleration_step <= 0.3 * plain.acceleration_step
    # Shape: (a) is no worse than (b), in nRMSE and in distance to the placed demonstration.
    assert online.shape_nrmse <= replan.shape_nrmse
    assert online.shape_error <= replan.shape_error
    # Each ends near the new goal at its own nominal end.
    for result in results.values():
        assert result.final_distance <= 0.01 * skill.size
        assert np.linalg.norm(result.x[-1] - new_goal) == pytest.approx(result.final_distance)
    assert online.end_time == pytest.approx(skill.tau)
    assert replan.end_time == pytest.approx(1.4 * skill.tau, abs=skill.dt)


@pytest.mark.parametrize('name, mode, obstacles, hold', [
    ('G', 1, False, False), ('G', 1, True, False), ('W', 1, False, True),
    ('stir', 1, False, False), ('stir', 2, True, False)])
def test_run_is_the_steps_in_one_call(skills, name, mode, obstacles, hold):
    # run(t_max) (batched placements, one numba loop) gives the samples of step() calls and
    # leaves the run where they leave it; also after phase stopping (off the offline grid).
    skill = skills[name]
    if skill.dim == 2:
        start = skill.goal + np.array([[0.0, -1.0], [1.0, 0.0]]) @ (skill.start - skill.goal)
        jump = 0.2 * skill.size * np.array([1.0, 0.3])
    else:
        start = skill.start + 0.1 * skill.size * np.array([1.0, -0.5, 0.2])
        jump = 0.15 * skill.size * np.array([1.0, 0.5, 0.0])
    obs = [0.5 * (start + skill.goal) + 0.05 * skill.size] if obstacles else ()
    a = skill.online(start, skill.goal, obs, mode=mode, dt=0.01)
    for k in range(int(0.4 * a.tau / a.dt)):
        a.step(actual=a.x + (0.02 * skill.size if hold and k > 20 else 0.0))
    a.step(goal=skill.goal + jump)
    b = a.copy()
    t, x, v, acc = a.run(3.0 * a.tau)
    rows = []
    while not b.done and b.t < 3.0 * b.tau - 0.5 * b.dt:
        rows.append(b.step())
    assert len(rows) == len(t) > 10 and a.done == b.done and a.t == pytest.approx(b.t)
    np.testing.assert_allclose(t, b.t - b.dt * np.arange(len(t))[::-1], atol=1e-9)
    ref = [np.array([r[i] for r in rows]) for i in range(3)]
    assert np.abs(x - ref[0]).max() <= 1e-9 * skill.size
    assert np.abs(v - ref[1]).max() <= 1e-9 * np.abs(ref[1]).max()
    assert np.abs(acc - ref[2]).max() <= 1e-9 * np.abs(ref[2]).max()
    # ... and both go on alike.
    np.testing.assert_allclose(a.step(goal=skill.goal)[0], b.step(goal=skill.goal)[0],
                               atol=1e-9 * skill.size)


@pytest.mark.parametrize('name, obstacles', [('G', False), ('G', True), ('stir', True)])
def test_take_predict_restore_and_replay_are_step_and_run_without_stepping(
        skills, name, obstacles):
    # The what-if API a plan in execution uses (following.FollowedPlan): take() is step()'s
    # input without the step, predict() is run() without advancing, restore() puts one of its
    # samples in force, replay() makes such samples from a rollout computed elsewhere.
    skill = skills[name]
    start = skill.start + 0.1 * skill.size * np.ones(skill.dim)
    jump = 0.15 * skill.size * np.eye(skill.dim)[0]
    obs = [0.5 * (start + skill.goal) + 0.05 * skill.size] if obstacles else ()
    radii = [0.02 * skill.size] if obstacles else None
    run = skill.online(start, skill.goal, obs, dt=0.01, obstacle_radii=radii)
    # replay: the run's own samples (with the detour's displacement) give the rows back.
    rows = run.predict(40)
    x, v, a = run.outputs(rows)
    replayed = run.replay(x, v, a)
    for field in ('t', 'x', 'v', 'a', 'goal_f', 'R', 'theta'):
        np.testing.assert_allclose(getattr(replayed, field), getattr(rows, field),
                                   atol=1e-12 * skill.size)
    for _ in range(30):
        run.step()
    # take: the new goal in force, nothing stepped; the next step is step(goal=...)'s.
    t0, x0 = run.t, run.x
    taken, stepped = run.copy(), run.copy()
    taken.take(goal=skill.goal + jump)
    assert taken.t == t0 and np.array_equal(taken.x, x0)
    np.testing.assert_array_equal(taken.goal, skill.goal + jump)
    np.testing.assert_array_equal(taken.filtered_goal, skill.goal)
    np.testing.assert_array_equal(taken.step()[0], stepped.step(goal=skill.goal + jump)[0])
    with pytest.raises(GeneralizationError, match='NaN|finite'):
        taken.take(goal=np.full(skill.dim, np.nan))
    with pytest.raises(GeneralizationError, match='obstacle_radii given without obstacles'):
        taken.take(obstacle_radii=[0.1])
    assert taken.t == stepped.t and np.array_equal(taken.x, stepped.x)
    # The filter moves now: no replay; predict is run without advancing.
    assert taken.replay(x[:3], v[:3], a[:3]) is None
    before = (taken.t, taken.x.copy(), taken.filtered_goal)
    rows = taken.predict(int(2 * taken.tau / taken.dt))
    assert taken.t == before[0]
    np.testing.assert_array_equal(taken.x, before[1])
    np.testing.assert_array_equal(taken.filtered_goal, before[2])
    ran = taken.copy()
    t, xs, vs, accs = ran.run(taken.t + 2 * taken.tau)
    np.testing.assert_array_equal(rows.t, t)
    for got, want in zip(taken.outputs(rows), (xs, vs, accs)):
        np.testing.assert_array_equal(got, want)
    # restore: the run as the steps left it at sample i, going on alike.
    i = len(rows.t) // 3
    restored, reference = taken.copy(), taken.copy()
    restored.restore(rows, i)
    for _ in range(i + 1):
        reference.step()
    assert restored.t == pytest.approx(reference.t) and restored.t == pytest.approx(rows.t[i])
    assert np.abs(restored.x - reference.x).max() <= 1e-9 * skill.size
    assert np.abs(restored.step()[0] - reference.step()[0]).max() <= 1e-9 * skill.size

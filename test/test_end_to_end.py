"""
End to end (issue 7): see the goal, plan with ET-DMP, write with the simulated UR10, measure.

The four INSTALLED nodes (``<install>/lib/etdmp_ros/<node>`` after sourcing the colcon install,
what ``ros2 run`` runs; parameters from the install's share folder) run as separate processes
on an isolated DDS domain, driven by the demo's code (:func:`etdmp_ros.demo.run_demo`, what
``make demo`` runs; the nodes started by :mod:`etdmp_ros.processes`): goal and obstacles
perceived from the camera images, ``/generalize`` called with empty frame ids (the DMP baseline
without execution first), the controller executing the ET-DMP plan. Checked against the
simulation's ground truth, for the letter G and for stirring in 3D, each on an idle machine and
next to a process busy-looping on one core: while the arm moves, commands at 0.95 of the
control rate or more per simulated second, within the UR10's velocity and the controller's
acceleration limits; the true pen trace reaches the goal within 5 mm, clears every obstacle and
keeps the demonstration's shape (nRMSE at most twice the plan's), and the DMP baseline from the
same start is clearly worse. One run per skill and load (~15 s each) serves all the checks.
"""

import json

from conftest import busy_core
from etdmp_ros import demo, system
from etdmp_ros.config_files import read_parameter_file
from etdmp_ros.processes import installed_command
import numpy as np
import pytest

SKILLS = ('G', 'stir')
#: Each skill idle, and next to a process busy-looping on one of the two cores (another user
#: on the machine): the closed loop must keep its rate either way.
CASES = [(skill, load) for load in ('idle', 'busy') for skill in SKILLS]
#: nRMSE below which a ratio means nothing: the DMP's own fit of the demonstration and a
#: tracking error of ~0.1 mm on a 0.2 m movement are of this order. ET-DMP's stirring plan
#: (no obstacle near it) is an exact copy of the demonstration: nRMSE 1.5e-4.
NRMSE_FLOOR = 1e-3


@pytest.fixture(scope='module', params=CASES, ids=[f'{s}-{load}' for s, load in CASES])
def run(request, colcon_install, module_ros_env, tmp_path_factory):
    """Run the closed-loop demo once for a skill and load; return (metrics, output folder)."""
    skill, load = request.param
    out = tmp_path_factory.mktemp(f'demo_{skill}_{load}')
    env = dict(module_ros_env, ROS_HOME=str(out / 'ros_home'))
    options = demo.Options(skill=skill, out=out, animation=False, quiet=True,
                           config_dir=colcon_install / 'share' / 'etdmp_ros' / 'config',
                           command=installed_command(colcon_install))
    with busy_core(load == 'busy'):
        metrics, _ = demo.run_demo(options, env)
    return metrics, out


def test_goal_and_obstacles_come_from_the_camera(run):
    m, _ = run
    assert m['obstacles'] and len(m['perceived_obstacle_errors_mm']) == len(m['obstacles'])
    assert max(m['perceived_obstacle_errors_mm']) < 3.0
    assert m['perceived_goal_error_mm'] < 3.0
    # dmp_server runs on simulated time: its plan is stamped with the simulation's clock, not
    # the wall clock (~1.8e9 s).
    assert abs(m['plan_stamp_minus_sim_time_s']) < 1.0


def test_generalize_with_empty_frame_ids_plans_from_the_tool(run):
    m, _ = run
    tool = np.array(m['tool_at_call'])
    start, end = np.array(m['start']), np.array(m['plan_end'])
    if m['skill'] == 'stir':
        # 3D skill in base_link: from the tool itself to the requested goal in the bottle.
        assert m['goal_source'] == 'explicit'
        assert np.linalg.norm(start - tool) < 1e-3
        assert np.linalg.norm(end - np.array(m['goal'])) < 1e-3
    else:
        # 2D skill: the tool and the perceived goal projected onto the task plane (z = 0).
        assert m['goal_source'] == 'perceived marker'
        assert np.linalg.norm(start - [tool[0], tool[1], 0.0]) < 1e-3
        goal = np.array(m['perceived_goal'])
        assert np.linalg.norm(end - [goal[0], goal[1], 0.0]) < 1e-3
        # The pen starts in another quadrant of the goal than in the demonstration.
        assert m['start_quadrant'] != m['demo_quadrant']


def test_commands_move_the_arm_within_its_limits(run):
    m, _ = run
    # Commands at the controller's 125 Hz while the arm moves (approach + plan + hold: from the
    # first non-zero command to the last), per simulated second, idle or next to a busy core.
    rate = float(read_parameter_file(system.parameter_files('controller')[1],
                                     'controller')['control_rate'])
    assert m['system']['moving_commands_per_s'] >= 0.95 * rate
    assert 0.05 < m['max_joint_velocity_ratio'] <= 1.0 + 1e-9
    assert m['max_joint_acceleration_ratio'] <= 1.0 + 1e-9
    assert m['controller_failure'] is None
    # Tracked the plan, then held its end (an 'idle' may come first: the recording can start
    # before the path arrives).
    status = m['controller_status']
    assert 'tracking' in status and 'holding' in status, status
    assert status.index('tracking') < status.index('holding'), status


def test_trace_reaches_the_goal_clears_obstacles_and_keeps_the_shape(run):
    m, _ = run
    assert m['goal_error_mm'] < 5.0
    assert m['min_clearance_mm'] > 0.0
    assert m['nrmse_trace'] <= 2.0 * max(m['nrmse_plan'], NRMSE_FLOOR)
    assert m['tracking_rms_mm'] < 1.0
    if m['skill'] == 'G':
        # The obstacles sit on the obstacle-free path: the avoidance is real.
        assert m['min_clearance_plan_mm'] > 0.0 and m['nrmse_plan'] > 0.05
    else:
        assert m['bottle_wall_clearance_mm'] > 0.0


def test_dmp_baseline_from_the_same_start_is_worse(run):
    m, _ = run
    assert m['method'] == 'etdmp'
    assert m['nrmse_dmp_baseline'] > 2.0 * m['nrmse_plan'] + 0.02


def test_outputs_and_clean_shutdown(run):
    m, out = run
    for name in ('plot.png', 'camera_start.png', 'camera_middle.png', 'camera_end.png',
                 'metrics.json', 'recording.npz'):
        assert (out / name).stat().st_size > 1000, name
    saved = json.loads((out / 'metrics.json').read_text())
    for key in ('skill', 'method', 'nrmse_plan', 'nrmse_trace', 'nrmse_dmp_baseline',
                'tracking_rms_mm', 'tracking_max_mm', 'min_clearance_mm', 'goal_error_mm',
                'duration_s'):
        assert saved[key] == m[key]
    # SIGINT stops every node cleanly.
    codes = m['node_exit_codes']
    assert [codes[n] for n in ('ur10_sim', 'perception', 'dmp_server', 'controller')] == [0] * 4

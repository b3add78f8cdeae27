"""
Kinesthetic teaching, through the installed ur10_sim and then the whole system.

1. :func:`etdmp_ros.demo.kinesthetic.record` (``make kinesthetic``) starts the installed ur10_sim,
   sets its ``teach_script`` as ``ros2 param set`` would (the teaching mode leads the arm
   through a stir as a hand in freedrive would) and records ``/joint_states`` to a rosbag2
   ``.mcap``, with the simulation's true tool tip beside it.
2. The demonstration read from that bag (the controller's forward kinematics, trimmed to the
   motion) is the true tool path, checked against the simulation's ground truth.
3. The demo (``make demo SKILL=stir DEMO_FILE=<bag>``) has dmp_server learn the skill from the
   bag (``demo_files``) and the robot repeat it with ET-DMP from a start 150 degrees round the
   bottle, in another quadrant: the true trace's nRMSE against the recorded tool path is at
   most 0.05, it ends at the goal and every command is within the limits.
"""

import math

from etdmp_ros.demo import kinesthetic, run as demo
from etdmp_ros.demo.scenario import Scenario, TAUGHT_STIR_TURN_DEG
from etdmp_ros.dmp import learn, load_demo
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.robot import UR10Model
from etdmp_ros.ros.processes import installed_command
from etdmp_ros.skills.library import load_demonstration
from etdmp_ros.skills.recorded import _motion_span
from etdmp_ros.skills.recordings import read_messages
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.serialization import deserialize_message

#: The script's moving part lasts 6 s, with 0.5 s of rest before and after it.
MOVING = 6.0


def _config(install):
    return install / 'share' / 'etdmp_ros' / 'config'


@pytest.fixture(scope='module')
def taught(colcon_install, module_ros_env, tmp_path_factory):
    """Record the stir by hand; return (bag path, message counts, scenario of the repeat)."""
    out = tmp_path_factory.mktemp('kinesthetic')
    env = dict(module_ros_env, ROS_HOME=str(out / 'ros_home'))
    path, counts = kinesthetic.record(out, env, config_dir=_config(colcon_install),
                                      command=installed_command(colcon_install),
                                      progress=lambda *_: None)
    scenario = Scenario(_config(colcon_install), 'stir', demo_file=path)
    return path, counts, scenario


@pytest.fixture(scope='module')
def repeated(taught, colcon_install, module_ros_env, tmp_path_factory):
    """Run the demo with the taught stir; return its metrics."""
    out = tmp_path_factory.mktemp('kinesthetic_demo')
    env = dict(module_ros_env, ROS_HOME=str(out / 'ros_home'))
    options = demo.Options(skill='stir', out=out, animation=False, quiet=True,
                           config_dir=_config(colcon_install),
                           command=installed_command(colcon_install), demo_file=taught[0])
    metrics, _ = demo.run_demo(options, env)
    return metrics


def test_the_recording_holds_the_joint_states_of_the_whole_movement(taught):
    path, counts, _ = taught
    assert path.suffix == '.mcap' and (path.parent / 'metadata.yaml').exists()
    assert counts['/joint_states'] >= 0.9 * 125 * (MOVING + 1.0)


def test_the_learned_demonstration_is_the_true_tool_path_trimmed_to_the_motion(taught):
    path, _, scenario = taught
    recorded = load_demonstration(path, scenario.plane, kinematics=UR10Model(
        tool_offset=scenario.scene['tool_offset']))
    assert recorded.dim == 3 and recorded.name == path.stem
    script = load_demo(path.parent / f'{path.stem}_script.csv')
    first, last = _motion_span(script.positions)       # the script's motion, by the same rule
    assert recorded.duration == pytest.approx(script.t[last] - script.t[first], abs=0.15)
    assert recorded.duration < script.duration - 2 * kinesthetic.REST + 0.1
    truth = {}
    for topic, _, _, data in read_messages(path, ['/ur10_sim/ground_truth/tool_tip']):
        msg = deserialize_message(data, PointStamped)
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        truth[stamp] = [msg.point.x, msg.point.y, msg.point.z]
    t0 = np.array(list(truth))[np.argmin(np.linalg.norm(
        np.array(list(truth.values())) - recorded.positions[0], axis=1))]
    stamps = t0 + np.round(recorded.t * 1e9).astype(np.int64)
    matched = [k for k, s in enumerate(stamps) if int(s) in truth]
    assert len(matched) > 0.9 * len(stamps)
    true = np.array([truth[int(stamps[k])] for k in matched])
    assert np.linalg.norm(recorded.positions[matched] - true, axis=1).max() < 1e-4
    speed = np.linalg.norm(np.diff(recorded.positions, axis=0), axis=1) / np.diff(recorded.t)
    assert max(speed[0], speed[-1]) < 0.1 * speed.max()      # from (near) rest to rest


def test_the_skill_learned_from_the_recording_comes_to_rest_at_its_goal(taught):
    """Issue 24 on a kinesthetic recording: every plan at its goal, at rest, also past tau."""
    path, _, scenario = taught
    recorded = load_demonstration(path, scenario.plane, kinematics=UR10Model(
        tool_offset=scenario.scene['tool_offset']))
    goal = recorded.positions[-1]
    offset = np.linalg.norm(recorded.positions[0] - goal)
    octants = np.array([[x, y, z] for x in (1, -1) for y in (1, -1) for z in (1, -1)])
    starts = np.vstack([recorded.positions[0], goal + offset * octants / math.sqrt(3.0)])
    for formulation in ('ijspeert', 'hoffmann'):
        skill = learn(recorded, formulation=formulation)
        for method, mode in (('etdmp', 1), ('etdmp', 2), ('dmp', 1)):
            traj = skill.generalize(starts, goal, method=method, mode=mode, margin=1.0,
                                    dt=skill.tau / 500)
            dist = np.linalg.norm(traj.x - goal, axis=2)
            k = (len(traj.t) - 1) // 2          # the sample at tau
            size = dist[:, :k + 1].max(axis=1)
            assert np.all(dist[:, k:].max(axis=1) <= 0.005 * size), (method, mode)
            assert np.all(dist[:, -1] <= 0.001 * size)
            assert np.all(np.linalg.norm(traj.v[:, -1], axis=1) * skill.tau <= 0.01 * size)
        # Its recorded orientations: a goal orientation a half turn away, reached at tau.
        q_goal = quat.multiply(quat.about_axis(np.array([0.0, 0.0, 1.0]), math.pi),
                               recorded.orientations[-1])
        traj = skill.generalize(starts[:3], goal, goal_orientation=q_goal, dt=skill.tau / 500)
        assert np.all(np.degrees(quat.angle_between(traj.q[:, -1], q_goal[None])) <= 0.1)


def test_the_robot_repeats_the_taught_stir_from_another_quadrant(taught, repeated):
    _, _, scenario = taught
    m = repeated
    assert m['skill'] == 'stir'
    goal = np.array(m['goal'])
    start, recorded_start = np.array(m['start']), scenario.demo.positions[0] + \
        scenario.bottle_mouth
    turn = math.degrees(abs(math.remainder(
        math.atan2(*(start - goal)[1::-1]) - math.atan2(*(recorded_start - goal)[1::-1]),
        2 * math.pi)))
    assert turn == pytest.approx(TAUGHT_STIR_TURN_DEG, abs=2.0)      # another quadrant
    assert m['nrmse_trace'] <= 0.05, m
    assert m['goal_error_mm'] <= 5.0
    assert m['max_joint_velocity_ratio'] <= 1.0 and m['max_joint_acceleration_ratio'] <= 1.0

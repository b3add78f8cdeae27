"""
End to end: see the goal, plan with ET-DMP, write with the simulated UR10, measure.

The four INSTALLED nodes (``<install>/lib/etdmp_ros/<node>`` after sourcing the colcon install,
what ``ros2 run`` runs; parameters from the install's share folder) run as separate processes
on an isolated DDS domain, driven by the demo's code (:func:`etdmp_ros.demo.run.run_demo`, what
``make demo`` runs; the nodes started by :mod:`etdmp_ros.ros.processes`): goal and obstacles
perceived from the camera images, ``/generalize`` called with empty frame ids (the DMP baseline
without execution first), the controller executing the ET-DMP plan. Checked against the
simulation's ground truth, for the letter G and for stirring in 3D, each on an idle machine and
next to a process busy-looping on one core: while the arm moves, commands at 0.95 of the
control rate or more per simulated second, within the UR10's velocity and the controller's
acceleration limits; the true pen trace reaches the goal within 5 mm, clears every obstacle and
keeps the demonstration's shape (nRMSE at most twice the plan's), and the DMP baseline from the
same start is clearly worse. One run per skill and load (~15 s each) serves all the checks.

Orientation, case ``wipe-idle`` besides ``stir``: the stirrer tilts and circles, the
sponge turns along the stroke. The true tool orientation (forward kinematics of the
simulation's /joint_states; the model's tip is the simulation's ground-truth tip) is within
0.5 degree RMS and 2 degrees max of the plan's at the same path time and of the controller's
reference, and the plan's orientations are the demonstration's turned by the Euclidean
transform (computed independently in ``etdmp_ros.demo.metrics``) within 0.5 degree.

Online ET-DMP, case ``G-move`` (idle only): while the pen writes G, the goal marker
is moved by 4 cm (ur10_sim's ``goal_position``, as ``ros2 param set`` would; the demo's
``--move-goal``). The pen ends within 2 mm of the new marker, every command within the
velocity and acceleration limits, no stop-and-go at the switch of plans (the tool's speed at
least 20 % of the plan's there, unless the plan itself slows) and no second approach, and the
trace keeps the demonstration's shape placed at the new goal (nRMSE within the move's own
cost, online ET-DMP's in the core, plus twice the no-move run's + 0.05; the G-idle run's metrics
are reused).

Contacts: in every run the simulation's ground truth (/ur10_sim/ground_truth/contacts,
recorded in demo.mcap) shows no link and not the tool touching an obstacle, the bottle or the
table: metrics.json's ``contacts`` is 0. The letters P and R (idle, written in the demo's 4 s)
and W in its own 2 s (the "unexplained stop" once seen) are run for that too, each written to
its end: tracked, held, the goal reached within 5 mm, commands within the limits.

Case ``stir-move`` (idle only): the same checks while stirring, with the bottle moved by 2 cm
(ur10_sim's ``bottle.position``) at 5 % of the stir, the stirrer coming down towards its mouth;
the request targets the perceived bottle (/etdmp/bottle, dmp_server's ``goal_object: bottle``
with the demonstration's goal offset). The stirrer ends within 2 mm of the goal in the moved
bottle and never touches its wall (the clearance against the bottle where it stood at each
moment); the stir-idle run is the no-move one.
"""

from collections import defaultdict
import json

from conftest import busy_core
import cv2
from etdmp_ros.demo import run as demo
from etdmp_ros.demo.cli import summary
from etdmp_ros.demo.recording import NOT_RECORDED, read_streams
from etdmp_ros.ros import system
from etdmp_ros.ros.config_files import read_parameter_file
from etdmp_ros.ros.conversions import tf_available
from etdmp_ros.ros.processes import installed_command
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from support.ros2_cli import readme_topics
import yaml

SKILLS = ('G', 'stir')
#: Each skill idle, and next to a process busy-looping on one of the two cores (another user
#: on the machine): the closed loop must keep its rate either way. Wipe (the sponge turning
#: along the stroke) idle only.
CASES = [(skill, load) for load in ('idle', 'busy') for skill in SKILLS] + [('wipe', 'idle')]
#: Skills whose demonstrations carry orientations: the tool turns as planned.
TURNING = ('stir', 'wipe')
#: nRMSE below which a ratio means nothing: the DMP's own fit of the demonstration and a
#: tracking error of ~0.1 mm on a 0.2 m movement are of this order. ET-DMP's stirring plan
#: (no obstacle near it) is an exact copy of the demonstration: nRMSE 1.5e-4.
NRMSE_FLOOR = 1e-3
#: The recording of a G or stir demo must stay this small (bytes).
BAG_LIMIT = 30e6


#: The runs of this module, (skill, load, move_goal) -> (metrics, output folder): the moved-goal
#: case compares with the G-idle run without running it again.
_RUNS = {}


def _run(case, colcon_install, env, tmp_path_factory, duration=None):
    if case not in _RUNS:
        skill, load, move = case
        out = tmp_path_factory.mktemp(f'demo_{skill}_{load}' + ('_move' if move else ''))
        env = dict(env, ROS_HOME=str(out / 'ros_home'))
        options = demo.Options(skill=skill, out=out, animation=False, quiet=True,
                               config_dir=colcon_install / 'share' / 'etdmp_ros' / 'config',
                               command=installed_command(colcon_install), move_goal=move,
                               parameters={} if duration is None else
                               {'dmp_server': {'duration': duration}})
        with busy_core(load == 'busy'):
            metrics, _ = demo.run_demo(options, env)
        _RUNS[case] = metrics, out
    return _RUNS[case]


@pytest.fixture(scope='module', params=CASES, ids=[f'{s}-{load}' for s, load in CASES])
def run(request, colcon_install, module_ros_env, tmp_path_factory):
    """Run the closed-loop demo once for a skill and load; return (metrics, output folder)."""
    skill, load = request.param
    return _run((skill, load, False), colcon_install, module_ros_env, tmp_path_factory)


#: How far the goal moves with --move-goal (mm): 3-5 cm for a letter, 2 cm for the
#: bottle.
MOVE_RANGE_MM = {'G': (30.0, 50.0), 'stir': (19.9, 20.1)}


@pytest.fixture(scope='module', params=['G', 'stir'], ids=['G-move', 'stir-move'])
def moved(request, colcon_install, module_ros_env, tmp_path_factory):
    """
    Run the demo with the goal marker (stir: the bottle) moved while the tool moves (idle).

    Return (metrics, output folder, metrics of the same skill without the move).
    """
    skill = request.param
    still, _ = _run((skill, 'idle', False), colcon_install, module_ros_env, tmp_path_factory)
    metrics, out = _run((skill, 'idle', True), colcon_install, module_ros_env,
                        tmp_path_factory)
    return metrics, out, still


#: The letters run for their contacts only (the others run above), and the duration (s, None:
#: the demo's) each is written in: the W in its own 2 s.
LETTERS = [('P', None), ('R', None), ('W', 2.0)]


@pytest.fixture(scope='module', params=LETTERS, ids=[f'{s}-{d or "demo"}s' for s, d in LETTERS])
def letter(request, colcon_install, module_ros_env, tmp_path_factory):
    """Run the demo for one of LETTERS, idle, in its duration; return its metrics, folder."""
    skill, duration = request.param
    return _run((skill, f'{duration}s' if duration else 'idle', False), colcon_install,
                module_ros_env, tmp_path_factory, duration)


def _assert_no_contact(m):
    assert m['contacts'] == 0, (m['contacts'], m['contact_pairs'], m['contact_max_depth_mm'])
    assert m['contact_pairs'] == []


def test_the_arm_touches_nothing(run):
    _assert_no_contact(run[0])


def test_every_letter_is_written_to_its_end_without_contact(letter):
    m, out = letter
    _assert_no_contact(m)
    _assert_commands_within_limits(m)
    # The same bounds as the other runs' (test_trace_reaches_the_goal_...).
    assert m['goal_error_mm'] < 5.0
    assert m['tracking_rms_mm'] < 1.0
    assert m['min_clearance_mm'] > 0.0
    assert 'contacts (simulation): none' in summary(m, [])
    if m['skill'] == 'W':
        # In its own 2 s, no stop. The plan lasts exactly the 2 s asked for: the detour (the
        # avoidance with the perceived radii) keeps the obstacle-free timing; only the paper's
        # coupling adds the run-on obstacle_margin (0.5 tau, which made it 3 s before).
        assert m['plan_duration_s'] == pytest.approx(2.0, abs=0.02)
        assert 'contacts' in json.loads((out / 'metrics.json').read_text())


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


def test_commands_drive_the_arm_within_its_limits(run):
    _assert_commands_within_limits(run[0])


def _assert_commands_within_limits(m):
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
    elif m['skill'] == 'stir':
        assert m['bottle_wall_clearance_mm'] > 0.0


def test_the_tool_tilts_and_turns_as_planned(run):
    # The true tool orientation (forward kinematics of the simulation's joint states, whose
    # tip is the simulation's ground-truth tip) follows the plan's; the plan's orientations
    # are the demonstration's turned by the Euclidean transform.
    m, _ = run
    if m['skill'] not in TURNING:
        assert 'orientation_tracking_rms_deg' not in m
        return
    assert m['orientation_fk_vs_tip_max_mm'] < 0.01
    assert m['orientation_samples'] > 100
    assert m['orientation_plan_turn_deg'] > 9.0            # the tool does tilt / turn
    assert m['orientation_tracking_rms_deg'] <= 0.5
    assert m['orientation_tracking_max_deg'] <= 2.0
    assert m['orientation_tracking_vs_reference_rms_deg'] <= 0.5
    assert m['orientation_tracking_vs_reference_max_deg'] <= 2.0
    assert m['orientation_plan_vs_demo_turned_max_deg'] <= 0.5


def test_dmp_baseline_from_the_same_start_is_worse(run):
    m, _ = run
    assert m['method'] == 'etdmp'
    assert m['nrmse_dmp_baseline'] > 2.0 * m['nrmse_plan'] + 0.02


def test_outputs_and_clean_shutdown(run):
    m, out = run
    for name in ('plot.png', 'camera_start.png', 'camera_middle.png', 'camera_end.png',
                 'metrics.json', 'recording.npz', demo.BAG_NAME, 'metadata.yaml'):
        assert (out / name).stat().st_size > 1000, name
    saved = json.loads((out / 'metrics.json').read_text())
    for key in ('skill', 'method', 'nrmse_plan', 'nrmse_trace', 'nrmse_dmp_baseline',
                'tracking_rms_mm', 'tracking_max_mm', 'min_clearance_mm', 'goal_error_mm',
                'duration_s'):
        assert saved[key] == m[key]
    # SIGINT stops every node cleanly.
    codes = m['node_exit_codes']
    assert [codes[n] for n in ('ur10_sim', 'perception', 'dmp_server', 'controller')] == [0] * 4


def test_the_recording_holds_the_run_as_the_readme_lists_it(run):
    m, out = run
    path = out / demo.BAG_NAME
    assert 0 < path.stat().st_size <= BAG_LIMIT
    wanted = ('/forward_velocity_controller/commands', '/etdmp/path',
              '/camera/camera/color/image_raw/compressed',
              '/camera/camera/aligned_depth_to_color/image_raw/compressed')
    decoded = defaultdict(list)
    with open(path, 'rb') as stream:        # read back with mcap-ros2-support, not our code
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        for _, channel, _, msg in reader.iter_decoded_messages(topics=list(wanted)):
            decoded[channel.topic].append(msg)
    types = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    counts = {c.topic: summary.statistics.channel_message_counts.get(c.id, 0)
              for c in summary.channels.values()}
    assert all(s.encoding == 'ros2msg' for s in summary.schemas.values())
    assert all(c.message_encoding == 'cdr' for c in summary.channels.values())

    # Every topic of docs/ros.md's table, with its type; images as image_transport's
    # compressed topic; /tf and /robot_description when the system publishes them.
    for topic, type_name in readme_topics(published_only=True)[0].items():
        if topic in NOT_RECORDED:   # left out on purpose, and said so
            assert topic not in types and topic in m['recording']['not_recorded'], topic
            continue
        if type_name == 'tf2_msgs/msg/TFMessage' and not tf_available():   # make ros-tools
            assert topic not in types, topic
            continue
        if type_name == 'sensor_msgs/msg/Image':
            topic, type_name = topic + '/compressed', 'sensor_msgs/msg/CompressedImage'
        assert topic in types, f'{topic} not recorded (recorded: {sorted(types)})'
        assert types[topic] == type_name, (topic, types[topic])
        # dmp_server builds markers only for a viewer matched when the plan is made (docs/
        # dmp_server.md; building them always costs ~4 ms per back-to-back /generalize call):
        # the recorder, subscribing as it discovers topics, may not be matched yet.
        assert counts[topic] > 0 or topic == '/etdmp/markers', topic
    for topic, type_name in (('/tf', 'tf2_msgs/msg/TFMessage'),
                             ('/robot_description', 'std_msgs/msg/String'),
                             ('/clock', 'rosgraph_msgs/msg/Clock'),
                             ('/rosout', 'rcl_interfaces/msg/Log')):
        assert types.get(topic, type_name) == type_name
    assert '/camera/camera/color/image_raw' not in types      # raw frames: compressed only

    # Counts: as the demo reported them and as rosbag2's metadata.yaml lists them.
    assert counts == m['recording']['message_counts']
    metadata = yaml.safe_load((out / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['relative_file_paths'] == [demo.BAG_NAME]
    assert {t['topic_metadata']['name']: t['message_count']
            for t in metadata['topics_with_message_count']} == counts
    assert counts['/ur10_sim/ground_truth/tool_tip'] >= 0.95 * 125 * m['duration_s']
    colour = counts['/camera/camera/color/image_raw/compressed']
    assert abs(colour - counts['/camera/camera/aligned_depth_to_color/image_raw/compressed']) <= 3
    # The camera publishes camera_info with every frame: no more than a few frames lost.
    assert colour >= 0.95 * counts['/camera/camera/color/camera_info'] - 3

    # The commands in the bag are the commands the demo measured; the plan is the executed one.
    recording = np.load(out / 'recording.npz')
    commands = np.array([msg.data for msg in decoded['/forward_velocity_controller/commands']])
    assert len(commands) == m['commands_received'] == counts[
        '/forward_velocity_controller/commands']
    np.testing.assert_array_equal(commands, recording['commands'])
    # The executed plan, then one remainder for each change dmp_server followed (an obstacle
    # the arm hid for a few frames can be seen moved: docs/dmp_server.md, Following).
    path_msg, *remainders = decoded['/etdmp/path']
    followed = [e for e in read_streams(path)['events']
                if e.node == 'dmp_server' and e.kind == 'followed']
    assert len(remainders) == len(followed), [e.message for e in followed]
    np.testing.assert_allclose([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                                for p in path_msg.poses], recording['plan_x'], atol=1e-12)
    # The images decode: JPEG colour, 16-bit PNG depth in mm.
    frame = decoded['/camera/camera/color/image_raw/compressed'][-1]
    assert 'jpeg' in frame.format
    assert cv2.imdecode(np.frombuffer(bytes(frame.data), np.uint8),
                        cv2.IMREAD_UNCHANGED).shape == (480, 640, 3)
    depth = decoded['/camera/camera/aligned_depth_to_color/image_raw/compressed'][-1]
    assert depth.format.startswith('16UC1; png')
    depth = cv2.imdecode(np.frombuffer(bytes(depth.data), np.uint8), cv2.IMREAD_UNCHANGED)
    assert depth.dtype == np.uint16 and depth.shape == (480, 640) and depth.max() > 500


# ------------------------------------------------------------------------- a goal that moves


def test_moved_goal_the_pen_ends_at_the_new_marker(moved):
    m, _, _ = moved
    low, high = MOVE_RANGE_MM[m['skill']]
    assert low <= m['goal_moved_by_mm'] <= high
    before, after = np.array(m['goal_marker_before']), np.array(m['goal_marker_after'])
    # The goal before the move: the marker, or (stir) the explicit goal in the unmoved bottle.
    first = np.array(m['true_goal_marker'] if m['skill'] != 'stir' else m['goal'])
    assert np.linalg.norm(before - first) < 1e-9
    assert np.linalg.norm(after - first) > 0.9 * low * 1e-3
    # goal_error_mm: to the marker's final position, projected onto the task plane; stir: to
    # the goal in the moved bottle (its mouth plus the demonstration's goal offset).
    assert m['goal_error_mm'] < 2.0, m['goal_error_mm']
    assert m['goal_error_vs_first_marker_mm'] > 0.9 * low
    assert np.linalg.norm(np.array(m['executed_plan_end'])[:2] - after[:2]) < 3e-3
    assert np.linalg.norm(np.array(m['perceived_goal_final']) - after) < 3e-3
    if m['skill'] == 'stir':
        assert m['goal_source'] == 'perceived bottle' and m['moved_object'] == 'bottle'


def test_moved_goal_no_contact(moved):
    _assert_no_contact(moved[0])


def test_moved_goal_commands_within_the_limits(moved):
    m, _, _ = moved
    _assert_commands_within_limits(m)
    assert m['tracking_rms_mm'] < 1.0


def test_moved_goal_no_stop_and_go_and_no_second_approach(moved):
    m, _, _ = moved
    assert m['plan_updates'] >= 1 and m['switch_path_time_s'] is not None
    # The marker moved at 40 % of the letter; dmp_server re-planned shortly after.
    follow = m['goal_follow']
    assert 0.0 < m['switch_path_time_s'] - follow['goal_moved_at_path_time_s'] < 1.0
    assert m['switch_speed_samples'] >= 20                       # 0.5 s at 125 Hz, mostly
    assert m['switch_speed_ratio_min'] >= 0.2, m['switch_speed_ratio_min']
    assert m['switch_tool_speed_min_fraction'] >= 0.2, m['switch_tool_speed_min_fraction']
    # The controller took the re-planned remainder over without an approach (stir starts at
    # the plan's start: no approach at all).
    words = [text.split(':')[0] for text in m['controller_status']]
    assert words.count('approaching') == (0 if m['skill'] == 'stir' else 1), words
    assert words.count('tracking') == 1 and words.index('tracking') < words.index('holding')
    assert 'approaching' not in words[words.index('tracking'):], words


def test_moved_goal_keeps_the_shape(moved):
    m, _, still = moved
    # The trace against the demonstration placed at the new goal (the nRMSE takes the trace
    # relative to its own end, the moved marker): what online ET-DMP itself makes of this move
    # (nrmse_move_reference: the core, no ROS, no obstacles, the same start, goals and switch)
    # plus twice the no-move run's + 0.05. The move's own cost is there however well the
    # system follows: the part written before the switch was written for the old goal (G:
    # ~0.37 with no obstacle at all). The bound without it (2 x no-move + 0.05) held only while
    # the paper's coupling made the no-move run cost 0.31; the detour's 0.06 leaves 0.17,
    # which online ET-DMP cannot reach for a goal moved at 45 % of the G.
    assert m['nrmse_move_reference'] is not None
    assert m['nrmse_trace'] <= (m['nrmse_move_reference'] + 2.0 * still['nrmse_trace']
                                + 0.05), (m['nrmse_trace'], m['nrmse_move_reference'],
                                          still['nrmse_trace'])
    assert m['min_clearance_mm'] > 0.0
    if m['skill'] == 'stir':
        # The stirrer never touched the bottle's wall, measured against the bottle where it
        # stood at each moment (the trace and the plan as executed).
        assert m['bottle_wall_clearance_mm'] > 0.0, m['bottle_wall_clearance_mm']
        assert m['bottle_wall_clearance_plan_mm'] > 0.0


def test_moved_goal_dmp_server_followed_it(moved):
    m, out, _ = moved
    # dmp_server's followed event, in the recording: the moved goal, where it was re-planned from.
    followed = [e for e in read_streams(out / demo.BAG_NAME)['events']
                if e.node == 'dmp_server' and e.kind == 'followed' and len(e.numbers('goal'))]
    assert followed, 'no followed event of dmp_server for the moved goal'
    follow = m['goal_follow']
    assert follow['dmp_server_ms'] == followed[0].number('took_ms')
    assert follow['replanned_from_path_time_s'] == followed[0].number('from_path_time_s')
    assert follow['updates'] >= 1
    for key in ('perception_latency_s', 'dmp_server_ms', 'controller_accept_ms',
                'end_to_end_ms', 'goal_change_to_first_command_s'):
        assert follow[key] is not None and follow[key] > 0.0, (key, follow)
    saved = json.loads((out / 'metrics.json').read_text())
    assert saved['goal_moved_by_mm'] == m['goal_moved_by_mm']
    assert saved['goal_error_mm'] == m['goal_error_mm']
    assert 'goal_follow' in saved['definitions']
    recording = np.load(out / 'recording.npz')
    assert len(recording['executed_x']) == len(recording['executed_t']) > 0
    assert (out / 'plot.png').stat().st_size > 1000
    codes = m['node_exit_codes']
    assert [codes[n] for n in ('ur10_sim', 'perception', 'dmp_server', 'controller')] == [0] * 4

"""Skill library: demonstrations from every source become skills; bad ones replace nothing."""

from pathlib import Path
import time

from etdmp_ros import limits
from etdmp_ros.dmp import (builtin_demo, builtin_demo_names, Demonstration, DemonstrationError,
                           learn, load_demo, nrmse, save_demo)
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.skills import library as skill_library
from etdmp_ros.skills.library import (default_skills_dir, demonstration_files, load_demonstration,
                                      read_mcap_path, recorded_path_demo, save_skill_demo,
                                      SkillExistsError, SkillLibrary, SkillNameClashError,
                                      UnknownSkillError)
import numpy as np
import pytest
from support.bad_files import forged_npy, npz_bomb
from support.bags import pose_message, write_mcap

PLANE = TaskPlane.create([0.75, 0.15, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02)
TILTED = TaskPlane.create([0.5, 0.0, 0.3], [0.0, 1.0, 0.0], [-np.sqrt(0.5), 0.0, np.sqrt(0.5)],
                          0.01)


def letter_path(n=80, height=0.05):
    """Return a curvy stroke (n, 3) in base_link, flat at ``height`` above the task plane."""
    s = np.linspace(0.0, 1.0, n)
    return np.column_stack([0.70 + 0.1 * s, 0.10 + 0.05 * np.sin(6 * s), np.full(n, height)])


def test_builtin_demos_are_learned_and_unknown_names_are_listed():
    library = SkillLibrary()
    for name in builtin_demo_names():
        entry = library.add(name, builtin_demo(name), 'built-in')
        assert entry.planar == (builtin_demo(name).dim == 2)
    assert library.names() == sorted(builtin_demo_names())
    skill = library.skill('G')
    assert nrmse(skill.reproduce().x, builtin_demo('G').positions) < 0.005
    assert library.skill('G') is skill                      # learned once per setting
    hoffmann = library.skill('G', formulation='hoffmann')
    assert hoffmann is not skill and hoffmann.formulation == 'hoffmann'
    with pytest.raises(UnknownSkillError, match="unknown skill 'Q'; known skills: G, P"):
        library.get('Q')


def test_a_bad_demonstration_never_replaces_a_learned_skill():
    library = SkillLibrary()
    good = library.add('mine', builtin_demo('P'), 'first')
    still = Demonstration('mine', np.ones((20, 2)))         # does not move
    with pytest.raises(DemonstrationError, match='does not move'):
        library.add('mine', still, 'second')
    with pytest.raises(DemonstrationError, match='has 4 coordinate'):
        library.add('mine', Demonstration('mine', np.random.default_rng(0).random((20, 4))), 'x')
    for bad in ('', '../etc', 'a b', 'x' * 65, '.hidden'):
        with pytest.raises(ValueError, match='not valid'):
            library.add(bad, builtin_demo('G'), 'x')
    assert library.get('mine') is good and library.names() == ['mine']


def test_files_and_folders_are_learned_and_bad_files_reported(tmp_path):
    folder = tmp_path / 'demos'
    folder.mkdir()
    save_demo(folder / 'wave.csv', Demonstration('w', np.column_stack(
        [np.linspace(0, 5, 50), np.sin(np.linspace(0, 5, 50))]), np.linspace(0, 1, 50)))
    np.save(folder / 'spiral.npy', np.column_stack(
        [np.cos(np.linspace(0, 6, 60)), np.sin(np.linspace(0, 6, 60)), np.linspace(0, 1, 60)]))
    (folder / 'short.csv').write_text('x,y\n1,2\n3,4\n')
    (folder / 'notes.txt').write_text('not a demonstration')
    (folder / '.hidden.csv').write_text('garbage')
    library = SkillLibrary()
    added, errors = library.add_files([folder, tmp_path / 'missing.csv'], PLANE)
    assert sorted(e.name for e in added) == ['spiral', 'wave']
    assert library.get('spiral').demo.dim == 3 and library.get('wave').planar
    assert len(errors) == 2
    assert 'short.csv' in errors[0] and 'at least 10 samples' in errors[0]
    assert 'missing.csv' in errors[1] and 'no such file' in errors[1]
    assert demonstration_files([folder]) == [folder / 'short.csv', folder / 'spiral.npy',
                                             folder / 'wave.csv']


def test_recorded_path_becomes_2d_when_flat_else_3d():
    path = letter_path()          # 5 cm above the table: flat and parallel to the plane
    demo = recorded_path_demo('flat', path, np.linspace(0, 2, len(path)), PLANE)
    assert demo.dim == 2
    np.testing.assert_allclose(demo.positions, (path[:, :2] - [0.75, 0.15]) / 0.02, atol=1e-12)
    np.testing.assert_allclose(demo.t, np.linspace(0, 2, len(path)))
    tilted = path + np.column_stack([np.zeros((len(path), 2)), np.linspace(0, 0.05, len(path))])
    assert recorded_path_demo('up', tilted, None, PLANE).dim == 3
    np.testing.assert_allclose(recorded_path_demo('up', tilted, None, PLANE).positions, tilted)
    assert recorded_path_demo('up', tilted, None, PLANE, recorded_dim='2d').dim == 2
    assert recorded_path_demo('flat', path, None, PLANE, recorded_dim='3d').dim == 3
    # In a tilted plane, "flat" means parallel to that plane.
    on_tilted = TILTED.from_plane(np.column_stack([np.linspace(0, 9, 30),
                                                   np.sin(np.linspace(0, 3, 30))]))
    demo = recorded_path_demo('t', on_tilted + 0.02 * TILTED.normal, None, TILTED)
    assert demo.dim == 2
    np.testing.assert_allclose(TILTED.from_plane(demo.positions), on_tilted, atol=1e-12)


def test_recorded_path_times_unset_stamps_and_errors():
    path = letter_path(20)
    assert recorded_path_demo('a', path, np.zeros(20), PLANE).duration == pytest.approx(1.0)
    t = np.linspace(5.0, 7.0, 20)
    assert recorded_path_demo('a', path, t, PLANE).duration == pytest.approx(2.0)
    t[7] = t[6]
    with pytest.raises(DemonstrationError, match='time does not increase'):
        recorded_path_demo('a', path, t, PLANE)
    with pytest.raises(DemonstrationError, match='5 samples'):
        recorded_path_demo('a', path[:5], None, PLANE)
    with pytest.raises(DemonstrationError, match='NaN'):
        recorded_path_demo('a', np.where(np.arange(60).reshape(20, 3) == 7, np.nan, path),
                           None, PLANE)
    with pytest.raises(DemonstrationError, match='recorded_dim'):
        recorded_path_demo('a', path, None, PLANE, recorded_dim='4d')


def test_mcap_pose_stamped_topic_is_read_with_header_stamps(tmp_path):
    path = letter_path(40)
    stamps = (10**9 * np.linspace(100.0, 101.95, 40)).astype(np.int64)
    log_times = stamps + 5_000_000          # recorded a little later than stamped
    other = [(int(t), pose_message([0, 0, 0], int(t), 'odom')) for t in log_times[:3]]
    write_mcap(tmp_path / 'rec.mcap', {
        '/tool_pose': ('pose', [(int(lt), pose_message(p, int(st))) for p, st, lt in
                                zip(path, stamps, log_times)]),
        '/other': ('pose', other)})
    recorded = read_mcap_path(tmp_path / 'rec.mcap', '/tool_pose')
    np.testing.assert_allclose(recorded.positions, path)
    np.testing.assert_allclose(recorded.t - recorded.t[0], (stamps - stamps[0]) * 1e-9,
                               atol=1e-6)
    with pytest.raises(DemonstrationError, match='holds 2 geometry_msgs/msg/PoseStamped, nav'):
        read_mcap_path(tmp_path / 'rec.mcap')
    with pytest.raises(DemonstrationError, match="frame 'odom'"):
        read_mcap_path(tmp_path / 'rec.mcap', '/other')
    with pytest.raises(DemonstrationError, match="named '/nope'.*found: /other, /tool_pose"):
        read_mcap_path(tmp_path / 'rec.mcap', '/nope')
    demo = load_demonstration(tmp_path / 'rec.mcap', PLANE, mcap_topic='/tool_pose')
    assert demo.name == 'rec' and demo.dim == 2 and demo.duration == pytest.approx(1.95)


def test_mcap_unset_stamps_use_the_recording_times(tmp_path):
    path = letter_path(30) + np.column_stack([np.zeros((30, 2)), np.linspace(0, 0.2, 30)])
    log_times = (10**9 * np.linspace(3.0, 4.5, 30)).astype(np.int64)
    write_mcap(tmp_path / 'up.mcap', {'/pen': ('pose', [(int(lt), pose_message(p, 0)) for p, lt in
                                                        zip(path, log_times)])})
    demo = load_demonstration(tmp_path / 'up.mcap', PLANE)     # the only topic
    assert demo.dim == 3 and demo.duration == pytest.approx(1.5)
    np.testing.assert_allclose(demo.positions, path)


def test_mcap_path_topic_uses_the_last_path(tmp_path):
    first, last = letter_path(15), letter_path(25, height=0.0)

    def path_msg(points, t0):
        return {'header': {'stamp': {'sec': t0, 'nanosec': 0}, 'frame_id': 'base_link'},
                'poses': [pose_message(p, t0 * 10**9 + k * 50_000_000)
                          for k, p in enumerate(points)]}
    write_mcap(tmp_path / 'plans.mcap', {'/plan': ('path', [(1, path_msg(first, 1)),
                                                            (2, path_msg(last, 2))])})
    library = SkillLibrary()
    added, errors = library.add_files([tmp_path / 'plans.mcap'], PLANE)
    assert errors == [] and added[0].name == 'plans'
    demo = library.get('plans').demo
    assert demo.n_samples == 25 and demo.duration == pytest.approx(1.2)
    np.testing.assert_allclose(PLANE.from_plane(demo.positions), last, atol=1e-12)


def test_broken_mcap_files_are_refused_with_a_reason(tmp_path):
    (tmp_path / 'junk.mcap').write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 40)
    (tmp_path / 'text.mcap').write_text('hello')
    write_mcap(tmp_path / 'empty.mcap', {})
    library = SkillLibrary()
    added, errors = library.add_files([tmp_path], PLANE)
    assert added == [] and len(errors) == 3
    assert all('.mcap' in e for e in errors)
    assert any('empty.mcap' in e and '0 geometry_msgs' in e for e in errors)
    assert any('not a readable rosbag2 .mcap' in e for e in errors)


def test_taught_skills_persist_exactly(tmp_path):
    demo = recorded_path_demo('zed', letter_path(), np.linspace(0, 2, 80), PLANE)
    saved = save_skill_demo(tmp_path / 'skills', demo)
    assert saved == tmp_path / 'skills' / 'zed.csv'
    assert [p.name for p in (tmp_path / 'skills').iterdir()] == ['zed.csv']
    assert saved.read_text().splitlines()[0] == 't,x,y'
    back = load_demo(saved)
    np.testing.assert_array_equal(back.positions, demo.positions)
    np.testing.assert_array_equal(back.t, demo.t)
    library = SkillLibrary()
    added, errors = library.add_files([tmp_path / 'skills'], PLANE)
    assert errors == [] and [e.name for e in added] == ['zed'] and library.get('zed').planar


def test_default_skills_dir_follows_ros_home():
    assert default_skills_dir({'ROS_HOME': '/x/ros'}) == Path('/x/ros/etdmp_ros/skills')
    assert default_skills_dir({'HOME': '/home/u'}) == Path('/home/u/.ros/etdmp_ros/skills')


def _wave(n=50):
    positions = np.column_stack([np.linspace(0, 5, n), np.sin(np.linspace(0, 5, n))])
    return Demonstration('w', positions, np.linspace(0, 1, n))


def test_files_beyond_the_limits_are_refused_before_they_are_read(tmp_path):
    # Found by attacks: a 289-byte .npy whose header claims (10^12, 2) raised
    # _ArrayMemoryError (14.6 TiB) and stopped the node; a 1.5 MB .npz of 10^8 x 2 zeros took
    # 11.8 GB (10^6 here, to be quick; the node test has the 10^8 one); a 200 MB CSV 16 GB.
    # Each is refused by its header or size; good files still load.
    folder = tmp_path / 'demos'
    folder.mkdir()
    save_demo(folder / 'wave.csv', _wave())
    forged_npy(folder / 'forged.npy', (10**12, 2))
    assert (folder / 'forged.npy').stat().st_size == 289
    npz_bomb(folder / 'bomb.npz', 10**6)
    assert (folder / 'bomb.npz').stat().st_size < 100_000
    with open(folder / 'big.csv', 'w') as f:
        f.write('x,y\n')
        f.truncate(limits.MAX_DEMO_FILE_BYTES + 1)
    rows = 'x,y\n' + '0.5,0.25\n' * (limits.MAX_DEMO_SAMPLES + 1)
    (folder / 'rows.csv').write_text(rows)
    assert len(rows) < limits.MAX_DEMO_FILE_BYTES
    library = SkillLibrary()
    started = time.perf_counter()
    added, errors = library.add_files([folder], PLANE)
    elapsed = time.perf_counter() - started
    assert [e.name for e in added] == ['wave']
    by_file = {Path(e.split(':')[0]).name: e for e in errors}
    assert sorted(by_file) == ['big.csv', 'bomb.npz', 'forged.npy', 'rows.csv']
    assert 'MAX_DEMO_FILE_BYTES' in by_file['big.csv'] and 'not read' in by_file['big.csv']
    assert '(1000000000000, 2)' in by_file['forged.npy']
    assert 'MAX_DEMO_SAMPLES' in by_file['forged.npy']
    assert "'positions'" in by_file['bomb.npz'] and '1000000 samples' in by_file['bomb.npz']
    assert 'MAX_DEMO_SAMPLES' in by_file['rows.csv']
    assert elapsed < 2.0


@pytest.mark.parametrize('failure', [MemoryError, OSError, EOFError, RuntimeError, KeyError])
def test_any_failure_reading_one_file_is_reported_and_the_others_load(tmp_path, monkeypatch,
                                                                      failure):
    save_demo(tmp_path / 'a_bad.csv', _wave())
    save_demo(tmp_path / 'good.csv', _wave())
    real = skill_library.load_demo

    def flaky(path, name=None):
        if Path(path).name == 'a_bad.csv':
            raise failure('simulated')
        return real(path, name=name)
    monkeypatch.setattr(skill_library, 'load_demo', flaky)
    library = SkillLibrary()
    added, errors = library.add_files([tmp_path], PLANE)
    assert [e.name for e in added] == ['good']
    assert len(errors) == 1 and 'a_bad.csv' in errors[0]


def test_a_mcap_over_the_size_limit_is_not_read(tmp_path):
    path = tmp_path / 'big.mcap'
    with open(path, 'wb') as f:
        f.truncate(limits.MAX_DEMO_FILE_BYTES + 1)
    with pytest.raises(DemonstrationError, match='MAX_DEMO_FILE_BYTES'):
        read_mcap_path(path)


def test_a_protected_skill_is_not_replaced():
    library = SkillLibrary()
    builtin = library.add('G', builtin_demo('G'), 'built-in')
    with pytest.raises(SkillExistsError, match="'G' exists already"):
        library.add('G', builtin_demo('P'), 'taught', protected=('built-in',))
    assert library.get('G') is builtin and library.source('G') == 'built-in'
    library.add('G', builtin_demo('P'), 'taught')          # not protected: replaced
    assert library.source('G') == 'taught' and library.source('nothing') is None


def test_a_name_that_differs_from_a_known_one_only_in_case_is_refused(tmp_path):
    # Before: 'g' beside 'G' and 'Stir' beside 'stir' were two skills, and in a skills folder
    # on a case-insensitive file system one file. Lookups stay case-sensitive.
    library = SkillLibrary()
    for name in ('G', 'stir'):
        library.add(name, builtin_demo(name), 'built-in')
    for name, twin in (('g', 'G'), ('Stir', 'stir'), ('STIR', 'stir')):
        with pytest.raises(SkillNameClashError, match=f'{name!r} differs from the known skill '
                           f'{twin!r} \\(built-in\\) only in case'):
            library.add(name, builtin_demo('P'), 'taught')
    assert library.names() == ['G', 'stir'] and library.source('G') == 'built-in'
    with pytest.raises(UnknownSkillError, match="unknown skill 'g' \\(did you mean 'G'\\?"):
        library.get('g')
    library.add('G', builtin_demo('P'), 'taught')          # the exact name replaces it
    assert library.source('G') == 'taught'
    # Files too: the second of two names that differ only in case is reported, not learned.
    for stem in ('wave', 'Wave'):
        save_demo(tmp_path / f'{stem}.csv', Demonstration(stem, np.column_stack(
            [np.linspace(0, 5, 50), np.sin(np.linspace(0, 5, 50))]), np.linspace(0, 1, 50)))
    added, errors = library.add_files([tmp_path], PLANE)
    assert [e.name for e in added] == ['Wave'] and len(errors) == 1
    assert 'wave.csv' in errors[0] and 'only in case' in errors[0]


# -- kinesthetic teaching: a rosbag2 recording of /joint_states


def _joint_state_bag(path, joints, stamps_ns, names=None, extra=False):
    """Write (n, 6) joint positions as sensor_msgs/JointState messages, as ros2 bag record."""
    from etdmp_ros.skills import recordings as bag
    from etdmp_ros.robot import JOINT_NAMES
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    names = list(JOINT_NAMES) if names is None else list(names)
    order = [list(JOINT_NAMES).index(n) for n in names]
    with bag.BagWriter(path) as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        for k, (q, stamp) in enumerate(zip(joints, stamps_ns)):
            msg = JointState(name=names + (['gripper_joint'] if extra else []),
                             position=[float(q[i]) for i in order] + ([0.5] if extra else []))
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp), 10**9)
            writer.write('/joint_states', 10**9 + k * 10**6, serialize_message(msg))


def _freedrive_joints(n_rest=40, n_move=300):
    """Return joints (n, 6) at rest, moving smoothly (a hand), then at rest again."""
    q0 = np.array([0.0, -1.9, 1.9, -1.57, -1.57, 0.0])
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n_move))
    moving = q0 + np.outer(s, [0.4, 0.25, -0.3, 0.2, 0.1, 0.3]) \
        + 0.03 * np.outer(np.sin(2 * np.pi * s), [1.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    return np.vstack([np.repeat(q0[None], n_rest, 0), moving,
                      np.repeat(moving[-1][None], n_rest, 0)])


@pytest.fixture(scope='module')
def ur10():
    from etdmp_ros.robot import UR10Model
    return UR10Model(tool_offset=(0.0, 0.0, 0.16))


def test_joint_state_recording_becomes_the_tool_path_by_forward_kinematics(tmp_path, ur10):
    joints = _freedrive_joints()
    stamps = 5 * 10**9 + np.arange(len(joints)) * 8 * 10**6          # 125 Hz, simulated time
    shuffled = ('wrist_2_joint', 'shoulder_pan_joint', 'elbow_joint', 'wrist_3_joint',
                'shoulder_lift_joint', 'wrist_1_joint')
    _joint_state_bag(tmp_path / 'taught.mcap', joints, stamps, shuffled, extra=True)
    recorded = read_mcap_path(tmp_path / 'taught.mcap', kinematics=ur10)
    tip = np.array([ur10.tool_position(q) for q in joints])
    threshold = skill_library.MOTION_THRESHOLD
    moving = np.flatnonzero(np.linalg.norm(tip - tip[0], axis=1) > threshold)
    still = np.flatnonzero(np.linalg.norm(tip - tip[-1], axis=1) > threshold)
    settled = skill_library.SETTLED_THRESHOLD       # widened to (nearly) at rest at both ends
    first = np.flatnonzero(np.linalg.norm(tip[:moving[0]] - tip[0], axis=1) <= settled)[-1]
    last = still[-1] + 1 + np.flatnonzero(
        np.linalg.norm(tip[still[-1] + 1:] - tip[-1], axis=1) <= settled)[0]
    assert recorded.topic == '/joint_states'
    np.testing.assert_allclose(recorded.positions, tip[first:last + 1], atol=1e-12)
    np.testing.assert_allclose(recorded.t, stamps[first:last + 1] * 1e-9)
    assert 39 <= first < 70 and len(joints) - 70 < last <= len(joints) - 40   # rest trimmed
    rotation = ur10.frame_pose(joints[first + 100])[1]
    np.testing.assert_allclose(quat.to_matrix(quat.normalized(recorded.orientations[100])),
                               rotation, atol=1e-9)
    demo = load_demonstration(tmp_path / 'taught.mcap', PLANE, kinematics=ur10)
    assert demo.dim == 3 and demo.name == 'taught' and demo.orientations is not None
    np.testing.assert_allclose(demo.t[0], 0.0)
    skill = learn(demo)
    traj = skill.generalize(demo.positions[0], demo.positions[-1])
    assert np.linalg.norm(traj.x[-1] - demo.positions[-1]) < 1e-3


def test_long_joint_state_recordings_are_decimated(tmp_path, ur10, monkeypatch):
    monkeypatch.setattr(limits, 'MAX_DEMO_SAMPLES', 100)
    joints = _freedrive_joints(n_rest=10, n_move=400)
    _joint_state_bag(tmp_path / 'long.mcap', joints, np.arange(len(joints)) * 2 * 10**6)
    recorded = read_mcap_path(tmp_path / 'long.mcap', kinematics=ur10)
    assert len(recorded.positions) == 100
    assert np.all(np.diff(recorded.t) > 0)


def test_bad_joint_state_recordings_are_refused_with_the_message(tmp_path, ur10):
    joints = _freedrive_joints(n_rest=5, n_move=50)
    stamps = np.arange(len(joints)) * 10**7
    _joint_state_bag(tmp_path / 'five.mcap', joints[:, :5], stamps,
                     names=('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint',
                            'wrist_1_joint', 'wrist_2_joint'))
    with pytest.raises(DemonstrationError, match=r'message 0 has no position of wrist_3_joint'):
        read_mcap_path(tmp_path / 'five.mcap', kinematics=ur10)
    broken = joints.copy()
    broken[17, 2] = np.nan
    _joint_state_bag(tmp_path / 'nan.mcap', broken, stamps)
    with pytest.raises(DemonstrationError, match=r'message 17 has a NaN or inf joint'):
        read_mcap_path(tmp_path / 'nan.mcap', kinematics=ur10)
    _joint_state_bag(tmp_path / 'still.mcap', np.repeat(joints[:1], 30, 0), stamps[:30])
    with pytest.raises(DemonstrationError, match=r'never moves more than'):
        read_mcap_path(tmp_path / 'still.mcap', kinematics=ur10)
    with pytest.raises(DemonstrationError, match=r'need the UR10 model'):
        read_mcap_path(tmp_path / 'nan.mcap')
    library = SkillLibrary()
    added, errors = library.add_files([tmp_path], PLANE, kinematics=ur10)
    assert added == [] and len(errors) == 3


def test_a_recorded_topic_without_messages_does_not_make_the_choice_ambiguous(tmp_path, ur10):
    # ros2 bag record -a of a partial system: a Path topic subscribed, never published.
    from etdmp_ros.skills import recordings as bag
    joints = _freedrive_joints(n_rest=5, n_move=60)
    _joint_state_bag(tmp_path / 'js.mcap', joints, np.arange(len(joints)) * 10**7)
    source = list(bag.read_messages(tmp_path / 'js.mcap'))
    with bag.BagWriter(tmp_path / 'partial.mcap') as writer:
        writer.add_topic('/etdmp/path', 'nav_msgs/msg/Path')
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        for topic, _, log_ns, data in source:
            writer.write(topic, log_ns, data)
    assert read_mcap_path(tmp_path / 'partial.mcap', kinematics=ur10).topic == '/joint_states'

"""
dmp_server under attack: the installed node, attacked as a user on the machine can.

Each row of ATTACKS does what ``ros2 service call``, ``ros2 param set`` or ``ros2 topic pub`` (or
a file put in ``demo_files`` / ``skills_dir``) would, and then checks, for every row: the node
is still up, the failure is reported as one (an ERROR line naming the problem and, where the
attack was a request, an empty plan), the next good request gets the same 201-pose plan as
before, nothing learned is lost (the skills learned at start-up still plan, nothing bad is
saved), and the node's memory stays under RSS_BOUND_MB (VmRSS read from /proc).

The start-up attacks (a forged .npy header, an .npz of 10^8 samples, an oversized CSV, in
demo_files and in skills_dir) are files the module's one node is started with.
"""

from pathlib import Path as FsPath
import time

from conftest import NodeProcess
from etdmp_ros import limits
from etdmp_ros.dmp import Demonstration, save_demo
from etdmp_ros.ros.conversions import path_from_numpy, path_to_numpy
from geometry_msgs.msg import PointStamped
from nav_msgs.srv import GetPlan
import numpy as np
import pytest
from rclpy.qos import QoSProfile
from std_msgs.msg import Header
from support.bad_files import big_csv, forged_npy, npz_bomb
from test_dmp_server_node import (Client, GOAL, obstacles_msg, request, START, TIMEOUT,
                                  wait_for_log)

#: The node's resident memory must stay below this (MB) through every attack. Measured here:
#: about 230-260 MB after start-up; the .npz attack alone took 11.8 GB before the limits.
RSS_BOUND_MB = 600.0
#: Start-up with every bad file must take less than this (s): the 200 MB CSV alone took 83 s.
STARTUP_BOUND = 45.0
BASE = Header(frame_id='base_link')
WAVE = np.column_stack([np.linspace(0.0, 8.0, 80), np.sin(np.linspace(0.0, 6.0, 80))])


def rss_mb(pid):
    """Return the largest VmRSS (MB) of process ``pid`` and its descendants (the node's shell)."""
    largest, todo = 0.0, [pid]
    while todo:
        current = todo.pop()
        try:
            status = FsPath(f'/proc/{current}/status').read_text()
            children = FsPath(f'/proc/{current}/task/{current}/children').read_text().split()
        except OSError:
            continue
        for line in status.splitlines():
            if line.startswith('VmRSS:'):
                largest = max(largest, int(line.split()[1]) / 1024.0)
        todo += [int(c) for c in children]
    return largest


@pytest.fixture(scope='module')
def attacked(colcon_install, module_ros_env, tmp_path_factory):
    """One dmp_server started with the bad files of the start-up attacks and one good file."""
    tmp = tmp_path_factory.mktemp('attacked')
    files, skills = tmp / 'demos', tmp / 'skills'
    files.mkdir()
    skills.mkdir()
    save_demo(files / 'wave.csv', Demonstration('wave', WAVE, np.linspace(0.0, 1.6, 80)))
    forged_npy(files / 'forged.npy', (10**12, 2))
    npz_bomb(files / 'bomb.npz', 10**8)
    big_csv(files / 'big.csv', limits.MAX_DEMO_FILE_BYTES + 1)
    forged_npy(skills / 'forged_taught.npy', (10**12, 2))
    save_demo(skills / 'kept.csv', Demonstration('kept', WAVE, np.linspace(0.0, 2.0, 80)))
    started = time.monotonic()
    node = NodeProcess(colcon_install, module_ros_env, tmp, 'dmp_server',
                       {'skills_dir': str(skills), 'demo_files': [str(files)],
                        'tool_state_max_age': 60.0})
    client = Client()
    client.wait_for_server(node)
    startup = time.monotonic() - started
    baseline = client.call(START, GOAL)[1]
    assert len(baseline) == 201, node.log()
    yield {'node': node, 'client': client, 'skills': skills, 'startup': startup,
           'baseline': baseline, 'files': files}
    client.close()
    assert node.stop() == 0, node.log()
    log = node.log()
    assert 'Traceback' not in log, log
    assert 'RuntimeWarning' not in log, log


def _nothing_lost(env):
    """Assert the skills learned at start-up still plan and the active one plans as before."""
    client, node = env['client'], env['node']
    for name in ('wave', 'kept'):
        assert client.set_parameters(skill=name)[0].successful
        try:
            assert len(client.call(START, GOAL)[1]) > 0, (name, node.log())
        finally:
            assert client.set_parameters(skill='G')[0].successful
    np.testing.assert_allclose(client.call(START, GOAL)[1], env['baseline'], atol=1e-12)


def _error_lines(node):
    return [line for line in node.log().splitlines() if '[ERROR]' in line]


def _attack_startup_file(name, *fragments):
    def attack(env):
        return None   # the file was in place when the node started
    attack.fragments = (name, 'not learned') + fragments
    return attack


def _request(start, goal, **params):
    """Return an attack by one /generalize request, after ``ros2 param set`` of ``params``."""
    def attack(env):
        client = env['client']
        if params:
            assert all(r.successful for r in client.set_parameters(**params))
        try:
            return client.call(start, goal)[1]
        finally:
            if params:
                defaults = {'duration': 0.0}
                assert all(r.successful for r in client.set_parameters(
                    **{k: defaults[k] for k in params}))
    return attack


def _goal_orientation(q):
    """Request a plan to GOAL with goal orientation ``q`` (x, y, z, w)."""
    def attack(env):
        msg = request(START, GOAL)
        o = msg.goal.pose.orientation
        o.x, o.y, o.z, o.w = (float(c) for c in q)
        future = env['client'].generalize.call_async(msg)
        return path_to_numpy(env['client']._result(future).plan)[1]
    return attack


def _perceived_goal(goal):
    """Publish ``goal`` on /etdmp/goal, then request a plan to the perceived goal."""
    def attack(env):
        client = env['client']
        client.publish('goal', PointStamped(header=BASE, point=_point(goal)))
        return client.call(START, None, goal_frame='')[1]
    return attack


def _point(p):
    from geometry_msgs.msg import Point
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _teach(name, positions, t, timed=False):
    """Publish a taught Path (``ros2 topic pub /etdmp/demonstrations``) as skill ``name``."""
    def attack(env):
        client = env['client']
        assert client.set_parameters(teach_skill_name=name)[0].successful
        try:
            msg = path_from_numpy(positions, t, stamp=10**9)
            client.publish('demonstrations', msg, times=1)
            if timed:   # /generalize must answer at once after the Path is refused
                began = time.monotonic()
                assert len(client.call(START, GOAL)[1]) == 201
                env['answered_after'] = time.monotonic() - began
        finally:
            assert client.set_parameters(teach_skill_name='taught')[0].successful
        assert not (env['skills'] / f'{name}.csv').exists(), f'{name} was saved'
        return None
    return attack


def _z_path(n, scale=1.0, span=2.0):
    s = np.linspace(0.0, 1.0, n)
    xy = np.column_stack([0.75 + 0.1 * s, 0.15 + 0.05 * np.sin(6.0 * s)])
    return np.column_stack([xy, np.full(n, 0.04)]) * scale, np.linspace(0.0, span, n)


_HUGE_PATH = _z_path(10**5)
_LONG_STAMPS = _z_path(80, span=1.975e9)
_FAR = _z_path(80, scale=1e300)
_TAUGHT_G = _z_path(80)

# id, attack, ERROR fragments, the attack's plan must be empty (None: no plan asked)
ATTACKS = [
    ('forged .npy header (demo_files)',
     _attack_startup_file('forged.npy', 'header claims shape', 'MAX_DEMO_SAMPLES'), None),
    ('forged .npy header (skills_dir)',
     _attack_startup_file('forged_taught.npy', 'header claims shape'), None),
    ('npz of 10^8 x 2 zeros', _attack_startup_file('bomb.npz', 'MAX_DEMO_SAMPLES'), None),
    ('CSV over the file size limit',
     _attack_startup_file('big.csv', 'MAX_DEMO_FILE_BYTES', 'not read'), None),
    ('taught Path of 10^5 poses',
     _teach('huge', *_HUGE_PATH, timed=True), ('rejected', 'MAX_TAUGHT_PATH_BYTES')),
    ('taught stamps spanning 1.975e9 s', _teach('eon', *_LONG_STAMPS),
     ('rejected', 'MAX_DEMO_DURATION')),
    ('taught coordinates x 1e300', _teach('far', *_FAR), ('rejected', 'MAX_REQUEST_COORDINATE')),
    ('teaching the built-in G', _teach('G', *_TAUGHT_G),
     ('rejected', 'exists already', 'teach_overwrite')),
    ('duration 0.005 s', _request(START, GOAL, duration=0.005), ('would have 1 sample',)),
    ('duration 0.01 s', _request(START, GOAL, duration=0.01), ('2 pose(s)', 'at least')),
    ('duration 0.5 s', _request(START, GOAL, duration=0.5),
     ('cannot follow', 'shortest feasible duration')),
    ('request goal out of reach', _request(START, [1.5, 0.2, 0.0]), ("out of the UR10's reach",)),
    ('perceived goal out of reach', _perceived_goal([0.1, 1.5, 0.0]),
     ("goal (0.100, 1.500, 0.000) is out of the UR10's reach",)),
    ('goal 0.5 m above the task plane', _request(START, [0.74, 0.15, 0.5]),
     ('from the task plane', 'MAX_GOAL_PLANE_DISTANCE')),
    ('start of 1e200', _request([1e200, 0.2, 0.0], GOAL), ('start', 'MAX_REQUEST_COORDINATE')),
    ('finite start of 1e308', _request([1e308, 0.2, 0.0], GOAL),
     ('1e+308 m', 'MAX_REQUEST_COORDINATE')),
    # Refused before as "overflow encountered in dot".
    ('goal orientation (1e308, 1e308, 0, 1)', _goal_orientation((1e308, 1e308, 0.0, 1.0)),
     ('goal orientation (1e+308, 1e+308, 0.000, 1.000) is not a unit quaternion',)),
]


@pytest.mark.parametrize('what, attack, fragments', [
    (row[0], row[1], row[2]) for row in ATTACKS], ids=[row[0] for row in ATTACKS])
def test_attack_is_refused_and_the_node_keeps_serving(attacked, what, attack, fragments):
    node, client = attacked['node'], attacked['client']
    fragments = attack.fragments if fragments is None else fragments
    before = len(_error_lines(node))
    plan = attack(attacked)
    line = wait_for_log(node, *fragments)
    assert len(line) < 600, line                        # a readable reason (1e200: 612 chars)
    assert 'NaN or inf' not in line, line               # a finite 1e308 is not called NaN
    if plan is not None:
        assert len(plan) == 0, f'{what}: a failure reported as a plan'
        assert len(_error_lines(node)) > before
    assert node.process.poll() is None, node.log()
    assert len(client.call(START, GOAL)[1]) == 201      # the next good request succeeds
    _nothing_lost(attacked)
    assert rss_mb(node.pid) < RSS_BOUND_MB, rss_mb(node.pid)


@pytest.mark.parametrize('name, value, reason', [
    ('static_obstacles', [1e308, 0.0, 0.0], 'static_obstacles has a coordinate of 1e+308 m'),
    ('task_plane.origin', [1e308, 0.0, 0.0], 'task_plane.origin has a coordinate of 1e+308 m'),
    ('tool_orientation', [0.0, 0.0, 0.0, 0.0], 'non-zero quaternion'),
])
def test_parameters_beyond_the_workcell_are_refused(attacked, name, value, reason):
    # Before: accepted, and then every /generalize was refused with "overflow encountered in
    # divide" until someone set them back.
    client = attacked['client']
    [result] = client.set_parameters(**{name: value})
    assert not result.successful and reason in result.reason, result.reason
    np.testing.assert_allclose(client.call(START, GOAL)[1], attacked['baseline'], atol=1e-12)


def test_a_perceived_obstacle_beyond_the_workcell_is_ignored(attacked):
    # Before: kept, and every /generalize failed ("overflow encountered in divide") until the
    # obstacle was older than obstacle_max_age.
    client, node = attacked['client'], attacked['node']
    client.publish('obstacles', obstacles_msg([1e308, 0.0, 0.0]))
    deadline = time.monotonic() + TIMEOUT
    while '/etdmp/obstacles has a coordinate of 1e+308 m' not in node.log():
        assert time.monotonic() < deadline, node.log()
        client.spin_for(0.1)
    assert '[WARN]' in next(line for line in node.log().splitlines()
                            if '/etdmp/obstacles has a coordinate' in line)
    np.testing.assert_allclose(client.call(START, GOAL)[1], attacked['baseline'], atol=1e-12)


def test_startup_with_every_bad_file_is_fast_and_bounded(attacked):
    # Before: 30 s and 11.8 GB for the .npz, 83 s and 16.1 GB for a 200 MB CSV, a crash for the
    # forged header. The good files are learned.
    assert attacked['startup'] < STARTUP_BOUND
    log = attacked['node'].log()
    assert "learned skill 'wave'" in log and "learned skill 'kept'" in log, log
    assert rss_mb(attacked['node'].pid) < RSS_BOUND_MB


def test_a_huge_taught_path_does_not_block_generalize(attacked):
    _teach('huge', *_HUGE_PATH, timed=True)(attacked)
    # Before: /generalize was blocked for 4.7 s; now the Path is refused by its size.
    assert attacked['answered_after'] < 1.0


@pytest.mark.parametrize('how', ['50 clients', 'one client', 'sequential'])
def test_a_burst_of_50_requests_is_answered_in_full(attacked, how):
    # Before: 11-12 of 50 requests sent at once were answered (rclpy's request queue of 10,
    # for one client or 50), the others never were, and nothing was logged. A client that sends
    # 50 requests at once must itself keep 50 responses (its QoS depth; rclpy's default is 10).
    client = attacked['client']
    node = client.node
    began = time.monotonic()
    if how == 'sequential':
        answers = [client.call(START + [0.001 * k, 0.0, 0.0], GOAL)[3] for k in range(50)]
    else:
        if how == '50 clients':
            # Every client's response reader receives every client's responses (rmw_fastrtps
            # filters them by client after the history): with rclpy's default depth of 10, a
            # client's own answer is pushed out when 50 come fast (16 of 50 lost in a fresh
            # clone). That depth is the client's to set, as for one client with 50 calls.
            callers = [node.create_client(GetPlan, '/generalize',
                                          qos_profile=QoSProfile(depth=64)) for _ in range(50)]
        else:
            callers = [node.create_client(GetPlan, '/generalize',
                                          qos_profile=QoSProfile(depth=64))] * 50
        assert all(c.wait_for_service(timeout_sec=TIMEOUT) for c in set(callers))
        # A new client is "ready" once its request writer matched the server; the server's
        # response writer may still be discovering it (rmw race, worst on a loaded machine: 2 s
        # of waiting still lost 6 of 50 answers there): a response sent before that is lost.
        # So each client is connected as a long-lived one is: it has had one answer.
        for c in set(callers):
            warm = c.call_async(request(START, GOAL))
            client.executor.spin_until_future_complete(warm, timeout_sec=TIMEOUT)
            assert warm.done(), 'a client got no first answer'
        began = time.monotonic()
        futures = [c.call_async(request(START + [0.001 * k, 0.0, 0.0], GOAL))
                   for k, c in enumerate(callers)]
        deadline = time.monotonic() + 60.0
        while not all(f.done() for f in futures) and time.monotonic() < deadline:
            client.executor.spin_once(timeout_sec=0.05)
        for c in set(callers):
            node.destroy_client(c)
        assert all(f.done() for f in futures), f'{sum(f.done() for f in futures)} of 50'
        answers = [f.result().plan for f in futures]
    attacked.setdefault('burst', {})[how] = time.monotonic() - began
    assert [len(path_to_numpy(plan)[1]) for plan in answers] == [201] * 50
    assert attacked['node'].process.poll() is None


def test_overload_is_refused_as_busy_never_lost(attacked):
    # More requests at once than the node plans within max_request_wait, and more than the
    # request history of 256 it had: before the node took requests into its own queue with
    # their receipt times, the middleware dropped those beyond its history unseen (a soak of 4
    # clients x 20 requests/s lost 1025 of 4800). Now each is answered: a plan, or at once an
    # empty one, refused as busy with an ERROR line.
    client, node = attacked['client'], attacked['node']
    n = 356
    assert n < limits.MAX_QUEUED_REQUESTS
    caller = client.node.create_client(GetPlan, '/generalize',
                                       qos_profile=QoSProfile(depth=2 * n))
    assert caller.wait_for_service(timeout_sec=TIMEOUT)
    client.spin_for(2.0)
    assert client.set_parameters(max_request_wait=0.05)[0].successful
    try:
        futures = [caller.call_async(request(START + [0.0001 * k, 0.0, 0.0], GOAL))
                   for k in range(n)]
        deadline = time.monotonic() + 60.0
        while not all(f.done() for f in futures) and time.monotonic() < deadline:
            client.executor.spin_once(timeout_sec=0.05)
        done = sum(f.done() for f in futures)
        lengths = [len(path_to_numpy(f.result().plan)[1]) for f in futures if f.done()]
    finally:
        client.node.destroy_client(caller)
        assert client.set_parameters(max_request_wait=5.0)[0].successful
    assert done == n, f'{done} of {n} answered'
    planned, refused = lengths.count(201), lengths.count(0)
    assert planned + refused == n, sorted(set(lengths))
    assert planned >= 1 and refused >= 1, (planned, refused)
    wait_for_log(node, 'refused as busy', 'max_request_wait 0.05 s')
    assert len(client.call(START, GOAL)[1]) == 201
    assert node.process.poll() is None, node.log()


# -- the teaching page beside another client of dmp_server ---------------------------------------

@pytest.fixture(scope='module')
def page(attacked, colcon_install, module_ros_env, tmp_path_factory):
    """Return the page of the installed teach node beside the module's dmp_server."""
    from support.drawings import request
    from etdmp_ros.demo.teach_session import free_port, page_answers
    tmp = tmp_path_factory.mktemp('page')
    port = free_port('127.0.0.1')
    node = NodeProcess(colcon_install, module_ros_env, tmp, 'teach', {'port': port})
    url = f'http://localhost:{port}/'
    deadline = time.monotonic() + 60.0
    while not page_answers(url + 'api/config'):
        assert node.process.poll() is None and time.monotonic() < deadline, node.log()
        time.sleep(0.1)
    # Once it has found dmp_server (DDS discovery: seconds on a loaded machine), as a page
    # opened beside a running system (make teach waits for every node likewise).
    while _post(url + 'api/teach', request('warm_up'))[0] == 503:
        assert time.monotonic() < deadline, node.log()
    yield url
    assert node.stop() == 0, node.log()
    assert 'Traceback' not in node.log(), node.log()


def _post(url, body):
    import json
    import urllib.error
    import urllib.request
    request = urllib.request.Request(url, json.dumps(body).encode(),
                                     {'Content-Type': 'application/json'})
    try:
        with urllib.request.urlopen(request, timeout=60) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


class Meddler:
    """Another client setting dmp_server's parameters as fast as it is answered, in a thread."""

    def __init__(self, **values):
        import itertools
        import threading
        self.client, self.sets = Client('another_client'), 0
        self._values = itertools.cycle([dict(zip(values, v)) for v in zip(*values.values())])
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        """Set the values in turn until stopped."""
        while not self._stop.is_set():
            assert all(r.successful for r in self.client.set_parameters(**next(self._values)))
            self.sets += 1
            time.sleep(0.01)    # the subject: a client setting them over and over

    def __enter__(self):
        assert self.client.parameters.wait_for_service(timeout_sec=TIMEOUT)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(timeout=TIMEOUT)
        self.client.close()


def test_a_teaching_from_the_page_cannot_be_saved_under_another_client_s_name(attacked, page):
    # Before: the page set teach_skill_name and then published the drawing; with another client
    # setting it to its own name meanwhile, 2 of 10 drawings were saved under that name
    # (silently replacing that skill), and the page answered 503 after 10 s. Now the name comes
    # in the request (~/teach).
    from support.drawings import request
    skills = attacked['skills']
    with Meddler(teach_skill_name=['other', 'taught']) as meddler:
        answers = [_post(page + 'api/teach', request(f'page{k}')) for k in range(10)]
    assert meddler.sets > 10, meddler.sets   # it really set the parameter meanwhile
    for k, (status, answer) in enumerate(answers):
        assert status == 200 and answer['message'].startswith(
            f"dmp_server learned skill 'page{k}' (2D, "), answer
        assert answer['seconds'] < 5.0, answer['seconds']
        assert (skills / f'page{k}.csv').is_file()
    assert not (skills / 'other.csv').exists() and not (skills / 'taught.csv').exists()
    assert attacked['client'].get_parameters('teach_skill_name')['teach_skill_name'] in (
        'other', 'taught')     # what the other client set, nothing of the page's
    print(f'\nten teachings beside {meddler.sets} parameter sets: '
          f'{sorted(a["seconds"] for _, a in answers)} s')


def test_a_writing_from_the_page_uses_its_skill_and_leaves_the_parameters_alone(attacked, page):
    # Before: the page set skill and duration, then called /generalize: another client's skill
    # could be written, and a refused plan left both changed for everyone.
    from etdmp_ros.ros.conversions import joint_state_msg
    from test_dmp_server_node import point_msg, Q_INIT, SCENE
    client = attacked['client']
    client.publish('joint_states', joint_state_msg(Q_INIT))
    client.publish('goal', PointStamped(header=BASE, point=point_msg(SCENE['goal_position'])))
    assert (attacked['skills'] / 'page0.csv').is_file()   # taught by the test above
    with Meddler(skill=['W', 'P'], duration=[0.0, 5.0]):
        written = [_post(page + 'api/write', {'name': 'page0', 'duration': 3.0})
                   for _ in range(5)]
        refused = _post(page + 'api/write', {'name': 'page0', 'duration': 0.3})
        unknown = _post(page + 'api/write', {'name': 'nothing', 'duration': None})
    for status, answer in written:
        assert status == 200 and answer['message'].startswith(
            "writing 'page0': dmp_server planned skill 'page0' (etdmp): 301 poses over 3.00 s"), \
            answer
    assert refused[0] == 422 and 'shortest feasible duration' in refused[1]['error'], refused
    assert unknown[0] == 422 and "unknown skill 'nothing'" in unknown[1]['error'], unknown
    values = client.get_parameters('skill', 'duration')
    assert (values['skill'], values['duration']) in (('W', 0.0), ('P', 5.0)), values
    assert client.set_parameters(skill='G', duration=0.0)[0].successful
    assert len(client.call(START, GOAL)[1]) == 201


def test_teaching_a_builtin_name_needs_teach_overwrite(attacked):
    # Last in the module (keep it so): it replaces the node's built-in G for good (as the user
    # asked). The page tests used to come after it and planned this taught stroke as 'G' (201
    # poses only while a taught stroke kept its 2 s; re-timed to come to rest it lasts 2.2 s).
    client, node = attacked['client'], attacked['node']
    positions, t = _TAUGHT_G
    assert client.set_parameters(teach_skill_name='G', teach_overwrite=True)[0].successful
    try:
        client.publish('demonstrations', path_from_numpy(positions, t, stamp=10**9), times=1)
        deadline = time.monotonic() + TIMEOUT
        while not (attacked['skills'] / 'G.csv').exists():
            assert time.monotonic() < deadline, node.log()
            client.spin_for(0.1)
        taught = client.call(START, GOAL)[1]
    finally:
        assert client.set_parameters(teach_skill_name='taught', teach_overwrite=False)[
            0].successful
        (attacked['skills'] / 'G.csv').unlink(missing_ok=True)
    # G is now the taught stroke, not the built-in letter.
    assert len(taught) > 0 and np.all(np.isfinite(taught))
    assert len(taught) != len(attacked['baseline']) or \
        np.abs(taught - attacked['baseline']).max() > 0.01

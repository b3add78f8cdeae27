"""
The system through the real ``ros2`` command line, as the README tells a user to run it.

From the colcon install, sourced, on a DDS domain of its own (fixture ``ros2``, conftest):
``ros2 run etdmp_ros <node>`` for every node; then one ``ros2 launch etdmp_ros etdmp.launch.py
skill:=W`` shared by the rest of the module: the node, topic and service lists against the
tables of docs/ros.md, both ``ros2 service call /generalize`` examples of the README verbatim (the
first one makes the arm write the W, checked on the true tool tip, the commands with ``ros2
topic echo`` and ``ros2 topic hz``), bad requests, ``ros2 param set|get|describe`` (a list
parameter set to ``[]``), and Ctrl-C to ``ros2 launch``. The tests of the shared system run in
file order. Skipped, with one reason, when the CLI is not installed (``make ros-tools``).
"""

import math
import re
import shlex
import time

from etdmp_ros.demo.scenario import Scenario
from etdmp_ros.dmp import learn
from etdmp_ros.ros import system
from etdmp_ros.skills.planning import place_demo
import numpy as np
import pytest
from support import ros2_cli
from support.ros2_cli import wait_for

SKILL = 'W'
CONTROL_RATE = system.node('ur10_sim').parameter('control_rate').default
#: Startup of the four nodes (numba caches, DDS discovery) on a loaded 2-core machine.
STARTUP = 120.0
GENERALIZE = 'ros2 service call /generalize nav_msgs/srv/GetPlan'
COMMANDS = '/forward_velocity_controller/commands'
TOOL_TIP = '/ur10_sim/ground_truth/tool_tip'
STATUS = '/etdmp/controller/status'
#: What each node logs when it is ready (a Ctrl-C before that, e.g. while the controller's
#: numba kernels compile, can be lost: see test_ros2_run_starts_every_node).
READY = {'ur10_sim': 'UR10 workcell ready', 'perception': 'perception ready',
         'dmp_server': 'serving /generalize', 'controller': 'following '}
#: A plan's start and goal against the requested (or tool / perceived) points (m).
PLAN_TOLERANCE = 1e-3
#: The true tool tip against the plan while it is tracked (m): tracking error is ~0.1 mm.
TRACE_TOLERANCE = 2e-3


#: Types of the topics echoed: given, so that echo needs no discovery of the type.
TYPES = {COMMANDS: 'std_msgs/msg/Float64MultiArray', TOOL_TIP: 'geometry_msgs/msg/PointStamped',
         STATUS: 'std_msgs/msg/String', '/etdmp/goal': 'geometry_msgs/msg/PointStamped',
         '/ur10_sim/ground_truth/goal': 'geometry_msgs/msg/PointStamped'}


def echo(topic, *options):
    """Return ``ros2 topic echo --csv`` of ``topic`` (reliable, latched for the status)."""
    qos = ['--qos-reliability', 'reliable']
    if topic == STATUS:
        qos += ['--qos-durability', 'transient_local']
    return ['ros2', 'topic', 'echo', '--csv', *qos, *options, topic, TYPES[topic]]


def param(ros2, verb, *args, check=True):
    """
    Run ``ros2 param <verb> <args>``; return its CompletedProcess.

    Retried (3 tries) when the CLI gave up discovering the node's parameter services: it waits
    5 s for them, which a loaded machine can take (the node is there all the time).
    """
    for _ in range(3):
        result = ros2.run(['ros2', 'param', verb, '--timeout', '10', *args], check=False)
        if 'timed out waiting for parameter services' not in result.stdout + result.stderr:
            break
    if check:
        assert result.returncode == 0, (args, result.stdout, result.stderr)
    return result


def call(ros2, request, timeout=60.0):
    """``ros2 service call /generalize`` with ``request`` (YAML); return the plan positions."""
    result = ros2.run(f'{GENERALIZE} {shlex.quote(request)}', timeout=timeout)
    return ros2_cli.plan_positions(result.stdout)


def echo_once(ros2, topic, fields, timeout=30.0):
    """Return the numbers at the end of one ``ros2 topic echo --once --csv`` message."""
    result = ros2.run(echo(topic, '--once'), timeout=timeout)
    rows = ros2_cli.csv_rows(result.stdout, fields)
    assert len(rows) == 1, result.stdout
    return rows[0]


def subscriptions(ros2, topic):
    """Return the subscription count ``ros2 topic info`` shows for ``topic``."""
    out = ros2.run(['ros2', 'topic', 'info', topic], check=False).stdout
    found = re.search(r'Subscription count: (\d+)', out)
    return int(found.group(1)) if found else 0


def projected(point):
    """Return ``point`` on the task plane (the table top, z = 0 in base_link)."""
    return np.array([point[0], point[1], 0.0])


# ------------------------------------------------------------------------------- ros2 run

def test_ros2_run_starts_every_node(ros2):
    """
    Run ``ros2 run etdmp_ros <node>`` (docs/ros.md: "Nodes one by one"); Ctrl-C ends each with 0.

    Ctrl-C only once every node is ready: one that reaches the controller while numba compiles
    its kernels is swallowed (llvmlite: "Exception ignored on calling ctypes callback
    function"), and the controller then runs on until killed.
    """
    runner = ros2.fresh()
    config = runner.install / 'share' / 'etdmp_ros' / 'config'
    nodes = {}
    try:
        for name in system.NODE_NAMES:
            files = ' '.join(f'--params-file {f}' for f in system.parameter_files(name, config))
            nodes[name] = runner.start(f'ros2 run etdmp_ros {name} --ros-args {files}', name)
        for name, line in READY.items():
            wait_for(lambda: line in nodes[name].log(), STARTUP, f'{name}: {line!r}',
                     nodes.values())
        expected = {f'/{n}' for n in system.NODE_NAMES} | {'/ur10_sim_camera'}

        def listed():
            out = runner.run('ros2 node list', check=False).stdout
            return set(out.split()) >= expected and set(out.split())
        names = wait_for(listed, 60, 'the nodes in ros2 node list', nodes.values())
        assert names == expected
    finally:
        codes = {}
        for name in reversed(system.NODE_NAMES):    # the simulation last
            codes[name] = nodes[name].stop(20.0) if name in nodes else None
    for name, process in nodes.items():
        assert codes[name] == 0, f'{name}: exit code {codes[name]}\n{process.log()[-3000:]}'
        assert 'Traceback' not in process.log(), process.log()


# ----------------------------------------------------------------------------- ros2 launch

class Launched:
    """``ros2 launch etdmp_ros etdmp.launch.py skill:=W``, its output in a log."""

    def __init__(self, ros2):
        """Start the launch; wait until /generalize is served and the goal perceived."""
        self.ros2 = ros2
        self.process = ros2.start(f'ros2 launch etdmp_ros etdmp.launch.py skill:={SKILL}',
                                  'launch')
        for name, line in READY.items():
            wait_for(lambda: any(f'[{name}]: {line}' in row for row in self.log().splitlines()),
                     STARTUP, f'{name}: {line!r}', [self.process])
        wait_for(lambda: 'goal marker at' in self.log(), STARTUP, 'a perceived goal',
                 [self.process])

    def log(self):
        """Return the launch's output so far (every node's, prefixed ``[<node>-<n>]``)."""
        return self.process.log()

    def errors(self, node):
        """Return the ERROR lines of ``node`` so far."""
        return [line for line in self.log().splitlines()
                if line.startswith(f'[{node}-') and '[ERROR]' in line]


@pytest.fixture(scope='module')
def launched(ros2):
    """One running system for the module's tests; stopped (if a test did not) at the end."""
    system_ = Launched(ros2)
    yield system_
    system_.process.stop(30.0)


def _listed(ros2, verb):
    """Return ``ros2 <verb> list -t`` as a user runs it (from the ``ros2 daemon``'s graph)."""
    out = ros2.run(f'ros2 {verb} list -t').stdout
    return ros2_cli.without_internals(ros2_cli.names_and_types(out))


def test_node_topic_and_service_lists_equal_the_readme_tables(launched):
    """``ros2 node list``, ``ros2 topic list -t``, ``ros2 service list -t``: docs/ros.md's."""
    ros2 = launched.ros2
    documented = ros2_cli.readme_nodes()
    # bringup is an executable that runs the four nodes in one process, not a node of its own.
    executables = ros2.run('ros2 pkg executables etdmp_ros').stdout.split()
    assert 'bringup' in executables and 'in one process' in documented.pop('bringup')
    nodes = {f'/{n}' for n in documented}

    def complete():
        out = ros2.run('ros2 node list', check=False).stdout
        return set(out.split()) >= nodes and set(out.split())
    running = wait_for(complete, 60, f'the documented nodes {sorted(nodes)} in ros2 node list')
    assert running == nodes, f'running, not in docs/ros.md: {sorted(running - nodes)}'

    topics, services = ros2_cli.readme_topics()
    # Discovery is incremental (the daemon the first list starts learns the graph as the
    # nodes announce themselves): take the union of lists for up to 30 s, then compare.
    found_topics, found_services = {}, {}
    deadline = time.monotonic() + 30.0
    while True:
        found_topics.update(_listed(ros2, 'topic'))
        found_services.update(_listed(ros2, 'service'))
        if set(found_topics) >= set(topics) and set(found_services) >= set(services) \
                or time.monotonic() > deadline:
            break
    diff = (ros2_cli.differences(topics, found_topics)
            + ros2_cli.differences(services, found_services))
    assert not diff, 'docs/ros.md topic table vs ros2 topic/service list -t:\n' + '\n'.join(diff)


def test_first_readme_example_writes_the_letter(launched):
    """Run the README's ``ros2 service call /generalize ... "{}"``: the arm writes the W."""
    ros2 = launched.ros2
    examples = ros2_cli.readme_commands(GENERALIZE)
    assert len(examples) == 2, examples
    tool = echo_once(ros2, TOOL_TIP, 3)
    goal = echo_once(ros2, '/etdmp/goal', 3)
    # The commands with the controller's own account of each (-i: source timestamp and
    # publication number), to measure what it sent, whatever this machine lets a reader get.
    echoes = {name: ros2.start(echo(topic, '--qos-depth', '1000',
                                    *(['--include-message-info'] if topic == COMMANDS else [])),
                               name)
              for name, topic in (('commands', COMMANDS), ('tool_tip', TOOL_TIP),
                                  ('status', STATUS))}
    hz = ros2.start(f'ros2 topic hz -s --window 100000 --filter "any(m.data)" {COMMANDS}', 'hz')
    try:
        # Every listener has subscribed: the commands seen by echo, the hz one counted.
        wait_for(lambda: len(ros2_cli.csv_rows(echoes['commands'].log(), 6)) > 10, 60,
                 'ros2 topic echo of the commands', [*echoes.values(), hz])
        wait_for(lambda: subscriptions(ros2, COMMANDS) >= 3, 60, 'ros2 topic hz subscribed',
                 [hz])
        wait_for(lambda: 'idle' in echoes['status'].log(), 30, 'the idle controller')
        # In the W's own 2 s (duration 0, the default), as a user runs it: the "tracking
        # error 51 mm" stop was the controller missing steps on a loaded machine, not the W.
        result = ros2.run(examples[0], timeout=60)
        plan = ros2_cli.plan_positions(result.stdout)
        assert len(plan) > 100, result.stdout[-2000:]
        assert np.linalg.norm(plan[0] - projected(tool)) < PLAN_TOLERANCE, (plan[0], tool)
        assert np.linalg.norm(plan[-1] - projected(goal)) < PLAN_TOLERANCE, (plan[-1], goal)

        def statuses():
            return [line.strip() for line in echoes['status'].log().splitlines()]
        wait_for(lambda: 'holding' in statuses(), 60, 'the controller holding the goal',
                 [launched.process])
        seen = statuses()
        wait_for(lambda: statuses()[-1].startswith('idle') and len(statuses()) > len(seen), 30,
                 'the controller idle after holding', [launched.process])
        n_commands = len(ros2_cli.csv_rows(echoes['commands'].log(), 6))
        wait_for(lambda: len(ros2_cli.csv_rows(echoes['commands'].log(), 6)) > n_commands + 20,
                 10, 'commands after the idle')
    finally:
        for process in (*echoes.values(), hz):
            process.stop(10.0)
    order = [s.split(':')[0] for s in statuses()]
    order = order[len(order) - 1 - order[::-1].index('approaching'):]
    assert order[:4] == ['approaching', 'tracking', 'holding', 'idle'], statuses()

    commands = ros2_cli.csv_rows(echoes['commands'].log(), 6)
    moving = np.all(commands != 0.0, axis=1)
    assert moving.sum() > 2 * CONTROL_RATE, 'fewer than 2 s of commands moving all 6 joints'
    last = np.flatnonzero(np.any(commands != 0.0, axis=1))[-1]
    assert len(commands) - last > 20 and np.all(commands[last + 1:] == 0.0), (
        'the commands after the motion are not zeros')
    # The command rate while moving, from the publisher's stamps and numbers. ros2 topic hz
    # counts what its own Python process receives, with the sensor-data QoS (best effort,
    # depth 5): beside a busy-looping process it was held off the CPU for over 5 commands at a
    # time and read 97.7, 105.6 and 113.3 Hz (three fresh clones, the last niced to -10) while
    # the controller sent every step. It must run and measure; its figure is not the rate.
    rates = ros2_cli.hz_rates(hz.log())
    assert rates, hz.log()
    stamps, numbers, rows = ros2_cli.published_rows(echoes['commands'].log(), 6)
    moving = np.flatnonzero(np.any(rows != 0.0, axis=1))
    assert len(moving) > 2 * CONTROL_RATE, echoes['commands'].log()[-2000:]
    first, last = moving[0], moving[-1]
    published = numbers[last] - numbers[first]
    rate = published / ((stamps[last] - stamps[first]) * 1e-9)
    print(f'commands while moving: {rate:.1f} Hz published ({published + 1} commands, '
          f'{last - first + 1} received by ros2 topic echo); ros2 topic hz read {rates[-1]} Hz')
    assert rate >= 0.95 * CONTROL_RATE, (
        f'the controller published its moving commands at {rate:.1f} Hz < 0.95 x '
        f'{CONTROL_RATE}')

    trace = ros2_cli.csv_rows(echoes['tool_tip'].log(), 3)
    arrived = np.flatnonzero(np.linalg.norm(trace - plan[0], axis=1) < TRACE_TOLERANCE)
    assert arrived.size, 'the tool tip never reached the plan start'
    written = trace[arrived[0]:]
    off = ros2_cli.distance_to_polyline(written, plan)
    assert off.max() < TRACE_TOLERANCE, f'the tool tip left the plan by {off.max() * 1e3:.2f} mm'
    missed = ros2_cli.distance_to_polyline(plan, written)
    assert missed.max() < TRACE_TOLERANCE, (
        f'part of the plan not written: {missed.max() * 1e3:.2f} mm from the trace')
    assert np.linalg.norm(written[-1] - plan[-1]) < TRACE_TOLERANCE
    # The W asked for (the demonstration drawn from the plan's start to its goal, as ET-DMP
    # places it without obstacles) is a letter of more than 10 cm. The plan itself is smaller
    # (8.0 x 7.8 cm instead of 9.4 x 12.0): the scene's first cylinder stands 11 mm from the
    # W's lower-left vertex and dmp_server's detour, the default avoidance with the perceived
    # radii, lifts that part of the letter by up to 4 cm to keep its clearance (the paper's
    # coupling, the default before, bent it less and ran on 1 s: 11 cm, 301 poses).
    scene = Scenario(config_dir=None, skill=SKILL, layout='default')
    placed = place_demo(learn(scene.demo), plan[0], plan[-1], scene.plane)
    assert np.ptp(placed[:, :2], axis=0).max() > 0.1, 'the W is less than 10 cm large'


def test_second_readme_example_plans_between_the_given_points(launched):
    ros2 = launched.ros2
    param(ros2, 'set', '/dmp_server', 'execute', 'false')   # plan only, the arm stays
    example = ros2_cli.readme_commands(GENERALIZE)[1]
    numbers = [float(v) for v in re.findall(r'[xyz]: (-?[0-9.]+)', example)]
    start, goal = np.array(numbers[:3]), np.array(numbers[3:])
    result = ros2.run(example, timeout=60)
    plan = ros2_cli.plan_positions(result.stdout)
    assert len(plan) > 100 and ros2_cli.is_nan_free(plan)
    assert np.linalg.norm(plan[0] - start) < PLAN_TOLERANCE, (plan[0], start)
    assert np.linalg.norm(plan[-1] - goal) < PLAN_TOLERANCE, (plan[-1], goal)


BAD_REQUESTS = {
    'NaN start': '{start: {header: {frame_id: base_link}, pose: {position: '
                 '{x: .nan, y: 0.2, z: 0.0}}}}',
    'wrong frame': '{goal: {header: {frame_id: map}, pose: {position: {x: 0.7, y: 0.3}}}}',
    'start = goal': '{start: {header: {frame_id: base_link}, pose: {position: {x: 0.8, y: 0.2}}}'
                    ', goal: {header: {frame_id: base_link}, pose: {position: {x: 0.8, y: 0.2}}}}',
}


@pytest.mark.parametrize('what', BAD_REQUESTS)
def test_bad_request_gives_an_empty_plan_and_an_error(launched, what):
    before = len(launched.errors('dmp_server'))
    assert len(call(launched.ros2, BAD_REQUESTS[what])) == 0
    errors = wait_for(lambda: launched.errors('dmp_server')[before:], 10,
                      'an ERROR line of dmp_server')
    assert '/generalize' in errors[0], errors
    good = ros2_cli.readme_commands(GENERALIZE)[1]
    assert len(ros2_cli.plan_positions(launched.ros2.run(good).stdout)) > 100


def _described(ros2, node, *names):
    """Return ``{name: its text}`` of one ``ros2 param describe <node> <names...>``."""
    out = param(ros2, 'describe', node, *names).stdout
    blocks = ['Parameter name: ' + block for block in out.split('Parameter name: ')[1:]]
    described = {block.splitlines()[0].split(': ', 1)[1].strip(): block for block in blocks}
    assert set(described) == set(names), out
    return described


def test_param_describe_and_get_show_the_system_description(launched):
    ros2 = launched.ros2
    texts = {('dmp_server', name): text for name, text in _described(
        ros2, '/dmp_server', 'skill', 'method', 'n_basis', 'duration').items()}
    texts.update({('ur10_sim', name): text for name, text in _described(
        ros2, '/ur10_sim', 'goal_position', 'control_rate').items()})
    for (node, name), text in texts.items():
        parameter = system.node(node).parameter(name)
        assert f'Parameter name: {name}' in text, text
        assert f'Description: {parameter.full_description}' in text, text
        assert f'Type: {parameter.type_name.replace("[]", " array")}' in text, text
        if parameter.value_range is not None and not isinstance(parameter.default, list):
            low, high = parameter.value_range
            assert f'Min value: {low}' in text and f'Max value: {high}' in text, text
        if parameter.choices:
            assert f'Additional constraints: one of {", ".join(parameter.choices)}' in text, text
        assert ('Read only: true' in text) == (not parameter.dynamic), text
    get = param(ros2, 'get', '/dmp_server', 'skill').stdout
    assert get.strip() == f'String value is: {SKILL}', get
    get = param(ros2, 'get', '/ur10_sim', 'control_rate').stdout
    assert get.strip() == f'Double value is: {CONTROL_RATE}', get
    refused = param(ros2, 'set', '/dmp_server', 'n_basis', '5000', check=False)
    assert 'Setting parameter failed' in refused.stdout + refused.stderr, refused


def test_param_set_changes_the_plan_and_the_goal(launched):
    ros2 = launched.ros2
    param(ros2, 'set', '/dmp_server', 'execute', 'false')
    example = ros2_cli.readme_commands(GENERALIZE)[1]

    def plan():
        return ros2_cli.plan_positions(ros2.run(example).stdout)
    plans = {'W etdmp': plan()}
    param(ros2, 'set', '/dmp_server', 'skill', 'G')
    assert param(ros2, 'get', '/dmp_server', 'skill').stdout.strip() == 'String value is: G'
    plans['G etdmp'] = plan()
    param(ros2, 'set', '/dmp_server', 'method', 'dmp')
    plans['G dmp'] = plan()
    for name, positions in plans.items():
        assert len(positions) > 100, name
        assert np.linalg.norm(positions[-1] - [0.70, 0.30, 0.0]) < PLAN_TOLERANCE, name
    keys = list(plans)
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            n = min(len(plans[a]), len(plans[b]))
            gap = np.abs(plans[a][:n] - plans[b][:n]).max()
            assert gap > 0.01, f'{a} and {b} plans differ by {gap * 1e3:.2f} mm only'

    param(ros2, 'set', '/dmp_server', 'method', 'etdmp')
    param(ros2, 'set', '/dmp_server', 'skill', f'{SKILL}')
    [move] = ros2_cli.readme_commands('ros2 param set /ur10_sim goal_position')
    target = np.array([float(v) for v in move.split('"')[1].strip('[]').split(',')])
    for _ in range(3):   # verbatim from the README; retried as param() is
        result = ros2.run(move, check=False)
        if 'timed out' not in result.stdout + result.stderr:
            break
    assert 'Set parameter successful' in result.stdout, (result.stdout, result.stderr)

    def perceived():
        goal = echo_once(ros2, '/etdmp/goal', 3)
        return [goal] if np.linalg.norm(goal[:2] - target[:2]) < 3e-3 else None
    [goal] = wait_for(perceived, 30, f'the goal perceived at {target}')
    positions = call(ros2, '{}')
    assert np.linalg.norm(positions[-1] - projected(goal)) < PLAN_TOLERANCE, (positions[-1], goal)
    truth = echo_once(ros2, '/ur10_sim/ground_truth/goal', 3)
    assert np.linalg.norm(truth - target) < 1e-6, truth


def test_param_set_of_an_empty_list_clears_static_obstacles(launched):
    """
    ``ros2 param set /dmp_server static_obstacles "[]"`` clears them.

    The CLI types ``[]`` as bool[]; it was refused (expected 'Type.DOUBLE_ARRAY'), and after an
    obstacle on the goal every request failed. A wrong type is still refused with the reason.
    """
    ros2 = launched.ros2
    param(ros2, 'set', '/dmp_server', 'execute', 'false')
    example = ros2_cli.readme_commands(GENERALIZE)[1]
    goal = [float(v) for v in re.findall(r'[xyz]: (-?[0-9.]+)', example)][3:]
    on_goal = '[' + ', '.join(f'{v:.3f}' for v in goal) + ']'
    param(ros2, 'set', '/dmp_server', 'static_obstacles', on_goal)
    get = param(ros2, 'get', '/dmp_server', 'static_obstacles').stdout.strip()
    assert get == f'Double values are: {[round(v, 3) for v in goal]}', get

    def plan():
        return ros2_cli.plan_positions(ros2.run(example).stdout)
    assert len(plan()) == 0       # an obstacle on the goal: the request fails

    cleared = param(ros2, 'set', '/dmp_server', 'static_obstacles', '[]')
    assert 'Set parameter successful' in cleared.stdout, (cleared.stdout, cleared.stderr)
    get = param(ros2, 'get', '/dmp_server', 'static_obstacles').stdout.strip()
    assert get == 'Double values are: []', get
    positions = plan()
    assert len(positions) > 100 and np.linalg.norm(positions[-1] - goal) < PLAN_TOLERANCE

    refused = param(ros2, 'set', '/dmp_server', 'static_obstacles', 'abc', check=False)
    out = refused.stdout + refused.stderr
    assert 'Setting parameter failed' in out and \
        "expected 'Type.DOUBLE_ARRAY' got 'Type.STRING'" in out, out
    assert param(ros2, 'get', '/dmp_server', 'static_obstacles').stdout.strip() == \
        'Double values are: []'
    # Integers as the CLI types them are numbers of the list too.
    param(ros2, 'set', '/dmp_server', 'static_obstacles', '[1, 0, 0]')
    get = param(ros2, 'get', '/dmp_server', 'static_obstacles').stdout.strip()
    assert get == 'Double values are: [1.0, 0.0, 0.0]', get
    param(ros2, 'set', '/dmp_server', 'static_obstacles', '[]')


def test_ctrl_c_to_ros2_launch_stops_the_four_nodes(launched):
    ros2 = launched.ros2
    commands = ros2.start(echo(COMMANDS), 'commands_at_exit')
    try:
        wait_for(lambda: len(ros2_cli.csv_rows(commands.log(), 6)) > 5, 60, 'commands echoed')
        code = launched.process.stop(40.0, group=False)   # SIGINT to ros2 launch only
    finally:
        commands.stop(10.0)
    log = launched.log()
    assert code == 0, log[-3000:]
    for node in system.NODE_NAMES:
        assert f'[INFO] [{node}-' in log and any(
            line.startswith(f'[INFO] [{node}-') and 'process has finished cleanly' in line
            for line in log.splitlines()), f'{node} did not exit cleanly:\n{log[-3000:]}'
    assert 'Traceback' not in log, log
    commands = ros2_cli.csv_rows(commands.log(), 6)
    assert np.all(commands[-1] == 0.0), commands[-1]
    assert not any(math.isnan(v) for v in commands.ravel())

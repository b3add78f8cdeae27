"""
The system description (etdmp_ros.ros.system) is the one place of every parameter and node.

The files written from it (config/*.yaml, the docs' parameter tables) must be up to date and
give back its defaults; the nodes must declare exactly what it describes, with its descriptors.
"""

from conftest import REPO
from etdmp_ros.ros import config_files, system
from etdmp_ros.ros.parameters import as_declared, declare, descriptor, list_type, values
import numpy as np
import pytest
import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter


def test_config_files_and_docs_tables_are_written_from_the_description():
    stale = [str(path.relative_to(REPO)) for path, text in config_files.generated_files(REPO)
             .items() if path.read_text(encoding='utf-8') != text]
    assert not stale, f'out of date (run `make config`): {stale}'


@pytest.mark.parametrize('name', system.NODE_NAMES)
def test_the_parameter_files_give_back_every_default(name):
    spec = system.node(name)
    from_files = config_files.read_node_parameters(name)
    for p in spec.all_parameters:
        if p.array_type and not p.default:
            assert p.name not in from_files   # ROS cannot type an empty list: left out
            continue
        value = from_files[p.name]
        assert type(value) is type(p.default), (p.name, value, p.default)
        if isinstance(p.default, float) or (isinstance(p.default, list)
                                            and isinstance(p.default[0], float)):
            assert np.allclose(value, p.default, rtol=1e-15, atol=0), p.name
        else:
            assert value == p.default, p.name


def test_a_default_outside_its_range_or_choices_is_refused():
    with pytest.raises(ValueError, match='outside'):
        system.Parameter('gain', 2.0, 'a gain', value_range=(0.0, 1.0))
    with pytest.raises(ValueError, match='not in'):
        system.Parameter('method', 'x', 'a method', choices=('etdmp', 'dmp'))
    with pytest.raises(ValueError, match='array_type'):
        system.Parameter('files', [], 'files')


#: List parameters with a number of values of their own, a count they refuse, and the reason:
#: checked once, by the description, wherever a value is typed (the nodes, scene_config).
COUNTS = [
    ('ur10_sim', 'goal_position', [0.7, 0.2], 'goal_position must have 3 values, got 2'),
    ('ur10_sim', 'table.color', [0.5, 0.5], 'table.color must have 3 or 4 values, got 2'),
    ('ur10_sim', 'obstacle_positions', [0.7, 0.2, 0.08, 0.7],
     'obstacle_positions must have a multiple of 3 (x1, y1, z1, x2, ...) values, got 4'),
    ('dmp_server', 'static_obstacles', [0.1, 0.2], 'multiple of 3'),
    ('dmp_server', 'goal_offset', [0.0, 0.0], 'goal_offset must have 3 values, got 2'),
    ('controller', 'joint_acceleration_limits', [25.0] * 5,
     'joint_acceleration_limits must have 6 values, got 5'),
    ('controller', 'initial_joint_positions', [0.0] * 7,
     'initial_joint_positions must have 6 values, got 7'),
]


@pytest.mark.parametrize('node, name, value, reason', COUNTS, ids=[row[1] for row in COUNTS])
def test_list_parameters_have_their_number_of_values(node, name, value, reason):
    parameter = system.node(node).parameter(name)
    with pytest.raises(ValueError) as refused:
        parameter.typed(value)
    assert reason in str(refused.value)
    parameter.typed(parameter.default)
    assert descriptor(parameter).additional_constraints == f'{parameter.count} values'
    with pytest.raises(ValueError, match='must have 2 values'):
        system.Parameter('centre', [0.0, 0.0, 0.0], 'a centre', lengths=(2,))


#: List parameters that took any finite value before (1e308 included), with a value beyond the
#: range they now have, and what the refusal says.
BEYOND = [
    ('dmp_server', 'static_obstacles', [1e308, 0.0, 0.0],
     'static_obstacles[0] = 1e+308 m is outside its range -100 to 100 m'),
    ('dmp_server', 'task_plane.origin', [1e308, 0.0, 0.0], 'task_plane.origin[0] = 1e+308 m'),
    ('dmp_server', 'goal_offset', [0.0, 0.0, -3.0], 'goal_offset[2] = -3 m'),
    ('ur10_sim', 'goal_position', [1e308, 0.0, 0.0], 'goal_position[0] = 1e+308 m'),
    ('ur10_sim', 'initial_joint_positions', [0.0, 7.0, 0.0, 0.0, 0.0, 0.0],
     'initial_joint_positions[1] = 7 rad is outside its range -6.28319 to 6.28319 rad'),
    ('ur10_sim', 'tool_offset', [0.0, 0.0, float('nan')], 'tool_offset[2] = nan m'),
    ('controller', 'joint_acceleration_limits', [25.0, 25.0, 35.0, 40.0, 40.0, 1e308],
     'joint_acceleration_limits[5] = 1e+308 rad/s^2'),
]


@pytest.mark.parametrize('node, name, value, reason', BEYOND, ids=[row[1] for row in BEYOND])
def test_list_parameters_are_checked_element_by_element(context, node, name, value, reason):
    spec = system.node(node)
    parameter = spec.parameter(name)
    with pytest.raises(ValueError) as refused:
        parameter.check(value)
    assert reason in str(refused.value)
    parameter.check(parameter.default)
    # Given in a parameter file: the node does not start (FATAL, exit 1; run() says so) ...
    described = _node(context, spec.name, [Parameter(name, value=value)])
    try:
        with pytest.raises(ValueError, match='outside its range'):
            declare(described, spec)
    finally:
        described.destroy_node()
    # ... set at runtime (ros2 param set): refused with the reason, the value kept.
    if parameter.dynamic and not parameter.dynamic_typing:
        running = _node(context, spec.name)
        try:
            declare(running, spec)
            result = running.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful and reason in result.reason, result.reason
            assert values(running, spec)[name] == parameter.default
        finally:
            running.destroy_node()


def test_the_scene_is_checked_where_it_is_made_without_ros():
    with pytest.raises(ValueError, match=r'table.size\[0\] = 100 m is outside'):
        system.scene_config({'table.size': [100.0, 1.5]})
    with pytest.raises(ValueError, match="bottle.position: the bottle .* inside the robot's base"):
        system.scene_config({'bottle.position': [0.1, 0.05]})


def test_wiring_scene_first_then_the_node_then_sim_time():
    for spec in system.NODES:
        files = system.parameter_files(spec.name)
        assert [f.name for f in files] == ['scene.yaml', f'{spec.name}.yaml']
        assert all(f.is_file() for f in files)
        assert system.wiring_overrides(spec.name) == (
            {'use_sim_time': True} if spec.sim_time else {})
    assert [n.name for n in system.NODES if n.sim_time] == ['dmp_server', 'controller']
    assert system.NODE_NAMES[0] == 'ur10_sim'   # started first: the others wait for it
    with pytest.raises(KeyError, match='nodes: ur10_sim'):
        system.node('planner')


def test_scene_parameters_are_one_description_shared_by_the_nodes():
    scene = {p.name: p for p in system.SCENE}
    for spec in system.NODES:
        for p in spec.scene:
            assert p.default == scene[p.name].default, (spec.name, p.name)
        own = {p.name for p in spec.parameters}
        assert not own & set(scene), f'{spec.name} redefines scene parameters'
    assert system.scene_config().goal_position.tolist() == scene['goal_position'].default


@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, args=['--ros-args', '--disable-rosout-logs'])
    yield ctx
    ctx.try_shutdown()


def _node(context, name, overrides=()):
    return Node(name, context=context, parameter_overrides=list(overrides),
                enable_rosout=False, start_parameter_services=False)


def test_declare_gives_each_parameter_its_default_and_descriptor(context):
    spec = system.node('dmp_server')
    node = _node(context, spec.name)
    try:
        values = declare(node, spec)
        assert values == {**spec.defaults()}
        assert values['static_obstacles'] == [] and values['demo_files'] == []
        k = node.describe_parameter('obstacle_k')
        assert k.description.endswith('[1/m]') and not k.read_only
        assert (k.floating_point_range[0].from_value, k.floating_point_range[0].to_value) == \
            spec.parameter('obstacle_k').value_range
        n = node.describe_parameter('n_basis')
        assert (n.integer_range[0].from_value, n.integer_range[0].to_value) == (2, 1000)
        assert node.describe_parameter('tool_offset').read_only
        assert 'one of etdmp, dmp' in node.describe_parameter('method').additional_constraints
        result = node.set_parameters([Parameter('obstacle_k', value=-1.0)])[0]
        assert not result.successful   # below the range: refused by rcl
        result = node.set_parameters([Parameter('tool_offset', value=[0.0, 0.0, 0.2])])[0]
        assert not result.successful   # read-only
    finally:
        node.destroy_node()


def test_declare_refuses_file_values_out_of_range_or_of_another_type(context):
    spec = system.node('controller')
    for override, error in ((Parameter('control_rate', value=5000.0),
                             InvalidParameterValueException),
                            (Parameter('control_rate', value=125), InvalidParameterTypeException)):
        node = _node(context, spec.name, [override])
        try:
            with pytest.raises(error):
                declare(node, spec)
        finally:
            node.destroy_node()


LIST_TYPES = (Parameter.Type.BOOL_ARRAY, Parameter.Type.INTEGER_ARRAY,
              Parameter.Type.DOUBLE_ARRAY, Parameter.Type.STRING_ARRAY)


@pytest.mark.parametrize('spec', system.NODES, ids=system.NODE_NAMES)
def test_an_empty_list_of_any_type_is_the_declared_empty_list(spec):
    """``ros2 param set <node> <list> "[]"`` sends bool[]: every list parameter takes it."""
    lists = [p for p in spec.all_parameters if list_type(p) is not None]
    assert lists
    for p in lists:
        for given in LIST_TYPES:
            [converted] = as_declared(spec, [Parameter(p.name, given, [])])
            assert (converted.name, converted.type_, list(converted.value)) == (
                p.name, list_type(p), []), (p.name, given)


def test_lists_the_command_line_types_otherwise_are_converted_or_left_to_be_refused():
    perception, dmp_server = system.node('perception'), system.node('dmp_server')
    cases = [   # (spec, given, expected type and value; None: left as it is)
        (dmp_server, Parameter('static_obstacles', value=[1, 0, 0]),
         (Parameter.Type.DOUBLE_ARRAY, [1.0, 0.0, 0.0])),
        (perception, Parameter('goal_hsv_low', value=[45.0, 100.0, 50.0]),
         (Parameter.Type.INTEGER_ARRAY, [45, 100, 50])),
        (perception, Parameter('goal_hsv_low', value=[45.5, 100.0, 50.0]), None),
        (perception, Parameter('goal_hsv_low', value=[float('inf'), 100.0, 50.0]), None),
        (dmp_server, Parameter('static_obstacles', value='[]'), None),
        (dmp_server, Parameter('static_obstacles', value=[True]), None),
        (dmp_server, Parameter('demo_files', value=[1, 2]), None),
        (dmp_server, Parameter('duration', value=[]), None),           # a scalar: left
        (dmp_server, Parameter('not_declared', value=[]), None),
    ]
    for spec, given, expected in cases:
        [converted] = as_declared(spec, [given])
        if expected is None:
            assert converted is given, given.name
        else:
            assert (converted.type_, list(converted.value)) == expected, given.name


def test_set_parameters_takes_an_empty_list_and_refuses_a_wrong_type(context):
    """What `ros2 param set /dmp_server static_obstacles "[]"` does, on a declared node."""
    spec = system.node('dmp_server')
    node = _node(context, spec.name)
    try:
        declare(node, spec)
        obstacles = 'static_obstacles'
        assert node.set_parameters([Parameter(obstacles, value=[0.7, 0.3, 0.0])])[0].successful
        result = node.set_parameters([Parameter(obstacles, Parameter.Type.BOOL_ARRAY, [])])[0]
        assert result.successful, result.reason
        value = node.get_parameter(obstacles)
        assert value.type_ == Parameter.Type.DOUBLE_ARRAY and list(value.value) == []
        assert node.set_parameters([Parameter(obstacles, value=[1, 0, 0])])[0].successful
        assert list(node.get_parameter(obstacles).value) == [1.0, 0.0, 0.0]
        for wrong in ('abc', [True, False], ['a']):
            result = node.set_parameters([Parameter(obstacles, value=wrong)])[0]
            assert not result.successful
            assert "Wrong parameter type, expected 'Type.DOUBLE_ARRAY'" in result.reason
        assert list(node.get_parameter(obstacles).value) == [1.0, 0.0, 0.0]
    finally:
        node.destroy_node()


def test_list_overrides_typed_by_the_command_line_are_converted_too(context):
    """``--ros-args -p tool_orientation:=[0, 1, 0, 0]`` is integer[]: taken as the floats."""
    spec = system.node('dmp_server')
    node = _node(context, spec.name, [Parameter('tool_orientation', value=[0, 1, 0, 0])])
    try:
        assert declare(node, spec)['tool_orientation'] == [0.0, 1.0, 0.0, 0.0]
        assert node.get_parameter('tool_orientation').type_ == Parameter.Type.DOUBLE_ARRAY
    finally:
        node.destroy_node()
    node = _node(context, spec.name, [Parameter('tool_orientation', value=['a', 'b'])])
    try:
        with pytest.raises(InvalidParameterTypeException):
            declare(node, spec)
    finally:
        node.destroy_node()


def test_every_descriptor_matches_its_parameter():
    for spec in system.NODES:
        for p in spec.all_parameters:
            d = descriptor(p)
            assert d.name == p.name and d.read_only == (not p.dynamic)
            assert d.dynamic_typing == p.dynamic_typing
            assert bool(d.floating_point_range or d.integer_range) == (
                p.value_range is not None and not isinstance(p.default, list))


@pytest.mark.parametrize('spec', system.NODES, ids=system.NODE_NAMES)
def test_each_node_declares_exactly_its_description(context, spec, monkeypatch, tmp_path):
    # Without parameter files: the built-in defaults are the description's.
    monkeypatch.setenv('ROS_HOME', str(tmp_path))
    monkeypatch.setenv('MUJOCO_GL', 'egl')
    from etdmp_ros.nodes.bringup import node_class
    node = node_class(spec)(context=context)
    try:
        declared = set(node._parameters) - {'use_sim_time', 'start_type_description_service'}
        assert declared == {p.name for p in spec.all_parameters}
        for p in spec.all_parameters:
            described = node.describe_parameter(p.name)
            assert described.read_only == (not p.dynamic), p.name
            if p.array_type and not p.default:
                continue
            value = node.get_parameter(p.name).value
            value = list(value) if isinstance(p.default, list) else value
            assert value == p.default, p.name
    finally:
        if hasattr(node, 'stop'):
            node.stop()
        node.destroy_node()


#: A node program whose start-up gets SIGINT inside a C callback (as numba's compiler calls
#: back while the controller warms up): Python prints the KeyboardInterrupt and drops it there.
_STARTUP_SIGNAL = """
import ctypes, os, signal, sys, time
from etdmp_ros.ros import spin as _spin
from rclpy.node import Node

def make(nodes):
    nodes.append(Node('startup_signal'))
    @ctypes.CFUNCTYPE(None)
    def callback():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)   # the signal is handled here, inside the callback
    callback()

sys.exit(_spin.run(make, 'startup_signal', ['startup_signal']))
"""


def test_a_signal_during_start_up_is_not_lost(ros_env):
    import subprocess
    import sys
    try:
        done = subprocess.run([sys.executable, '-c', _STARTUP_SIGNAL], env=ros_env, timeout=20,
                              capture_output=True, text=True)
    except subprocess.TimeoutExpired:
        pytest.fail('the program kept running after a SIGINT during its start-up')
    assert done.returncode == 0, done.stderr


#: A node program whose clean-up never ends (its node's stop() hangs).
_HANGS_IN_STOP = """
import sys, time
from etdmp_ros.ros import spin as _spin
from rclpy.node import Node

class Stuck(Node):
    def __init__(self):
        super().__init__('stuck')
        print('made', flush=True)

    def stop(self):
        print('stopping', flush=True)
        while True:
            time.sleep(0.05)   # stuck_in_stop

sys.exit(_spin.run(lambda nodes: nodes.append(Stuck()), 'stuck', ['stuck']))
"""


def test_a_node_that_does_not_stop_leaves_its_stacks_in_its_log(ros_env, tmp_path):
    from pathlib import Path
    import sys
    import time
    from etdmp_ros.ros.processes import NodeProcess
    node = NodeProcess([sys.executable, '-c', _HANGS_IN_STOP], tmp_path / 'stuck.log', ros_env)
    deadline = time.monotonic() + 20
    while 'made' not in node.log():
        assert time.monotonic() < deadline and node.returncode is None, node.log()
        time.sleep(0.1)
    assert node.stop(timeout=1.0) == -9
    log = node.log()
    # faulthandler's dump: the stuck line and the way to it through spin.run.
    assert 'Current thread' in log and 'in stop' in log and 'in run' in log, log
    if (Path(sys.executable).parent / 'py-spy').is_file():     # and the native stacks
        assert 'py-spy dump --native' in log and 'Thread' in log, log


# ------------------------------------------------------------- a part of the system


def test_hosts_place_every_node_once_the_controller_beside_the_robot():
    placed = [n for names in system.HOSTS.values() for n in names]
    assert sorted(placed) == sorted(system.NODE_NAMES)
    # The 125 Hz loop (joint states in, velocities out) stays on the robot's PC.
    assert system.HOSTS['robot'] == ('ur10_sim', 'controller')
    assert system.HOSTS['workstation'] == ('perception', 'dmp_server')


def test_select_nodes_by_host_or_by_name_in_start_order():
    assert system.select_nodes() == system.NODE_NAMES
    assert system.select_nodes('robot') == ('ur10_sim', 'controller')
    assert system.select_nodes('workstation') == ('perception', 'dmp_server')
    assert system.select_nodes(nodes='controller, ur10_sim') == ('ur10_sim', 'controller')
    assert system.select_nodes(nodes=['dmp_server']) == ('dmp_server',)
    for kwargs, words in (({'host': 'lab'}, 'all, robot, workstation'),
                          ({'nodes': 'ur10_sim,camera'}, "'camera'"),
                          ({'host': 'robot', 'nodes': 'ur10_sim'}, 'not both')):
        with pytest.raises(ValueError, match=words):
            system.select_nodes(**kwargs)


def _launch(monkeypatch, **arguments):
    """Return the executables that etdmp.launch.py starts with ``arguments``."""
    pytest.importorskip('launch', reason='ros2 launch is not installed (make ros-tools)')
    import importlib.util
    from launch import LaunchContext
    from launch.actions import DeclareLaunchArgument, OpaqueFunction
    spec = importlib.util.spec_from_file_location('etdmp_launch', REPO / 'launch' /
                                                  'etdmp.launch.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, 'get_package_share_directory', lambda package: str(REPO))
    context = LaunchContext()
    entities = module.generate_launch_description().entities
    for action in entities:
        if isinstance(action, DeclareLaunchArgument):
            default = action.default_value[0].text if action.default_value else ''
            context.launch_configurations[action.name] = arguments.get(action.name, default)
    (nodes,) = [a for a in entities if isinstance(a, OpaqueFunction)]
    return [n.node_executable for n in nodes.execute(context) if n.condition is None]


def test_the_launch_file_starts_the_chosen_part(monkeypatch):
    assert _launch(monkeypatch) == list(system.NODE_NAMES)
    assert _launch(monkeypatch, host='robot') == ['ur10_sim', 'controller']
    assert _launch(monkeypatch, host='workstation') == ['perception', 'dmp_server']
    assert _launch(monkeypatch, nodes='dmp_server') == ['dmp_server']
    with pytest.raises(ValueError, match="no node 'sim'"):
        _launch(monkeypatch, nodes='sim')


def test_bringup_takes_the_same_choice():
    from etdmp_ros.nodes.bringup import split_arguments
    assert split_arguments(['bringup']) == (system.NODE_NAMES, ['bringup'])
    assert split_arguments(['bringup', '--host', 'robot', '--ros-args', '-p', 'a:=1']) == (
        ('ur10_sim', 'controller'), ['bringup', '--ros-args', '-p', 'a:=1'])
    assert split_arguments(['bringup', '--nodes', 'perception', '--ros-args'])[0] == (
        'perception',)
    with pytest.raises(ValueError, match='host must be one of'):
        split_arguments(['bringup', '--host', 'lab'])

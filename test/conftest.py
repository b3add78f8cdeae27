"""
Shared fixtures: the colcon install layout, built once per session, and isolated DDS settings.

Node tests start the installed executables (as ``ros2 run`` would) and talk to them with rclpy;
each test gets its own ``ROS_DOMAIN_ID`` and localhost-only discovery, so parallel runs on one
machine cannot hear each other.
"""

import contextlib
import itertools
import os
from pathlib import Path
import subprocess
import sys

from etdmp_ros import processes, system
from etdmp_ros.processes import installed_argv, isolated_environment, sourced  # noqa: F401
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
PKG = 'etdmp_ros'
COLCON = Path(sys.executable).with_name('colcon')
# What a build that wrote into the source tree would leave there.
SOURCE_LITTER = ('build', 'install', 'log', '*.egg-info')
# Domain ids 1..101 (0 is the default that stray ROS processes use), spread by process id.
_DOMAIN_IDS = itertools.count(1 + os.getpid() % 50)


#: Every test module in one suite, marked so (``pytest -m unit``; ``make test-fast``):
#: ``unit`` runs in this process without ROS processes (about 30 s in all, linters included),
#: ``nodes`` starts installed executables, ``system`` runs the whole closed loop.
SUITES = {
    'unit': ('test_bag', 'test_cli', 'test_controller_sim', 'test_demos', 'test_dmp_core',
             'test_docs', 'test_dmp_obstacles', 'test_dmp_online', 'test_dmp_orientation',
             'test_dmp_rest',
             'test_dmp_similarity', 'test_dmp_skill', 'test_flake8', 'test_guide',
             'test_ik', 'test_metrics', 'test_package_xml', 'test_paper_reproduction',
             'test_pep257', 'test_planning',
             'test_readme', 'test_robot_model', 'test_ros_conversions_geometry',
             'test_ros_conversions_image', 'test_ros_conversions_sim',
             'test_ros_conversions_tf', 'test_sim',
             'test_skill_library', 'test_system', 'test_teaching', 'test_vision'),
    'nodes': ('test_adversarial_controller', 'test_adversarial_dmp_server',
              'test_adversarial_perception',
              'test_bringup_and_launch', 'test_controller_node', 'test_dmp_server_node',
              'test_install_layout', 'test_namespaces', 'test_perception_node',
              'test_ros2_cli', 'test_ur10_sim_node', 'test_ur10_sim_tf'),
    'system': ('test_end_to_end', 'test_kinesthetic', 'test_teach_page'),
}
_SUITE_OF = {module: suite for suite, modules in SUITES.items() for module in modules}


def pytest_configure(config):
    """Register the suite markers; every test module of this folder must be in exactly one."""
    present = {path.stem for path in Path(__file__).parent.glob('test_*.py')}
    listed = [module for modules in SUITES.values() for module in modules]
    if sorted(listed) != sorted(present):
        raise pytest.UsageError(
            f'test/conftest.py SUITES disagrees with the test modules: unlisted '
            f'{sorted(present - set(listed))}, missing {sorted(set(listed) - present)}, '
            f'listed twice {sorted({m for m in listed if listed.count(m) > 1})}')
    for suite in SUITES:
        config.addinivalue_line('markers', f'{suite}: a test of the {suite} suite (conftest)')


def pytest_collection_modifyitems(config, items):
    """Mark every test with its module's suite; a module in no suite is an error."""
    for item in items:
        module = item.path.stem
        if module not in _SUITE_OF:
            raise pytest.UsageError(f'{module} is in no suite: add it to SUITES in '
                                    'test/conftest.py')
        item.add_marker(getattr(pytest.mark, _SUITE_OF[module]))


def _litter():
    return {p.name for pattern in SOURCE_LITTER for p in REPO.glob(pattern)}


@pytest.fixture(scope='session')
def colcon_install(tmp_path_factory):
    """Run `colcon build --merge-install` of the repository once; return the install prefix."""
    if not COLCON.exists():
        pytest.skip(f'colcon is not installed beside {sys.executable} (make venv installs it)')
    tmp = tmp_path_factory.mktemp('colcon')
    env = dict(os.environ, COLCON_HOME=str(tmp / 'colcon_home'))
    before = _litter()
    result = subprocess.run(
        [str(COLCON), '--log-base', str(tmp / 'log'), 'build',
         '--paths', str(REPO), '--merge-install',
         '--build-base', str(tmp / 'build'), '--install-base', str(tmp / 'install')],
        cwd=tmp, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f'colcon build failed:\n{result.stdout}\n{result.stderr}'
    assert _litter() == before, 'colcon build wrote into the source tree'
    return tmp / 'install'


def isolate_dds(patch):
    """
    Give this process (via ``patch``, a pytest MonkeyPatch) its own DDS domain; return the env.

    A fresh ROS_DOMAIN_ID in 1..101 (the range safe from Linux's ephemeral ports) and
    localhost-only discovery, so parallel runs on one machine cannot hear each other. Pass the
    returned env to the node processes; rclpy in this process sees it too.
    """
    env = isolated_environment(next(_DOMAIN_IDS) % 101 + 1)
    for name in set(os.environ) - set(env):
        patch.delenv(name)
    for name, value in env.items():
        if os.environ.get(name) != value:
            patch.setenv(name, value)
    patch.setenv('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    return dict(os.environ)


@pytest.fixture
def ros_env(monkeypatch):
    """Isolate DDS for this test (see isolate_dds); return the env."""
    return isolate_dds(monkeypatch)


@pytest.fixture(scope='module')
def ros2(request):
    """
    Give the real ``ros2`` CLI on the colcon install (:class:`ros2_cli.Ros2`), own DDS domain.

    Skips the module when the CLI is not installed; stops the ``ros2 daemon`` of every domain it
    gave out (``ros2.fresh()`` makes another runner on a new domain) after the module.
    """
    import ros2_cli
    if ros2_cli.missing():
        pytest.skip(ros2_cli.missing())
    install = request.getfixturevalue('colcon_install')
    home = request.getfixturevalue('tmp_path_factory').mktemp('ros2')
    runners = []

    def fresh():
        domain = next(_DOMAIN_IDS) % 101 + 1
        runners.append(ros2_cli.Ros2(install, domain, home / str(len(runners))))
        runners[-1].fresh = fresh
        return runners[-1]
    yield fresh()
    for runner in runners:
        runner.stop_daemon()


@pytest.fixture(scope='module')
def module_ros_env():
    """Isolate DDS for a whole test module (nodes shared by its tests); return the env."""
    with pytest.MonkeyPatch.context() as patch:
        yield isolate_dds(patch)


class NodeProcess(processes.NodeProcess):
    """
    An installed node started as `ros2 run etdmp_ros <node>` would be, its output in a file.

    Parameters: the system's files (:func:`etdmp_ros.system.parameter_files`: config/scene.yaml,
    then config/<node>.yaml) from the install's share folder, then ``overrides`` written as the
    node's own section in a third file (a `-p name:=value` would lose against the node's section
    of its YAML), then ``extra_args`` verbatim. Stopping: :meth:`stop` (SIGINT, then kill).
    """

    def __init__(self, install, env, tmp, node, overrides=None, name=None, extra_args=''):
        """Start the node; ``name`` (default: the node's) names its log and override files."""
        name = name or node
        files = system.parameter_files(node, install / 'share' / PKG / 'config')
        if overrides:
            files.append(tmp / f'{name}_overrides.yaml')
            files[-1].write_text(yaml.safe_dump({node: {'ros__parameters': overrides}}))
        super().__init__(installed_argv(install, node, files, extra_args), tmp / f'{name}.log',
                         dict(env, ROS_HOME=str(tmp / 'ros_home'), MUJOCO_GL='egl'))


#: The busy loop of :func:`busy_core`: spins until killed or until its time is up.
_BUSY_LOOP = ('import sys, time\n'
              'end = time.monotonic() + float(sys.argv[1])\n'
              'while time.monotonic() < end:\n'
              '    pass\n')


@contextlib.contextmanager
def busy_core(active=True, limit=600.0):
    """
    Keep one core busy meanwhile (another program on the machine): one busy-looping process.

    Bounded: the process ends by itself after ``limit`` seconds even if this one dies first.
    """
    if not active:
        yield None
        return
    process = subprocess.Popen([sys.executable, '-c', _BUSY_LOOP, str(limit)])
    try:
        yield process
    finally:
        process.kill()
        process.wait()

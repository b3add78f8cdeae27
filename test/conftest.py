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

from etdmp_ros.ros import processes, system
from etdmp_ros.ros.processes import installed_argv, isolated_environment, sourced  # noqa: F401
import pytest
from support.leftovers import Leftovers
import yaml

REPO = Path(__file__).resolve().parents[1]
PKG = 'etdmp_ros'
COLCON = Path(sys.executable).with_name('colcon')
# What a build that wrote into the source tree would leave there.
SOURCE_LITTER = ('build', 'install', 'log', '*.egg-info')
# Domain ids 1..101 (0 is the default that stray ROS processes use), spread by process id.
_DOMAIN_IDS = itertools.count(1 + os.getpid() % 50)


#: The suites, one folder each (``pytest -m unit`` or ``pytest test/unit``; ``make test-fast``):
#: ``unit`` runs in this process without ROS processes (linters included), ``nodes`` starts
#: installed executables, ``system`` runs the whole closed loop. Helpers for the tests live in
#: ``support/`` (no tests), the benchmarks in ``benchmarks/`` (not collected).
SUITES = ('unit', 'nodes', 'system')
TEST_DIR = Path(__file__).resolve().parent
#: The watch over what the suite starts (pytest_configure to pytest_sessionfinish).
_LEFTOVERS = None


def pytest_configure(config):
    """
    Register the suite markers; every test module must sit in a suite's folder.

    Also starts watching what the suite starts (:mod:`support.leftovers`): at the end a
    process of the suite still running, or a Fast DDS shared-memory file of its processes
    still in /dev/shm, fails the run (:func:`pytest_sessionfinish`).
    """
    global _LEFTOVERS
    # With pytest-xdist (make test-fast: -n 2) the workers watch what their tests start; the
    # process that only hands out tests (no workerinput) would count the workers themselves.
    distributing = getattr(config, 'workerinput', None) is None and \
        config.getoption('numprocesses', None)
    if _LEFTOVERS is None and not distributing:
        _LEFTOVERS = Leftovers()
    stray = sorted(str(path.relative_to(TEST_DIR)) for path in TEST_DIR.rglob('test_*.py')
                   if path.parent.name not in SUITES or path.parent.parent != TEST_DIR)
    if stray:
        raise pytest.UsageError(f"test modules outside the suites' folders {SUITES}: {stray}")
    for suite in SUITES:
        config.addinivalue_line('markers', f'{suite}: a test of the {suite} suite (test/{suite}/)')


def pytest_sessionfinish(session, exitstatus):
    """Fail the run if it left a process or a shared-memory file behind (and remove them)."""
    global _LEFTOVERS
    if _LEFTOVERS is None:
        return
    problems, _LEFTOVERS = _LEFTOVERS.finish(), None
    if problems:
        reporter = session.config.pluginmanager.get_plugin('terminalreporter')
        text = ('the test suite left these behind (now killed and removed):\n  '
                + '\n  '.join(problems))
        if reporter is not None:
            reporter.write_sep('=', 'leftovers', red=True)
            reporter.write_line(text)
        else:
            print(text)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_runtest_logstart(nodeid, location):
    """Tell the leftovers' watch which test runs (a leftover names the test it came from)."""
    if _LEFTOVERS is not None:
        _LEFTOVERS.test = nodeid


def pytest_collection_modifyitems(config, items):
    """Mark every test with its folder's suite."""
    for item in items:
        item.add_marker(getattr(pytest.mark, item.path.parent.name))


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
    from support import ros2_cli
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

    Parameters: the system's files (:func:`etdmp_ros.ros.system.parameter_files`:
    config/scene.yaml, then config/<node>.yaml) from the install's share folder, then ``overrides``
    written as the node's own section in a third file (a `-p name:=value` would lose against the
    node's section of its YAML), then ``extra_args`` verbatim. Stopping: :meth:`stop` (SIGINT, then
    kill).
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

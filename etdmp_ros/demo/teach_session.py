"""
``make teach``: the simulated system and the teaching page, each node in its own process.

::

    make teach                                              # then open http://localhost:8080
    .venv/bin/python -m etdmp_ros.demo.teach_session --port 8090 --obstacles none

The four nodes start as ``make demo`` starts them (:mod:`etdmp_ros.ros.processes`: the package's
parameter files, then an overrides file per node, on a DDS domain of their own with
localhost-only discovery), then the teach node (:mod:`etdmp_ros.nodes.teach`). Ctrl-C stops
them all, the simulation last. Taught skills are saved where dmp_server keeps them
(``$ROS_HOME/etdmp_ros/skills``, else ``~/.ros/etdmp_ros/skills``), so they are there again
next time. No ROS here: processes only.
"""

import argparse
from pathlib import Path
import signal
import socket
import sys
import tempfile
import time
import urllib.error
import urllib.request

from etdmp_ros.ros import system
from etdmp_ros.ros.processes import isolated_environment, module_argv, NodeExited, NodeProcess
from etdmp_ros.ros.processes import SystemProcesses
import yaml

#: What each node of the system logs once it serves (dmp_server answers only after it).
SYSTEM_READY = {'ur10_sim': 'UR10 workcell ready', 'perception': 'perception ready',
                'dmp_server': 'serving /generalize', 'controller': 'following '}
#: Start-up of the nodes (numba caches, DDS discovery) on a loaded 2-core machine (s).
STARTUP = 120.0


class TeachSession:
    """
    The system's four nodes and the teach node, output in ``<log_dir>/<node>.log``.

    ``command(node, param_files)``: the argv of a node
    (:func:`etdmp_ros.ros.processes.module_argv`, or ``installed_command(install)``);
    ``config_dir``: the parameter files' folder (None: the package's); ``parameters``: ``{node:
    {name: value}}`` after the system's wiring, e.g. ``{'teach': {'port': 0}}``; ``obstacles``:
    False clears the scene's obstacles (ur10_sim's ``obstacle_positions``), so that a taught letter
    is written without detours.
    """

    def __init__(self, log_dir, env, command=module_argv, config_dir=None, parameters=None,
                 obstacles=True):
        """Start the nodes, the teach node last (the others keep the system's order)."""
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        overrides = {spec.name: dict(system.wiring_overrides(spec.name))
                     for spec in system.ALL_NODES}
        if not obstacles:
            # `[]` in YAML leaves it unset, which ur10_sim takes as no obstacles.
            overrides['ur10_sim']['obstacle_positions'] = []
        for name, values in (parameters or {}).items():
            overrides[system.node(name).name].update(values)
        teach = {**system.defaults('teach'), **overrides['teach']}
        if not teach['port']:    # any free port: chosen here, so that the address is known
            overrides['teach']['port'] = teach['port'] = free_port(teach['address'])
        host = 'localhost' if teach['address'] in ('127.0.0.1', '::1', 'localhost') \
            else teach['address']
        self.page = f'http://[{host}]:{teach["port"]}/' if ':' in host else \
            f'http://{host}:{teach["port"]}/'

        def param_files(name, directory):
            files = system.parameter_files(name, config_dir)
            if overrides[name]:
                path = Path(directory) / f'{name}_overrides.yaml'
                path.write_text(yaml.safe_dump({name: {'ros__parameters': overrides[name]}}))
                files.append(path)
            return files

        self.system = SystemProcesses(param_files, self.log_dir, env, command)
        self.teach = NodeProcess(command('teach', param_files('teach', self.log_dir)),
                                 self.log_dir / 'teach.log', env)

    def url(self, timeout=STARTUP):
        """
        Wait until every node serves; return the page's address.

        Raises NodeExited if a node ended, TimeoutError naming the nodes not ready in time.
        """
        deadline = time.monotonic() + timeout
        while True:
            self.check_alive()
            waiting = [name for name, line in SYSTEM_READY.items()
                       if line not in self.system.log(name)] + \
                ([] if page_answers(self.page + 'api/config') else ['teach'])
            if not waiting:
                return self.page
            if time.monotonic() > deadline:
                raise TimeoutError(f'not ready within {timeout:g} s: {", ".join(waiting)}')
            time.sleep(0.1)

    def check_alive(self):
        """Raise NodeExited naming a node that has exited, with the end of its log."""
        self.system.check_alive()
        if self.teach.returncode is not None:
            tail = '\n'.join(self.teach.log().splitlines()[-15:])
            raise NodeExited(f'teach exited with code {self.teach.returncode}:\n{tail}')

    def stop(self, timeout=10.0, interrupted=False):
        """Stop the teach node, then the system (SIGINT); return every exit code."""
        self.teach.interrupt()
        codes = {'teach': self.teach.wait(timeout)}
        codes.update(self.system.stop(timeout, interrupted))
        return codes


def free_port(address):
    """Return a TCP port free on ``address`` now (the system's choice)."""
    family = socket.AF_INET6 if ':' in address else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.bind((address, 0))
        return probe.getsockname()[1]


def page_answers(url):
    """Return True if the teaching page answers ``url`` (it is served)."""
    try:
        with urllib.request.urlopen(url, timeout=1.0) as answer:
            return answer.status == 200
    except (urllib.error.URLError, OSError):
        return False


class _Terminated(Exception):
    """SIGTERM: stop the nodes as for Ctrl-C (they did not get the signal themselves)."""


def _terminate(signum, frame):
    raise _Terminated()


def main(argv=None):
    """Run the system and the teaching page until Ctrl-C."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip('`: '))
    parser.add_argument('--port', type=int, default=8080, help='port of the page (0: any)')
    parser.add_argument('--obstacles', choices=('scene', 'none'), default='scene',
                        help="the scene's obstacles (scene.yaml) or none")
    parser.add_argument('--domain-id', type=int, default=None,
                        help='ROS_DOMAIN_ID of the nodes (default: one from the process id)')
    parser.add_argument('--logs', type=Path, default=None,
                        help="folder of the nodes' logs (default: a temporary one)")
    args = parser.parse_args(argv)
    # Ctrl-C, and SIGTERM like it (a service manager, `timeout`): stop the nodes, never orphan
    # them. SIGINT is set explicitly, since a shell starts a background job with it ignored.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _terminate)
    env = isolated_environment(args.domain_id)
    with tempfile.TemporaryDirectory(prefix='etdmp_teach_') as tmp:
        logs = args.logs or Path(tmp)
        print(f'starting the simulated UR10, its camera, perception, dmp_server, the '
              f'controller and the teaching page (ROS_DOMAIN_ID {env["ROS_DOMAIN_ID"]}, logs '
              f'in {logs}) ...', flush=True)
        session = TeachSession(logs, env, parameters={'teach': {'port': args.port}},
                               obstacles=args.obstacles == 'scene')
        interrupted = False
        try:
            print(f'open {session.url()} in a browser; Ctrl-C stops everything', flush=True)
            while True:
                time.sleep(0.5)
                session.check_alive()
        except KeyboardInterrupt:
            interrupted = True   # the nodes, in the same process group, got it too
        except _Terminated:
            pass
        except (NodeExited, TimeoutError) as err:
            print(f'error: {err}', file=sys.stderr)
        finally:
            codes = session.stop(interrupted=interrupted)
        print('stopped: ' + ', '.join(f'{name} {code}' for name, code in codes.items()))
        return 0 if all(code == 0 for code in codes.values()) and not \
            any(code is None for code in codes.values()) else 1


if __name__ == '__main__':
    sys.exit(main())

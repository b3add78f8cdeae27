"""
bringup: ur10_sim, perception, dmp_server and controller in ONE process (no ros2launch needed).

``ros2 run etdmp_ros bringup`` runs the same node classes with the same parameter files as
``ros2 launch etdmp_ros etdmp.launch.py`` runs in four processes, as the system description
(:mod:`etdmp_ros.ros.system`) says: config/scene.yaml, then each node's config/<node>.yaml (every
file is keyed by node name, so all of them can be given to the one process), then the system's
overrides (``use_sim_time`` for dmp_server and the controller, which follow /clock), then the
arguments given here (e.g. ``--ros-args --params-file my.yaml``). One executor spins them
(the simulation steps in its own threads); on Ctrl-C the controller sends zero velocity before
anything shuts down (``_spin.run``).

``ros2 run etdmp_ros bringup --host robot`` (or ``workstation``) runs the part of the system one
computer of a lab runs (docs/two_hosts.md), ``--nodes ur10_sim,controller`` any part, as the
launch file's ``host:=`` and ``nodes:=`` (:func:`etdmp_ros.ros.system.select_nodes`).
"""

import argparse
import importlib
import sys
import tempfile

from etdmp_ros.ros import system
import yaml


def parameter_files():
    """Return the parameter files of the system: scene.yaml, then every node's own file."""
    files = []
    for spec in system.NODES:
        files += [str(f) for f in system.parameter_files(spec.name) if str(f) not in files]
    return files


def overrides_file(directory):
    """Write the system's overrides of every node (use_sim_time) into one parameter file."""
    path = f'{directory}/system_overrides.yaml'
    with open(path, 'w') as f:
        yaml.safe_dump({n: {'ros__parameters': system.wiring_overrides(n)}
                        for n in system.NODE_NAMES if system.wiring_overrides(n)}, f)
    return path


def node_class(spec):
    """Return the class of a NodeSpec (``module:Class``), imported."""
    module, name = spec.node_class.split(':')
    return getattr(importlib.import_module(module), name)


def split_arguments(argv):
    """
    Return (chosen node names, argv without ``--host`` / ``--nodes``): see the module docstring.

    Only the arguments before ``--ros-args`` are this program's; ValueError for a bad choice.
    """
    argv = list(argv)
    end = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    parser = argparse.ArgumentParser(prog='bringup', add_help=False)
    parser.add_argument('--host', default='all')
    parser.add_argument('--nodes', default='')
    known, rest = parser.parse_known_args(argv[1:end])
    return (system.select_nodes(known.host, known.nodes),
            argv[:1] + rest + argv[end:])


def ros_arguments(user_args, directory):
    """Return the rclpy arguments: the system's parameter files first, the user's last."""
    files = parameter_files() + [overrides_file(directory)]
    args = list(user_args)
    head = args[:1]                     # the program name, as rclpy expects it
    rest = args[1:]
    if '--ros-args' in rest:
        i = rest.index('--ros-args')
        before, ros = rest[:i], rest[i + 1:]
    else:
        before, ros = rest, []
    files_args = [a for f in files for a in ('--params-file', f)]
    return head + before + ['--ros-args'] + files_args + ros


def main(args=None):
    """Run the four nodes (or the chosen ones) in one process until Ctrl-C (or SIGTERM)."""
    from etdmp_ros.ros.spin import run
    from etdmp_ros.nodes.dmp_server import InvalidConfiguration

    try:
        chosen, args = split_arguments(sys.argv if args is None else args)
    except ValueError as err:
        print(f'bringup: {err}', file=sys.stderr)
        return 2

    def make(nodes):
        for spec in system.NODES:   # the simulation first: its thread starts at once
            if spec.name not in chosen:
                continue
            nodes.append(node_class(spec)())
            if hasattr(nodes[-1], 'start'):
                nodes[-1].start()

    with tempfile.TemporaryDirectory(prefix='etdmp_bringup_') as directory:
        argv = ros_arguments(args, directory)
        return run(make, 'bringup', argv, startup_errors=(InvalidConfiguration,))


if __name__ == '__main__':
    raise SystemExit(main())

"""
bringup: ur10_sim, perception, dmp_server and controller in ONE process (no ros2launch needed).

``ros2 run etdmp_ros bringup`` runs the same node classes with the same parameter files as
``ros2 launch etdmp_ros etdmp.launch.py`` runs in four processes: config/scene.yaml, then each
node's config/<node>.yaml (every file is keyed by node name, so all of them can be given to the
one process), then the arguments given here (e.g. ``--ros-args --params-file my.yaml``).
dmp_server runs on simulated time (``use_sim_time``: it stamps plans with the ROS clock), as the
launch file sets it; the other nodes stamp with their inputs' stamps. One executor spins them
(the simulation steps in its own threads); on Ctrl-C the controller sends zero velocity before
anything shuts down (``_spin.run``).
"""

import sys
import tempfile

from etdmp_ros._paths import config_path
from etdmp_ros.nodes._spin import run
import yaml

NODES = ('ur10_sim', 'perception', 'dmp_server', 'controller')
#: Nodes that follow the simulation's /clock: those that stamp with the ROS clock (plans).
SIM_TIME_NODES = ('dmp_server',)


def parameter_files():
    """Return the parameter files of the system: scene.yaml, then every node's own file."""
    return [str(config_path('scene.yaml'))] + [str(config_path(f'{n}.yaml')) for n in NODES]


def sim_time_file(directory):
    """Write a parameter file setting ``use_sim_time`` for the nodes that follow /clock."""
    path = f'{directory}/use_sim_time.yaml'
    with open(path, 'w') as f:
        yaml.safe_dump({n: {'ros__parameters': {'use_sim_time': True}} for n in SIM_TIME_NODES},
                       f)
    return path


def ros_arguments(user_args, directory):
    """Return the rclpy arguments: the system's parameter files first, the user's last."""
    files = parameter_files() + [sim_time_file(directory)]
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
    """Run the four nodes in one process until Ctrl-C (or SIGTERM)."""
    from etdmp_ros.nodes.controller import ControllerNode
    from etdmp_ros.nodes.dmp_server import DmpServer, InvalidConfiguration
    from etdmp_ros.nodes.perception import PerceptionNode
    from etdmp_ros.nodes.ur10_sim import UR10SimNode

    def make(nodes):
        nodes.append(UR10SimNode())
        nodes[-1].start()
        for node_class in (PerceptionNode, DmpServer, ControllerNode):
            nodes.append(node_class())

    with tempfile.TemporaryDirectory(prefix='etdmp_bringup_') as directory:
        argv = ros_arguments(sys.argv if args is None else args, directory)
        return run(make, 'bringup', argv, startup_errors=(InvalidConfiguration,))


if __name__ == '__main__':
    raise SystemExit(main())

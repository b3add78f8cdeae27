"""
bringup: ur10_sim, perception, dmp_server and controller in ONE process (no ros2launch needed).

``ros2 run etdmp_ros bringup`` runs the same node classes with the same parameter files as
``ros2 launch etdmp_ros etdmp.launch.py`` runs in four processes: config/scene.yaml, then each
node's config/<node>.yaml (every file is keyed by node name, so all of them can be given to the
one process), then the arguments given here (e.g. ``--ros-args --params-file my.yaml``). The
nodes other than the simulation run on simulated time (``use_sim_time``), as the launch file
sets it. One SingleThreadedExecutor spins them (the simulation steps in its own thread; rclpy's
MultiThreadedExecutor keeps a core busy with 125 Hz topics); on Ctrl-C the controller sends zero
velocity before anything shuts down.
"""

import signal
import sys
import tempfile

from etdmp_ros._paths import config_path
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions
import yaml

NODES = ('ur10_sim', 'perception', 'dmp_server', 'controller')
#: Nodes that follow the simulation's /clock.
SIM_TIME_NODES = ('perception', 'dmp_server', 'controller')


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


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main(args=None):
    """Run the four nodes in one process until Ctrl-C (or SIGTERM)."""
    from etdmp_ros.nodes.controller import ControllerNode
    from etdmp_ros.nodes.dmp_server import DmpServer
    from etdmp_ros.nodes.perception import PerceptionNode
    from etdmp_ros.nodes.ur10_sim import UR10SimNode

    with tempfile.TemporaryDirectory(prefix='etdmp_bringup_') as directory:
        argv = ros_arguments(sys.argv if args is None else args, directory)
        # Our own signal handling: the controller must send zeros before the context goes.
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
        signal.signal(signal.SIGINT, _interrupt)
        signal.signal(signal.SIGTERM, _interrupt)
        nodes = []
        code = 0
        try:
            sim = UR10SimNode()
            nodes.append(sim)
            sim.start()
            nodes += [PerceptionNode(), DmpServer(), ControllerNode()]
            executor = SingleThreadedExecutor()
            for node in nodes:
                executor.add_node(node)
            executor.spin()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except Exception as exc:   # noqa: B902 - a node refused its parameters: say so, exit 1
            rclpy.logging.get_logger('bringup').fatal(f'cannot start: {exc}')
            code = 1
        finally:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            for node in reversed(nodes):
                if hasattr(node, 'send_zeros'):
                    node.send_zeros()
                if hasattr(node, 'stop'):
                    node.stop()
                node.destroy_node()
            rclpy.try_shutdown()
        return code


if __name__ == '__main__':
    raise SystemExit(main())

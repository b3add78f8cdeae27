"""
Start the system as four processes: ur10_sim, perception, dmp_server, controller (or a part).

The nodes and their parameter files come from the system description (etdmp_ros.ros.system): each
node gets the shared workcell file config/scene.yaml, then its own config/<node>.yaml, then the
system's overrides (use_sim_time for the nodes that follow /clock), exactly as
`ros2 run etdmp_ros bringup` does in one process (for installs without ros2launch).

    ros2 launch etdmp_ros etdmp.launch.py
    ros2 launch etdmp_ros etdmp.launch.py skill:=W method:=dmp
    ros2 launch etdmp_ros etdmp.launch.py namespace:=robot2     # a second robot, /robot2/...
    ros2 launch etdmp_ros etdmp.launch.py teach:=true           # and the teaching page
    ros2 launch etdmp_ros etdmp.launch.py host:=robot           # ur10_sim, controller
    ros2 launch etdmp_ros etdmp.launch.py host:=workstation     # perception, dmp_server
    ros2 launch etdmp_ros etdmp.launch.py nodes:=ur10_sim       # any part, by node name

``host`` and ``nodes`` choose the part of the system this computer runs (etdmp_ros.ros.system:
``HOSTS``, ``select_nodes``): a lab with two computers runs ``host:=robot`` on the one beside the
arm and ``host:=workstation`` on the other, on the same ROS_DOMAIN_ID (docs/two_hosts.md has
the recipe). An unknown host or node stops the launch with an error naming the choices.

Every topic and service name of the nodes is relative, so ``namespace`` moves all of them
(``/robot2/joint_states``, ``/robot2/generalize``, ...). Two things follow the namespace here
that would not by themselves: a node's section of its parameter file is keyed by its bare name,
which rcl matches in the root namespace only, so each node also gets that section's values as
launch parameters (the same values, so nothing changes in the root namespace); and rclpy's sim
time listens to the absolute ``/clock``, so ``/clock`` is remapped to the relative ``clock``
(``/robot2/clock``: each robot's simulation drives its own dmp_server; in the root namespace it
stays ``/clock``).
"""

import os

from ament_index_python.packages import get_package_share_directory
from etdmp_ros.ros import config_files, system
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Describe the chosen nodes (and teach), each with scene.yaml then its own parameter file."""
    arguments = [
        DeclareLaunchArgument('skill', default_value='G',
                              description='skill the DMP server generalizes'),
        DeclareLaunchArgument('method', default_value='etdmp', description='etdmp or dmp'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of every node, topic and service'),
        DeclareLaunchArgument('teach', default_value='false',
                              description='also serve the teaching page (node teach, '
                              'http://localhost:8080)'),
        DeclareLaunchArgument('host', default_value='all', choices=list(system.HOST_CHOICES),
                              description='the part of the system this computer runs: all, '
                              'robot (' + ', '.join(system.HOSTS['robot']) + ') or workstation ('
                              + ', '.join(system.HOSTS['workstation']) + ')'),
        DeclareLaunchArgument('nodes', default_value='',
                              description='instead of host: the nodes to start, separated by '
                              'commas (' + ', '.join(system.NODE_NAMES) + ')'),
    ]
    return LaunchDescription(arguments + [OpaqueFunction(function=_nodes)])


def _nodes(context):
    """Return the Node actions of the nodes chosen by ``host`` or ``nodes``."""
    chosen = system.select_nodes(LaunchConfiguration('host').perform(context),
                                 LaunchConfiguration('nodes').perform(context))
    config = os.path.join(get_package_share_directory('etdmp_ros'), 'config')
    nodes = []
    for spec in system.ALL_NODES:
        if spec is not system.TEACH_NODE and spec.name not in chosen:
            continue
        files = system.parameter_files(spec.name, config)
        parameters = [str(f) for f in files]
        parameters.append(config_files.read_parameter_file(files[-1], spec.name))
        overrides = system.wiring_overrides(spec.name)
        if overrides:
            parameters.append(overrides)
        if spec.name == 'dmp_server':
            parameters.append({'skill': LaunchConfiguration('skill'),
                               'method': LaunchConfiguration('method')})
        nodes.append(Node(package='etdmp_ros', executable=spec.executable, name=spec.name,
                          namespace=LaunchConfiguration('namespace'), output='screen',
                          emulate_tty=True, parameters=parameters,
                          ros_arguments=['-r', '/clock:=clock'],
                          condition=IfCondition(LaunchConfiguration('teach'))
                          if spec is system.TEACH_NODE else None))
    return nodes

"""
Start the whole system as four processes: ur10_sim, perception, dmp_server, controller.

The nodes and their parameter files come from the system description (etdmp_ros.system): each
node gets the shared workcell file config/scene.yaml, then its own config/<node>.yaml, then the
system's overrides (use_sim_time for the nodes that follow /clock), exactly as
`ros2 run etdmp_ros bringup` does in one process (for installs without ros2launch).

    ros2 launch etdmp_ros etdmp.launch.py
    ros2 launch etdmp_ros etdmp.launch.py skill:=W method:=dmp
"""

import os

from ament_index_python.packages import get_package_share_directory
from etdmp_ros import system
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Describe the four nodes, each with scene.yaml then its own parameter file."""
    config = os.path.join(get_package_share_directory('etdmp_ros'), 'config')
    arguments = [
        DeclareLaunchArgument('skill', default_value='G',
                              description='skill the DMP server generalizes'),
        DeclareLaunchArgument('method', default_value='etdmp', description='etdmp or dmp'),
    ]
    nodes = []
    for spec in system.NODES:
        parameters = [str(f) for f in system.parameter_files(spec.name, config)]
        overrides = system.wiring_overrides(spec.name)
        if overrides:
            parameters.append(overrides)
        if spec.name == 'dmp_server':
            parameters.append({'skill': LaunchConfiguration('skill'),
                               'method': LaunchConfiguration('method')})
        nodes.append(Node(package='etdmp_ros', executable=spec.executable, name=spec.name,
                          output='screen', emulate_tty=True, parameters=parameters))
    return LaunchDescription(arguments + nodes)

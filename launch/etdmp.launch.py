"""
Start the whole system as four processes: ur10_sim, perception, dmp_server, controller.

Each node gets the shared workcell file config/scene.yaml and then its own config/<node>.yaml,
exactly as `ros2 run etdmp_ros bringup` does in one process (for installs without ros2launch).

    ros2 launch etdmp_ros etdmp.launch.py
    ros2 launch etdmp_ros etdmp.launch.py skill:=W method:=dmp
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

NODES = ('ur10_sim', 'perception', 'dmp_server', 'controller')
SIM_TIME_NODES = ('dmp_server',)


def generate_launch_description():
    """Describe the four nodes, each with scene.yaml then its own parameter file."""
    config = os.path.join(get_package_share_directory('etdmp_ros'), 'config')
    scene = os.path.join(config, 'scene.yaml')
    arguments = [
        DeclareLaunchArgument('skill', default_value='G',
                              description='skill the DMP server generalizes'),
        DeclareLaunchArgument('method', default_value='etdmp', description='etdmp or dmp'),
    ]
    nodes = []
    for name in NODES:
        parameters = [scene, os.path.join(config, f'{name}.yaml')]
        if name in SIM_TIME_NODES:
            # dmp_server stamps plans with the ROS clock: the simulation's /clock. The others
            # stamp with their inputs' stamps (images, joint states) and need no clock.
            parameters.append({'use_sim_time': True})
        if name == 'dmp_server':
            parameters.append({'skill': LaunchConfiguration('skill'),
                               'method': LaunchConfiguration('method')})
        nodes.append(Node(package='etdmp_ros', executable=name, name=name, output='screen',
                          emulate_tty=True, parameters=parameters))
    return LaunchDescription(arguments + nodes)

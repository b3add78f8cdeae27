"""
The simulated workcell: a MuJoCo UR10 driven by joint velocities, and a RealSense-style camera.

Built from the same ``example-robot-data`` UR10 as :class:`etdmp_ros.robot.UR10Model`; the node
``ur10_sim`` is its ROS shell. Importing this package imports MuJoCo.
"""

from etdmp_ros.sim._sim import CameraState, Contact, UR10Sim
from etdmp_ros.sim._workcell import MAX_OBSTACLES

__all__ = ['CameraState', 'Contact', 'MAX_OBSTACLES', 'UR10Sim']

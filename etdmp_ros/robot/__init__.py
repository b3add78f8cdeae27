"""
ROS-free robot side: the UR10 model (Pinocchio); the MuJoCo scene, camera and vision to come.

Kinematics live in one place, :class:`UR10Model`, which the simulation checks itself against, the
controller drives, and the DMP server uses to find the tool.
"""

from ._ur10 import (JOINT_NAMES, OFFICIAL_VELOCITY_LIMITS, robot_data_dir, ur10_urdf_path,
                    UR10Model)

__all__ = ['JOINT_NAMES', 'OFFICIAL_VELOCITY_LIMITS', 'UR10Model', 'robot_data_dir',
           'ur10_urdf_path']

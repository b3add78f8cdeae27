"""
ROS-free robot side: the UR10 model, inverse kinematics, trajectories and the controller.

Kinematics live in one place, :class:`UR10Model` (Pinocchio), which the simulation checks itself
against, the controller drives and the DMP server uses to find the tool. The workcell every node
shares is :class:`SceneConfig`; the robot description and its frame tree are what a UR driver
and robot_state_publisher would publish.
"""

from ._check_process import CheckError, CheckProcess
from ._controller import Command, ControllerConfig, STATUSES, TrajectoryController
from ._delay import DelayEstimator
from ._description import (CAMERA_OPTICAL_FRAME, camera_transforms, chain_pose, FrameTree,
                           robot_description, Transform)
from ._guide import GuidedMotion, GuideError
from ._ik import DEFAULT_ACCELERATION_LIMITS, DifferentialIK, IKResult
from ._scene import (obstacle_radii_for, parse_bottle_position, parse_goal_position,
                     parse_obstacle_positions, parse_obstacle_radii, PEN_RADIUS, PEN_TIP_LENGTH,
                     PEN_TIP_RADIUS, SCENE_PARAMETERS, SceneConfig)
from ._trajectory import (MinimumJerkMove, PoseTrajectory, quaternions_to_rotations,
                          trajectory_from_path, TrajectoryError)
from ._ur10 import (JOINT_NAMES, OFFICIAL_VELOCITY_LIMITS, robot_data_dir, ur10_urdf_path,
                    UR10Model, WATCHDOG_TIMEOUT)
from ._watch import InputWatch, TrackingSummary

__all__ = [
    'CAMERA_OPTICAL_FRAME', 'CheckError', 'CheckProcess', 'Command', 'ControllerConfig',
    'DEFAULT_ACCELERATION_LIMITS',
    'DelayEstimator', 'DifferentialIK', 'FrameTree', 'GuidedMotion', 'GuideError', 'IKResult',
    'InputWatch', 'JOINT_NAMES', 'MinimumJerkMove', 'OFFICIAL_VELOCITY_LIMITS', 'PEN_RADIUS',
    'PEN_TIP_LENGTH', 'PEN_TIP_RADIUS', 'PoseTrajectory', 'SCENE_PARAMETERS', 'STATUSES',
    'SceneConfig', 'TrackingSummary', 'TrajectoryController', 'Transform', 'TrajectoryError',
    'UR10Model', 'camera_transforms',
    'chain_pose', 'obstacle_radii_for', 'parse_bottle_position', 'parse_goal_position',
    'parse_obstacle_positions', 'parse_obstacle_radii', 'quaternions_to_rotations',
    'robot_data_dir', 'robot_description', 'trajectory_from_path', 'ur10_urdf_path',
    'WATCHDOG_TIMEOUT',
]

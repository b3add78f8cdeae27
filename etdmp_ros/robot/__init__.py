"""
ROS-free robot side: the UR10 model, the controller, the MuJoCo workcell and the vision.

Kinematics live in one place, :class:`UR10Model` (Pinocchio), which the simulation checks itself
against, the controller drives and the DMP server uses to find the tool. :class:`UR10Sim` (MuJoCo)
and the vision (:class:`Detector`, OpenCV) are imported on first use, so the nodes that need
neither (dmp_server, controller) start without loading MuJoCo or OpenCV.
"""

import importlib

from ._camera import CameraIntrinsics, CameraPose, matrix_to_quaternion, quaternion_to_matrix
from ._controller import Command, ControllerConfig, DelayEstimator, STATUSES, TrajectoryController
from ._description import (camera_transforms, chain_pose, FrameTree, robot_description,
                           Transform)
from ._guide import GuidedMotion, GuideError
from ._ik import DEFAULT_ACCELERATION_LIMITS, DifferentialIK, IKResult
from ._scene import (obstacle_radii_for, parse_bottle_position, parse_goal_position,
                     parse_obstacle_positions, parse_obstacle_radii, PEN_RADIUS, PEN_TIP_LENGTH,
                     PEN_TIP_RADIUS, SCENE_PARAMETERS, SceneConfig)
from ._trajectory import (MinimumJerkMove, PoseTrajectory, quaternions_to_rotations,
                          trajectory_from_path, TrajectoryError)
from ._ur10 import (JOINT_NAMES, OFFICIAL_VELOCITY_LIMITS, robot_data_dir, ur10_urdf_path,
                    UR10Model)

_LAZY = {
    '_sim': ('CameraState', 'Contact', 'MAX_OBSTACLES', 'UR10Sim'),
    '_vision': ('check_frame', 'Detection', 'Detections', 'Detector', 'detector_from_parameters',
                'DETECTOR_PARAMETERS', 'DetectorSettings', 'FrameSynchronizer', 'HsvRange',
                'ObjectModel', 'Rejection'),
}
_LAZY_NAMES = {name: module for module, names in _LAZY.items() for name in names}


def __getattr__(name):
    """Import the MuJoCo simulation and the OpenCV vision on first use (PEP 562)."""
    module = _LAZY_NAMES.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'.{module}', __name__), name)
    globals()[name] = value
    return value


__all__ = [
    'CameraIntrinsics', 'CameraPose', 'Command', 'ControllerConfig',
    'DEFAULT_ACCELERATION_LIMITS', 'DelayEstimator', 'DifferentialIK', 'FrameTree',
    'GuidedMotion', 'GuideError', 'IKResult',
    'JOINT_NAMES', 'MinimumJerkMove', 'OFFICIAL_VELOCITY_LIMITS', 'PEN_RADIUS',
    'PEN_TIP_LENGTH', 'PEN_TIP_RADIUS',
    'PoseTrajectory', 'SCENE_PARAMETERS', 'STATUSES', 'SceneConfig', 'TrajectoryController',
    'Transform', 'TrajectoryError', 'UR10Model', 'camera_transforms', 'chain_pose',
    'matrix_to_quaternion', 'obstacle_radii_for', 'parse_bottle_position',
    'parse_goal_position', 'parse_obstacle_positions', 'parse_obstacle_radii',
    'quaternion_to_matrix', 'quaternions_to_rotations',
    'robot_data_dir', 'robot_description', 'trajectory_from_path', 'ur10_urdf_path',
    *_LAZY_NAMES,
]

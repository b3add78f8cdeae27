"""
The goal marker, the obstacles and the bottle from colour and aligned depth images (OpenCV).

The node ``perception`` is its ROS shell. Importing this package imports OpenCV.
"""

from etdmp_ros.perception._frames import check_frame, FrameSynchronizer
from etdmp_ros.perception._models import (Detection, Detections, DetectorSettings, HsvRange,
                                          ObjectModel, Rejection)
from etdmp_ros.perception._vision import Detector, detector_from_parameters, DETECTOR_PARAMETERS

__all__ = ['DETECTOR_PARAMETERS', 'Detection', 'Detections', 'Detector', 'DetectorSettings',
           'FrameSynchronizer', 'HsvRange', 'ObjectModel', 'Rejection', 'check_frame',
           'detector_from_parameters']

"""
The goal marker, the obstacles and the bottle from colour and aligned depth images (OpenCV).

The node ``perception`` is its ROS shell. Importing this package imports OpenCV.
"""

from etdmp_ros.perception._vision import (check_frame, Detection, Detections, Detector,
                                          detector_from_parameters, DETECTOR_PARAMETERS,
                                          DetectorSettings, FrameSynchronizer, HsvRange,
                                          ObjectModel, Rejection)

__all__ = ['DETECTOR_PARAMETERS', 'Detection', 'Detections', 'Detector', 'DetectorSettings',
           'FrameSynchronizer', 'HsvRange', 'ObjectModel', 'Rejection', 'check_frame',
           'detector_from_parameters']

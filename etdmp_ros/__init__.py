"""
etdmp_ros: Euclidean-transformation DMPs (ET-DMPs) on a simulated UR10 with ROS 2.

The ROS-free core lives in :mod:`etdmp_ros.dmp`; nodes are thin shells around it.
"""

__version__ = '0.1.0'

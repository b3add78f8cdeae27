"""
Thin rclpy nodes: each translates messages and parameters to calls of the ROS-free core.

Run them with ``ros2 run etdmp_ros <node>`` (console scripts in setup.py).
"""

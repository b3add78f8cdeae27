"""
numpy <-> ROS message helpers, written once for every node (no cv_bridge or tf2 here).

Importing this package imports rclpy message modules; the ROS-free core never does.
"""

"""
The DMP server's logic without ROS: skills, their recordings, planning, following, teaching.

- :mod:`~etdmp_ros.skills.library`: the skills the server knows, learned from demonstration
  files, recordings and taught paths.
- :mod:`~etdmp_ros.skills.recordings`: rosbag2 MCAP recordings read and written without rclpy.
- :mod:`~etdmp_ros.skills.planning`: a request (skill, start, goal, obstacles, settings) to a
  timed ``base_link`` path, and a plan in execution that follows a moved goal or obstacle.
- :mod:`~etdmp_ros.skills.teaching`: a drawing from the teaching page to a demonstration.
"""

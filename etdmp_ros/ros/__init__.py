"""
What every node shares with ROS: the system description, parameters, spinning, conversions.

- :mod:`~etdmp_ros.ros.system`: the one description of the nodes, their parameters and how
  they start; :mod:`~etdmp_ros.ros.config_files` writes ``config/*.yaml`` and the docs' tables
  from it; :mod:`~etdmp_ros.ros.parameters` declares them on a node.
- :mod:`~etdmp_ros.ros.spin`: the executor, the DDS profile, the shutdown every node uses;
  :mod:`~etdmp_ros.ros.background` a node in a thread of its own (tools, tests, the demo);
  :mod:`~etdmp_ros.ros.queued_service` the service that answers every request.
- :mod:`~etdmp_ros.ros.conversions`: numpy to and from ROS messages.
- :mod:`~etdmp_ros.ros.topics`: the topic and service names; :mod:`~etdmp_ros.ros.qos` the
  shared QoS profiles; :mod:`~etdmp_ros.ros.events`: what a node reports happened, as data
  (its ``~/events`` topic).
- :mod:`~etdmp_ros.ros.processes`: the nodes started as separate processes, as ``ros2 run``.
"""

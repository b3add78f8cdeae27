"""
Geometry that every layer shares, numpy only: the lowest layer above :mod:`etdmp_ros.limits`.

- :mod:`~etdmp_ros.geometry.quaternion`: unit quaternions in ROS order ``(x, y, z, w)``,
  batched: products, logarithm and exponential maps, conversion to and from rotation matrices.
- :mod:`~etdmp_ros.geometry.camera`: the pinhole camera model and camera poses (the link between
  pixels and ``base_link``).
- :mod:`~etdmp_ros.geometry.task_plane`: the plane in the workcell where 2D skills are executed.
- :mod:`~etdmp_ros.geometry.arrays`: the names of float arrays in signatures (shape and unit).
"""

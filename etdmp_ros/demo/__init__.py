"""
The closed-loop demo and the programs around the running system, with their measurements.

- :mod:`~etdmp_ros.demo.run`: ``make demo`` (``python -m etdmp_ros.demo``): see, plan, write,
  measure; :mod:`~etdmp_ros.demo.cli` its command line and printed summary;
  :mod:`~etdmp_ros.demo.scenario` each skill's layout.
- :mod:`~etdmp_ros.demo.recording` records the whole system as ``ros2 bag record`` would;
  :mod:`~etdmp_ros.demo.metrics` computes a run's figures from its recording;
  :mod:`~etdmp_ros.demo.pictures` draws them; :mod:`~etdmp_ros.demo.cpu_monitor` measures CPU.
- :mod:`~etdmp_ros.demo.teach_session` (``make teach``) and :mod:`~etdmp_ros.demo.kinesthetic`
  (``make kinesthetic``).
"""

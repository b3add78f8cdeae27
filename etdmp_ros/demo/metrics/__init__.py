"""
What a closed-loop run is measured by: computed from its recording, without ROS.

:func:`compute_metrics` takes a :class:`Run` (the scenario, the plans, and the streams read back
from the run's MCAP recording by :func:`etdmp_ros.demo.recording.read_streams`) and returns its
figures; :func:`system_figures` adds what the closed loop cost. What each figure means is
written once, in :mod:`._definitions` (``DEFINITIONS``, ``MOVE_DEFINITIONS``,
``SYSTEM_DEFINITIONS``), and repeated in ``metrics.json`` under ``definitions``. The nodes' own
figures (the controller's tracking summary, the simulation's stalls, a re-plan's latency) are
read from their events (:mod:`etdmp_ros.ros.events`), never from log text.

By what they measure:

- :mod:`._trace`: the executed motion against the plan (tracking start, nRMSE, tracking error,
  the plan as executed when it was re-planned);
- :mod:`._clearance`: clearances to the obstacles and the bottle's wall, contacts;
- :mod:`._orientation`: the tool's orientation;
- :mod:`._moved_goal`: a goal that moved while the pen wrote (switch, speeds, latencies);
- :mod:`._system`: CPU, command rates, the nodes' loops;
- :mod:`._compute`: all of them put together.
"""

from etdmp_ros.demo.metrics._clearance import (bottle_clearances, clearance_mm, contact_figures,
                                               cylinder_gap, matched_errors, obstacle_radii)
from etdmp_ros.demo.metrics._compute import command_ratios, compute_metrics, start_direction
from etdmp_ros.demo.metrics._definitions import (DEFINITIONS, MOVE_DEFINITIONS, SLOW_PLAN,
                                                 SWITCH_WINDOW, SYSTEM_DEFINITIONS)
from etdmp_ros.demo.metrics._moved_goal import (follow_latencies, goal_move_figures,
                                                goal_seen_after_move, move_reference_nrmse,
                                                path_speed, perceived_goal_rows, switch_speeds)
from etdmp_ros.demo.metrics._orientation import demo_turned, orientation_figures
from etdmp_ros.demo.metrics._run import format_nrmse, MeasurementError, Run
from etdmp_ros.demo.metrics._system import system_figures
from etdmp_ros.demo.metrics._trace import (executed_plan, fit_tracking_start, nrmse_over_tau,
                                           switch_index, tracking_errors)
from etdmp_ros.skills.following import FOLLOW_CONFIRMATIONS

__all__ = [
    'DEFINITIONS', 'FOLLOW_CONFIRMATIONS', 'MOVE_DEFINITIONS', 'MeasurementError', 'Run',
    'SLOW_PLAN', 'SWITCH_WINDOW', 'SYSTEM_DEFINITIONS', 'bottle_clearances', 'clearance_mm',
    'command_ratios', 'compute_metrics', 'contact_figures', 'cylinder_gap', 'demo_turned',
    'executed_plan', 'fit_tracking_start', 'follow_latencies', 'format_nrmse',
    'goal_move_figures', 'goal_seen_after_move', 'matched_errors', 'move_reference_nrmse',
    'nrmse_over_tau',
    'obstacle_radii', 'orientation_figures', 'path_speed', 'perceived_goal_rows',
    'start_direction', 'switch_index', 'switch_speeds', 'system_figures', 'tracking_errors',
]

"""A run as the metrics take it (:class:`Run`), and what they raise when it cannot be measured."""

from dataclasses import dataclass

import numpy as np


class MeasurementError(ValueError):
    """The run cannot be measured (e.g. the controller published no reference)."""


@dataclass
class Run:
    """
    Everything the demo measured in one run (inputs of :func:`compute_metrics`).

    ``scene``: the run's :class:`etdmp_ros.demo.scenario.Scenario`; ``rec``: the recorded streams,
    read back from the run's MCAP recording (:func:`etdmp_ros.demo.recording.read_streams`); times
    are simulated ns.
    """

    scene: object
    method: str
    start: np.ndarray                 # tool position when the plans were requested
    goal: np.ndarray                  # the goal as requested (perceived or explicit)
    plan: tuple                       # (t, positions, quaternions) executed
    other: tuple                      # (method, t, positions) or (method, None, reason)
    rec: dict                         # recording.read_streams(the run's demo.mcap)
    status: list                      # (sim ns, text) after the call
    call_ns: int
    plan_stamp_ns: int
    end_ns: int
    goal_truth: np.ndarray
    goal_seen: np.ndarray
    obstacles_truth: np.ndarray
    obstacles_seen: np.ndarray
    wall_time: float = 0.0
    #: (sim ns, marker before (3,), marker after (3,)) when the goal marker moved during the
    #: run (the demo's ``--move-goal``), else None.
    goal_move: tuple = None


def format_nrmse(value):
    """Format an nRMSE: three decimals, or two significant digits when it is that small."""
    return 'n/a' if value is None else (f'{value:.3f}' if value >= 0.01 else f'{value:.2g}')

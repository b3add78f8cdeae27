"""The closed loop's measuring functions (etdmp_ros.metrics), without ROS."""

import math

from etdmp_ros.metrics import cylinder_gap, fit_tracking_start, system_figures
from etdmp_ros.task_plane import quadrant
import numpy as np
import pytest


def test_cylinder_gap_is_the_distance_to_the_cylinder_surface():
    top = [[1.0, 0.0, 0.08]]            # a cylinder of radius 0.025 standing on the table
    points = [[1.1, 0.0, 0.0], [1.0, 0.0, 0.18], [1.0, 0.0, 0.05], [1.1, 0.0, 0.18],
              [1.01, 0.0, 0.079]]
    gap = cylinder_gap(points, top, 0.025)
    np.testing.assert_allclose(gap, [0.075, 0.1, -0.025, math.hypot(0.075, 0.1), -0.001],
                               atol=1e-12)
    assert cylinder_gap(points, np.zeros((0, 3)), 0.025)[0] == math.inf


def test_tracking_start_is_found_from_the_reference():
    t = np.arange(0.0, 3.0, 0.01)
    plan = np.stack([0.1 * np.sin(2 * t), 0.1 * np.cos(3 * t), 0 * t], axis=1)
    t0 = 12.34567
    stamps = np.arange(10.0, 16.0, 0.008)
    tau = np.clip(stamps - t0, 0.0, t[-1])
    reference = np.column_stack([stamps * 1e9] + [np.interp(tau, t, plan[:, i])
                                                  for i in range(3)])
    assert fit_tracking_start(reference, t, plan, t0 + 0.02) == pytest.approx(t0, abs=2e-4)


def test_quadrants():
    assert [quadrant(v) for v in ([1, 1], [-1, 1], [-1, -1], [1, -1])] == \
        ['I', 'II', 'III', 'IV']


def test_command_rate_is_taken_while_the_arm_moves():
    class Logs:

        def log(self, node):
            return ''

    period = 8_000_000                                   # ns, 125 Hz
    call = 1_000_000_000
    t = call + period * np.arange(-50, 1200)             # commands from before the call on
    commands = np.zeros((len(t), 6))
    first = 110                                          # 0.48 s after the call: planning
    commands[first:first + 1000, 0] = 0.1                # 8 s of motion, then zeros
    rec = {'command_time': t, 'commands': commands, 'command_wall_time': t * 1e-9}
    end = int(t[first + 1060])
    figures = system_figures(_NoMonitor(), rec, call, end, Logs())
    assert figures['moving_commands_per_s'] == pytest.approx(125.0)
    assert figures['first_moving_command_after_call_s'] == pytest.approx(0.48)
    commands[first + 400:first + 425, 0] = 0.0          # a 0.2 s halt in the middle
    figures = system_figures(_NoMonitor(), rec, call, end, Logs())
    assert figures['moving_commands_per_s'] == pytest.approx(974 / (999 * 0.008))


class _NoMonitor:

    def window(self, start, end):
        return None

"""What the closed loop cost and how kept time: CPU, command rates, the nodes' own figures."""

from etdmp_ros.ros import events as ev
import numpy as np


def _cpu_figures(monitor, call_ns, end_ns):
    window = monitor.window(call_ns * 1e-9, end_ns * 1e-9) if end_ns else None
    if window is None:
        return {}
    return {'cpu_cores': window['cpu'],
            'cpu_cores_total': window['total'],
            'cpu_cores_nodes_but_sim': sum(v for k, v in window['cpu'].items()
                                           if k != 'ur10_sim'),
            'real_time_factor': window['real_time_factor'],
            'min_real_time_factor_1s': window['min_real_time_factor_1s']}


def _command_figures(rec, call_ns, end_ns):
    figures = {}
    t = rec['command_time']
    inside = (t >= call_ns) & (t <= (end_ns or 0))
    moving = inside & np.any(rec['commands'] != 0.0, axis=1) if len(t) else inside
    moving_t = t[moving]
    if len(moving_t) >= 2:
        # While the arm moves: from the first non-zero command to the last. The time before
        # the first (planning, the path check, numba loading a kernel) is a latency, reported
        # apart; zero commands in between (a halt) count against the rate.
        span = (moving_t[-1] - moving_t[0]) * 1e-9
        figures['moving_commands_per_s'] = float((len(moving_t) - 1) / span) if span > 0 else 0.0
        figures['first_moving_command_after_call_s'] = float((moving_t[0] - call_ns) * 1e-9)
    periods = np.diff(rec['command_wall_time'][inside]) * 1e3
    if len(periods):
        figures['command_period_ms'] = {'p50': float(np.median(periods)),
                                        'p99': float(np.percentile(periods, 99)),
                                        'max': float(periods.max())}
    return figures


def _controller_figures(recorded):
    tracked = ev.of_kind(recorded, 'controller', 'path_tracked')
    if not tracked:
        return {}
    last = tracked[-1]
    return {'controller': {'tracking_rms_mm': last.number('error_rms_mm'),
                           'tracking_max_mm': last.number('error_max_mm'),
                           'steps': last.integer('steps'), 'periods': last.integer('periods'),
                           'joint_states_received': last.integer('joint_states'),
                           'largest_joint_state_gap_ms': last.number('largest_gap_ms'),
                           'largest_joint_state_gap_at_s': last.number('largest_gap_at_s')}}


def _simulation_figures(recorded, call_ns, end_ns):
    stalls = [(e.number('t_s'), e.number('gap_ms'))
              for e in ev.of_kind(recorded, 'ur10_sim', 'stalled')]
    figures = {'simulation_stalls': [(t, ms) for t, ms in stalls
                                     if call_ns * 1e-9 <= t <= (end_ns or 0) * 1e-9]}
    stopped = ev.of_kind(recorded, 'ur10_sim', 'stopped')
    if stopped:
        last = stopped[-1]
        figures['simulation'] = {
            'late_ticks': last.integer('late_ticks'),
            'largest_tick_gap_ms': last.number('largest_tick_gap_ms'),
            'frames': last.integer('frames'), 'frames_dropped': last.integer('frames_dropped'),
            'command_waits': last.integer('command_waits'),
            'command_wait_ms': last.number('command_wait_ms'),
            'command_waits_in_vain': last.integer('command_waits_in_vain'),
            'largest_command_age_ms': last.number('largest_command_age_ms')}
        camera = ev.of_kind(recorded, 'ur10_sim_camera', 'stopped')
        if camera:   # snapshots the camera process skipped because it was still rendering
            figures['simulation']['frames_rendered'] = camera[-1].integer('frames')
            figures['simulation']['frames_dropped'] += camera[-1].integer('skipped')
    return figures


def system_figures(monitor, rec, call_ns, end_ns):
    """
    Return what the closed loop cost and how well it kept time from the call to the end.

    CPU per process (CPU-s per simulated s, from /proc), the real-time factor, the moving
    commands per simulated second and the wall-clock period between commands as this process
    received them, and what the controller and the simulation reported about their loops (their
    events in the recording, ``rec['events']``; SYSTEM_DEFINITIONS). ``monitor``: a started and
    stopped :class:`etdmp_ros.demo.cpu_monitor.CpuMonitor`.
    """
    recorded = rec.get('events', [])
    return {**_cpu_figures(monitor, call_ns, end_ns), **_command_figures(rec, call_ns, end_ns),
            **_controller_figures(recorded),
            **_simulation_figures(recorded, call_ns, end_ns)}

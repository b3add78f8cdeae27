"""
A run's figures put together (:func:`compute_metrics`): the headline, the plan, the positions.

The figures of each kind come from the modules that measure them (``_trace``, ``_clearance``,
``_orientation``, ``_moved_goal``); their meaning is in :mod:`._definitions`.
"""

import math

from etdmp_ros.demo.metrics._clearance import (bottle_clearances, clearance_mm, contact_figures,
                                               matched_errors, obstacle_radii)
from etdmp_ros.demo.metrics._definitions import (DEFINITIONS, MOVE_DEFINITIONS,
                                                 SYSTEM_DEFINITIONS)
from etdmp_ros.demo.metrics._moved_goal import goal_move_figures, moved_bottle_mouths
from etdmp_ros.demo.metrics._orientation import orientation_figures
from etdmp_ros.demo.metrics._trace import (cut_trace, nrmse_over_tau, plan_as_executed,
                                           tracking_errors)
from etdmp_ros.geometry.task_plane import quadrant
from etdmp_ros.robot import UR10Model
import numpy as np


def compute_metrics(run):
    """
    Return (metrics, extra) of a run (``metrics['definitions']`` defines them).

    ``extra``: what the figures need besides, ``{'t0', 'tau', 'trace', 'goal', 'executed'}``
    (``executed``: (t, positions) of the plan as executed; with a moved goal also ``switch``,
    the index of its first re-planned pose or None). Raises MeasurementError when the run
    tracked nothing that could be measured.
    """
    ex = plan_as_executed(run)
    tr = cut_trace(run, ex)
    metrics = {**_headline(run, tr, ex), **_plan_details(run, tr, ex), **_positions(run, tr),
               **_perception(run), **command_ratios(run.scene, run.rec['commands']),
               **contact_figures(run.rec),
               'plan_stamp_minus_sim_time_s': float((run.plan_stamp_ns - run.call_ns) * 1e-9),
               'controller_status': [text for _, text in run.status],
               'wall_time_s': float(run.wall_time),
               'definitions': {**DEFINITIONS, **SYSTEM_DEFINITIONS}}
    if not run.scene.planar:
        mouths = (moved_bottle_mouths(run, tr, ex) if run.goal_move is not None
                  and getattr(run.scene, 'perceived_bottle', False) else (None, None))
        metrics.update(bottle_clearances(run.scene, tr.trace, ex.x, *mouths))
    metrics.update(orientation_figures(run, tr))
    metrics.update(_other_plan(run, tr.tau))
    extra = {'t0': tr.t0, 'tau': tr.tau, 'trace': tr.trace, 'goal': tr.goal,
             'executed': (ex.t, ex.x)}
    if run.goal_move is not None:
        metrics.update(goal_move_figures(run, tr, ex))
        metrics['definitions'].update(MOVE_DEFINITIONS)
        extra['switch'] = ex.switch
    return metrics, extra


def start_direction(scene, start, goal):
    """
    Return (start - goal, demonstration start - goal, turn in rad between the two).

    2D skills: in the task plane, the turn signed; 3D: in base_link, the unsigned angle.
    """
    demo_rel = scene.demo.positions[0] - scene.demo.positions[-1]
    if scene.planar:
        start_rel = scene.plane.to_plane(start) - scene.plane.to_plane(goal)
        turn = math.atan2(demo_rel[0] * start_rel[1] - demo_rel[1] * start_rel[0],
                          demo_rel @ start_rel)
    else:
        start_rel = start - goal
        turn = math.acos(np.clip(demo_rel @ start_rel / np.linalg.norm(demo_rel)
                                 / np.linalg.norm(start_rel), -1.0, 1.0))
    return start_rel, demo_rel, turn


def _dmp_plan(run):
    """Return (t, positions) of the plain-DMP plan of the run (executed or not), or None."""
    plan_t, plan_x, _ = run.plan
    other_method, other_t, other_x = run.other
    if run.method == 'dmp':
        return plan_t, plan_x
    return (other_t, other_x) if other_method == 'dmp' and other_t is not None else None


def _headline(run, tr, ex):
    scene, radius = run.scene, obstacle_radii(run)
    plan_t, plan_x = ex.t, ex.x
    dmp = _dmp_plan(run)
    errors = tracking_errors(run.rec, tr.t0, plan_t[-1])
    return {
        'skill': scene.skill,
        'method': run.method,
        'nrmse_plan': nrmse_over_tau(plan_x, tr.tau, plan_t, scene),
        'nrmse_trace': nrmse_over_tau(tr.tip_x[tr.in_plan], tr.tau, tr.span[tr.in_plan], scene,
                                      end=tr.goal if run.goal_move is not None else None),
        'nrmse_dmp_baseline': (nrmse_over_tau(dmp[1], tr.tau, dmp[0], scene)
                               if dmp is not None else None),
        'tracking_rms_mm': float(np.sqrt(np.mean(errors ** 2)) * 1e3),
        'tracking_max_mm': float(np.max(errors) * 1e3),
        'min_clearance_mm': (clearance_mm(tr.trace, run.obstacles_truth, radius)
                             if len(tr.trace) else None),
        'goal_error_mm': float(np.linalg.norm(tr.final - tr.goal) * 1e3),
        'duration_s': float((run.end_ns - run.call_ns) * 1e-9),
    }


def _plan_details(run, tr, ex):
    radius = obstacle_radii(run)
    plan_t, plan_x = ex.t, ex.x
    dmp = _dmp_plan(run)
    return {
        'plan_duration_s': float(plan_t[-1]),
        'tau_s': tr.tau,
        'approach_duration_s': float(tr.t0 - run.call_ns * 1e-9),
        'min_clearance_plan_mm': clearance_mm(plan_x, run.obstacles_truth, radius),
        'min_clearance_dmp_baseline_mm': (clearance_mm(dmp[1], run.obstacles_truth, radius)
                                          if dmp is not None else None),
        'goal_error_vs_plan_end_mm': float(np.linalg.norm(tr.final - plan_x[-1]) * 1e3),
    }


def _positions(run, tr):
    scene = run.scene
    start_rel, demo_rel, turn = start_direction(scene, run.start, run.goal)
    at_call = max(int(np.searchsorted(tr.tip_t, run.call_ns * 1e-9, 'right')) - 1, 0)
    return {
        'start': run.start.tolist(),
        'goal': run.goal.tolist(),
        'plan_end': run.plan[1][-1].tolist(),
        'tool_at_call': tr.tip_x[at_call].tolist(),
        'perceived_goal': None if run.goal_seen is None else run.goal_seen.tolist(),
        'true_goal_marker': None if run.goal_truth is None else run.goal_truth.tolist(),
        'goal_source': ('perceived marker' if scene.explicit_goal is None else
                        'perceived bottle' if getattr(scene, 'perceived_bottle', False)
                        else 'explicit'),
        'start_quadrant': quadrant(start_rel[:2]),
        'demo_quadrant': quadrant(demo_rel[:2]),
        'start_turn_deg': math.degrees(turn),
    }


def _perception(run):
    return {
        'perceived_goal_error_mm': (float(np.linalg.norm(run.goal_seen - run.goal_truth) * 1e3)
                                    if run.goal_seen is not None else None),
        'perceived_obstacle_errors_mm': matched_errors(run.obstacles_seen, run.obstacles_truth),
        'obstacles': np.asarray(run.obstacles_truth).tolist(),
    }


def command_ratios(scene, qd):
    """Return the commands' figures: counts and ratios to the limits the controller applies."""
    model = UR10Model(tool_offset=scene.scene['tool_offset'])
    v_lim = model.velocity_limits * float(scene.controller['velocity_scale'])
    a_lim = np.asarray(scene.controller['joint_acceleration_limits'], dtype=float)
    rate = float(scene.controller['control_rate'])
    dqd = np.abs(np.diff(qd, axis=0)) * rate if len(qd) > 1 else np.zeros((1, 6))
    return {
        'commands_received': int(len(qd)),
        'commands_nonzero': int(np.count_nonzero(np.any(qd != 0.0, axis=1))) if len(qd) else 0,
        'max_joint_velocity_ratio': float(np.max(np.abs(qd) / v_lim)) if len(qd) else 0.0,
        'max_joint_acceleration_ratio': float(np.max(dqd / a_lim)),
        'max_joint_velocity_rad_s': np.max(np.abs(qd), axis=0).tolist() if len(qd) else [],
        'joint_velocity_limits_rad_s': v_lim.tolist(),
        'joint_acceleration_limits_rad_s2': a_lim.tolist(),
    }


def _other_plan(run, tau):
    other_method, other_t, other_x = run.other
    out = {}
    if other_method != 'dmp' or other_t is None:
        out[f'nrmse_{other_method}_plan'] = (
            nrmse_over_tau(other_x, tau, other_t, run.scene) if other_t is not None else None)
    if other_t is None:
        out[f'{other_method}_error'] = other_x
    return out

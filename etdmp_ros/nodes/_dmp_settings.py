"""
dmp_server's settings: its parameters validated into one immutable object (a snapshot).

Built from {parameter name: value} as :mod:`etdmp_ros.ros.system` describes them (the node's
DESCRIPTION), at start and whenever parameters change; the node replaces its snapshot whole.
"""

from dataclasses import dataclass, field

from etdmp_ros.dmp import AVOIDANCES, FORMULATIONS, METHODS, ObstacleGains
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.ros import system
from etdmp_ros.skills.library import check_skill_name, RECORDED_DIMS
from etdmp_ros.skills.planning import bounded, PLAN_ORIENTATION_MODES, PlanSettings, Workspace
import numpy as np

#: Where dmp_server takes the tool position from (its parameter tool_position_source).
TOOL_SOURCES = system.node('dmp_server').parameter('tool_position_source').choices


def _choice(values, name, choices):
    if values[name] not in choices:
        raise ValueError(f'{name} must be one of {", ".join(choices)}, got {values[name]!r}')
    return values[name]


@dataclass(frozen=True, eq=False)
class Settings:
    """Everything a request or an input callback needs, validated; replaced whole on change."""

    skill: str
    formulation: str
    n_basis: int
    plan: PlanSettings
    plane: TaskPlane
    static_obstacles: np.ndarray
    obstacle_max_age: float
    goal_max_age: float
    tool_position_source: str
    tool_state_max_age: float
    teach_skill_name: str
    recorded_dim: str
    plane_tolerance: float
    execute: bool
    publish_markers: bool
    teach_overwrite: bool
    check_timing: bool
    check_arm: bool
    arm_clearance: float
    max_request_wait: float
    follow_goal: bool
    follow_threshold: float
    follow_lead: float
    initial_joints: np.ndarray
    goal_object: str = 'marker'
    goal_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_values(cls, values):
        """Build from {parameter name: value}; raise ValueError saying what is wrong."""
        check_skill_name(values['skill'])
        check_skill_name(values['teach_skill_name'])
        static = np.asarray(values['static_obstacles'], dtype=float)
        if static.size % 3:
            raise ValueError('static_obstacles must be numbers x1, y1, z1, x2, ... (a multiple '
                             f'of 3), got {len(static)} values')
        bounded(static, 'static_obstacles')
        gains = ObstacleGains(gamma=values['obstacle_gamma'], beta=values['obstacle_beta'],
                              gamma2=values['obstacle_gamma2'],
                              k_relative=values['obstacle_k_relative'])
        workspace = Workspace(reach=values['reach_radius'], margin=values['reach_margin'],
                              min_radius=values['min_reach_radius'],
                              min_height=values['min_height'])
        plan = PlanSettings(
            method=_choice(values, 'method', METHODS), mode=values['mode'],
            independent_axis=values['independent_axis'], duration=values['duration'],
            output_period=values['output_period'], gains=gains, obstacle_k=values['obstacle_k'],
            obstacle_margin=values['obstacle_margin'], goal_clearance=values['goal_clearance'],
            min_distance=values['min_distance'], orientation=values['tool_orientation'],
            orientation_mode=_choice(values, 'orientation_mode', PLAN_ORIENTATION_MODES),
            workspace=workspace, tool_radius=values['tool_radius'],
            obstacle_clearance=values['obstacle_clearance'],
            avoidance=_choice(values, 'avoidance', AVOIDANCES))
        plane = TaskPlane.create(values['task_plane.origin'], values['task_plane.x_axis'],
                                 values['task_plane.y_axis'], values['task_plane.scale'])
        return cls(
            skill=values['skill'], formulation=_choice(values, 'formulation', FORMULATIONS),
            n_basis=values['n_basis'], plan=plan, plane=plane,
            static_obstacles=static.reshape(-1, 3), obstacle_max_age=values['obstacle_max_age'],
            goal_max_age=values['goal_max_age'],
            tool_position_source=_choice(values, 'tool_position_source', TOOL_SOURCES),
            tool_state_max_age=values['tool_state_max_age'],
            teach_skill_name=values['teach_skill_name'],
            recorded_dim=_choice(values, 'recorded_dim', RECORDED_DIMS),
            plane_tolerance=values['plane_tolerance'], execute=values['execute'],
            publish_markers=values['publish_markers'], teach_overwrite=values['teach_overwrite'],
            check_timing=values['check_timing'], check_arm=values['check_arm'],
            arm_clearance=values['arm_clearance'], max_request_wait=values['max_request_wait'],
            follow_goal=values['follow_goal'], follow_threshold=values['follow_threshold'],
            follow_lead=values['follow_lead'],
            initial_joints=_joints(values['initial_joint_positions']),
            goal_object=_choice(values, 'goal_object', system.GOAL_OBJECTS),
            goal_offset=_offset(values['goal_offset']))


def _offset(values):
    offset = np.asarray(values, dtype=float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)) or np.any(np.abs(offset) > 2.0):
        raise ValueError(f'goal_offset must be 3 finite numbers [x, y, z] within 2 m, got '
                         f'{values!r}')
    return offset


def _joints(values):
    q = np.asarray(values, dtype=float)
    if q.shape != (6,) or not np.all(np.isfinite(q)):
        raise ValueError(f'initial_joint_positions must be 6 finite numbers, got {values!r}')
    return q

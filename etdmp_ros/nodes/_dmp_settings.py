"""
dmp_server's settings: its parameters validated into one immutable object (a snapshot).

Built from {parameter name: value} as :mod:`etdmp_ros.ros.system` describes them (the node's
DESCRIPTION), at start and whenever parameters change; the node replaces its snapshot whole.
"""

from dataclasses import dataclass, field

from etdmp_ros.dmp import ObstacleGains
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.ros.node_parameters import DmpServerParameters
from etdmp_ros.skills.library import check_skill_name
from etdmp_ros.skills.planning import bounded, PlanSettings, Workspace
import numpy as np

#: Points of the workcell: one beyond it is refused naming its coordinate (:func:`bounded`),
#: which says more than their description's range (the same bound, MAX_REQUEST_COORDINATE).
WORKCELL_POINTS = ('static_obstacles', 'task_plane.origin')


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
    #: Every parameter, typed (the start-up ones read from here: tool_offset, skills_dir ...).
    parameters: DmpServerParameters
    goal_object: str = 'marker'
    goal_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_values(cls, values):
        """
        Build from {parameter name: value}; raise ValueError saying what is wrong.

        Each value is checked by its description (type, number of values, range, choices:
        DmpServerParameters); here only what a description cannot say: skill names, the task
        plane's axes (orthogonal), the plan settings together (PlanSettings). Points beyond the
        workcell first, with their own reason (WORKCELL_POINTS).
        """
        for name in WORKCELL_POINTS:
            if isinstance(values[name], (list, tuple)) and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in values[name]):
                bounded(values[name], name)
        p = DmpServerParameters.from_values(values)
        check_skill_name(p.skill)
        check_skill_name(p.teach_skill_name)
        gains = ObstacleGains(gamma=p.obstacle_gamma, beta=p.obstacle_beta,
                              gamma2=p.obstacle_gamma2, k_relative=p.obstacle_k_relative)
        workspace = Workspace(reach=p.reach_radius, margin=p.reach_margin,
                              min_radius=p.min_reach_radius, min_height=p.min_height)
        plan = PlanSettings(
            method=p.method, mode=p.mode, independent_axis=p.independent_axis,
            duration=p.duration, output_period=p.output_period, gains=gains,
            obstacle_k=p.obstacle_k, obstacle_margin=p.obstacle_margin,
            goal_clearance=p.goal_clearance, min_distance=p.min_distance,
            orientation=p.tool_orientation, orientation_mode=p.orientation_mode,
            workspace=workspace, tool_radius=p.tool_radius,
            obstacle_clearance=p.obstacle_clearance, avoidance=p.avoidance)
        plane = TaskPlane.create(p.task_plane_origin, p.task_plane_x_axis, p.task_plane_y_axis,
                                 p.task_plane_scale)
        return cls(
            skill=p.skill, formulation=p.formulation, n_basis=p.n_basis, plan=plan, plane=plane,
            static_obstacles=np.reshape(p.static_obstacles, (-1, 3)),
            obstacle_max_age=p.obstacle_max_age, goal_max_age=p.goal_max_age,
            tool_position_source=p.tool_position_source,
            tool_state_max_age=p.tool_state_max_age, teach_skill_name=p.teach_skill_name,
            recorded_dim=p.recorded_dim, plane_tolerance=p.plane_tolerance, execute=p.execute,
            publish_markers=p.publish_markers, teach_overwrite=p.teach_overwrite,
            check_timing=p.check_timing, check_arm=p.check_arm, arm_clearance=p.arm_clearance,
            max_request_wait=p.max_request_wait, follow_goal=p.follow_goal,
            follow_threshold=p.follow_threshold, follow_lead=p.follow_lead,
            initial_joints=np.array(p.initial_joint_positions, dtype=float),
            parameters=p, goal_object=p.goal_object,
            goal_offset=np.array(p.goal_offset, dtype=float))

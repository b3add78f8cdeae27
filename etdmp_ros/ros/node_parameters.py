"""
Each node's parameters as one typed, frozen object: written by ``make config``, do not edit.

Made from the node's description in :mod:`etdmp_ros.ros.system`: a field per parameter (its
name with ``_`` for ``.``), typed as declared (lists as tuples). ``from_values`` checks every
value by its description (:meth:`etdmp_ros.ros.specs.Parameter.typed`) and raises ValueError
naming the first wrong one. What each parameter means: ``docs/<node>.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from etdmp_ros.ros import system
from etdmp_ros.ros.specs import NodeSpec, typed_values


@dataclass(frozen=True)
class Ur10SimParameters:
    """The parameters of ur10_sim (docs/ur10_sim.md)."""

    SPEC: ClassVar[NodeSpec] = system.node('ur10_sim')

    tool_offset: tuple[float, ...]
    initial_joint_positions: tuple[float, ...]
    task_plane_origin: tuple[float, ...]
    camera_position: tuple[float, ...]
    camera_orientation: tuple[float, ...]
    table_center: tuple[float, ...]
    table_size: tuple[float, ...]
    table_height: float
    table_color: tuple[float, ...]
    whiteboard_size: tuple[float, ...]
    whiteboard_color: tuple[float, ...]
    bottle_position: Any
    bottle_radius: float
    bottle_height: float
    bottle_color: tuple[float, ...]
    goal_position: Any
    goal_marker_radius: float
    goal_marker_color: tuple[float, ...]
    obstacle_positions: Any
    obstacle_radii: tuple[float, ...]
    obstacle_radius: float
    obstacle_height: float
    obstacle_color: tuple[float, ...]
    control_rate: float
    physics_timestep: float
    real_time_factor: float
    watchdog_timeout: float
    thread_priority: int
    command_wait: float
    camera_rate: float
    image_width: int
    image_height: int
    fovy_deg: float
    depth_min: float
    depth_max: float
    depth_noise: float
    multisamples: int
    teach_script: str

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> Ur10SimParameters:
        """Return the typed parameters of ``values`` ({name: value}); ValueError: a bad one."""
        return cls(**typed_values(cls.SPEC, values))


@dataclass(frozen=True)
class PerceptionParameters:
    """The parameters of perception (docs/perception.md)."""

    SPEC: ClassVar[NodeSpec] = system.node('perception')

    camera_position: tuple[float, ...]
    camera_orientation: tuple[float, ...]
    table_center: tuple[float, ...]
    table_size: tuple[float, ...]
    goal_marker_radius: float
    obstacle_radius: float
    obstacle_height: float
    bottle_radius: float
    bottle_height: float
    goal_hsv_low: Any
    goal_hsv_high: Any
    obstacle_hsv_low: Any
    obstacle_hsv_high: Any
    detect_bottle: bool
    bottle_hsv_low: Any
    bottle_hsv_high: Any
    min_blob_area: int
    min_depth_pixels: int
    top_band: float
    occlusion_gap: float
    min_rim_points: int
    max_rim_rms: float
    obstacle_radius_range: Any
    height_tolerance: float
    stamp_tolerance: float
    match_camera_info: bool
    max_rate: float
    debug_image_rate: float
    warn_period: float
    reliable_images: bool

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> PerceptionParameters:
        """Return the typed parameters of ``values`` ({name: value}); ValueError: a bad one."""
        return cls(**typed_values(cls.SPEC, values))


@dataclass(frozen=True)
class DmpServerParameters:
    """The parameters of dmp_server (docs/dmp_server.md)."""

    SPEC: ClassVar[NodeSpec] = system.node('dmp_server')

    tool_offset: tuple[float, ...]
    initial_joint_positions: tuple[float, ...]
    task_plane_origin: tuple[float, ...]
    task_plane_x_axis: tuple[float, ...]
    task_plane_y_axis: tuple[float, ...]
    skill: str
    builtin_skills: tuple[str, ...]
    demo_files: tuple[str, ...]
    mcap_topic: str
    recorded_dim: str
    plane_tolerance: float
    skills_dir: str
    teach_skill_name: str
    teach_overwrite: bool
    formulation: str
    n_basis: int
    method: str
    mode: int
    independent_axis: int
    duration: float
    output_period: float
    task_plane_scale: float
    tool_orientation: tuple[float, ...]
    orientation_mode: str
    avoidance: str
    obstacle_gamma: float
    obstacle_beta: float
    obstacle_gamma2: float
    obstacle_k: float
    obstacle_k_relative: float
    obstacle_margin: float
    obstacle_max_age: float
    static_obstacles: tuple[float, ...]
    tool_radius: float
    obstacle_clearance: float
    goal_clearance: float
    tool_position_source: str
    tool_state_max_age: float
    goal_max_age: float
    goal_object: str
    goal_offset: tuple[float, ...]
    min_distance: float
    reach_radius: float
    reach_margin: float
    min_reach_radius: float
    min_height: float
    check_timing: bool
    check_arm: bool
    arm_clearance: float
    follow_goal: bool
    follow_threshold: float
    follow_lead: float
    execute: bool
    publish_markers: bool
    max_request_wait: float

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> DmpServerParameters:
        """Return the typed parameters of ``values`` ({name: value}); ValueError: a bad one."""
        return cls(**typed_values(cls.SPEC, values))


@dataclass(frozen=True)
class ControllerParameters:
    """The parameters of controller (docs/controller.md)."""

    SPEC: ClassVar[NodeSpec] = system.node('controller')

    tool_offset: tuple[float, ...]
    initial_joint_positions: tuple[float, ...]
    control_rate: float
    actuation_delay: float
    estimate_delay: bool
    joint_state_timeout: float
    simulation_stall_timeout: float
    thread_priority: int
    position_gain: float
    orientation_gain: float
    singular_value_threshold: float
    max_damping: float
    condition_slowdown: float
    condition_halt: float
    posture_gain: float
    velocity_scale: float
    joint_acceleration_limits: tuple[float, ...]
    joint_limit_margin: float
    approach_speed: float
    approach_angular_speed: float
    approach_acceleration: float
    approach_tolerance: float
    approach_angle_tolerance: float
    resume_ramp_time: float
    hold_time: float
    max_tracking_error: float
    untimed_path_speed: float
    untimed_path_angular_speed: float
    check_paths: bool
    max_path_poses: int

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> ControllerParameters:
        """Return the typed parameters of ``values`` ({name: value}); ValueError: a bad one."""
        return cls(**typed_values(cls.SPEC, values))


@dataclass(frozen=True)
class TeachParameters:
    """The parameters of teach (docs/teach.md)."""

    SPEC: ClassVar[NodeSpec] = system.node('teach')

    camera_position: tuple[float, ...]
    camera_orientation: tuple[float, ...]
    port: int
    address: str
    canvas_width: float
    dmp_server: str
    report_timeout: float
    camera_rate: float
    jpeg_quality: int
    watch_timeout: float
    trace_source: str

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> TeachParameters:
        """Return the typed parameters of ``values`` ({name: value}); ValueError: a bad one."""
        return cls(**typed_values(cls.SPEC, values))

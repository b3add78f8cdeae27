"""
The parameters of the nodes that plan and move: dmp_server (and its services), the controller.

See :mod:`etdmp_ros.ros.system`, which makes the nodes of these tables.
"""

from etdmp_ros.dmp import AVOIDANCES, builtin_demo_names, FORMULATIONS, METHODS, ObstacleGains
from etdmp_ros.robot import ControllerConfig, DEFAULT_ACCELERATION_LIMITS
from etdmp_ros.ros._workcell_parameters import scene_parameters, WORKCELL_RANGE
from etdmp_ros.ros.specs import DOUBLE_ARRAY, parameter, ServiceSpec, STRING_ARRAY
from etdmp_ros.skills.library import RECORDED_DIMS
from etdmp_ros.skills.planning import PLAN_ORIENTATION_MODES, PlanSettings, TOOL_DOWN, Workspace

P = parameter
_CONTROL = ControllerConfig()
_PLAN = PlanSettings()
_GAINS = ObstacleGains()
_REACH = Workspace()

# ------------------------------------------------------------------------------- dmp_server
_RUNTIME = {'dynamic': True}
#: dmp_server's goal_object: the perceived objects an empty goal frame id may mean.
GOAL_OBJECTS = ('marker', 'bottle')
DMP_SERVER_SCENE = (*scene_parameters('tool_offset', 'initial_joint_positions'),
                    *scene_parameters('task_plane.origin', 'task_plane.x_axis',
                                      'task_plane.y_axis', **_RUNTIME))
_DAY = (0.0, 86400.0)
DMP_SERVER = (
    P('skill', 'G', 'Active skill planned by /generalize (a known or later taught skill name).',
      section='Skills: learned at start-up', **_RUNTIME),
    P('builtin_skills', builtin_demo_names(), 'Built-in demonstrations learned at start-up.'),
    P('demo_files', [], 'Demonstration files or folders learned at start-up (.csv .npy .npz: '
      '2 columns = task-plane skill in demo units, 3 = base_link metres; rosbag2 .mcap: a '
      'PoseStamped or Path topic in base_link, or a JointState topic (kinesthetic teaching: '
      'the tool tip by forward kinematics, trimmed to the motion)); the skill is named after '
      'the file stem.',
      array_type=STRING_ARRAY, example=['/path/to/my_demo.csv', '/path/to/recordings/']),
    P('mcap_topic', '', 'Topic (PoseStamped, Path or JointState) to learn from in .mcap '
      'files; empty = the only such topic.'),
    P('recorded_dim', 'auto', 'How a recorded or taught base_link path becomes a skill: 2d '
      '(projected onto the task plane), 3d (base_link) or auto (2d when flat and parallel to '
      'the plane).', choices=RECORDED_DIMS, **_RUNTIME),
    P('plane_tolerance', 0.01, 'recorded_dim auto: a path whose heights above the task plane '
      'spread less than this is a 2D skill.', unit='m', value_range=(0.0, 1.0), **_RUNTIME),
    P('skills_dir', '', 'Folder where taught skills are saved and loaded from at start-up; '
      'empty = $ROS_HOME/etdmp_ros/skills or ~/.ros/etdmp_ros/skills.'),
    P('teach_skill_name', 'taught', 'Name of the skill a Path on /etdmp/demonstrations becomes '
      '(replacing a taught skill of that name).', **_RUNTIME),
    P('teach_overwrite', False, 'Let a taught skill replace a built-in skill or one from '
      'demo_files of the same name (saved, so also at every later start); false = refused.',
      **_RUNTIME),
    P('formulation', 'ijspeert', 'DMP formulation.', choices=FORMULATIONS, **_RUNTIME),
    P('n_basis', 100, 'Basis functions of the forcing term (paper Table 1).',
      value_range=(2, 1000),
      **_RUNTIME),
    P('method', _PLAN.method, 'etdmp (Euclidean transformation DMP) or dmp (the plain '
      'baseline).', choices=METHODS, section='Generalization', **_RUNTIME),
    P('mode', _PLAN.mode, '3D skills: 1 = Rodrigues rotation, 2 = independent axis (1D rule) '
      '+ 2D rule.', value_range=(1, 2), **_RUNTIME),
    P('independent_axis', _PLAN.independent_axis, 'Mode 2: the axis following the 1D rule (0 '
      'x, 1 y, 2 z).', value_range=(0, 2), **_RUNTIME),
    P('duration', _PLAN.duration, "Tau of a plan; 0 = the demonstration's own duration.",
      unit='s', value_range=(0.0, 600.0), **_RUNTIME),
    P('output_period', _PLAN.output_period, 'Time between the poses of a plan.', unit='s',
      value_range=(0.001, 1.0), **_RUNTIME),
    P('task_plane.scale', 0.02, 'Metres per demo unit of 2D skills (letters are about 10 '
      'units: 20 cm).', unit='m', value_range=(1e-5, 10.0), **_RUNTIME),
    P('tool_orientation', list(TOOL_DOWN), 'Tool orientation [x, y, z, w] in base_link of '
      'every pose of a plan of a position-only skill, or of any skill with orientation_mode '
      'tool (normalised); the default points the tool down.', **_RUNTIME),
    P('orientation_mode', _PLAN.orientation_mode, "demo: a skill's own orientations, turned "
      'with the motion (or converging to the goal orientation of a request), when it has them; '
      'tool: always tool_orientation.', choices=PLAN_ORIENTATION_MODES, **_RUNTIME),
    P('avoidance', 'detour', 'How a plan avoids obstacles: detour = a local smooth detour of '
      "the obstacle-free plan that keeps each obstacle's radius + tool_radius + "
      'obstacle_clearance from its centre (checked; docs/design.md, Obstacles with a size); '
      "paper = the paper's point-obstacle coupling (Eq. 22-27, the gains below), the baseline.",
      choices=AVOIDANCES, section='Obstacles', **_RUNTIME),
    P('obstacle_gamma', _GAINS.gamma, 'Steering gain gamma (paper Eq. 24; avoidance paper).',
      value_range=(0.0, 1e5), **_RUNTIME),
    P('obstacle_beta', _GAINS.beta, 'Steering decay beta (paper Eq. 24; 20/pi).',
      value_range=(0.0, 1e3), **_RUNTIME),
    P('obstacle_gamma2', _GAINS.gamma2, 'Distance gain gamma2 (paper Eq. 26).',
      value_range=(0.0, 1e5), **_RUNTIME),
    P('obstacle_k', 60.0, 'Distance decay k (paper Eq. 26); 0 = obstacle_k_relative / |start '
      '- goal|.', unit='1/m', value_range=(0.0, 1e4),
      note='Distance decay k (paper Eq. 26), 1/m; 0 = obstacle_k_relative / |start - goal|. '
      "The scene's obstacles are cylinders of a fixed size (25 mm radius), so the Eq. 26 "
      'repulsion decays over a fixed length: 1/60 m.', **_RUNTIME),
    P('obstacle_k_relative', _GAINS.k_relative, 'k times |start - goal| when obstacle_k is 0.',
      value_range=(0.0, 1e3), **_RUNTIME),
    P('obstacle_margin', _PLAN.obstacle_margin, 'Extra time, as a fraction of tau, of a plan '
      "with obstacles avoided by the paper's coupling (its detour arrives later; the detour "
      'keeps the timing).', value_range=(0.0, 10.0), **_RUNTIME),
    P('obstacle_max_age', 2.0, '/etdmp/obstacles (and /etdmp/obstacle_volumes) older than this '
      'are ignored; 0 = no limit.', unit='s', value_range=_DAY, **_RUNTIME),
    P('static_obstacles', [], 'Obstacle points always used, flat [x1, y1, z1, x2, ...] in '
      'base_link (radius 0: points; as cylinders from the table up to them in the arm check).',
      unit='m', value_range=WORKCELL_RANGE, multiple_of=3, array_type=DOUBLE_ARRAY,
      example=[0.8, 0.1, 0.0], **_RUNTIME),
    P('tool_radius', _PLAN.tool_radius, "Radius of the tool (the simulation's pen and stirrer: "
      "9 mm): added to each obstacle's radius for the clearance a plan keeps from its centre.",
      unit='m', value_range=(0.0, 0.5), **_RUNTIME),
    P('obstacle_clearance', _PLAN.obstacle_clearance, "Safety margin added to each obstacle's "
      "radius and the tool's: the gap a plan keeps between the tool's surface and an "
      "obstacle's.", unit='m', value_range=(0.0, 0.5), **_RUNTIME,
      note="Safety margin between the tool's surface and an obstacle's: 5 mm wanted "
      '+ 3 mm for what is not exact: the measured radius and centre (under 1 mm), the '
      "controller's tracking (under 0.5 mm) and the plan's sampling."),
    P('goal_clearance', _PLAN.goal_clearance, 'A request with an obstacle closer than this to '
      'the goal fails.', unit='m', value_range=(0.0, 1.0), **_RUNTIME),
    P('tool_position_source', 'joint_states', 'Tool position for an empty start frame: '
      'joint_states (UR10 forward kinematics) or tool_pose (/etdmp/tool_pose).',
      choices=('joint_states', 'tool_pose'), section='Inputs', **_RUNTIME),
    P('tool_state_max_age', 1.0, 'An older tool state counts as unknown; 0 = no limit.',
      unit='s', value_range=_DAY, **_RUNTIME),
    P('goal_max_age', 0.0, 'An older /etdmp/goal (or /etdmp/bottle) counts as none; 0 = no '
      'limit.', unit='s', value_range=_DAY, **_RUNTIME),
    P('goal_object', 'marker', 'What an empty goal frame id means: marker = the perceived goal '
      'marker (/etdmp/goal), bottle = the perceived bottle mouth (/etdmp/bottle); goal_offset '
      'is added to it, and a plan in execution follows that object.', choices=GOAL_OBJECTS,
      **_RUNTIME),
    P('goal_offset', [0.0, 0.0, 0.0], 'Added (base_link) to the perceived goal object for an '
      'empty goal frame id: e.g. the stirring goal near the bottom of the bottle, [0, 0, '
      '-0.15] below its mouth.', unit='m', value_range=(-2.0, 2.0), lengths=(3,), **_RUNTIME),
    P('min_distance', _PLAN.min_distance, 'Start and goal closer than this fail the request '
      '(start equals goal).', unit='m', value_range=(0.0, 1.0), **_RUNTIME),
    P('reach_radius', _REACH.reach, 'UR10 reach about the shoulder (reach check: a simple '
      'criterion, not IK).', unit='m', value_range=(0.1, 5.0), section='Reach check', **_RUNTIME),
    P('reach_margin', _REACH.margin, 'Subtracted from reach_radius (reach check).', unit='m',
      value_range=(0.0, 1.0), **_RUNTIME),
    P('min_reach_radius', _REACH.min_radius, "Points closer to the base's z axis are out of "
      'reach.', unit='m', value_range=(0.0, 1.0), **_RUNTIME),
    P('min_height', _REACH.min_height, 'Points below this z (table top z = 0) are out of '
      'reach.', unit='m', value_range=(-2.0, 2.0), **_RUNTIME),
    P('check_timing', True, 'Refuse a plan whose joint velocities or accelerations (IK along '
      "the plan from the current joints, or initial_joint_positions) exceed the controller's "
      'UR10 limits; the reason gives the shortest feasible duration.', **_RUNTIME),
    P('check_arm', True, 'Refuse a plan that would bring a link of the arm (spheres enclosing '
      'its collision mesh, at the joints of the IK along the plan) closer than arm_clearance to '
      'an obstacle (an upright cylinder of its perceived radius); the reason names the link. '
      "The tool is the plan's (tool_radius, obstacle_clearance).", **_RUNTIME),
    P('arm_clearance', 0.005, 'Smallest gap between a link of the arm and an obstacle that '
      'check_arm accepts.', unit='m', value_range=(0.0, 0.5), **_RUNTIME),
    P('follow_goal', True, 'While a plan executes, follow the perceived goal (when the request '
      'used it) and the obstacles: when one moves by more than follow_threshold, the rest of '
      'the movement is re-planned online from where the controller is (online ET-DMP) and '
      'published on /etdmp/path; false = a plan is fixed once published.',
      section='Following', **_RUNTIME),
    P('follow_threshold', 0.005, 'A goal or obstacle that moved less than this is not followed '
      '(perception noise).', unit='m', value_range=(0.0005, 1.0), **_RUNTIME),
    P('follow_lead', 0.1, 'A change takes effect this far ahead of where the controller is on '
      'the path: the time to re-plan, publish and check the new path.', unit='s',
      value_range=(0.0, 2.0), **_RUNTIME),
    P('execute', True, 'Publish each plan on /etdmp/path for the controller.',
      section='Outputs', **_RUNTIME),
    P('publish_markers', True, 'Publish /etdmp/markers (built only while someone subscribes).',
      **_RUNTIME),
    P('max_request_wait', 5.0, 'Longest time a /generalize request may wait for its turn '
      'behind others; one that waited longer is answered with an empty plan (refused as busy), '
      'so that under overload every request is answered (docs/limits.md).', unit='s',
      value_range=(0.01, 60.0), **_RUNTIME),
)

_SERVER = {p.name: p for p in DMP_SERVER}
DMP_SERVER_SERVICES = (
    ServiceSpec('teach', 'Learn a demonstration as the skill it names, saved like every taught '
                'one; the answer says what was learned, or why not.', (
                    P('name', '', 'Name of the skill (1-64 letters, digits, _ or -); a taught '
                      'skill of that name is replaced.'),
                    P('t', [], 'Time of each sample (s), rising.', unit='s',
                      array_type=DOUBLE_ARRAY),
                    P('positions', [], 'Position of each sample in base_link, flat [x1, y1, '
                      'z1, x2, ...].', unit='m', value_range=WORKCELL_RANGE,
                      array_type=DOUBLE_ARRAY),
                    P('orientations', [], 'Tool orientation of each sample in base_link, flat '
                      '[x1, y1, z1, w1, ...]; none: position only.', array_type=DOUBLE_ARRAY),
                    _SERVER['recorded_dim']),
                required=('name', 't', 'positions')),
    ServiceSpec('generalize_with', '/generalize with its skill and settings in the request: '
                'the plan goes to /etdmp/path (unless execute is false); the answer says what '
                'was planned, or why not. No parameter of the node changes.', (
                    _SERVER['skill'], _SERVER['method'], _SERVER['duration'],
                    _SERVER['execute'],
                    P('start', [], "Start [x, y, z] in base_link; none: the tool's position "
                      '(as an empty start frame id of /generalize).', unit='m',
                      value_range=WORKCELL_RANGE, array_type=DOUBLE_ARRAY),
                    P('goal', [], 'Goal [x, y, z] in base_link; none: the perceived goal object '
                      'plus goal_offset (as an empty goal frame id).', unit='m',
                      value_range=WORKCELL_RANGE, array_type=DOUBLE_ARRAY),
                    P('goal_orientation', [], 'Goal orientation [x, y, z, w] in base_link; none '
                      'or all zeros: none.', array_type=DOUBLE_ARRAY))),
)


# ------------------------------------------------------------------------------- controller
CONTROLLER_SCENE = scene_parameters('tool_offset', 'initial_joint_positions')
CONTROLLER = (
    P('control_rate', _CONTROL.rate, 'Commands per second at most. A step runs when a joint '
      'state arrives (in step with the robot, as a ros2_control controller). 125 Hz: UR10 '
      'CB3; 500 Hz: e-series.', unit='Hz', value_range=(1.0, 1000.0), section='Timing'),
    P('actuation_delay', 0.0, 'Time from a measurement to its command taking effect; -1 = one '
      'control period (a real UR through ros2_control applies a command at its next update). '
      'ur10_sim applies it at its next tick, which simulates the period that starts at the '
      'measurement: 0.', unit='s', value_range=(-1.0, 0.5)),
    P('estimate_delay', _CONTROL.estimate_delay, 'Estimate the actual delay online (0 to 2 '
      'periods, from how the joints moved after each command; it also absorbs the lag of the '
      'joint velocity servos); actuation_delay is then only the starting value. ur10_sim: '
      'about 0.2 periods at 125 Hz, 0.7 at 500 Hz.', dynamic=True),
    P('joint_state_timeout', 0.1, "Time of the robot's clock without joint states before the "
      'command is forced to zero and the path dropped (status stale-input): simulated time '
      'under use_sim_time (a stalled simulation stops it too), else the wall clock.', unit='s',
      value_range=(0.001, 10.0), dynamic=True),
    P('simulation_stall_timeout', 1.0, 'Under use_sim_time: wall-clock time without joint '
      'states while the simulation clock stopped with them, after which the simulation counts '
      'as gone (stale-input).', unit='s', value_range=(0.01, 60.0), dynamic=True),
    P('thread_priority', 50, 'SCHED_FIFO priority (1-99) of the thread that runs the control '
      'steps; 0 = normal scheduling. Needs CAP_SYS_NICE or an rtprio limit, else a warning and '
      'normal scheduling.', value_range=(0, 99),
      note="SCHED_FIFO priority of the thread that runs the control steps (the executor's), as "
      "ros2_control's controller_manager gives its update loop (thread_priority, 50 there "
      'too); 0 = normal scheduling. At 500 Hz next to the camera and perception on 2 cores it '
      'decides whether the controller steps on nearly every joint state. Needs CAP_SYS_NICE or '
      'an rtprio limit (ulimit -r); without, a warning and normal scheduling.'),
    P('position_gain', _CONTROL.position_gain, 'Position error feedback: an error decays as '
      'exp(-gain t); below control_rate.', unit='1/s', value_range=(0.0, 1000.0), dynamic=True,
      section='Closed-loop IK'),
    P('orientation_gain', _CONTROL.orientation_gain, 'Orientation error feedback; below '
      'control_rate.', unit='1/s', value_range=(0.0, 1000.0), dynamic=True),
    P('singular_value_threshold', _CONTROL.singular_value_threshold, 'Damped least squares: '
      'no damping while the smallest singular value of the 6x6 tool Jacobian is above this; '
      'then lambda^2 = max_damping^2 (1 - (s_min/threshold)^2).', value_range=(0.0, 1.0)),
    P('max_damping', _CONTROL.max_damping, 'Damping lambda at a singularity.',
      value_range=(0.0, 1.0)),
    P('condition_slowdown', _CONTROL.condition_slowdown, 'Jacobian condition number where '
      'slowing down starts when moving towards a singularity (scale 1 -> 0 at '
      'condition_halt).', value_range=(1.0, 1e6),
      note='Jacobian condition number: slow down above condition_slowdown when moving towards '
      'a singularity (scale 1 -> 0 at condition_halt), halt at condition_halt. MoveIt Servo: '
      '17 and 30 with an undamped pseudo-inverse; the damping here keeps joint speeds bounded, '
      'so the arm may go closer (wrist_2 about 15 deg and 6 deg from its singularity).'),
    P('condition_halt', _CONTROL.condition_halt, 'Jacobian condition number where the arm '
      'halts.', value_range=(1.0, 1e6)),
    P('posture_gain', _CONTROL.posture_gain, 'Null-space pull towards initial_joint_positions '
      '(0 = off). With 6 joints and a 6D task it acts only where the damping frees directions '
      'near a singularity.', unit='1/s', value_range=(0.0, 100.0)),
    P('velocity_scale', _CONTROL.velocity_scale, 'Fraction of the UR10 joint velocity limits '
      '(the stricter of the URDF and 120/180 deg/s).', value_range=(0.01, 1.0), section='Limits'),
    P('joint_acceleration_limits', list(DEFAULT_ACCELERATION_LIMITS), 'Per joint, UR order '
      '(shoulder pan ... wrist 3). UR publishes none (only torques: 330, 330, 150, 56, 56, 56 '
      'N m); letter G 0.2 m tall in its nominal 2 s needs up to 20 at the elbow.',
      unit='rad/s^2', value_range=(0.1, 1000.0), lengths=(6,)),
    P('joint_limit_margin', _CONTROL.joint_limit_margin, 'Kept from each joint position '
      'limit; a joint that could not stop before it halts the arm.', unit='rad',
      value_range=(0.0, 0.5)),
    P('approach_speed', _CONTROL.approach_speed, "Peak tool speed of the approach to a path's "
      'start.', unit='m/s', value_range=(0.001, 1.0), dynamic=True, section='Path execution'),
    P('approach_angular_speed', _CONTROL.approach_angular_speed, 'Peak tool rotation speed of '
      'the approach.', unit='rad/s', value_range=(0.001, 3.0), dynamic=True),
    P('approach_acceleration', _CONTROL.approach_acceleration, 'Peak tool acceleration of the '
      'approach.', unit='m/s^2', value_range=(0.01, 10.0), dynamic=True),
    P('approach_tolerance', _CONTROL.approach_tolerance, 'A path starting closer to the tool '
      '(at rest) needs no approach.', unit='m', value_range=(0.0, 0.1), dynamic=True),
    P('approach_angle_tolerance', _CONTROL.approach_angle_tolerance, 'The same for the '
      'orientation.', unit='rad', value_range=(0.0, 0.5), dynamic=True),
    P('resume_ramp_time', _CONTROL.resume_ramp_time, 'Time for the path clock to ramp back to '
      'full speed after a pause.', unit='s', value_range=(0.0, 10.0), dynamic=True),
    P('hold_time', _CONTROL.hold_time, 'Time holding the last pose before sending zeros.',
      unit='s', value_range=(0.0, 60.0), dynamic=True),
    P('max_tracking_error', _CONTROL.max_tracking_error, 'A larger tracking error stops the '
      'arm (status unreachable).', unit='m', value_range=(0.001, 1.0), dynamic=True),
    P('untimed_path_speed', 0.05, 'Paths whose poses all have the same stamp are timed by '
      'their length at this peak speed.', unit='m/s', value_range=(0.001, 1.0), dynamic=True),
    P('untimed_path_angular_speed', 0.5, 'The same for rotations.', unit='rad/s',
      value_range=(0.001, 3.0), dynamic=True),
    P('check_paths', True, 'Check every received path with position IK (reach, joint limits, '
      'singularities) before moving; a failing path is refused (status unreachable, with the '
      'reason).', dynamic=True),
    P('max_path_poses', 20000, 'Longest path accepted; a longer one is ignored with an error '
      'before it is read (timing and checking it would hold the interpreter long enough to '
      'delay control steps). 20000 poses: 160 s at 125 Hz.', value_range=(2, 1000000),
      dynamic=True),
)

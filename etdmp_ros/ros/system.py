"""
The system, described once: its nodes, their parameters and how they are started.

Everything else is made from this module. The nodes declare their parameters from it
(:func:`etdmp_ros.ros.parameters.declare`); ``config/*.yaml`` and the parameter tables in
``docs/<node>.md`` are written from it (``make config``, checked by ``test/unit/test_system.py``);
the launch file, ``bringup``, the demo and the test fixtures start the nodes as
:data:`NODES` and :func:`parameter_files` say. To change a default, a range or a description,
change it here and run ``make config``.

A parameter is a :class:`Parameter`: name, default (its type is the ROS type), description,
unit, range, whether it may change at runtime, and an optional longer note (the comment above it
in the YAML file). The workcell that every node shares is :data:`SCENE` (``config/scene.yaml``,
section ``/**``); each node declares the scene parameters it needs (:attr:`NodeSpec.scene`) and
its own (:attr:`NodeSpec.parameters`, ``config/<node>.yaml``).

Wiring: every node gets ``config/scene.yaml``, then its own ``config/<node>.yaml``, then
:func:`wiring_overrides` (``use_sim_time`` for the nodes that stamp with the ROS clock), then
the user's files. The module needs no ROS.
"""

from dataclasses import dataclass, field, replace
import math
from pathlib import Path

from etdmp_ros import limits
from etdmp_ros.dmp import AVOIDANCES, builtin_demo_names, FORMULATIONS, METHODS, ObstacleGains
from etdmp_ros.robot import (ControllerConfig, DEFAULT_ACCELERATION_LIMITS, SCENE_PARAMETERS,
                             SceneConfig)
from etdmp_ros.ros.paths import config_path
from etdmp_ros.skills.library import RECORDED_DIMS
from etdmp_ros.skills.planning import PLAN_ORIENTATION_MODES, PlanSettings, TOOL_DOWN, Workspace

#: ROS types of parameters whose default is an empty list (ROS cannot type ``[]``).
STRING_ARRAY, DOUBLE_ARRAY = 'string_array', 'double_array'


@dataclass(frozen=True)
class Parameter:
    """
    One ROS parameter of a node, as declared and as documented.

    ``value_range`` is ``(low, high)`` (ints for an integer parameter), ``choices`` the allowed
    strings. ``dynamic``: may change at runtime (``ros2 param set``); otherwise read-only.
    ``dynamic_typing``: values of another type are accepted and converted by the node (a list
    as a YAML string). Every list parameter takes ``[]`` (which ``ros2 param set`` types as
    ``bool[]``), integers for floats and whole floats for integers without it: they are turned
    into its declared list type before rclpy checks the type
    (:func:`etdmp_ros.ros.parameters.as_declared`). ``array_type`` types an empty-list
    default. ``section`` starts a new group of parameters in the YAML file; ``note`` is the
    comment above the parameter there (the description when empty); ``example``, for an empty
    default, is shown commented out.
    """

    name: str
    default: object
    description: str
    unit: str = ''
    value_range: tuple = None
    choices: tuple = ()
    dynamic: bool = False
    dynamic_typing: bool = False
    array_type: str = ''
    section: str = ''
    note: str = ''
    example: object = None

    def __post_init__(self):
        """Check that the default fits the declared range and choices."""
        if self.value_range is not None:
            low, high = self.value_range
            values = self.default if isinstance(self.default, list) else [self.default]
            if any(not low <= v <= high for v in values):
                raise ValueError(f'{self.name}: default {self.default!r} outside '
                                 f'{self.value_range}')
        if self.choices and self.default not in self.choices:
            raise ValueError(f'{self.name}: default {self.default!r} not in {self.choices}')
        if isinstance(self.default, list) and not self.default and not self.array_type:
            raise ValueError(f'{self.name}: an empty default needs array_type')

    def check(self, value):
        """
        Raise ValueError saying why ``value`` is no value of this parameter, by its description.

        Checks ``choices`` and ``value_range`` (each element of a list, NaN included: a list
        parameter's range is checked here, rclpy checks only a scalar's). A value of another
        type (a string for a list with ``dynamic_typing``) is the node's to check.
        """
        if self.choices and isinstance(value, str) and value not in self.choices:
            raise ValueError(f'{self.name} must be one of {", ".join(self.choices)}, got '
                             f'{value!r}')
        if self.value_range is None:
            return
        low, high = self.value_range
        many = isinstance(value, (list, tuple))
        for i, v in enumerate(value if many else [value]):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            if not low <= v <= high:
                where = f'{self.name}[{i}]' if many else self.name
                unit = f' {self.unit}' if self.unit else ''
                raise ValueError(f'{where} = {v:.6g}{unit} is outside its range {low:g} to '
                                 f'{high:g}{unit}')

    @property
    def type_name(self):
        """Return the ROS type name (``double``, ``integer[]`` ...) of the parameter."""
        if self.array_type:
            return {STRING_ARRAY: 'string[]', DOUBLE_ARRAY: 'double[]'}[self.array_type]
        value = self.default
        suffix = ''
        if isinstance(value, list):
            value, suffix = value[0], '[]'
        for kind, name in ((bool, 'bool'), (int, 'integer'), (float, 'double'), (str, 'string')):
            if isinstance(value, kind):
                return name + suffix
        raise TypeError(f'{self.name}: no ROS type for {value!r}')

    @property
    def full_description(self):
        """Return the description with its unit, as ``ros2 param describe`` shows it."""
        return f'{self.description} [{self.unit}]' if self.unit else self.description


def _parameter(name, default, description, **kwargs):
    if isinstance(default, tuple):
        default = list(default)
    return Parameter(name, default, description, **kwargs)


P = _parameter
_CONTROL = ControllerConfig()
#: Range of a coordinate in base_link (m): limits.MAX_REQUEST_COORDINATE either way.
_WORKCELL = (-limits.MAX_REQUEST_COORDINATE, limits.MAX_REQUEST_COORDINATE)
#: Range of a joint position (rad): the UR10's joint limits, +-2 pi (its URDF).
_JOINT_RANGE = (-2.0 * math.pi, 2.0 * math.pi)
#: Range of a colour component (rgb in 0..1).
_COLOUR = (0.0, 1.0)
_PLAN = PlanSettings()
_GAINS = ObstacleGains()
_REACH = Workspace()

# ------------------------------------------------------------------------------------ scene
#: The workcell shared by every node (config/scene.yaml). Base frame: base_link of the UR10.
SCENE = (
    P('tool_offset', [0.0, 0.0, 0.16], 'Tool tip (pen, stirrer) in the flange frame tool0, in '
      'tool0 axes (along the flange axis).', unit='m', value_range=(-1.0, 1.0)),
    P('initial_joint_positions', [0.0, -1.2, 1.9, -2.27, -1.57, 0.0],
      'Joint positions the simulation starts in (pen 8 cm above the table, pointing down); '
      'the posture of posture_gain.', unit='rad', value_range=_JOINT_RANGE),
    P('task_plane.origin', [0.75, 0.15, 0.0], 'Origin of the plane in which 2D skills '
      '(letters, wiping) are executed: the table top in front of the robot.', unit='m',
      value_range=_WORKCELL),
    P('task_plane.x_axis', [1.0, 0.0, 0.0], 'x axis of the task plane in base_link.'),
    P('task_plane.y_axis', [0.0, 1.0, 0.0], 'y axis of the task plane in base_link '
      '(orthogonal to x).'),
    P('camera.position', [1.55, 0.05, 0.85], 'Position of the colour optical frame of the '
      'RealSense D435 (z forward, x right, y down) in base_link.', unit='m',
      value_range=_WORKCELL,
      section='Simulated workcell: ur10_sim builds it, perception reads camera and sizes',
      note='RealSense D435 colour optical frame (ROS: z forward, x right, y down) in '
      'base_link: position [x, y, z] and orientation quaternion [x, y, z, w]. The ONE copy of '
      'the extrinsics: ur10_sim renders from it and perception deprojects with it. Computed '
      'with CameraPose.look_at(eye=position, target=[0.72, 0.05, 0.0]) (tools/render_scene.py '
      '--look-at).'),
    P('camera.orientation', [-0.654881, -0.654881, 0.266705, 0.266705],
      'Orientation quaternion [x, y, z, w] of the colour optical frame in base_link.'),
    P('table.center', [0.45, 0.0], 'Centre [x, y] of the table top (the plane z = 0).',
      unit='m', value_range=_WORKCELL),
    P('table.size', [1.9, 1.5], 'Size [x, y] of the table top.', unit='m',
      value_range=(0.1, 10.0)),
    P('table.height', 0.75, 'Height of the table legs.', unit='m', value_range=(0.1, 2.0)),
    P('table.color', [0.62, 0.52, 0.40], 'Table colour, rgb in 0..1.', value_range=_COLOUR),
    P('whiteboard.size', [0.6, 0.6], 'Size of a thin (0.5 mm) white sheet lying on the table, '
      'centred under task_plane.origin; [0, 0]: none.', unit='m', value_range=(0.0, 10.0)),
    P('whiteboard.color', [0.95, 0.95, 0.95], 'Whiteboard colour, rgb in 0..1.',
      value_range=_COLOUR),
    P('bottle.position', [0.70, -0.30], 'Where [x, y] the open bottle stands on the table '
      "(all of it, clear of the robot's base); ur10_sim moves it at runtime (ros2 param set "
      '/ur10_sim bottle.position "[0.7, -0.28]").', unit='m', value_range=_WORKCELL),
    P('bottle.radius', 0.045, 'Bottle radius.', unit='m', value_range=(0.005, 0.5)),
    P('bottle.height', 0.20, 'Bottle height; its mouth is at this z.', unit='m',
      value_range=(0.01, 1.0)),
    P('bottle.color', [0.20, 0.35, 0.85], 'Bottle colour, rgb in 0..1.', value_range=_COLOUR),
    P('goal_position', [0.838, 0.1, 0.002], 'Centre of the top face of the goal marker (a '
      "green disc lying on the table: all of it on the table top, clear of the robot's base) "
      'in base_link.', unit='m', value_range=_WORKCELL,
      note='Goal marker: a green disc lying on the table; goal_position is the centre of its '
      'top face. ur10_sim moves it at runtime (ros2 param set /ur10_sim goal_position '
      '"[...]"). Default (make demo): 9 cm from where the pen starts, which lies towards -x, '
      "+y of it (quadrant II) while the letter G's demonstration starts towards +x, +y of its "
      'goal (quadrant I): ET-DMP turns the G by 90 degrees, upright as the camera sees it, and '
      'scales it to about 0.23 m tall, on the whiteboard.'),
    P('goal_marker.radius', 0.03, 'Radius of the goal marker disc.', unit='m',
      value_range=(0.005, 0.5)),
    P('goal_marker.color', [0.10, 0.75, 0.20], 'Goal marker colour, rgb in 0..1.',
      value_range=_COLOUR),
    P('obstacle_positions', [0.757, 0.063, 0.08, 0.921, 0.045, 0.08], 'Centres of the top '
      'faces of the obstacle cylinders, flat [x1, y1, z1, x2, ...] in base_link (each on the '
      "table top, clear of the robot's base).", unit='m', value_range=_WORKCELL,
      note='Obstacles: red upright cylinders; each point [x, y, z] is the centre of a '
      "cylinder's top face (z = obstacle.height: it stands on the table). Flat list [x1, y1, "
      'z1, x2, ...]; ur10_sim moves them at runtime; [] for none (at most 8). Default (make '
      'demo): 20 mm beside the obstacle-free ET-DMP path of the G from the default start to '
      "goal_position (a quarter and half-way along it, inside the letter's bowl): that path "
      'would run through both cylinders (the pen tip needs 25 + 3 mm from an axis).'),
    P('obstacle_radii', [], 'Radius of each obstacle cylinder, in the order of '
      'obstacle_positions; obstacles beyond this list (all, when it is empty) have '
      'obstacle.radius.', unit='m', value_range=(0.005, 0.5), array_type=DOUBLE_ARRAY,
      example=[0.025, 0.04]),
    P('obstacle.radius', 0.025, 'Radius of the obstacle cylinders that obstacle_radii does not '
      'size; perception starts its measurement of a radius from it.', unit='m',
      value_range=(0.005, 0.5)),
    P('obstacle.height', 0.08, 'Height of the obstacle cylinders.', unit='m',
      value_range=(0.01, 1.0)),
    P('obstacle.color', [0.85, 0.10, 0.10], 'Obstacle colour, rgb in 0..1.',
      value_range=_COLOUR),
)
_SCENE = {p.name: p for p in SCENE}


def _scene(*names, **changes):
    """Return scene parameters as a node declares them (``changes`` applied to each)."""
    return tuple(replace(_SCENE[name], **changes) for name in names)


# --------------------------------------------------------------------------------- ur10_sim
#: Parameters of ur10_sim that may change while it runs.
_SIM_DYNAMIC = {'dynamic': True, 'dynamic_typing': True}
#: What the simulation builds from: the parameters of SceneConfig.
_SIM_RUNTIME_SCENE = ('goal_position', 'obstacle_positions', 'bottle.position')
UR10_SIM_SCENE = tuple(
    _scene(name, **(_SIM_DYNAMIC if name in _SIM_RUNTIME_SCENE else
                    {'dynamic': True} if name == 'obstacle_radii' else {}))[0]
    for name in SCENE_PARAMETERS)
UR10_SIM = (
    P('control_rate', 125.0, 'Rate of /joint_states, /clock and the ground truth; velocity '
      'commands take effect at these ticks. 125 Hz is a UR10 (CB3), 500 Hz an e-series.',
      unit='Hz', value_range=(1.0, 2000.0)),
    P('physics_timestep', 0.002, 'Physics step; the control period is a whole number of '
      'them.', unit='s', value_range=(1e-4, 0.02)),
    P('real_time_factor', 1.0, 'Simulated seconds per wall-clock second; 0 runs as fast as '
      'the CPU allows.', value_range=(0.0, 100.0), dynamic=True),
    P('watchdog_timeout', 0.1, 'Simulated time without a command before braking to zero '
      'velocity; 0 disables it and the last command then applies forever, like the real '
      'forward_velocity_controller.', unit='s', value_range=(0.0, 60.0), dynamic=True),
    P('command_wait', 0.016, "Wall-clock time a tick waits for the controller's command "
      'answering the previous joint states, while a controller answers every tick: a '
      'controller late for a moment (a busy machine) slows the simulation instead of the arm '
      'moving on the old command unanswered; 0 = never wait.', unit='s',
      value_range=(0.0, 1.0), dynamic=True),
    P('camera_rate', 30.0, 'Rate of the colour + aligned depth camera (RealSense D435-like); '
      '0 disables the camera.', unit='Hz', value_range=(0.0, 90.0)),
    P('image_width', 640, 'Camera image width.', unit='px', value_range=(16, 4096)),
    P('image_height', 480, 'Camera image height.', unit='px', value_range=(16, 4096)),
    P('fovy_deg', 42.5, 'Vertical field of view of the colour camera; 42.5 at 640x480 is a '
      "D435's (about 55 x 43 deg, f = 617 px).", unit='deg', value_range=(1.0, 170.0)),
    P('depth_min', 0.1, 'Nearer depth (z in the optical frame) reads 0 (no data), as a '
      'D435.', unit='m', value_range=(0.0, 65.0)),
    P('depth_max', 3.0, 'Farther depth reads 0 (no data).', unit='m', value_range=(0.0, 65.0)),
    P('depth_noise', 0.0, 'Standard deviation of the depth noise at 1 m; it grows with z^2 '
      "like a stereo camera's.", unit='m', value_range=(0.0, 1.0)),
    P('multisamples', 0, 'MSAA samples of the colour image (0 fastest; 4 smoother edges, '
      'about twice the render time).', value_range=(0, 16)),
    P('teach_script', '', 'Teaching mode (kinesthetic teaching, simulated): a file of tool tip '
      'positions (.csv/.npy/.npz, 3 columns in metres, with times) that leads the tool as a '
      'hand in freedrive would, as offsets from where the tool is, its orientation held; '
      'velocity commands are ignored while it plays; ~/teaching says when it is done. Set '
      'at runtime to start it from the current pose; empty = off.',
      section='Teaching mode', dynamic=True, example='/path/to/stir_by_hand.csv'),
)

# ------------------------------------------------------------------------------- perception
PERCEPTION_SCENE = _scene('camera.position', 'camera.orientation', 'table.center', 'table.size',
                          'goal_marker.radius', 'obstacle.radius', 'obstacle.height',
                          'bottle.radius', 'bottle.height')
_DETECTION = {'dynamic': True}
PERCEPTION = (
    P('goal_hsv_low', [45, 100, 50], 'Lower corner [h, s, v] of the goal colour (OpenCV HSV: '
      'H 0..179 = degrees / 2, S and V 0..255).', dynamic=True,
      dynamic_typing=True, section='Colour classes',
      note='Colour classes: boxes [h, s, v] in OpenCV HSV units (H 0..179 = degrees / 2, S and '
      'V 0..255). A hue low above the hue high wraps through 0, as red needs. In the simulated '
      'scene: goal marker H 65 S 220, obstacles H 0 S 225 (V 130 on their shaded sides), table '
      'H 16 S 90, bottle H 113, robot and whiteboard S < 30.'),
    P('goal_hsv_high', [85, 255, 255], 'Upper corner [h, s, v] of the goal colour; a hue '
      'below the low hue wraps through 0.', dynamic=True, dynamic_typing=True),
    P('obstacle_hsv_low', [170, 120, 50], 'Lower corner [h, s, v] of the obstacle colour.',
      dynamic=True, dynamic_typing=True),
    P('obstacle_hsv_high', [8, 255, 255], 'Upper corner [h, s, v] of the obstacle colour; a '
      'hue below the low hue wraps through 0 (red).', dynamic=True,
      dynamic_typing=True),
    P('detect_bottle', True, 'Also locate the open bottle (an upright cylinder of '
      'bottle.radius and bottle.height) and publish the centre of its mouth on /etdmp/bottle '
      '(about 2 ms more per frame).', dynamic=True),
    P('bottle_hsv_low', [100, 100, 40], 'Lower corner [h, s, v] of the bottle colour.',
      dynamic=True, dynamic_typing=True),
    P('bottle_hsv_high', [125, 255, 255], 'Upper corner [h, s, v] of the bottle colour.',
      dynamic=True, dynamic_typing=True),
    P('min_blob_area', 40, 'Smaller colour blobs are ignored. At 640x480 the goal marker seen '
      'from 1.2 m covers about 1000 px, an obstacle about 1500 px.', unit='px',
      value_range=(1, 1_000_000), section='Blobs', **_DETECTION),
    P('min_depth_pixels', 20, 'Pixels with depth (0 = no data) a blob needs to be located.',
      value_range=(1, 1_000_000), **_DETECTION),
    P('top_band', 0.005, 'The highest points of a blob within this band are its top face '
      '(above the depth noise).', unit='m', value_range=(1e-4, 0.1), **_DETECTION),
    P('occlusion_gap', 0.01, 'An outline pixel next to something nearer to the camera by more '
      "than this is an occlusion edge (the arm in front), not the object's rim.", unit='m',
      value_range=(1e-3, 1.0), **_DETECTION),
    P('min_rim_points', 8, 'Fewer usable rim pixels than this: the centroid of the top face '
      'instead of the circle fit.', value_range=(3, 100_000), **_DETECTION),
    P('max_rim_rms', 0.004, 'A worse rim fit (RMS) flags the blob as two objects overlapping '
      'in the image.', unit='m', value_range=(1e-4, 0.1), **_DETECTION),
    P('obstacle_radius_range', [0.005, 0.1], 'Radii [low, high] an obstacle may have: each '
      "obstacle's radius is measured from its rim (when the rim seen spans half the circle or "
      'more; else obstacle.radius is reported), and one measured outside this range is not '
      'reported.', unit='m', value_range=(1e-4, 1.0), dynamic=True, dynamic_typing=True),
    P('height_tolerance', 0.02, 'A goal or obstacle whose top face is seen higher than this '
      'above its height (goal marker 2 mm, obstacle.height) or lower below the table top is '
      'refused, as is one off the table (table.center, table.size).', unit='m',
      value_range=(1e-3, 1.0), **_DETECTION),
    P('stamp_tolerance', 0.005, 'Colour, depth (and camera_info) messages belong to one frame '
      'when their stamps are this close (a RealSense stamps aligned depth with the colour '
      "frame's stamp).", unit='s', value_range=(0.0, 1.0), section='Frames', **_DETECTION),
    P('match_camera_info', True, 'Match camera_info by stamp too (the driver publishes one per '
      'frame); false: use the latest camera_info received.', **_DETECTION),
    P('max_rate', 0.0, 'Process at most this many frames per second (0: every frame). Only '
      'the newest frame is ever processed, so the node never falls behind the camera.',
      unit='Hz', value_range=(0.0, 1000.0), **_DETECTION),
    P('debug_image_rate', 15.0, 'Annotated /etdmp/detections/image at most this often, and '
      'only while someone subscribes (0: never).', unit='Hz', value_range=(0.0, 1000.0),
      **_DETECTION),
    P('warn_period', 2.0, 'Repeated warnings (no goal visible, frames skipped) at most this '
      'often.', unit='s', value_range=(0.0, 3600.0), **_DETECTION),
    P('reliable_images', True, 'Reliable image subscriptions (ur10_sim publishes reliably); '
      'false: best effort, for publishers with the sensor-data QoS.',
      note='Image subscriptions: true = reliable (ur10_sim publishes reliably; a lost fragment '
      'of a big image is then resent instead of the whole frame being lost: under load, best '
      'effort lost up to half of the 30 frames/s in some runs here, reliable 1-2); false = best '
      'effort, needed for publishers with the sensor-data (best-effort) QoS.'),
)

# ------------------------------------------------------------------------------- dmp_server
_RUNTIME = {'dynamic': True}
#: dmp_server's goal_object: the perceived objects an empty goal frame id may mean.
GOAL_OBJECTS = ('marker', 'bottle')
DMP_SERVER_SCENE = (*_scene('tool_offset', 'initial_joint_positions'),
                    *_scene('task_plane.origin', 'task_plane.x_axis', 'task_plane.y_axis',
                            **_RUNTIME))
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
      unit='m', value_range=_WORKCELL, array_type=DOUBLE_ARRAY, example=[0.8, 0.1, 0.0],
      **_RUNTIME),
    P('tool_radius', _PLAN.tool_radius, "Radius of the tool (the simulation's pen and stirrer: "
      "9 mm): added to each obstacle's radius for the clearance a plan keeps from its centre.",
      unit='m', value_range=(0.0, 0.5), **_RUNTIME),
    P('obstacle_clearance', _PLAN.obstacle_clearance, "Safety margin added to each obstacle's "
      "radius and the tool's: the gap a plan keeps between the tool's surface and an "
      "obstacle's.", unit='m', value_range=(0.0, 0.5), **_RUNTIME,
      note="Safety margin between the tool's surface and an obstacle's: 5 mm wanted (issue 25) "
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
      '-0.15] below its mouth.', unit='m', value_range=(-2.0, 2.0), **_RUNTIME),
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

# -------------------------------------------------------------------- dmp_server's services
#: The type of dmp_server's services whose request carries what it needs, so that concurrent
#: clients cannot mix (docs/dmp_server.md, "Requests that carry their settings"): named, typed
#: arguments (rcl_interfaces/Parameter) answered with successful and a reason. Standard types
#: only: the package builds no message package of its own.
ARGUMENTS_SERVICE_TYPE = 'rcl_interfaces/srv/SetParametersAtomically'


@dataclass(frozen=True)
class ServiceSpec:
    """
    A service whose request is named, typed arguments (:data:`ARGUMENTS_SERVICE_TYPE`).

    ``name`` is relative to the node (``~/<name>``). Each argument is a :class:`Parameter`: its
    default gives its type (and is its value when not given, unless it is ``required``); an
    argument named like one of the node's parameters is that parameter's value for this one
    request, with its range and choices.
    """

    name: str
    summary: str
    arguments: tuple
    required: tuple = ()

    def argument(self, name):
        """Return the argument :class:`Parameter` called ``name``; KeyError if none."""
        for a in self.arguments:
            if a.name == name:
                return a
        raise KeyError(f'~/{self.name} has no argument {name!r}')

    def values(self, given):
        """
        Return ``{argument: value}`` of a request's ``given`` arguments ({name: plain value}).

        Arguments not given are absent (the caller's defaults apply). Raises ValueError naming
        an unknown argument, a missing required one, a value of the wrong type, or one outside
        its range or choices (:meth:`Parameter.check`).
        """
        known = {a.name: a for a in self.arguments}
        unknown = sorted(set(given) - set(known))
        if unknown:
            raise ValueError(f'~/{self.name} has no argument {unknown[0]!r}; its arguments are '
                             f'{", ".join(known)}')
        missing = [name for name in self.required if name not in given]
        if missing:
            raise ValueError(f'~/{self.name} needs the argument {missing[0]!r}')
        values = {}
        for name, value in given.items():
            values[name] = _typed(known[name], value, self.name)
            known[name].check(values[name])
        return values


def _typed(argument, value, service):
    """Return ``value`` as the type of ``argument``'s default; ValueError if it is not one."""
    default = [] if argument.array_type == DOUBLE_ARRAY else argument.default
    number = (int, float)
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, number) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, str):
        ok = isinstance(value, str)
    else:   # a list of floats
        ok = isinstance(value, (list, tuple)) and all(
            isinstance(v, number) and not isinstance(v, bool) for v in value)
        value = [float(v) for v in value] if ok else value
    if not ok:
        raise ValueError(f'~/{service} argument {argument.name!r} must be a {argument.type_name}, '
                         f'got {type(value).__name__}')
    return value


_SERVER = {p.name: p for p in DMP_SERVER}
DMP_SERVER_SERVICES = (
    ServiceSpec('teach', 'Learn a demonstration as the skill it names, saved like every taught '
                'one; the answer says what was learned, or why not.', (
                    P('name', '', 'Name of the skill (1-64 letters, digits, _ or -); a taught '
                      'skill of that name is replaced.'),
                    P('t', [], 'Time of each sample (s), rising.', unit='s',
                      array_type=DOUBLE_ARRAY),
                    P('positions', [], 'Position of each sample in base_link, flat [x1, y1, '
                      'z1, x2, ...].', unit='m', value_range=_WORKCELL,
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
                      value_range=_WORKCELL, array_type=DOUBLE_ARRAY),
                    P('goal', [], 'Goal [x, y, z] in base_link; none: the perceived goal object '
                      'plus goal_offset (as an empty goal frame id).', unit='m',
                      value_range=_WORKCELL, array_type=DOUBLE_ARRAY),
                    P('goal_orientation', [], 'Goal orientation [x, y, z, w] in base_link; none '
                      'or all zeros: none.', array_type=DOUBLE_ARRAY))),
)


# ------------------------------------------------------------------------------- controller
CONTROLLER_SCENE = _scene('tool_offset', 'initial_joint_positions')
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
      unit='rad/s^2', value_range=(0.1, 1000.0)),
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

# ------------------------------------------------------------------------------------ teach
TEACH_SCENE = _scene('camera.position', 'camera.orientation')
TEACH = (
    P('port', 8080, 'TCP port of the teaching page (http://localhost:<port>/); 0 = any free port '
      '(the log names it).', value_range=(0, 65535), section='Web server'),
    P('address', '127.0.0.1', 'Address the page is served on: 127.0.0.1 = this machine only; '
      '0.0.0.0 = every network interface (whoever reaches it can teach skills and move the '
      'robot).'),
    P('canvas_width', 0.4, 'Width of the task plane the drawing canvas shows (4:3, centred on '
      'task_plane.origin, robot base at the top as the camera sees it).', unit='m',
      value_range=(0.01, 10.0), section='Teaching'),
    P('dmp_server', 'dmp_server', "The DMP server node (relative to this node's namespace) whose "
      'parameters the page reads (task plane, formulation, n_basis) and whose ~/teach and '
      '~/generalize_with services it calls (the page changes none of its parameters).'),
    P('report_timeout', 10.0, "Longest wait for dmp_server's answer to a service call (reading "
      'its parameters, teaching, writing).', unit='s', value_range=(0.1, 120.0)),
    P('camera_rate', 5.0, 'Camera images per second a page gets at most (JPEG).', unit='Hz',
      value_range=(0.1, 30.0), section='Camera view'),
    P('jpeg_quality', 80, 'JPEG quality of the camera images sent to the page.',
      value_range=(10, 100)),
    P('watch_timeout', 3.0, 'A page that asked for no image for this long no longer watches: '
      'the camera image and the pen trace are unsubscribed until one asks again.', unit='s',
      value_range=(0.5, 60.0)),
    P('trace_source', 'ground_truth', 'The pen trace drawn over the camera image: ground_truth '
      '(/ur10_sim/ground_truth/tool_tip, the simulation) or tool_pose (/etdmp/tool_pose, the '
      "controller's forward kinematics, as on a real robot).",
      choices=('ground_truth', 'tool_pose')),
)


# ----------------------------------------------------------------------------------- wiring
@dataclass(frozen=True)
class NodeSpec:
    """
    One node of the system: what it is, how it starts, which parameters it declares.

    ``sim_time``: the node follows the simulation's /clock (``use_sim_time``): dmp_server,
    which stamps plans with the ROS clock, and the controller, which judges its joint states
    stale on the simulation's time (a stalled simulation is late, not lost). The others stamp
    with their inputs' stamps and need no clock.

    ``shared_memory``: the node receives camera images, which Fast DDS's shared-memory
    transport carries (config/fastdds.xml). The others talk UDP only (config/fastdds_udp.xml):
    a shared-memory send can wait seconds for another process (docs/reliability.md), and the
    simulation, the controller and dmp_server close the control loop.
    """

    name: str
    summary: str
    scene: tuple
    parameters: tuple
    node_class: str
    sim_time: bool = False
    shared_memory: bool = False
    config_header: str = field(default='', repr=False)
    services: tuple = ()

    @property
    def executable(self):
        """Return the executable's name (``ros2 run etdmp_ros <executable>``)."""
        return self.name

    @property
    def module(self):
        """Return the module that runs the node (``python -m <module>``)."""
        return f'etdmp_ros.nodes.{self.name}'

    @property
    def all_parameters(self):
        """Return every parameter the node declares: its scene ones, then its own."""
        return self.scene + self.parameters

    def parameter(self, name):
        """Return the :class:`Parameter` called ``name``; KeyError if the node has none."""
        for p in self.all_parameters:
            if p.name == name:
                return p
        raise KeyError(f'{self.name} has no parameter {name!r}')

    def defaults(self):
        """Return ``{name: default}`` of every parameter the node declares."""
        return {p.name: p.default for p in self.all_parameters}

    def service(self, name):
        """Return the :class:`ServiceSpec` called ``name``; KeyError if the node has none."""
        for spec in self.services:
            if spec.name == name:
                return spec
        raise KeyError(f'{self.name} has no service {name!r}')


#: The nodes in start order (the simulation first: the others wait for its topics).
NODES = (
    NodeSpec('ur10_sim', 'MuJoCo UR10 workcell: joint states, /clock, camera, ground truth',
             UR10_SIM_SCENE, UR10_SIM, 'etdmp_ros.nodes.ur10_sim:UR10SimNode',
             config_header='Without parameter files the node uses these values too (they '
             'are its built-in defaults).'),
    NodeSpec('perception', 'goal and obstacles in base_link from the colour + depth camera',
             PERCEPTION_SCENE, PERCEPTION, 'etdmp_ros.nodes.perception:PerceptionNode',
             shared_memory=True,
             config_header='Everything here except reliable_images can be changed at runtime '
             '(ros2 param set /perception <name> <value>).'),
    NodeSpec('dmp_server', 'learns skills from demonstrations and serves /generalize',
             DMP_SERVER_SCENE, DMP_SERVER, 'etdmp_ros.nodes.dmp_server:DmpServer',
             sim_time=True, services=DMP_SERVER_SERVICES),
    NodeSpec('controller', 'follows /etdmp/path with the UR10 tool tip (closed-loop IK)',
             CONTROLLER_SCENE, CONTROLLER, 'etdmp_ros.nodes.controller:ControllerNode',
             sim_time=True),
)
NODE_NAMES = tuple(n.name for n in NODES)
#: The teaching page (docs/teach.md): started beside the system on demand (``make teach``, the
#: launch file's ``teach:=true``), not by ``make demo``, ``bringup`` or the launch file's default.
TEACH_NODE = NodeSpec('teach', 'the teaching page: draw a movement in a browser, teach it to '
                      'dmp_server, watch the UR10 write it', TEACH_SCENE, TEACH,
                      'etdmp_ros.nodes.teach:TeachNode', shared_memory=True,
                      config_header='The page is served to this machine only unless address '
                      'says otherwise.')
#: Every node of the package: the system's, then the teaching page's.
ALL_NODES = NODES + (TEACH_NODE,)
SCENE_FILE = 'scene.yaml'
#: Where the nodes run in a lab of two computers (docs/two_hosts.md): the robot's PC beside the
#: arm runs the UR driver (here ur10_sim) and the controller, which closes the 125 Hz loop with
#: it (a real UR's velocity interface holds its last command: that loop must not cross a link
#: that can fail); the workstation runs the camera processing and the skills. The launch file's
#: ``host:=robot|workstation``, bringup's ``--host``; ``all`` (the default) is every node.
HOSTS = {'robot': ('ur10_sim', 'controller'), 'workstation': ('perception', 'dmp_server')}
HOST_CHOICES = ('all', *HOSTS)


def select_nodes(host='all', nodes=''):
    """
    Return the names of the nodes to start on this computer, in start order (:data:`NODES`).

    ``host``: ``all`` or a key of :data:`HOSTS`; ``nodes``: node names (a list, or one string
    separated by commas or spaces) instead of a host's. ValueError, naming the choices, for an
    unknown host or node, or both given.
    """
    if isinstance(nodes, str):
        nodes = nodes.replace(',', ' ').split()
    nodes = list(nodes)
    if host not in HOST_CHOICES:
        raise ValueError(f'host must be one of {", ".join(HOST_CHOICES)}, got {host!r}')
    if nodes and host != 'all':
        raise ValueError(f'give host ({host!r}) or nodes ({",".join(nodes)}), not both')
    unknown = [n for n in nodes if n not in NODE_NAMES]
    if unknown:
        raise ValueError(f'no node {unknown[0]!r} (nodes: {", ".join(NODE_NAMES)})')
    chosen = set(nodes) if nodes else set(NODE_NAMES if host == 'all' else HOSTS[host])
    return tuple(n for n in NODE_NAMES if n in chosen)


def node(name):
    """Return the :class:`NodeSpec` called ``name``; KeyError naming the nodes if none."""
    for spec in ALL_NODES:
        if spec.name == name:
            return spec
    raise KeyError(f'no node {name!r} (nodes: {", ".join(n.name for n in ALL_NODES)})')


def defaults(name):
    """Return ``{parameter: default}`` of node ``name`` (scene parameters it declares + own)."""
    return node(name).defaults()


def scene_defaults():
    """Return ``{parameter: default}`` of the whole workcell (config/scene.yaml)."""
    return {p.name: p.default for p in SCENE}


def scene_config(overrides=None):
    """
    Return the default workcell as a validated SceneConfig.

    ``overrides``: optional ``{flat name: value}`` replacing defaults, e.g.
    ``{'goal_position': [0.7, 0.2, 0.002]}``; ValueError names a bad value.
    """
    values = scene_defaults()
    values.update(overrides or {})
    for p in SCENE:
        p.check(values[p.name])
    return SceneConfig.from_parameters(values)


def parameter_files(name, config_dir=None):
    """
    Return the parameter files of node ``name`` in order: scene.yaml, then ``<name>.yaml``.

    From ``config_dir`` if given, else from the package's config folder (share/etdmp_ros).
    """
    node(name)
    if config_dir is not None:
        return [Path(config_dir) / SCENE_FILE, Path(config_dir) / f'{name}.yaml']
    return [config_path(SCENE_FILE), config_path(f'{name}.yaml')]


def wiring_overrides(name):
    """Return the parameters the system sets on node ``name`` after its files (sim time)."""
    return {'use_sim_time': True} if node(name).sim_time else {}


def _check_names():
    placed = sorted(n for names in HOSTS.values() for n in names)
    if placed != sorted(NODE_NAMES):
        raise ValueError(f'HOSTS must place every node once, got {placed}')
    for spec in ALL_NODES:
        names = [p.name for p in spec.all_parameters]
        if len(names) != len(set(names)):
            raise ValueError(f'{spec.name}: a parameter is declared twice')


_check_names()

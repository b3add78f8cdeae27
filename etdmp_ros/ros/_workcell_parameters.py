"""
The parameters of the workcell (config/scene.yaml) and of the nodes that see it.

The simulation (ur10_sim), perception and the teaching page (teach); see
:mod:`etdmp_ros.ros.system`, which makes the nodes of these tables.
"""

from __future__ import annotations

from dataclasses import replace
import math
from typing import Any

from etdmp_ros import limits
from etdmp_ros.robot import SCENE_PARAMETERS, WATCHDOG_TIMEOUT
from etdmp_ros.ros.specs import DOUBLE_ARRAY, Parameter, parameter

P = parameter
#: Range of a coordinate in base_link (m): limits.MAX_REQUEST_COORDINATE either way.
WORKCELL_RANGE = (-limits.MAX_REQUEST_COORDINATE, limits.MAX_REQUEST_COORDINATE)
#: Range of a joint position (rad): the UR10's joint limits, +-2 pi (its URDF).
JOINT_RANGE = (-2.0 * math.pi, 2.0 * math.pi)
#: A colour: rgb (or rgba), each in 0..1.
_COLOUR: dict[str, Any] = {'value_range': (0.0, 1.0), 'lengths': (3, 4)}

# ------------------------------------------------------------------------------------ scene
#: The workcell shared by every node (config/scene.yaml). Base frame: base_link of the UR10.
SCENE = (
    P('tool_offset', [0.0, 0.0, 0.16], 'Tool tip (pen, stirrer) in the flange frame tool0, in '
      'tool0 axes (along the flange axis).', unit='m', value_range=(-1.0, 1.0), lengths=(3,)),
    P('initial_joint_positions', [0.0, -1.2, 1.9, -2.27, -1.57, 0.0],
      'Joint positions the simulation starts in (pen 8 cm above the table, pointing down); '
      'the posture of posture_gain.', unit='rad', value_range=JOINT_RANGE, lengths=(6,)),
    P('task_plane.origin', [0.75, 0.15, 0.0], 'Origin of the plane in which 2D skills '
      '(letters, wiping) are executed: the table top in front of the robot.', unit='m',
      value_range=WORKCELL_RANGE, lengths=(3,)),
    P('task_plane.x_axis', [1.0, 0.0, 0.0], 'x axis of the task plane in base_link.',
      lengths=(3,)),
    P('task_plane.y_axis', [0.0, 1.0, 0.0], 'y axis of the task plane in base_link '
      '(orthogonal to x).', lengths=(3,)),
    P('camera.position', [1.55, 0.05, 0.85], 'Position of the colour optical frame of the '
      'RealSense D435 (z forward, x right, y down) in base_link.', unit='m',
      value_range=WORKCELL_RANGE,
      section='Simulated workcell: ur10_sim builds it, perception reads camera and sizes',
      note='RealSense D435 colour optical frame (ROS: z forward, x right, y down) in '
      'base_link: position [x, y, z] and orientation quaternion [x, y, z, w]. The ONE copy of '
      'the extrinsics: ur10_sim renders from it and perception deprojects with it. Computed '
      'with CameraPose.look_at(eye=position, target=[0.72, 0.05, 0.0]) (tools/render_scene.py '
      '--look-at).', lengths=(3,)),
    P('camera.orientation', [-0.654881, -0.654881, 0.266705, 0.266705],
      'Orientation quaternion [x, y, z, w] of the colour optical frame in base_link.',
      lengths=(4,)),
    P('table.center', [0.45, 0.0], 'Centre [x, y] of the table top (the plane z = 0).',
      unit='m', value_range=WORKCELL_RANGE, lengths=(2,)),
    P('table.size', [1.9, 1.5], 'Size [x, y] of the table top.', unit='m',
      value_range=(0.1, 10.0), lengths=(2,)),
    P('table.height', 0.75, 'Height of the table legs.', unit='m', value_range=(0.1, 2.0)),
    P('table.color', [0.62, 0.52, 0.40], 'Table colour, rgb (or rgba) in 0..1.', **_COLOUR),
    P('whiteboard.size', [0.6, 0.6], 'Size of a thin (0.5 mm) white sheet lying on the table, '
      'centred under task_plane.origin; [0, 0]: none.', unit='m', value_range=(0.0, 10.0),
      lengths=(2,)),
    P('whiteboard.color', [0.95, 0.95, 0.95], 'Whiteboard colour, rgb (or rgba) in 0..1.',
      **_COLOUR),
    P('bottle.position', [0.70, -0.30], 'Where [x, y] the open bottle stands on the table '
      "(all of it, clear of the robot's base); ur10_sim moves it at runtime (ros2 param set "
      '/ur10_sim bottle.position "[0.7, -0.28]").', unit='m', value_range=WORKCELL_RANGE,
      lengths=(2,)),
    P('bottle.radius', 0.045, 'Bottle radius.', unit='m', value_range=(0.005, 0.5)),
    P('bottle.height', 0.20, 'Bottle height; its mouth is at this z.', unit='m',
      value_range=(0.01, 1.0)),
    P('bottle.color', [0.20, 0.35, 0.85], 'Bottle colour, rgb (or rgba) in 0..1.', **_COLOUR),
    P('goal_position', [0.838, 0.1, 0.002], 'Centre of the top face of the goal marker (a '
      "green disc lying on the table: all of it on the table top, clear of the robot's base) "
      'in base_link.', unit='m', value_range=WORKCELL_RANGE,
      note='Goal marker: a green disc lying on the table; goal_position is the centre of its '
      'top face. ur10_sim moves it at runtime (ros2 param set /ur10_sim goal_position '
      '"[...]"). Default (make demo): 9 cm from where the pen starts, which lies towards -x, '
      "+y of it (quadrant II) while the letter G's demonstration starts towards +x, +y of its "
      'goal (quadrant I): ET-DMP turns the G by 90 degrees, upright as the camera sees it, and '
      'scales it to about 0.23 m tall, on the whiteboard.', lengths=(3,)),
    P('goal_marker.radius', 0.03, 'Radius of the goal marker disc.', unit='m',
      value_range=(0.005, 0.5)),
    P('goal_marker.color', [0.10, 0.75, 0.20], 'Goal marker colour, rgb (or rgba) in 0..1.',
      **_COLOUR),
    P('obstacle_positions', [0.757, 0.063, 0.08, 0.921, 0.045, 0.08], 'Centres of the top '
      'faces of the obstacle cylinders, flat [x1, y1, z1, x2, ...] in base_link (each on the '
      "table top, clear of the robot's base).", unit='m', value_range=WORKCELL_RANGE,
      note='Obstacles: red upright cylinders; each point [x, y, z] is the centre of a '
      "cylinder's top face (z = obstacle.height: it stands on the table). Flat list [x1, y1, "
      'z1, x2, ...]; ur10_sim moves them at runtime; [] for none (at most 8). Default (make '
      'demo): 20 mm beside the obstacle-free ET-DMP path of the G from the default start to '
      "goal_position (a quarter and half-way along it, inside the letter's bowl): that path "
      'would run through both cylinders (the pen tip needs 25 + 3 mm from an axis).',
      multiple_of=3),
    P('obstacle_radii', [], 'Radius of each obstacle cylinder, in the order of '
      'obstacle_positions; obstacles beyond this list (all, when it is empty) have '
      'obstacle.radius.', unit='m', value_range=(0.005, 0.5), array_type=DOUBLE_ARRAY,
      example=[0.025, 0.04]),
    P('obstacle.radius', 0.025, 'Radius of the obstacle cylinders that obstacle_radii does not '
      'size; perception starts its measurement of a radius from it.', unit='m',
      value_range=(0.005, 0.5)),
    P('obstacle.height', 0.08, 'Height of the obstacle cylinders.', unit='m',
      value_range=(0.01, 1.0)),
    P('obstacle.color', [0.85, 0.10, 0.10], 'Obstacle colour, rgb (or rgba) in 0..1.',
      **_COLOUR),
)
_SCENE = {p.name: p for p in SCENE}


def scene_parameters(*names: str, **changes: Any) -> tuple[Parameter, ...]:
    """Return scene parameters as a node declares them (``changes`` applied to each)."""
    return tuple(replace(_SCENE[name], **changes) for name in names)


# --------------------------------------------------------------------------------- ur10_sim
#: Parameters of ur10_sim that may change while it runs.
_SIM_DYNAMIC = {'dynamic': True, 'dynamic_typing': True}
#: What the simulation builds from: the parameters of SceneConfig.
_SIM_RUNTIME_SCENE = ('goal_position', 'obstacle_positions', 'bottle.position')
UR10_SIM_SCENE = tuple(
    scene_parameters(name, **(_SIM_DYNAMIC if name in _SIM_RUNTIME_SCENE else
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
    P('watchdog_timeout', WATCHDOG_TIMEOUT, 'Simulated time without a command before '
      'braking to zero velocity (the arm is at rest some 20 ms later); 0 disables it and the '
      'last command then applies forever, like the real forward_velocity_controller.',
      unit='s', value_range=(0.0, 60.0), dynamic=True),
    P('thread_priority', 60, 'SCHED_FIFO priority (1-99) of the simulation thread while it '
      'runs paced (real_time_factor > 0); 0 = normal scheduling. Needs CAP_SYS_NICE or an '
      'rtprio limit, else a warning and normal scheduling.', value_range=(0, 99),
      note='SCHED_FIFO priority of the simulation thread (the physics ticks), while paced: '
      "the robot's own controller runs on hardware of its own, which no program on this "
      "machine slows down; above the controller's 50. A tick takes about 1 ms of each 8 ms "
      'period; unpaced (real_time_factor 0) the thread would never sleep, so it then runs '
      'under normal scheduling. Needs CAP_SYS_NICE or an rtprio limit (ulimit -r); without, '
      'a warning and normal scheduling.'),
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
PERCEPTION_SCENE = scene_parameters('camera.position', 'camera.orientation', 'table.center',
                                    'table.size', 'goal_marker.radius', 'obstacle.radius',
                                    'obstacle.height', 'bottle.radius', 'bottle.height')
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

# ------------------------------------------------------------------------------------ teach
TEACH_SCENE = scene_parameters('camera.position', 'camera.orientation')
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

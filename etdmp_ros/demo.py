"""
The closed-loop demo (``make demo``): see, plan, write, measure.

``python -m etdmp_ros.demo [--skill G|P|R|W|wipe|stir] [--method etdmp|dmp] [--out out/demo]``
starts the four nodes as separate processes, exactly as ``ros2 run`` starts them (``ur10_sim``,
``perception``, ``dmp_server``, ``controller``; parameters: config/scene.yaml, then the node's
own file, then a small overrides file), on a DDS domain of its own with localhost-only
discovery, dmp_server on simulated time (``use_sim_time``: it stamps plans with the ROS clock;
the others stamp with their inputs' stamps). Then it

1. waits until the camera has shown the goal marker and the obstacles to ``perception``;
2. asks ``/generalize`` for the plain-DMP baseline without executing it (``dmp_server``
   parameters ``method: dmp``, ``execute: false``, set through its SetParameters service), then
   for the real plan (``method: etdmp``, ``execute: true``), both with empty frame ids: from the
   tool's current position to the perceived goal (stir: to an explicit goal in the bottle);
3. records the true pen tip (``/ur10_sim/ground_truth/tool_tip``), the joint-velocity commands
   (``/forward_velocity_controller/commands``), the controller's status and reference, and the
   camera images until the controller is idle again (the controller's own tracking error comes
   from the summary it logs);
4. stops the nodes with SIGINT (Ctrl-C) and writes ``plot.png``, ``camera_start.png``,
   ``camera_middle.png``, ``camera_end.png``, ``animation.gif``, ``metrics.json`` and
   ``recording.npz`` to the output folder, node logs to ``<out>/logs/``.

Scenes. The letter G uses config/scene.yaml's ``goal_position`` and ``obstacle_positions`` as
shipped (they are G's layout: the pen starts in another quadrant of the goal than the
demonstration, two obstacles sit 20 mm beside the obstacle-free path). The other 2D skills get
their own layout (:data:`LAYOUTS`, given to ``ur10_sim`` like ``ros2 param set`` would): the goal
90 degrees round from the demonstration's start direction, so that each is drawn upright as the
camera sees it, about 0.2 m tall, with two obstacles 20-35 mm beside its obstacle-free path
(chosen offline with the planning core; ``--layout scene`` keeps the scene file's). ``stir``
(3D, base_link): the simulation starts with the stirrer above the bottle, its start direction
turned 30 degrees about the vertical from the demonstration's (:data:`STIR_START_TURN_DEG`); the
goal is explicit: the bottle's mouth centre plus the demonstration's goal offset (the built-in
stir demo's origin is the mouth), near the bottom, because the marker on the table cannot be
seen inside a bottle. The request's start stays empty (the tool's current position). Letters
are written in 4 s, wiping in 5 s (:data:`DURATIONS`, dmp_server's ``duration``).

How the numbers are measured (``metrics.json`` repeats this under ``definitions``):

- nRMSE: SPEC §3.4, conventional variant (``etdmp_ros.dmp.nrmse``) against the demonstration,
  over the plan's ``tau`` only (its duration; a plan with obstacles runs 1.5 tau; its tail
  would be squeezed into the phase resampling, as in ``etdmp reproduce``). 2D skills are
  compared in the task plane (base_link points projected onto it), 3D skills in base_link.
  The executed trace is cut to the same span of the plan: from the moment the controller
  started tracking (found by fitting the controller's stamped reference to the plan, to a
  tenth of a millisecond) to that plus ``tau``; the approach before it is left out.
- tracking error: true pen tip minus the controller's reference at the same simulated stamps,
  while the plan is tracked.
- goal error: the pen tip at the end (after the hold) to the true goal marker projected onto
  the task plane (2D) or to the requested goal (stir).
- clearance: smallest distance from the pen tip's surface (radius 3 mm) to an obstacle
  cylinder's surface (true positions from the simulation; cylinders of ``obstacle.radius``
  standing on the table up to their top point), over the whole executed motion; > 0: no
  contact. For a pen on the table it is the distance to the axis minus 25 mm minus 3 mm.
- commands: the largest ``|qd_j| / limit_j`` (limits: ``UR10Model.velocity_limits`` times the
  controller's ``velocity_scale``) and ``|qd_j[k] - qd_j[k-1]| * control_rate / a_j``
  (the controller's ``joint_acceleration_limits``) over every command received.
"""

import argparse
from dataclasses import dataclass, field
import json
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import threading
import time

from etdmp_ros._paths import share_dir
from etdmp_ros._reproduce import quadrant
from etdmp_ros.cpu_monitor import CpuMonitor
from etdmp_ros.dmp import builtin_demo, learn, METHOD_LABELS, METHODS, nrmse
from etdmp_ros.nodes._spin import BackgroundNode
from etdmp_ros.planning import place_demo
from etdmp_ros.plotting import DEMO_STYLE, METHOD_STYLE
from etdmp_ros.robot import (CameraIntrinsics, CameraPose, quaternion_to_matrix,
                             read_parameter_file, UR10Model)
from etdmp_ros.ros_conversions import (header_stamp_ns, image_from_msg,
                                       intrinsics_from_camera_info, path_to_numpy,
                                       point_to_numpy, pose_array_to_numpy, stamp_to_ns)
from etdmp_ros.task_plane import TaskPlane
from geometry_msgs.msg import PointStamped, PoseArray, PoseStamped
from nav_msgs.srv import GetPlan
import numpy as np
import pinocchio as pin
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Float64MultiArray, String
import yaml

NODES = ('ur10_sim', 'perception', 'dmp_server', 'controller')
#: Nodes that follow the simulation's /clock: those that stamp with the ROS clock (plans).
#: perception and the controller stamp with their inputs' stamps (images, joint states).
SIM_TIME_NODES = ('dmp_server',)
SKILLS = ('G', 'P', 'R', 'W', 'wipe', 'stir')
#: Layouts of the 2D skills other than G on the shipped scene (default start pose and task
#: plane): ur10_sim's goal_position and obstacle_positions (base_link, m). G uses scene.yaml.
LAYOUTS = {
    'P': ([0.898, 0.111, 0.002], [0.826, 0.127, 0.08, 0.828, 0.233, 0.08]),
    'R': ([0.993, 0.256, 0.002], [0.83, 0.126, 0.08, 0.843, 0.222, 0.08]),
    'W': ([0.827, 0.329, 0.002], [0.909, 0.164, 0.08, 0.974, 0.257, 0.08]),
    # A wiping motion covers an area with no room for a 5 cm cylinder: beside its turns.
    'wipe': ([0.83, 0.256, 0.002], [0.746, 0.248, 0.08, 0.908, 0.296, 0.08]),
}
#: Plan duration (dmp_server ``duration``, s) per skill; stir: its demonstration's own 5 s.
#: The letters are demonstrated in 2 s (wipe in 4 s): written 0.2 m tall, with the detours
#: around the obstacles, in that time they ask the elbow for more than its acceleration limit
#: (35 rad/s^2) at their sharpest turns and the tracking error grows to millimetres there.
DURATIONS = {'G': 4.0, 'P': 4.0, 'R': 4.0, 'W': 4.0, 'wipe': 5.0}
#: Stir: the stirrer starts at the demonstration's start offset from the goal turned by this
#: angle about the vertical and scaled (the default Rodrigues ET-DMP then tilts the movement
#: by 9 degrees, which keeps it inside the bottle; the plain DMP squeezes its circles).
STIR_START_TURN_DEG = 30.0
STIR_START_SCALE = 0.9
#: Radius of the simulated pen's tip (etdmp_ros.robot._sim.PEN_TIP_RADIUS), m.
PEN_TIP_RADIUS = 0.003
#: Keep every n-th camera frame for the animation (30 Hz camera: 15 frames per second).
FRAME_EVERY = 2
STARTUP_TIMEOUT = 150.0
STATUS_FAILURES = ('unreachable', 'halted-singularity', 'halted-joint-limit', 'stale-input')
LATCHED = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STREAM = QoSProfile(depth=1000)
# Reliable, as perception subscribes: a lost fragment is resent instead of the frame lost.
IMAGES = QoSProfile(depth=2)
#: RGB of the pen's ink drawn into the camera frames.
INK_COLOR = (25, 35, 150)
DEFINITIONS = {
    'nrmse': 'SPEC 3.4 conventional variant (etdmp_ros.dmp.nrmse) vs the demonstration, over '
             "the plan's tau (without the obstacle margin); 2D skills in the task plane, 3D in "
             'base_link; '
             'trace: true pen tip from the start of tracking (controller reference fitted to '
             'the plan) to that + tau',
    'tracking_error': 'true pen tip minus the controller reference at the same simulated '
                      'stamps, while tracking the plan',
    'goal_error': 'pen tip after the hold to the true goal marker projected onto the task '
                  'plane (2D) or to the requested goal (3D)',
    'min_clearance': 'smallest distance from the pen tip surface (radius 3 mm) to an obstacle '
                     'cylinder surface (true positions), over the executed motion; > 0: clear',
    'command_ratios': 'max |qd_j| / velocity limit_j and max |dqd_j| * control_rate / '
                      'acceleration limit_j over all joint-velocity commands received',
    'quadrant': 'quadrant of start - goal in the task plane (I: +x +y, II: -x +y, ...); for '
                'the demonstration in its own coordinates',
    'moving_commands_per_s': 'non-zero joint-velocity commands per simulated second from the '
                             'first to the last of them (approach, plan, hold); the time from '
                             'the /generalize call to the first is '
                             'first_moving_command_after_call_s',
}


class DemoError(RuntimeError):
    """The demo could not run to the end; the message says why (and where the logs are)."""


# ------------------------------------------------------------------------------------ set-up


def isolated_environment(domain_id=None, base=None):
    """
    Return an environment for a private DDS domain: ``ROS_DOMAIN_ID`` and localhost discovery.

    ``domain_id`` defaults to one derived from the process id in 1..101 (Fast DDS's range that
    is safe from Linux's ephemeral ports); static peers and ROS_LOCALHOST_ONLY are dropped.
    """
    env = dict(os.environ if base is None else base)
    env['ROS_DOMAIN_ID'] = str(domain_id if domain_id is not None else 1 + os.getpid() % 101)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.pop('ROS_LOCALHOST_ONLY', None)
    env.pop('ROS_STATIC_PEERS', None)
    env.setdefault('MUJOCO_GL', 'egl')
    return env


def module_command(node, param_files):
    """Return the argv starting ``node`` with this Python (what ``ros2 run`` runs)."""
    return [sys.executable, '-m', f'etdmp_ros.nodes.{node}', '--ros-args',
            *[a for f in param_files for a in ('--params-file', str(f))]]


@dataclass
class Scene:
    """What the demo needs from the parameter files (config folder + the skill's layout)."""

    config_dir: Path
    skill: str
    layout: str = 'skill'
    parameters: dict = field(default_factory=dict)
    scene: dict = field(init=False)
    server: dict = field(init=False)
    controller: dict = field(init=False)
    plane: TaskPlane = field(init=False)
    demo: object = field(init=False)
    overrides: dict = field(init=False)
    explicit_goal: np.ndarray = field(init=False, default=None)

    def __post_init__(self):
        """Read the files; work out the per-node overrides of this skill's scene."""
        self.config_dir = Path(self.config_dir)
        self.scene = read_parameter_file(self.config_dir / 'scene.yaml')
        self.server = read_parameter_file(self.config_dir / 'scene.yaml', 'dmp_server')
        self.server.update(read_parameter_file(self.config_dir / 'dmp_server.yaml', 'dmp_server'))
        self.controller = read_parameter_file(self.config_dir / 'controller.yaml', 'controller')
        self.plane = TaskPlane.create(self.scene['task_plane.origin'],
                                      self.scene['task_plane.x_axis'],
                                      self.scene['task_plane.y_axis'],
                                      self.server['task_plane.scale'])
        self.demo = builtin_demo(self.skill)
        sim = {}
        if self.layout == 'skill' and self.skill in LAYOUTS:
            goal, obstacles = LAYOUTS[self.skill]
            sim.update(goal_position=[float(v) for v in goal],
                       obstacle_positions=[float(v) for v in obstacles])
        if self.skill == 'stir':
            self.explicit_goal = self.bottle_mouth + self.demo.positions[-1]
            sim['initial_joint_positions'] = stir_start_joints(self).tolist()
        server = {'skill': self.skill}
        if self.skill in DURATIONS:
            server['duration'] = self.server['duration'] = DURATIONS[self.skill]
        self.overrides = {'ur10_sim': sim, 'perception': {}, 'controller': {},
                          'dmp_server': server}
        for node in SIM_TIME_NODES:
            self.overrides[node]['use_sim_time'] = True
        for node, values in self.parameters.items():
            if node not in self.overrides:
                raise DemoError(f'no node {node!r} (nodes: {", ".join(NODES)})')
            self.overrides[node].update(values)
        if 'control_rate' in self.parameters.get('controller', {}):
            self.controller['control_rate'] = self.parameters['controller']['control_rate']

    @property
    def planar(self):
        """Whether the skill is a 2D one (drawn in the task plane)."""
        return self.demo.positions.shape[1] == 2

    @property
    def bottle_mouth(self):
        """Centre of the bottle's mouth (base_link)."""
        return np.array([*self.scene['bottle.position'], self.scene['bottle.height']], float)

    @property
    def tool_rotation(self):
        """Tool orientation of every planned pose (dmp_server's ``tool_orientation``)."""
        return quaternion_to_matrix(self.server['tool_orientation'])

    def param_files(self, node, directory):
        """Write ``node``'s overrides file into ``directory``; return its parameter files."""
        path = Path(directory) / f'{node}_overrides.yaml'
        path.write_text(yaml.safe_dump({node: {'ros__parameters': self.overrides[node]}}))
        return [self.config_dir / 'scene.yaml', self.config_dir / f'{node}.yaml', path]


def solve_joints(model, position, rotation, q0, iterations=200):
    """
    Return joints (6,) putting the tool tip at ``position`` with ``rotation`` (damped Newton).

    Raises DemoError when the pose cannot be reached within 0.01 mm from ``q0``.
    """
    q = np.array(q0, dtype=float)
    for _ in range(iterations):
        p, r = model.frame_pose(q)
        error = np.r_[position - p, pin.log3(rotation @ r.T)]
        if np.linalg.norm(error) < 1e-9:
            break
        jac = model.tool_jacobian(q)
        step = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), error)
        q += step * min(1.0, 0.3 / max(np.linalg.norm(step), 1e-12))
    if np.linalg.norm(error[:3]) > 1e-5 or np.any(q < model.lower) or np.any(q > model.upper):
        raise DemoError(f'cannot put the tool at {np.round(position, 3).tolist()}')
    return q


def stir_start(scene):
    """Return where the stirrer starts (base_link): see :data:`STIR_START_TURN_DEG`."""
    a = math.radians(STIR_START_TURN_DEG)
    turn = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                     [0.0, 0.0, 1.0]])
    offset = scene.demo.positions[0] - scene.demo.positions[-1]
    return scene.explicit_goal + STIR_START_SCALE * turn @ offset


def stir_start_joints(scene):
    """Return the simulation's initial joints for stir: the stirrer at :func:`stir_start`."""
    model = UR10Model(tool_offset=scene.scene['tool_offset'])
    q0 = np.array(scene.scene['initial_joint_positions'], dtype=float)
    target = stir_start(scene)
    # Turn the base towards the bottle first, so Newton starts from the same elbow-up posture.
    p0 = model.tool_position(q0)
    q0[0] += math.atan2(target[1], target[0]) - math.atan2(p0[1], p0[0])
    return solve_joints(model, target, scene.tool_rotation, q0)


# ------------------------------------------------------------------------------------ nodes


class NodeProcesses:
    """The four nodes, each in its own process, output in ``<log_dir>/<node>.log``."""

    def __init__(self, scene, log_dir, env, command=module_command):
        """Start them: ``command(node, param_files)`` returns the argv of one node."""
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        env = dict(env, PYTHONUNBUFFERED='1', RCUTILS_COLORIZED_OUTPUT='0')
        env.setdefault('MUJOCO_GL', 'egl')
        self.processes = {}
        self._logs = {}
        for node in NODES:
            argv = command(node, scene.param_files(node, self.log_dir))
            self._logs[node] = open(self.log_dir / f'{node}.log', 'w')
            self.processes[node] = subprocess.Popen(argv, env=env, stdout=self._logs[node],
                                                    stderr=subprocess.STDOUT)

    def log(self, node):
        """Return the output of ``node`` so far."""
        return (self.log_dir / f'{node}.log').read_text(errors='replace')

    def check_alive(self):
        """Raise DemoError naming a node that has exited, with the end of its log."""
        for node, process in self.processes.items():
            if process.poll() is not None:
                tail = '\n'.join(self.log(node).splitlines()[-15:])
                raise DemoError(f'{node} exited with code {process.returncode}:\n{tail}')

    def last_error(self, node):
        """Return the last ERROR line of ``node``'s log, or ''."""
        lines = [line for line in self.log(node).splitlines() if '[ERROR]' in line]
        return lines[-1] if lines else ''

    def stop(self, timeout=10.0, interrupted=False):
        """
        SIGINT (Ctrl-C) to every node, the simulation last; kill stragglers; return exit codes.

        ``interrupted``: the user pressed Ctrl-C, which the nodes (same process group) got too:
        give them time to finish before a second SIGINT could cut their own clean-up short.
        """
        if interrupted:
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and any(
                    p.poll() is None for p in self.processes.values()):
                time.sleep(0.05)
        codes = {}
        for group in (NODES[1:], NODES[:1]):
            for node in group:
                if self.processes[node].poll() is None:
                    self.processes[node].send_signal(signal.SIGINT)
            for node in group:
                process = self.processes[node]
                try:
                    process.wait(timeout=timeout)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
                codes[node] = process.returncode
        for f in self._logs.values():
            f.close()
        return codes


# ------------------------------------------------------------------------------- recording


class Recorder(BackgroundNode):
    """
    rclpy in this process (own context, spinning in a thread): records what the demo measures.

    Times are simulated (ns), from message stamps; unstamped messages (commands, status) get
    the stamp of the latest pen-tip sample received before them. The streams at the control
    rate (pen tip, commands, reference) are kept as the serialized bytes their raw
    subscriptions hand over and decoded in :meth:`arrays`, after
    the run: deserializing each on arrival cost this process a tenth of a core.
    """

    def __init__(self, domain_id, animation=True):
        """Create the node, subscriptions and clients; start spinning."""
        super().__init__('etdmp_demo', domain_id)
        self.lock = threading.Lock()
        self.animation = animation
        self.sim_ns = 0
        self.tip = []                 # (stamp ns, serialized PointStamped)
        self.reference = []           # serialized PoseStamped
        self.commands = []            # (sim ns at receipt, monotonic s, serialized command)
        self.status = []              # (sim ns at receipt, text)
        self.goal_truth = self.obstacles_truth = None
        self.goal_seen = self.obstacles_seen = None
        self.goal_seen_stamp = 0
        self.camera_info = None
        self.frames = {}              # stamp ns -> [half-size rgb, half-size depth mm]
        self.snapshots = {}           # name -> [stamp ns, rgb, depth mm]
        self._candidates = {}         # name -> [stamp ns, rgb, None]: its depth still to come
        self._requests = {}           # name -> earliest stamp ns
        self._depth_wanted = {}       # stamp ns -> where the depth image goes
        self._recent_depth = {}       # stamp ns -> serialized depth image not yet wanted
        self._frame_count = 0
        self.keep_frames_after = None
        n = self.node
        n.create_subscription(PointStamped, '/ur10_sim/ground_truth/tool_tip', self._on_tip,
                              STREAM, raw=True)
        n.create_subscription(PointStamped, '/ur10_sim/ground_truth/goal', self._on_goal_truth,
                              10)
        n.create_subscription(PoseArray, '/ur10_sim/ground_truth/obstacles',
                              self._on_obstacles_truth, 10)
        n.create_subscription(PointStamped, '/etdmp/goal', self._on_goal_seen, 10)
        n.create_subscription(PoseArray, '/etdmp/obstacles', self._on_obstacles_seen, 10)
        n.create_subscription(Float64MultiArray, '/forward_velocity_controller/commands',
                              self._on_command, STREAM, raw=True)
        n.create_subscription(String, '/etdmp/controller/status', self._on_status, LATCHED)
        n.create_subscription(PoseStamped, '/etdmp/controller/reference', self._on_reference,
                              STREAM, raw=True)
        n.create_subscription(CameraInfo, '/camera/camera/color/camera_info',
                              self._on_camera_info, 10)
        n.create_subscription(Image, '/camera/camera/color/image_raw', self._on_color, IMAGES,
                              raw=True)
        n.create_subscription(Image, '/camera/camera/aligned_depth_to_color/image_raw',
                              self._on_depth, IMAGES, raw=True)
        self.generalize = n.create_client(GetPlan, '/generalize')
        self.server_parameters = n.create_client(SetParameters, '/dmp_server/set_parameters')
        self.start()

    # -- callbacks
    def _on_tip(self, raw):
        stamp = header_stamp_ns(raw)
        with self.lock:
            self.sim_ns = max(self.sim_ns, stamp)
            self.tip.append((stamp, raw))

    def _on_goal_truth(self, msg):
        self.goal_truth = point_to_numpy(msg.point)

    def _on_obstacles_truth(self, msg):
        self.obstacles_truth = pose_array_to_numpy(msg)

    def _on_goal_seen(self, msg):
        self.goal_seen = point_to_numpy(msg.point)
        self.goal_seen_stamp = stamp_to_ns(msg.header.stamp)

    def _on_obstacles_seen(self, msg):
        self.obstacles_seen = pose_array_to_numpy(msg)

    def _on_command(self, raw):
        with self.lock:
            self.commands.append((self.sim_ns, time.monotonic(), raw))

    def _on_status(self, msg):
        with self.lock:
            self.status.append((self.sim_ns, msg.data))

    def _on_reference(self, raw):
        with self.lock:
            self.reference.append(raw)

    def _on_camera_info(self, msg):
        if self.camera_info is None:
            self.camera_info = intrinsics_from_camera_info(msg)

    def _on_color(self, raw):
        # Deserializing a 0.9 MB image costs time: only the frames kept are parsed. The depth
        # image of the same stamp (published after the colour one) is kept with it.
        stamp = header_stamp_ns(raw)
        self._frame_count += 1
        with self.lock:
            wanted = [name for name, t in self._requests.items() if stamp >= t]
            keep = (self.animation and self.keep_frames_after is not None
                    and stamp >= self.keep_frames_after and self._frame_count % FRAME_EVERY == 0)
        if not (wanted or keep):
            return
        rgb = np.array(image_from_msg(deserialize_message(raw, Image)))
        with self.lock:
            targets = []
            for name in wanted:
                # A request is done when a frame's depth image has come too (else the next
                # frame is tried): the ink needs it to be hidden behind nearer things.
                self._candidates[name] = [stamp, rgb, None]
                targets.append((self._candidates[name], 1, name))
            if keep:
                self.frames[stamp] = [rgb[::2, ::2].copy(), None]
                targets.append((self.frames[stamp], 2, None))
            depth = self._recent_depth.pop(stamp, None)
            if depth is None:
                self._depth_wanted[stamp] = targets
        if depth is not None:
            self._fill_depth(targets, depth)

    def _on_depth(self, raw):
        stamp = header_stamp_ns(raw)
        with self.lock:
            targets = self._depth_wanted.pop(stamp, None)
            if targets is None:     # the colour image may still come: keep a few (references)
                self._recent_depth[stamp] = raw
                while len(self._recent_depth) > 4:
                    self._recent_depth.pop(next(iter(self._recent_depth)))
                return
        self._fill_depth(targets, raw)

    def _fill_depth(self, targets, raw):
        depth = np.array(image_from_msg(deserialize_message(raw, Image)))
        with self.lock:
            for target, step, name in targets:
                target[-1] = depth[::step, ::step].copy()
                if name is not None and self._requests.pop(name, None) is not None:
                    self.snapshots[name] = target

    # -- requests
    def snapshot(self, name):
        """Return the frame [stamp ns, rgb, depth] kept as ``name`` (depth None if missing)."""
        with self.lock:
            return self.snapshots.get(name) or self._candidates.get(name)

    def request_snapshot(self, name, not_before_ns):
        """Keep the first camera frame stamped at or after ``not_before_ns`` as ``name``."""
        with self.lock:
            self._requests[name] = int(not_before_ns)

    def state(self, since=0):
        """Return the status messages received after the first ``since`` ones."""
        with self.lock:
            return list(self.status[since:])

    def _wait(self, future, timeout, what):
        deadline = time.monotonic() + timeout
        while not future.done():
            if time.monotonic() > deadline:
                raise DemoError(f'no answer from {what} within {timeout:g} s')
            time.sleep(0.005)
        return future.result()

    def set_server_parameters(self, timeout=10.0, **values):
        """Set dmp_server parameters (as ``ros2 param set``); raise DemoError if refused."""
        if not self.server_parameters.wait_for_service(timeout_sec=timeout):
            raise DemoError('/dmp_server/set_parameters is not available')
        request = SetParameters.Request(
            parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
        result = self._wait(self.server_parameters.call_async(request), timeout,
                            '/dmp_server/set_parameters')
        for name, r in zip(values, result.results):
            if not r.successful:
                raise DemoError(f'dmp_server refused {name} = {values[name]!r}: {r.reason}')

    def call_generalize(self, goal=None, timeout=30.0):
        """
        Call /generalize from the tool's current position (empty frame id) to the perceived goal.

        ``goal``: an explicit base_link goal instead. Return (header stamp ns, t, positions,
        quaternions); positions is empty when the server refused the request.
        """
        request = GetPlan.Request()
        if goal is not None:
            request.goal.header.frame_id = 'base_link'
            p = request.goal.pose.position
            p.x, p.y, p.z = (float(v) for v in goal)
        response = self._wait(self.generalize.call_async(request), timeout, '/generalize')
        t, positions, quaternions = path_to_numpy(response.plan)
        return stamp_to_ns(response.plan.header.stamp), t, positions, quaternions

    def latest_tip(self):
        """Return the latest pen-tip position received (3,)."""
        with self.lock:
            raw = self.tip[-1][1]
        return point_to_numpy(deserialize_message(raw, PointStamped).point)

    def arrays(self):
        """Return the recorded streams as numpy arrays, decoding the serialized ones."""
        with self.lock:
            tip, reference = list(self.tip), list(self.reference)
            commands = list(self.commands)

        tip = _points([raw for _, raw in tip], PointStamped)
        reference = _points(reference, PoseStamped)
        qd = np.array([deserialize_message(raw, Float64MultiArray).data for _, _, raw in commands],
                      dtype=float).reshape(-1, 6)
        return {'tip': tip[np.argsort(tip[:, 0], kind='stable')],
                'reference': reference[np.argsort(reference[:, 0], kind='stable')],
                'command_time': np.array([c[0] for c in commands], dtype=float),
                'command_wall_time': np.array([c[1] for c in commands], dtype=float),
                'commands': qd}


def _points(messages, msg_type):
    """Return (n, 4) stamps (ns) and positions of serialized PointStamped or PoseStamped."""
    out = np.empty((len(messages), 4))
    for i, raw in enumerate(messages):
        msg = deserialize_message(raw, msg_type)
        p = msg.point if msg_type is PointStamped else msg.pose.position
        out[i] = stamp_to_ns(msg.header.stamp), p.x, p.y, p.z
    return out


# ---------------------------------------------------------------------------------- metrics


def cylinder_gap(points, obstacles, radius):
    """
    Return the distance (n,) from points to the nearest upright cylinder's surface.

    Each obstacle point (m, 3) is the centre of a cylinder's top face; the cylinder of
    ``radius`` stands on the table (z = 0) up to that point. Negative inside a cylinder.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    obstacles = np.asarray(obstacles, dtype=float).reshape(-1, 3)
    if not len(obstacles):
        return np.full(len(points), np.inf)
    radial = np.linalg.norm(points[:, None, :2] - obstacles[None, :, :2], axis=2) - radius
    above = points[:, None, 2] - obstacles[None, :, 2]
    outside = np.where(above > 0.0, np.hypot(np.maximum(radial, 0.0), above), radial)
    inside = np.where(above > 0.0, above, np.maximum(radial, above))
    gap = np.where((radial > 0.0) | (above > 0.0), outside, inside)
    return gap.min(axis=1)


def fit_tracking_start(reference, plan_t, plan_x, rough_s, window=0.3):
    """
    Return the simulated time (s) at which the controller's reference started the plan.

    ``reference``: (n, 4) stamps (ns) and positions; the reference is ``plan(t - t0)`` while
    tracking. Searched around ``rough_s`` (±``window`` s) by least squares on a 0.1 ms grid.
    """
    s = reference[:, 0] * 1e-9
    best = (math.inf, rough_s)
    for step, half in ((1e-3, window), (1e-4, 2e-3)):
        for t0 in best[1] + np.arange(-half, half + step / 2, step):
            inside = (s >= t0 + 0.05) & (s <= t0 + plan_t[-1] - 0.05)
            if inside.sum() < 10:
                continue
            tau = s[inside] - t0
            model = np.stack([np.interp(tau, plan_t, plan_x[:, i]) for i in range(3)], axis=1)
            cost = float(np.mean(np.sum((model - reference[inside, 1:]) ** 2, axis=1)))
            if cost < best[0]:
                best = (cost, float(t0))
    if not math.isfinite(best[0]):
        raise DemoError('the controller published no reference while tracking the plan')
    return best[1]


def _nrmse_over_tau(points, tau, t, scene):
    keep = t <= tau + 1e-9
    x = points[keep]
    if scene.planar:
        x = scene.plane.to_plane(x)
    return float(nrmse(x, scene.demo.positions))


@dataclass
class Run:
    """Everything the demo measured in one run (inputs of :func:`compute_metrics`)."""

    scene: Scene
    method: str
    start: np.ndarray                 # tool position when the plans were requested
    goal: np.ndarray                  # the goal as requested (perceived or explicit)
    plan: tuple                       # (t, positions, quaternions) executed
    other: tuple                      # (method, t, positions) or (method, None, reason)
    rec: dict                         # Recorder.arrays()
    status: list                      # (sim ns, text) after the call
    call_ns: int
    plan_stamp_ns: int
    end_ns: int
    goal_truth: np.ndarray
    goal_seen: np.ndarray
    obstacles_truth: np.ndarray
    obstacles_seen: np.ndarray
    wall_time: float = 0.0


def compute_metrics(run):
    """Return the metrics dict of a run (see the module docstring for the definitions)."""
    scene, rec = run.scene, run.rec
    plan_t, plan_x, _ = run.plan
    tau = float(scene.server['duration']) or float(scene.demo.duration)
    radius = float(scene.scene['obstacle.radius'])
    tip_t = rec['tip'][:, 0] * 1e-9
    tip_x = rec['tip'][:, 1:]
    moving = tip_t >= run.call_ns * 1e-9
    tracking = [ns for ns, text in run.status if text.split(':')[0] == 'tracking']
    rough = tracking[0] * 1e-9 if tracking else run.call_ns * 1e-9
    t0 = fit_tracking_start(rec['reference'], plan_t, plan_x, rough)
    span = tip_t - t0
    in_plan = (span >= -1e-6) & (span <= plan_t[-1] + 1e-6)
    trace = tip_x[moving & (tip_t <= run.end_ns * 1e-9 + 1e-9)]
    # Tracking error: true tip vs the controller's reference at the same stamps.
    ref = rec['reference']
    ref_by_stamp = {int(s): p for s, p in zip(ref[:, 0], ref[:, 1:])}
    pairs = [(x, ref_by_stamp[int(s)]) for s, x in zip(rec['tip'][:, 0], tip_x)
             if int(s) in ref_by_stamp and 0.0 <= s * 1e-9 - t0 <= plan_t[-1]]
    errors = np.array([np.linalg.norm(a - b) for a, b in pairs]) if pairs else np.full(1, np.nan)
    # Goal: the true marker projected onto the task plane (2D); the requested goal (3D).
    if scene.planar:
        goal = scene.plane.from_plane(scene.plane.to_plane(run.goal_truth))
    else:
        goal = run.goal
    final = trace[-1] if len(trace) else tip_x[-1]
    # Commands: ratios to the limits the controller applies.
    model = UR10Model(tool_offset=scene.scene['tool_offset'])
    v_lim = model.velocity_limits * float(scene.controller['velocity_scale'])
    a_lim = np.asarray(scene.controller['joint_acceleration_limits'], dtype=float)
    rate = float(scene.controller['control_rate'])
    qd = rec['commands']
    dqd = np.abs(np.diff(qd, axis=0)) * rate if len(qd) > 1 else np.zeros((1, 6))
    demo_rel = scene.demo.positions[0] - scene.demo.positions[-1]
    start_rel = run.start - run.goal
    if scene.planar:
        start_rel = scene.plane.to_plane(run.start) - scene.plane.to_plane(run.goal)
        turn = math.atan2(demo_rel[0] * start_rel[1] - demo_rel[1] * start_rel[0],
                          demo_rel @ start_rel)
    else:
        turn = math.acos(np.clip(demo_rel @ start_rel / np.linalg.norm(demo_rel)
                                 / np.linalg.norm(start_rel), -1.0, 1.0))
    other_method, other_t, other_x = run.other
    dmp = (plan_t, plan_x) if run.method == 'dmp' else (
        (other_t, other_x) if other_method == 'dmp' and other_t is not None else None)
    metrics = {
        'skill': scene.skill,
        'method': run.method,
        'nrmse_plan': _nrmse_over_tau(plan_x, tau, plan_t, scene),
        'nrmse_trace': _nrmse_over_tau(tip_x[in_plan], tau, span[in_plan], scene),
        'nrmse_dmp_baseline': (_nrmse_over_tau(dmp[1], tau, dmp[0], scene)
                               if dmp is not None else None),
        'tracking_rms_mm': float(np.sqrt(np.mean(errors ** 2)) * 1e3),
        'tracking_max_mm': float(np.max(errors) * 1e3),
        'min_clearance_mm': float((cylinder_gap(trace, run.obstacles_truth, radius).min()
                                   - PEN_TIP_RADIUS) * 1e3) if len(trace) else None,
        'goal_error_mm': float(np.linalg.norm(final - goal) * 1e3),
        'duration_s': float((run.end_ns - run.call_ns) * 1e-9),
        # More detail.
        'plan_duration_s': float(plan_t[-1]),
        'tau_s': tau,
        'approach_duration_s': float(t0 - run.call_ns * 1e-9),
        'min_clearance_plan_mm': float((cylinder_gap(plan_x, run.obstacles_truth, radius).min()
                                        - PEN_TIP_RADIUS) * 1e3),
        'min_clearance_dmp_baseline_mm': (
            float((cylinder_gap(dmp[1], run.obstacles_truth, radius).min() - PEN_TIP_RADIUS)
                  * 1e3) if dmp is not None else None),
        'goal_error_vs_plan_end_mm': float(np.linalg.norm(final - plan_x[-1]) * 1e3),
        'start': run.start.tolist(),
        'goal': run.goal.tolist(),
        'plan_end': plan_x[-1].tolist(),
        'tool_at_call': tip_x[max(int(np.searchsorted(tip_t, run.call_ns * 1e-9, 'right')) - 1,
                              0)].tolist(),
        'perceived_goal': None if run.goal_seen is None else run.goal_seen.tolist(),
        'true_goal_marker': None if run.goal_truth is None else run.goal_truth.tolist(),
        'goal_source': 'perceived marker' if scene.explicit_goal is None else 'explicit',
        'start_quadrant': quadrant(start_rel[:2]),
        'demo_quadrant': quadrant(demo_rel[:2]),
        'start_turn_deg': math.degrees(turn),
        'perceived_goal_error_mm': (float(np.linalg.norm(run.goal_seen - run.goal_truth) * 1e3)
                                    if run.goal_seen is not None else None),
        'perceived_obstacle_errors_mm': _matched_errors(run.obstacles_seen,
                                                        run.obstacles_truth),
        'obstacles': np.asarray(run.obstacles_truth).tolist(),
        'commands_received': int(len(qd)),
        'commands_nonzero': int(np.count_nonzero(np.any(qd != 0.0, axis=1))) if len(qd) else 0,
        'max_joint_velocity_ratio': float(np.max(np.abs(qd) / v_lim)) if len(qd) else 0.0,
        'max_joint_acceleration_ratio': float(np.max(dqd / a_lim)),
        'max_joint_velocity_rad_s': np.max(np.abs(qd), axis=0).tolist() if len(qd) else [],
        'joint_velocity_limits_rad_s': v_lim.tolist(),
        'joint_acceleration_limits_rad_s2': a_lim.tolist(),
        'plan_stamp_minus_sim_time_s': float((run.plan_stamp_ns - run.call_ns) * 1e-9),
        'controller_status': [text for _, text in run.status],
        'wall_time_s': float(run.wall_time),
        'definitions': DEFINITIONS,
    }
    if not scene.planar:
        # Stirring: how close the pen tip came to the bottle's wall while inside it.
        mouth, r_b = scene.bottle_mouth, float(scene.scene['bottle.radius'])
        for key, points in (('bottle_wall_clearance_mm', trace),
                            ('bottle_wall_clearance_plan_mm', plan_x)):
            inside = points[points[:, 2] < mouth[2]]
            gap = r_b - np.linalg.norm(inside[:, :2] - mouth[:2], axis=1) - PEN_TIP_RADIUS
            metrics[key] = float(gap.min() * 1e3) if len(gap) else None
    if other_method != 'dmp' or other_t is None:
        metrics[f'nrmse_{other_method}_plan'] = (
            _nrmse_over_tau(other_x, tau, other_t, scene) if other_t is not None else None)
    if other_t is None:
        metrics[f'{other_method}_error'] = other_x
    return metrics, {'t0': t0, 'tau': tau, 'trace': trace, 'goal': goal}


def _matched_errors(seen, truth):
    if seen is None or truth is None or not len(truth):
        return []
    seen = np.asarray(seen).reshape(-1, 3)
    if not len(seen):
        return [None] * len(truth)
    return [float(np.min(np.linalg.norm(seen - p, axis=1)) * 1e3) for p in truth]


# --------------------------------------------------------------------------------- pictures


def _fmt(value):
    """Format an nRMSE: three decimals, or two significant digits when it is that small."""
    return 'n/a' if value is None else (f'{value:.3f}' if value >= 0.01 else f'{value:.2g}')


def plot_run(path, run, metrics, extra):
    """Draw the top view (2D skills) or top and side views (stir) of a run into ``path``."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, Rectangle

    scene, plane = run.scene, run.scene.plane
    radius = float(scene.scene['obstacle.radius'])
    plan_t, plan_x, _ = run.plan
    placed = place_demo(learn(scene.demo), run.start, run.goal,
                        plane if scene.planar else None)
    other_method, other_t, other_x = run.other
    label = {'etdmp': 'ET-DMP plan', 'dmp': 'DMP plan'}
    curves = [(placed, DEMO_STYLE, 'demonstration, turned and scaled into place')]
    executed = [(plan_x, dict(METHOD_STYLE[run.method], linewidth=3.5, alpha=0.5),
                 f'{label[run.method]} (executed), nRMSE {_fmt(metrics["nrmse_plan"])}'),
                (extra['trace'], {'color': 'k', 'linewidth': 0.9},
                 f'pen tip, true (MuJoCo), nRMSE {_fmt(metrics["nrmse_trace"])}')]
    obstacles = np.asarray(run.obstacles_truth, dtype=float).reshape(-1, 3)
    # The view shows what was executed (a wild baseline may leave it).
    focus = [np.reshape(c[0], (-1, 3)) for c in curves + executed]
    if scene.planar:
        focus.append(obstacles)
    else:
        mouth, r_b = scene.bottle_mouth, float(scene.scene['bottle.radius'])
        focus.append(mouth + [[r_b, r_b, 0.0], [-r_b, -r_b, -mouth[2]]])
    focus = np.concatenate(focus)
    pad = 0.02 + (radius if scene.planar else 0.0)
    low, high = focus.min(axis=0) - pad, focus.max(axis=0) + pad
    if other_t is not None:
        value = (metrics['nrmse_dmp_baseline'] if other_method == 'dmp'
                 else metrics.get(f'nrmse_{other_method}_plan'))
        out_of_view = np.any((other_x[:, :2] < low[:2]) | (other_x[:, :2] > high[:2]))
        curves.append((other_x, dict(METHOD_STYLE[other_method], linewidth=1.6),
                       f'{label[other_method]} (not executed), nRMSE {_fmt(value)}'
                       + (', leaves the view' if out_of_view else '')))
    curves += executed
    views = [('top', 'top view (robot base at the top)')]
    if not scene.planar:
        views.append(('side', 'side view (as the camera sees it)'))
    # Size the figure to the data, so that equal axes leave no empty band.
    width = (high - low) @ plane.y_axis
    heights = [abs((high - low) @ plane.x_axis)] + ([high[2] - low[2]] if not scene.planar
                                                    else [])
    panel = 6.0 if scene.planar else 5.0
    fig = Figure(figsize=(panel * len(views) + 0.8,
                          min(max(panel * max(heights) / abs(width), 3.0), 9.0) + 2.2),
                 layout='constrained')
    for i, (view, name) in enumerate(views):
        ax = fig.add_subplot(1, len(views), i + 1)

        def xy(points, view=view):
            points = np.asarray(points, dtype=float).reshape(-1, 3)
            if view == 'top':
                return points @ plane.y_axis, points @ plane.x_axis
            return points @ plane.y_axis, points[:, 2]

        if not scene.planar:
            (h,), (v,) = xy(mouth)
            if view == 'top':
                ax.add_patch(Circle((h, v), r_b, fill=False, edgecolor='tab:blue',
                                    linewidth=1.5, label='bottle'))
            else:
                ax.add_patch(Rectangle((h - r_b, 0.0), 2 * r_b, mouth[2], fill=False,
                                       edgecolor='tab:blue', linewidth=1.5, label='bottle'))
                ax.axhline(0.0, color='0.6', linewidth=1.0)
        nearby = obstacles[np.all((obstacles[:, :2] > low[:2] - radius)
                                  & (obstacles[:, :2] < high[:2] + radius), axis=1)]
        for j, o in enumerate(nearby):
            (h,), (v,) = xy(o)
            kind = {'color': 'tab:red', 'alpha': 0.45, 'label': 'obstacle' if j == 0 else None}
            if view == 'top':
                ax.add_patch(Circle((h, v), radius, **kind))
                # Where the pen tip's centre would touch the cylinder.
                ax.add_patch(Circle((h, v), radius + PEN_TIP_RADIUS, fill=False,
                                    edgecolor='tab:red', linestyle=':', linewidth=0.8))
            else:
                ax.add_patch(Rectangle((h - radius, 0.0), 2 * radius, o[2], **kind))
        for points, style, text in curves:
            ax.plot(*xy(points), label=text, **style)
        ax.plot(*xy(run.start), marker='*', markersize=14, color='gold', markeredgecolor='k',
                linestyle='none', label='start (tool)', zorder=6)
        ax.plot(*xy(extra['goal']), marker='o', markersize=12, markerfacecolor='none',
                markeredgecolor='k', markeredgewidth=1.8, linestyle='none',
                label='goal (true marker)' if scene.planar else 'goal (requested)', zorder=6)
        if scene.planar:
            ax.plot(*xy(run.goal), marker='x', markersize=8, color='tab:green',
                    linestyle='none', label='goal as perceived', zorder=7)
        h, v = xy(focus)
        ax.set_xlim(h.min() - pad, h.max() + pad)
        ax.set_ylim(v.min() - pad, v.max() + pad)
        ax.set_aspect('equal', adjustable='box')
        ax.grid(True, alpha=0.3)
        standard = np.allclose(plane.x_axis, [1, 0, 0]) and np.allclose(plane.y_axis, [0, 1, 0])
        ax.set_xlabel('y (m)' if standard else 'along task_plane.y_axis (m)')
        if view == 'top':
            ax.set_ylabel('x (m)' if standard else 'along task_plane.x_axis (m)')
            ax.invert_yaxis()
        else:
            ax.set_ylabel('z (m)')
        ax.set_title(name, fontsize=10)
    handles = {}
    for ax in fig.axes:
        for handle, text in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(text, handle)
    fig.legend(handles.values(), handles.keys(), loc='outside lower center', ncol=2,
               fontsize=8, frameon=False)
    fig.suptitle(
        f'{scene.skill}: {METHOD_LABELS[run.method]} executed by the simulated UR10\n'
        f'start direction {metrics["start_turn_deg"]:+.0f} deg from the demonstration\'s '
        f'(quadrant {metrics["start_quadrant"]} of the goal; demonstration: '
        f'{metrics["demo_quadrant"]})\ntracking error RMS {metrics["tracking_rms_mm"]:.2f} mm, '
        f'goal error {metrics["goal_error_mm"]:.1f} mm, min obstacle clearance '
        f'{metrics["min_clearance_mm"]:.1f} mm', fontsize=10)
    fig.savefig(path, dpi=110, bbox_inches='tight')


def draw_ink(frame, depth_mm, points, camera, intrinsics, scale, thickness=1):
    """
    Draw the pen-tip trace ``points`` (n, 3, base_link) onto ``frame`` (in place) as ink.

    The simulation leaves no ink: the trace is projected with the camera model (``scale``: the
    frame's size relative to the camera's) and drawn where the camera sees it, i.e. where the
    point is not farther than the depth image (plus 5 mm) or the depth has no data.
    """
    import cv2

    if len(points) < 2:
        return
    in_camera = camera.from_base(points)
    uv = intrinsics.project(in_camera) * scale
    pixels = np.round(uv).astype(np.int64)
    h, w = frame.shape[:2]
    inside = (pixels[:, 0] >= 0) & (pixels[:, 0] < w) & (pixels[:, 1] >= 0) & (pixels[:, 1] < h)
    visible = inside.copy()
    if depth_mm is not None:
        seen = depth_mm[pixels[inside, 1], pixels[inside, 0]].astype(float)
        visible[inside] = (seen == 0) | (in_camera[inside, 2] * 1000.0 <= seen + 5.0)
    # Runs of consecutive visible points become polylines (sub-pixel precision: shift 2).
    edges = np.flatnonzero(np.diff(np.r_[0, visible.astype(int), 0]))
    runs = [np.round(uv[a:b] * 4).astype(np.int32).reshape(-1, 1, 2)
            for a, b in zip(edges[::2], edges[1::2]) if b - a >= 2]
    if runs:
        cv2.polylines(frame, runs, False, INK_COLOR, thickness, cv2.LINE_AA, shift=2)


def _caption(frame, text, scale):
    import cv2

    cv2.putText(frame, text, (int(8 * scale), int(20 * scale)), cv2.FONT_HERSHEY_SIMPLEX,
                0.45 * scale, (0, 0, 0), 1 if scale < 1.5 else 2, cv2.LINE_AA)


def write_pictures(out, run, rec, snapshots, frames, intrinsics, animation=True):
    """
    Write the camera frames (PNG) and the animation (GIF), the pen's trace drawn in as ink.

    Returns the paths written. Frames are captioned with the simulated time since the
    ``/generalize`` call and the controller's status.
    """
    from PIL import Image as PilImage

    camera = CameraPose(tuple(run.scene.scene['camera.position']),
                        tuple(run.scene.scene['camera.orientation']))
    tip = rec['tip'][rec['tip'][:, 0] >= run.call_ns]

    def render(stamp, rgb, depth, scale):
        frame = rgb.copy()
        draw_ink(frame, depth, tip[tip[:, 0] <= stamp, 1:], camera, intrinsics, scale,
                 thickness=1 if scale < 1 else 2)
        state = [text.split(':')[0] for ns, text in run.status if ns <= stamp]
        _caption(frame, f't = {(stamp - run.call_ns) * 1e-9:+.2f} s  '
                        f'{state[-1] if state else "perceiving, planning"}', scale * 2)
        return frame

    written = []
    for name in ('start', 'middle', 'end'):
        if snapshots.get(name) is not None:
            stamp, rgb, depth = snapshots[name]
            path = out / f'camera_{name}.png'
            PilImage.fromarray(render(stamp, rgb, depth, 1.0)).save(path)
            written.append(path)
    if not (animation and frames):
        return written
    stamps = sorted(frames)
    images = [PilImage.fromarray(render(s, *frames[s], 0.5)) for s in stamps]
    # Real-time playback: each frame lasts until the next one's stamp.
    durations = [int(round(d * 1e-6)) for d in np.diff(stamps)] + [1500]
    path = out / 'animation.gif'
    images[0].save(path, save_all=True, append_images=images[1:], duration=durations, loop=0,
                   optimize=True)
    written.append(path)
    return written


# ---------------------------------------------------------------------------- system budget


#: The controller's log line at the end of a tracked path (etdmp_ros.nodes.controller).
_TRACKED = re.compile(r'path tracked: error RMS ([\d.]+) mm, max ([\d.]+) mm; (\d+) control '
                      r'steps in (\d+) periods \((\d+) joint states received, largest gap '
                      r'([\d.]+) ms(?: at t = ([\d.]+) s)?\)')
#: The camera process's log line when it stops (etdmp_ros.nodes._sim_camera).
_CAMERA_STOPPED = re.compile(r'camera stopped: (\d+) frames published, (\d+) skipped')
#: ur10_sim's warning about a stalled simulation loop.
_STALL = re.compile(r'simulation loop stalled: (\d+) ms between two ticks at t = ([\d.]+) s')
#: ur10_sim's log line when it stops.
_SIM_STOPPED = re.compile(r'(\d+) more than \d+ periods after the previous one, largest '
                          r'wall-clock gap between two ([\d.]+) ms; camera frames published '
                          r'(\d+), dropped (\d+)')


def system_figures(monitor, rec, call_ns, end_ns, nodes):
    """
    Return what the closed loop cost and how well it kept time from the call to the end.

    CPU per process (CPU-s per simulated s, from /proc), the real-time factor, the moving
    commands per simulated second and the wall-clock period between commands as this process
    received them, and what the controller and the simulation logged about their loops.
    """
    figures = {}
    window = monitor.window(call_ns * 1e-9, end_ns * 1e-9) if end_ns else None
    if window is not None:
        figures['cpu_cores'] = window['cpu']
        figures['cpu_cores_total'] = window['total']
        figures['cpu_cores_nodes_but_sim'] = sum(v for k, v in window['cpu'].items()
                                                 if k != 'ur10_sim')
        figures['real_time_factor'] = window['real_time_factor']
        figures['min_real_time_factor_1s'] = window['min_real_time_factor_1s']
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
    found = _TRACKED.findall(nodes.log('controller'))
    if found:
        rms, peak, steps, periods_, received, gap, gap_at = found[-1]
        figures['controller'] = {'tracking_rms_mm': float(rms), 'tracking_max_mm': float(peak),
                                 'steps': int(steps), 'periods': int(periods_),
                                 'joint_states_received': int(received),
                                 'largest_joint_state_gap_ms': float(gap),
                                 'largest_joint_state_gap_at_s': float(gap_at or 'nan')}
    stalls = _STALL.findall(nodes.log('ur10_sim'))
    figures['simulation_stalls'] = [(float(t), float(ms)) for ms, t in stalls
                                    if call_ns * 1e-9 <= float(t) <= (end_ns or 0) * 1e-9]
    found = _SIM_STOPPED.findall(nodes.log('ur10_sim'))
    if found:
        late, gap, frames, dropped = found[-1]
        figures['simulation'] = {'late_ticks': int(late), 'largest_tick_gap_ms': float(gap),
                                 'frames': int(frames), 'frames_dropped': int(dropped)}
        camera = _CAMERA_STOPPED.findall(nodes.log('ur10_sim'))
        if camera:   # snapshots the camera process skipped because it was still rendering
            figures['simulation']['frames_rendered'] = int(camera[-1][0])
            figures['simulation']['frames_dropped'] += int(camera[-1][1])
    return figures


# ------------------------------------------------------------------------------------- run


@dataclass
class Options:
    """How to run the demo (the command line's options)."""

    skill: str = 'G'
    method: str = 'etdmp'
    out: Path = Path('out/demo')
    animation: bool = True
    layout: str = 'skill'
    timeout: float = 60.0
    config_dir: Path = None
    command: object = module_command
    quiet: bool = False
    #: Extra node parameters, {node: {name: value}}, after the scene's (e.g. control_rate).
    parameters: dict = field(default_factory=dict)


class _Progress:

    def __init__(self, quiet):
        self.quiet = quiet
        self.start = time.monotonic()

    def __call__(self, text):
        if not self.quiet:
            print(f'[{time.monotonic() - self.start:6.1f} s] {text}', flush=True)


def _wait_until(predicate, timeout, what, nodes):
    deadline = time.monotonic() + timeout
    while not predicate():
        nodes.check_alive()
        if time.monotonic() > deadline:
            raise DemoError(f'timed out after {timeout:g} s waiting for {what}')
        time.sleep(0.05)


def _generalize(recorder, nodes, goal, attempts=20):
    """
    Call /generalize; return (stamp, t, positions, quaternions, reason if refused).

    Right after start-up dmp_server may not have heard the tool or the goal yet (its
    subscriptions match after its service is offered): such a refusal is retried.
    """
    for _ in range(attempts):
        stamp, t, positions, quaternions = recorder.call_generalize(goal)
        if len(positions):
            return stamp, t, positions, quaternions, ''
        time.sleep(0.2)     # the node's ERROR line reaches its log file
        reason = nodes.last_error('dmp_server')
        if reason and ' yet' not in reason:
            break
    return stamp, t, positions, quaternions, reason


def run_demo(options, env):
    """
    Run the demo once; return (metrics, written files).

    ``env``: the environment of the node processes (see :func:`isolated_environment`); this
    process must already be on the same DDS domain settings (its ``os.environ``).
    """
    progress = _Progress(options.quiet)
    wall = time.monotonic()
    out = Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    config_dir = Path(options.config_dir or share_dir() / 'config')
    scene = Scene(config_dir, options.skill, options.layout, options.parameters)
    other = 'dmp' if options.method == 'etdmp' else 'etdmp'
    progress(f'starting ur10_sim, perception, dmp_server and controller (ROS_DOMAIN_ID '
             f'{env["ROS_DOMAIN_ID"]}, localhost only; logs in {out / "logs"})')
    recorder = Recorder(env['ROS_DOMAIN_ID'], animation=options.animation)
    nodes = NodeProcesses(scene, out / 'logs', env, options.command)
    monitor = CpuMonitor({**{n: p.pid for n, p in nodes.processes.items()},
                          'demo': os.getpid()},
                         lambda: recorder.sim_ns * 1e-9 if recorder.sim_ns else None).start()
    n_status = 0
    try:
        expected = len(np.asarray(scene.overrides['ur10_sim'].get(
            'obstacle_positions', scene.scene['obstacle_positions'])).reshape(-1, 3))
        _wait_until(lambda: len(recorder.tip) > 0 and recorder.goal_truth is not None
                    and recorder.obstacles_truth is not None, STARTUP_TIMEOUT,
                    'the simulation (/ur10_sim/ground_truth/*)', nodes)
        progress('simulation running; waiting for the camera to show the goal and obstacles')
        _wait_until(lambda: recorder.goal_seen is not None
                    and recorder.obstacles_seen is not None
                    and len(recorder.obstacles_seen) == expected, STARTUP_TIMEOUT,
                    f'perception to see the goal and {expected} obstacles', nodes)
        progress(f'perceived goal {np.round(recorder.goal_seen, 3).tolist()}, obstacles '
                 f'{np.round(recorder.obstacles_seen, 3).tolist()}')
        _wait_until(lambda: recorder.generalize.service_is_ready()
                    and any(t.split(':')[0] == 'idle' for _, t in recorder.state()),
                    STARTUP_TIMEOUT, 'dmp_server (/generalize) and the controller (idle)', nodes)
        recorder.keep_frames_after = recorder.sim_ns - int(0.5e9)
        goal_truth, goal_seen = recorder.goal_truth, recorder.goal_seen
        # perception stamps its output with the image's (simulated) stamp.
        goal_stamp_lag = (recorder.sim_ns - recorder.goal_seen_stamp) * 1e-9
        obstacles_truth, obstacles_seen = recorder.obstacles_truth, recorder.obstacles_seen
        # The comparison plan first, not executed: the plain DMP baseline (ET-DMP with --method
        # dmp), from the same start, to the same goal.
        recorder.set_server_parameters(method=other, execute=False)
        _, o_t, o_x, _, reason = _generalize(recorder, nodes, scene.explicit_goal)
        if len(o_x):
            progress(f'{METHOD_LABELS[other]} plan (not executed): {len(o_x)} poses over '
                     f'{o_t[-1]:.2f} s')
            other_plan = (other, o_t, o_x)
        else:
            progress(f'{METHOD_LABELS[other]} plan refused: {reason}')
            other_plan = (other, None, reason)
        recorder.set_server_parameters(method=options.method, execute=True)
        n_status = len(recorder.state())
        start = recorder.latest_tip()
        call_ns = recorder.sim_ns
        recorder.request_snapshot('start', call_ns)
        stamp, p_t, p_x, p_q, reason = _generalize(recorder, nodes, scene.explicit_goal)
        if not len(p_x):
            raise DemoError(f'/generalize returned no plan: {reason}')
        # The plan starts where dmp_server saw the tool (projected onto the task plane for 2D
        # skills) and ends at the goal it was given (the perceived one, projected).
        start = p_x[0]
        goal = p_x[-1] if scene.explicit_goal is None else scene.explicit_goal
        progress(f'{METHOD_LABELS[options.method]} plan: {len(p_x)} poses over {p_t[-1]:.2f} s,'
                 f' published on /etdmp/path; the controller executes it')
        deadline = time.monotonic() + p_t[-1] + options.timeout
        seen, end_ns, failure = 0, None, None
        while end_ns is None:
            nodes.check_alive()
            news = recorder.state(n_status)
            for ns, text in news[seen:]:
                word = text.split(':')[0]
                progress(f'controller: {text} (t = {(ns - call_ns) * 1e-9:.2f} s simulated)')
                if word == 'tracking':
                    recorder.request_snapshot('middle', ns + int(p_t[-1] * 0.5e9))
                if word in STATUS_FAILURES:
                    failure, end_ns = text, ns
                elif word == 'idle' and any(t.split(':')[0] in ('holding', 'tracking')
                                            for _, t in news):
                    end_ns = ns
            seen = len(news)
            if time.monotonic() > deadline:
                raise DemoError('timed out waiting for the controller to finish; status '
                                f'{[t for _, t in news]}')
            time.sleep(0.02)
        recorder.request_snapshot('end', end_ns + int(0.2e9))
        deadline = time.monotonic() + 5.0
        while 'end' not in recorder.snapshots and time.monotonic() < deadline:
            time.sleep(0.05)
        if recorder.snapshot('end') is None:
            raise DemoError('no camera frame arrived after the end of the motion')
    finally:
        monitor.stop()
        codes = nodes.stop(interrupted=sys.exc_info()[0] is KeyboardInterrupt)
        rec = recorder.arrays()
        status = recorder.state(n_status)
        recorder.close()
    progress(f'nodes stopped (exit codes {codes}); measuring and drawing')
    run = Run(scene, options.method, np.asarray(start), np.asarray(goal), (p_t, p_x, p_q),
              other_plan, rec, status, call_ns, stamp, end_ns, goal_truth, goal_seen,
              obstacles_truth, obstacles_seen)
    try:
        metrics, extra = compute_metrics(run)
    except DemoError as err:
        if failure:   # stopped before it tracked anything worth measuring: say why
            raise DemoError(f'the controller stopped: {failure} (nothing measured: {err}; '
                            f'logs in {out / "logs"})') from None
        raise
    metrics['node_exit_codes'] = codes
    metrics['perceived_goal_stamp_age_s'] = goal_stamp_lag
    metrics['controller_failure'] = failure
    metrics['system'] = system_figures(monitor, rec, call_ns, end_ns, nodes)
    # The controller's own tracking error (reference minus its forward kinematics), from the
    # summary it logs at the end of the path.
    metrics['controller_reported_tracking_max_mm'] = (
        metrics['system'].get('controller', {}).get('tracking_max_mm'))
    intrinsics = recorder.camera_info or CameraIntrinsics.from_fovy(640, 480, 42.5)
    written = [out / 'plot.png']
    plot_run(written[0], run, metrics, extra)
    snapshots = {name: recorder.snapshot(name) for name in ('start', 'middle', 'end')}
    written += write_pictures(out, run, rec, snapshots, recorder.frames, intrinsics,
                              options.animation)
    np.savez_compressed(out / 'recording.npz', tip=rec['tip'], reference=rec['reference'],
                        commands=rec['commands'], command_time=rec['command_time'],
                        plan_t=p_t, plan_x=p_x,
                        other_t=other_plan[1] if other_plan[1] is not None else np.zeros(0),
                        other_x=other_plan[2] if other_plan[1] is not None else np.zeros(0),
                        tracking_start=extra['t0'])
    metrics['wall_time_s'] = time.monotonic() - wall
    (out / 'metrics.json').write_text(json.dumps(metrics, indent=2) + '\n')
    written += [out / 'metrics.json', out / 'recording.npz']
    if failure:
        raise DemoError(f'the controller stopped: {failure} (files written to {out})')
    return metrics, written


def summary(metrics, written):
    """Return the short summary printed at the end."""
    m = metrics
    method = METHOD_LABELS[m['method']]
    other = 'dmp' if m['method'] == 'etdmp' else 'etdmp'
    value = m['nrmse_dmp_baseline'] if other == 'dmp' else m.get('nrmse_etdmp_plan')
    lines = [
        f'{m["skill"]} with {method}: the pen started in quadrant {m["start_quadrant"]} of the '
        f'goal (demonstration: {m["demo_quadrant"]}; start direction turned by '
        f'{m["start_turn_deg"]:+.0f} deg), goal: {m["goal_source"]}',
        f'  nRMSE vs the demonstration: {method} plan {_fmt(m["nrmse_plan"])}, executed pen '
        f'trace {_fmt(m["nrmse_trace"])}; {METHOD_LABELS[other]} plan (not executed) '
        + ('refused' if value is None else _fmt(value)),
        f'  tracking error RMS {m["tracking_rms_mm"]:.3f} mm, max {m["tracking_max_mm"]:.3f} mm;'
        f' goal error {m["goal_error_mm"]:.2f} mm; min obstacle clearance '
        f'{m["min_clearance_mm"]:.1f} mm',
        f'  commands: {m["commands_nonzero"]} moving; up to '
        f'{100 * m["max_joint_velocity_ratio"]:.0f} % of the velocity and '
        f'{100 * m["max_joint_acceleration_ratio"]:.0f} % of the acceleration limits',
        f'  motion {m["duration_s"]:.2f} s simulated (approach {m["approach_duration_s"]:.2f} s,'
        f' plan {m["plan_duration_s"]:.2f} s); demo took {m["wall_time_s"]:.0f} s',
    ]
    system = m.get('system', {})
    if 'cpu_cores' in system and 'moving_commands_per_s' in system:
        cpu = ', '.join(f'{name} {value:.2f}' for name, value in system['cpu_cores'].items())
        lines.append(f'  while moving: {system["moving_commands_per_s"]:.0f} commands/s, '
                     f'real-time factor {system["real_time_factor"]:.3f}, CPU '
                     f'{system["cpu_cores_total"]:.2f} cores ({cpu})')
    lines.append('files: ' + ', '.join(str(p) for p in written))
    return '\n'.join(lines)


def parse_args(argv=None):
    """Return the parsed command line."""
    parser = argparse.ArgumentParser(
        prog='python -m etdmp_ros.demo',
        description='Closed-loop demo: the four nodes as processes, the simulated UR10 writes '
                    'the skill generalized to the goal the camera sees, around the obstacles.')
    parser.add_argument('--skill', default='G', choices=SKILLS,
                        help='built-in skill (default G; stir is the 3D one)')
    parser.add_argument('--method', default='etdmp', choices=METHODS,
                        help='method executed (the other one is planned for comparison)')
    parser.add_argument('--out', default='out/demo', type=Path, help='output folder')
    parser.add_argument('--no-animation', dest='animation', action='store_false',
                        help='skip animation.gif (the camera PNGs are still written)')
    parser.add_argument('--layout', default='skill', choices=('skill', 'scene'),
                        help="goal and obstacles: the skill's own layout (default) or "
                             "config/scene.yaml's as they are (G's layout)")
    parser.add_argument('--timeout', default=60.0, type=float,
                        help='s allowed beyond the plan duration for the execution')
    parser.add_argument('--domain-id', default=None, type=int,
                        help='ROS_DOMAIN_ID of the demo (default: derived from the process id)')
    return parser.parse_args(argv)


def main(argv=None):
    """Run the demo from the command line; return the exit code."""
    args = parse_args(argv)
    env = isolated_environment(args.domain_id)
    os.environ.update(env)
    for name in ('ROS_LOCALHOST_ONLY', 'ROS_STATIC_PEERS'):
        os.environ.pop(name, None)
    options = Options(skill=args.skill, method=args.method, out=args.out,
                      animation=args.animation, layout=args.layout, timeout=args.timeout)
    try:
        metrics, written = run_demo(options, env)
    except DemoError as err:
        print(f'demo failed: {err}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130
    print(summary(metrics, written), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())

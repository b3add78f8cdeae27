"""
Recording a closed-loop run: a node in the caller's process that listens to the system.

:class:`Recorder` subscribes to the simulation's ground truth, perception's output, the
controller's commands, status and reference and the camera; it calls ``/generalize`` and sets
dmp_server's parameters as a user would (``ros2 service call``, ``ros2 param set``).
:meth:`Recorder.arrays` returns the streams as numpy arrays (the input of
:mod:`etdmp_ros.metrics`), :func:`save_recording` writes them with the plans to an ``.npz``.
"""

import threading
import time

from etdmp_ros.nodes.background import BackgroundNode
from etdmp_ros.ros_conversions import (header_stamp_ns, image_from_cdr,
                                       intrinsics_from_camera_info, path_to_numpy,
                                       point_to_numpy, pose_array_to_numpy, stamp_to_ns)
from geometry_msgs.msg import PointStamped, PoseArray, PoseStamped
from nav_msgs.srv import GetPlan
import numpy as np
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Float64MultiArray, String

#: Keep every n-th camera frame for the animation (30 Hz camera: 15 frames per second).
FRAME_EVERY = 2
LATCHED = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STREAM = QoSProfile(depth=1000)
# Reliable, as perception subscribes: a lost fragment is resent instead of the frame lost.
IMAGES = QoSProfile(depth=2)


class RecorderError(RuntimeError):
    """A service of the system did not answer or refused the request."""


class Recorder(BackgroundNode):
    """
    rclpy in this process (own context, spinning in a thread): records what the demo measures.

    Times are simulated (ns), from message stamps; unstamped messages (commands, status) get
    the stamp of the latest pen-tip sample received before them. The streams at the control
    rate (pen tip, commands, reference) are kept as the serialized bytes their raw
    subscriptions hand over and decoded in :meth:`arrays`, after
    the run: deserializing each on arrival cost this process a tenth of a core.

    Camera frames: :meth:`request_snapshot` keeps the first frame (colour and depth) at or
    after a stamp; with ``animation``, every :data:`FRAME_EVERY`-th frame after
    ``keep_frames_after`` is kept at half size in ``frames``.
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
        self._subscribe()
        self.generalize = self.node.create_client(GetPlan, '/generalize')
        self.server_parameters = self.node.create_client(SetParameters,
                                                         '/dmp_server/set_parameters')
        self.start()

    def _subscribe(self):
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
        # Decoding a 0.9 MB image costs time: only the frames kept are read. The depth
        # image of the same stamp (published after the colour one) is kept with it.
        stamp = header_stamp_ns(raw)
        self._frame_count += 1
        with self.lock:
            wanted = [name for name, t in self._requests.items() if stamp >= t]
            keep = (self.animation and self.keep_frames_after is not None
                    and stamp >= self.keep_frames_after and self._frame_count % FRAME_EVERY == 0)
        if not (wanted or keep):
            return
        rgb = np.array(image_from_cdr(raw))
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
        depth = np.array(image_from_cdr(raw))
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
                raise RecorderError(f'no answer from {what} within {timeout:g} s')
            time.sleep(0.005)
        return future.result()

    def set_server_parameters(self, timeout=10.0, **values):
        """Set dmp_server parameters (as ``ros2 param set``); raise RecorderError if refused."""
        if not self.server_parameters.wait_for_service(timeout_sec=timeout):
            raise RecorderError('/dmp_server/set_parameters is not available')
        request = SetParameters.Request(
            parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
        result = self._wait(self.server_parameters.call_async(request), timeout,
                            '/dmp_server/set_parameters')
        for name, r in zip(values, result.results):
            if not r.successful:
                raise RecorderError(f'dmp_server refused {name} = {values[name]!r}: {r.reason}')

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


def save_recording(path, rec, plan, other, tracking_start):
    """
    Write the recorded streams and the plans to ``path`` (``.npz``).

    ``rec``: :meth:`Recorder.arrays`; ``plan``: (t, positions, ...) executed; ``other``:
    (method, t, positions), t None when that plan was refused; ``tracking_start``: simulated s.
    """
    _, other_t, other_x = other
    refused = other_t is None
    np.savez_compressed(path, tip=rec['tip'], reference=rec['reference'],
                        commands=rec['commands'], command_time=rec['command_time'],
                        plan_t=plan[0], plan_x=plan[1],
                        other_t=np.zeros(0) if refused else other_t,
                        other_x=np.zeros(0) if refused else other_x,
                        tracking_start=tracking_start)

"""
perception: the goal marker and the obstacles from the RealSense-style camera.

Its place in the system: docs/design.md#nodes-and-interfaces.

``ros2 run etdmp_ros perception --ros-args --params-file config/scene.yaml --params-file
config/perception.yaml``. Subscribes ``/camera/camera/color/image_raw`` (rgb8),
``/camera/camera/aligned_depth_to_color/image_raw`` (16UC1, mm, 0 = no data) and
``/camera/camera/color/camera_info``; matches them by stamp (:class:`FrameSynchronizer`: no
message_filters here) and runs :class:`etdmp_ros.perception.Detector` (the ROS-free vision) on the
newest complete frame. Publishes, stamped with the image's stamp, in base_link:

- ``/etdmp/goal`` (geometry_msgs/PointStamped): centre of the goal marker's top face; nothing
  when no goal is visible (and a throttled warning);
- ``/etdmp/obstacles`` (geometry_msgs/PoseArray): centres of the obstacles' top faces, every
  processed frame, empty when none are visible;
- ``/etdmp/obstacle_volumes`` (visualization_msgs/MarkerArray): the same obstacles as upright
  cylinders with their measured radii (a CYLINDER marker each, in the PoseArray's order and
  with its stamp: diameter ``scale.x = scale.y``, height ``scale.z`` from the table to the top
  face; :mod:`etdmp_ros.ros.conversions._markers`), every processed frame: what dmp_server
  plans around and what RViz or Foxglove show;
- ``/etdmp/bottle`` (geometry_msgs/PointStamped): centre of the open bottle's mouth (while
  ``detect_bottle``); nothing when it is not seen. dmp_server takes it as the goal object of a
  skill with ``goal_object: bottle`` (stirring; docs/dmp_server.md);
- ``/etdmp/detections/image`` (sensor_msgs/Image rgb8): the colour image annotated, at most
  ``debug_image_rate`` and only while someone subscribes.

Latest-only: image subscriptions keep the last 2 messages and the synchronizer drops every set
older than the one processed, so a slow machine skips frames instead of falling behind. Bad input
(unsupported encodings, a wrong byte order, sizes that do not match camera_info, intrinsics no
D435 has, stamps that never match) is skipped with a throttled warning; blobs that cannot be the
goal or an obstacle (depth outside the D435's range, too large, off the table) are not reported,
with a throttled warning naming the reason (docs/perception.md). The node keeps running.

Parameters: the camera pose, the table and the object sizes from config/scene.yaml (read-only),
colours, thresholds and rates from config/perception.yaml (changeable at runtime, validated).
"""

from dataclasses import dataclass
import time

import cv2
from etdmp_ros.perception import detector_from_parameters, FrameSynchronizer
from etdmp_ros.ros import system
from etdmp_ros.ros.conversions import (camera_image_from_msg, cylinder_markers, image_msg,
                                       intrinsics_from_camera_info, pose_array_from_numpy,
                                       stamp_to_ns)
from etdmp_ros.ros.node_parameters import PerceptionParameters
from etdmp_ros.ros.parameters import declare, plain, values as parameter_values
from etdmp_ros.ros.spin import run
from geometry_msgs.msg import PointStamped, PoseArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from visualization_msgs.msg import MarkerArray

NODE_NAME = 'perception'
COLOR_TOPIC = 'camera/camera/color/image_raw'
DEPTH_TOPIC = 'camera/camera/aligned_depth_to_color/image_raw'
INFO_TOPIC = 'camera/camera/color/camera_info'
GOAL_TOPIC = 'etdmp/goal'
OBSTACLES_TOPIC = 'etdmp/obstacles'
VOLUMES_TOPIC = 'etdmp/obstacle_volumes'
BOTTLE_TOPIC = 'etdmp/bottle'
DEBUG_IMAGE_TOPIC = 'etdmp/detections/image'
BASE_FRAME = 'base_link'
COLOR_ENCODINGS = ('rgb8', 'bgr8')
DEPTH_ENCODINGS = ('16UC1', 'mono16')
# Without a processed frame for this long while images arrive, say why (s).
STALL_WARNING = 2.0

DESCRIPTION = system.node(NODE_NAME)


@dataclass(frozen=True)
class Settings:
    """Everything a frame needs, replaced whole when parameters change."""

    detector: object
    tolerance_ns: int
    match_camera_info: bool
    min_period: float
    debug_period: float
    warn_period: float

    @classmethod
    def from_parameters(cls, p):
        """
        Return the settings of flat parameter values; ValueError if one is invalid.

        Each value is checked by its description (type, range: PerceptionParameters), the
        detector's colours and sizes together by :func:`detector_from_parameters`.
        """
        params = PerceptionParameters.from_values(p)
        return cls(detector=detector_from_parameters(p),
                   tolerance_ns=round(params.stamp_tolerance * 1e9),
                   match_camera_info=params.match_camera_info,
                   min_period=1.0 / params.max_rate if params.max_rate > 0 else 0.0,
                   debug_period=(1.0 / params.debug_image_rate
                                 if params.debug_image_rate > 0 else -1.0),
                   warn_period=params.warn_period)


class PerceptionNode(Node):
    """Camera topics in, goal and obstacles in base_link out; the vision is the Detector's."""

    def __init__(self, **kwargs):
        """Declare parameters, build the detector, create subscriptions and publishers."""
        super().__init__(NODE_NAME, **kwargs)
        # OpenCV's worker pool spins (sched_yield) between the calls of a frame's detection:
        # about 13000 system calls a second and a tenth of a core here, for a detection that
        # takes 3 ms on one thread (strace -c of the node at 30 frames/s). Run it sequentially.
        cv2.setNumThreads(0)
        self._declare_parameters()
        self.settings = Settings.from_parameters(self._values())
        self._sync = self._synchronizer(self.settings)
        self._latest_info = None
        self._last_processed = -float('inf')
        self._last_debug = -float('inf')
        self._started = time.monotonic()
        self._arrivals = {}      # stream -> (monotonic arrival, stamp ns) of the last message
        self.frames = 0
        self._goal_seen = False
        self._warned = {}        # throttle key -> monotonic time of the last such warning

        reliability = (ReliabilityPolicy.RELIABLE if self.get_parameter('reliable_images').value
                       else ReliabilityPolicy.BEST_EFFORT)
        images = QoSProfile(depth=2, reliability=reliability)
        self.create_subscription(Image, COLOR_TOPIC, self._on_color, images)
        self.create_subscription(Image, DEPTH_TOPIC, self._on_depth, images)
        self.create_subscription(CameraInfo, INFO_TOPIC, self._on_info,
                                 QoSProfile(depth=5, reliability=reliability))
        self._goal_pub = self.create_publisher(PointStamped, GOAL_TOPIC, 10)
        self._obstacles_pub = self.create_publisher(PoseArray, OBSTACLES_TOPIC, 10)
        self._volumes_pub = self.create_publisher(MarkerArray, VOLUMES_TOPIC, 10)
        self._bottle_pub = self.create_publisher(PointStamped, BOTTLE_TOPIC, 10)
        self._debug_pub = self.create_publisher(Image, DEBUG_IMAGE_TOPIC, 1)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.create_timer(1.0, self._check_inputs)
        d = self.settings.detector
        self.get_logger().info(
            f'perception ready: camera at {list(d.camera_pose.position)} in {BASE_FRAME}, goal '
            f'HSV {d.goal.color.low}..{d.goal.color.high}, obstacles HSV '
            f'{d.obstacle.color.low}..{d.obstacle.color.high}, stamp tolerance '
            f'{self.settings.tolerance_ns * 1e-9:g} s')

    # --------------------------------------------------------------------------- parameters
    def _declare_parameters(self):
        declare(self, DESCRIPTION)

    def _values(self, updates=()):
        return parameter_values(self, DESCRIPTION, updates)

    def _validate_parameters(self, parameters):
        try:
            Settings.from_parameters(self._values(parameters))
        except (TypeError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters):
        old = self.settings
        self.settings = Settings.from_parameters(self._values())
        if (self.settings.tolerance_ns, self.settings.match_camera_info) != \
                (old.tolerance_ns, old.match_camera_info):
            self._sync = self._synchronizer(self.settings)
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{p.name} = {plain(p.value)}' for p in parameters))

    @staticmethod
    def _synchronizer(settings):
        streams = ('color', 'depth', 'info') if settings.match_camera_info else ('color', 'depth')
        return FrameSynchronizer(streams, settings.tolerance_ns)

    # ------------------------------------------------------------------------------- inputs
    def _on_color(self, msg):
        self._add('color', msg)

    def _on_depth(self, msg):
        self._add('depth', msg)

    def _on_info(self, msg):
        self._latest_info = msg
        if self.settings.match_camera_info:
            self._add('info', msg)
        else:
            self._arrivals['info'] = (time.monotonic(), stamp_to_ns(msg.header.stamp))

    def _add(self, stream, msg):
        stamp = stamp_to_ns(msg.header.stamp)
        self._arrivals[stream] = (time.monotonic(), stamp)
        frame = self._sync.add(stream, stamp, msg)
        if frame is None:
            return
        now = time.monotonic()
        if now - self._last_processed < self.settings.min_period:
            return
        self._last_processed = now
        self._process(*frame)

    def _warn(self, text, key=None, error=False):
        """
        Log a warning unless the same one (``key``, default the text) was logged lately.

        At most one per ``warn_period``. (rclpy's own throttle is per call site, so different
        problems would hide each other, and its period cannot change at runtime.)
        """
        key = text if key is None else key
        now = time.monotonic()
        if now - self._warned.get(key, -float('inf')) < self.settings.warn_period:
            return
        self._warned[key] = now
        if len(self._warned) > 100:   # texts with changing numbers: forget old keys
            self._warned = {k: t for k, t in self._warned.items()
                            if now - t < self.settings.warn_period}
        (self.get_logger().error if error else self.get_logger().warning)(text)

    def _check_inputs(self):
        """Say why no frame is processed: nothing arrives, or the stamps never match."""
        now = time.monotonic()
        if now - max(self._last_processed, self._started) < STALL_WARNING:
            return
        streams = ('color', 'depth', 'info')
        missing = [s for s in streams if s not in self._arrivals or
                   now - self._arrivals[s][0] > STALL_WARNING]
        if missing:
            topics = dict(zip(streams, (COLOR_TOPIC, DEPTH_TOPIC, INFO_TOPIC)))
            self._warn(f'no frame processed: nothing received for {STALL_WARNING:g} s on '
                       + ', '.join(topics[s] for s in missing))
        else:
            stamps = ', '.join(f'{s} {self._arrivals[s][1] * 1e-9:.3f} s' for s in streams)
            self._warn(f'no frame processed: colour, depth and camera_info stamps do not match '
                       f'within stamp_tolerance {self.settings.tolerance_ns * 1e-9:g} s '
                       f'(latest: {stamps})', key='stamps')

    # ---------------------------------------------------------------------------- a frame
    def _process(self, stamp_ns, messages):
        settings = self.settings
        color_msg, depth_msg = messages['color'], messages['depth']
        try:
            info = messages.get('info', self._latest_info)
            if info is None:
                raise ValueError(f'no camera_info received yet on {INFO_TOPIC}')
            try:
                rgb = camera_image_from_msg(color_msg, COLOR_ENCODINGS)
            except ValueError as exc:
                raise ValueError(f'colour {exc}') from None
            try:
                depth = camera_image_from_msg(depth_msg, DEPTH_ENCODINGS)
            except ValueError as exc:
                raise ValueError(f'depth {exc} (millimetres)') from None
            intrinsics = intrinsics_from_camera_info(info)   # checked in detect
            bgr = color_msg.encoding == 'bgr8'
            detections = settings.detector.detect(rgb, depth, intrinsics, bgr=bgr)
        except ValueError as exc:
            self._warn(f'frame skipped: {exc}')
            return
        except Exception as exc:   # noqa: B902 - a frame must never take the node down
            self._warn(f'frame skipped: {type(exc).__name__}: {exc}', error=True)
            return
        self.frames += 1
        stamp = color_msg.header.stamp
        if detections.goal is not None:
            goal = PointStamped()
            goal.header.stamp = stamp
            goal.header.frame_id = BASE_FRAME
            goal.point.x, goal.point.y, goal.point.z = (float(v)
                                                        for v in detections.goal.position)
            self._goal_pub.publish(goal)
            if not self._goal_seen:
                self._goal_seen = True
                self.get_logger().info('goal marker at {:.3f} {:.3f} {:.3f} m'.format(
                    *detections.goal.position))
        tops = detections.obstacle_positions()
        self._obstacles_pub.publish(pose_array_from_numpy(tops, frame_id=BASE_FRAME,
                                                          stamp=stamp))
        self._volumes_pub.publish(cylinder_markers(tops, detections.obstacle_radii(), stamp,
                                                   BASE_FRAME))
        if detections.bottle is not None:
            bottle = PointStamped()
            bottle.header.stamp = stamp
            bottle.header.frame_id = BASE_FRAME
            bottle.point.x, bottle.point.y, bottle.point.z = (
                float(v) for v in detections.bottle.position)
            self._bottle_pub.publish(bottle)
        self._warn_about(detections)
        self._publish_debug_image(detections, rgb, intrinsics, color_msg, bgr)

    def _warn_about(self, detections):
        if detections.goal is None:
            reasons = [r.reason for r in detections.rejected if r.kind == 'goal']
            if reasons:
                self._warn('goal marker seen but not located: ' + '; '.join(reasons),
                           key='goal')
            else:
                self._warn(f'no goal marker visible: nothing published on {GOAL_TOPIC}',
                           key='goal')
        refused = [r.reason for r in detections.rejected if r.kind == 'obstacle']
        if refused:
            self._warn(f'{len(refused)} obstacle blob(s) not reported: ' + '; '.join(refused),
                       key='obstacle')
        unmeasured = sum(not d.radius_measured for d in detections.obstacles)
        if unmeasured:
            self._warn(f'{unmeasured} obstacle(s) seen over less than half their rim (hidden): '
                       f'radius not measured, obstacle.radius '
                       f'{self.settings.detector.obstacle.radius * 1e3:g} mm reported',
                       key='radius')
        merged = sum(not d.single for d in detections.obstacles)
        if merged:
            self._warn(f'{merged} obstacle blob(s) do not fit one cylinder (obstacles '
                       'overlapping in the image?): each reported once', key='merged')

    def _publish_debug_image(self, detections, rgb, intrinsics, color_msg, bgr):
        period = self.settings.debug_period
        now = time.monotonic()
        if period < 0 or now - self._last_debug < period or \
                self._debug_pub.get_subscription_count() == 0:
            return
        self._last_debug = now
        image = self.settings.detector.annotate(rgb, detections, intrinsics, bgr=bgr)
        self._debug_pub.publish(image_msg(image, color_msg.encoding, color_msg.header.stamp,
                                          color_msg.header.frame_id))


def main(args=None):
    """Run the perception node until Ctrl-C (or SIGTERM)."""
    return run(lambda nodes: nodes.append(PerceptionNode()), NODE_NAME, args)


if __name__ == '__main__':
    raise SystemExit(main())

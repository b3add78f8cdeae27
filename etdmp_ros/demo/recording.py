"""
Recording a closed-loop run: a node in the caller's process that records the whole system.

:class:`Recorder` subscribes to every topic of the system, discovered from the ROS graph as the
nodes start (``ros2 bag record --all`` does the same), and keeps each message as the
serialized bytes its raw subscription hands over, stamped with the time it arrived; a few
topics it also reads at once to drive the demo (the pen tip, perception's output, the
controller's status, the nodes' events, the camera frames kept for the pictures). It calls
``/generalize`` and sets dmp_server's parameters as a user would (``ros2 service call``,
``ros2 param set``).

After the run :func:`write_bag` writes it all to a rosbag2-compatible MCAP file
(:mod:`etdmp_ros.skills.recordings`), the camera images as sensor_msgs/CompressedImage on
``<topic>/compressed`` as image_transport names them (compressed then, not while the system
runs); :func:`read_streams` reads back from that file the streams that
:mod:`etdmp_ros.demo.metrics` measures, and :func:`save_recording` writes them with the plans to an
``.npz``.
"""

from concurrent.futures import ThreadPoolExecutor
import heapq
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from etdmp_ros.ros import events, qos, topics
from etdmp_ros.ros.background import BackgroundNode
from etdmp_ros.ros.conversions import (compress_image_cdr, COMPRESSED_IMAGE_TYPE,
                                       COMPRESSED_SUFFIX, contacts_from_markers,
                                       header_stamp_ns, image_from_cdr,
                                       intrinsics_from_camera_info, joint_state_arrays,
                                       message_class, path_to_numpy, point_to_numpy,
                                       pose_array_to_numpy, stamp_to_ns)
from etdmp_ros.skills import recordings as bag
from geometry_msgs.msg import PointStamped, PoseArray, PoseStamped
from nav_msgs.msg import Path as PathMessage
from nav_msgs.srv import GetPlan
import numpy as np
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Float64MultiArray, String
from visualization_msgs.msg import MarkerArray

#: Keep every n-th camera frame for the animation (30 Hz camera: 15 frames per second).
FRAME_EVERY = 2
STREAM = QoSProfile(depth=1000)
# Reliable, as perception subscribes: a lost fragment is resent instead of the frame lost.
IMAGES = QoSProfile(depth=2)
#: How often the graph is looked at for new topics (s; ros2 bag record: 0.1 s).
DISCOVERY_PERIOD = 0.2
IMAGE_TYPE = 'sensor_msgs/msg/Image'
SIM = 'ur10_sim'
TIP_TOPIC = topics.absolute(topics.GROUND_TRUTH_TOOL_TIP, SIM)
COMMAND_TOPIC = topics.absolute(topics.COMMANDS)
REFERENCE_TOPIC = topics.absolute(topics.REFERENCE)
STATUS_TOPIC = topics.absolute(topics.CONTROLLER_STATUS)
COLOR_TOPIC = topics.absolute(topics.COLOR)
DEPTH_TOPIC = topics.absolute(topics.DEPTH)
PATH_TOPIC = topics.absolute(topics.PATH)
GOAL_SEEN_TOPIC = topics.absolute(topics.GOAL)
BOTTLE_SEEN_TOPIC = topics.absolute(topics.BOTTLE)
JOINTS_TOPIC = topics.absolute(topics.JOINT_STATES)
CONTACTS_TOPIC = topics.absolute(topics.GROUND_TRUTH_CONTACTS, SIM)
#: The nodes whose ``~/events`` the metrics read (etdmp_ros.ros.events), by topic.
EVENT_TOPICS = {topics.absolute(topics.EVENTS, node): node
                for node in (SIM, f'{SIM}_camera', 'controller', 'dmp_server')}
#: Topics left out of the recording, with the reason (metrics.json ``recording.not_recorded``).
NOT_RECORDED = {
    topics.absolute(topics.DETECTIONS_IMAGE):
        'a view of the recorded camera images that perception draws only while someone '
        'subscribes (recording it costs the drawing)',
}
#: Why the images are not in a recording made without them (``Recorder(images=False)``).
IMAGES_LEFT_OUT = 'camera images left out of this recording (no pictures)'
#: The streams :func:`read_streams` returns for the metrics.
MEASURED_TOPICS = (TIP_TOPIC, COMMAND_TOPIC, REFERENCE_TOPIC, STATUS_TOPIC, PATH_TOPIC,
                   GOAL_SEEN_TOPIC, BOTTLE_SEEN_TOPIC, JOINTS_TOPIC, CONTACTS_TOPIC,
                   *EVENT_TOPICS)


class Stream:
    """One recorded topic: its type, its publishers' QoS, (receipt ns, CDR bytes) in order."""

    def __init__(self, type_name, qos_profiles=()):
        """Start an empty stream of ``type_name`` (``pkg/msg/Name``)."""
        self.type_name = type_name
        self.qos_profiles = list(qos_profiles)
        self.messages = []


class RecorderError(RuntimeError):
    """A service of the system did not answer or refused the request."""


class Recorder(BackgroundNode):
    """
    rclpy in this process (own context, spinning in a thread): records the whole system.

    ``streams``: {topic: :class:`Stream`}, every topic that some other node publishes, found in
    the graph every :data:`DISCOVERY_PERIOD` (the demo's own topics subscribed from the start),
    subscribed raw with the QoS its publishers offer (reliable and transient local only if all
    are). A message's receipt time is the wall clock (ns since the epoch, as ``ros2 bag
    record`` stamps it), kept strictly increasing so that the order of arrival can be read
    back from the file. Deserializing messages on arrival cost this process a tenth of a
    core: only the few the demo acts on are read at once.

    ``sim_ns``: the latest pen-tip stamp (simulated ns); ``status``: (sim ns at receipt, text).
    Camera frames: :meth:`request_snapshot` keeps the first frame (colour and depth) at or
    after a stamp; with ``animation``, every :data:`FRAME_EVERY`-th frame after
    ``keep_frames_after`` is kept at half size in ``frames``.
    """

    def __init__(self, domain_id, animation=True, images=True):
        """
        Create the node, subscriptions and clients; start spinning.

        ``images`` False: the camera images are neither recorded nor kept (no pictures): a
        recorder on another computer than the camera then does not double the images' traffic
        (docs/two_hosts.md).
        """
        super().__init__('etdmp_demo', domain_id)
        self.lock = threading.Lock()
        self.animation = animation
        self.images = images
        self.sim_ns = 0
        self.streams = {}             # topic -> Stream
        self.unrecorded = {}          # topic -> why not
        self.status = []              # (sim ns at receipt, text)
        self.events = []              # the nodes' events (etdmp_ros.ros.events.Event)
        self.goal_truth = self.obstacles_truth = self.bottle_truth = None
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
        self._wall0, self._mono0 = time.time_ns(), time.monotonic_ns()
        self._last_receipt = 0
        self._subscribe()
        self.generalize = self.node.create_client(GetPlan, '/generalize')
        self._parameter_clients = {
            'dmp_server': self.node.create_client(SetParameters, '/dmp_server/set_parameters')}
        self.node.create_timer(DISCOVERY_PERIOD, self._discover)
        self.start()

    @property
    def tip(self):
        """Return the pen-tip messages received so far, [(receipt ns, CDR bytes)]."""
        return self.streams[TIP_TOPIC].messages

    def _subscribe(self):
        """Subscribe the topics the demo acts on (before their publishers exist)."""
        truth = {name: topics.absolute(name, SIM) for name in (
            topics.GROUND_TRUTH_GOAL, topics.GROUND_TRUTH_OBSTACLES, topics.GROUND_TRUTH_BOTTLE)}
        for topic, msg_type, profile, handler in (
                (TIP_TOPIC, PointStamped, STREAM, self._on_tip),
                (truth[topics.GROUND_TRUTH_GOAL], PointStamped, 10, self._on_goal_truth),
                (truth[topics.GROUND_TRUTH_OBSTACLES], PoseArray, 10, self._on_obstacles_truth),
                (truth[topics.GROUND_TRUTH_BOTTLE], PointStamped, 10, self._on_bottle_truth),
                (BOTTLE_SEEN_TOPIC, PointStamped, 10, None),
                (GOAL_SEEN_TOPIC, PointStamped, 10, self._on_goal_seen),
                (topics.absolute(topics.OBSTACLES), PoseArray, 10, self._on_obstacles_seen),
                (COMMAND_TOPIC, Float64MultiArray, STREAM, None),
                (STATUS_TOPIC, String, qos.latched(10), self._on_status),
                (REFERENCE_TOPIC, PoseStamped, STREAM, None),
                (topics.absolute(topics.COLOR_INFO), CameraInfo, 10, self._on_camera_info),
                (COLOR_TOPIC, Image, IMAGES, self._on_color),
                (DEPTH_TOPIC, Image, IMAGES, self._on_depth),
                *((topic, DiagnosticArray, qos.latched(events.HISTORY), self._on_event)
                  for topic in EVENT_TOPICS)):
            if msg_type is Image and not self.images:
                continue
            self._record(topic, msg_type, profile, handler)

    def _record(self, topic, msg_type, qos, handler=None):
        module, name = msg_type.__module__.split('.')[0], msg_type.__name__
        stream = self.streams[topic] = Stream(f'{module}/msg/{name}')
        messages, lock = stream.messages, self.lock

        def on_message(raw):
            with lock:
                now = self._wall0 + time.monotonic_ns() - self._mono0
                now = self._last_receipt = max(now, self._last_receipt + 1)
                messages.append((now, raw))
            if handler is not None:
                handler(raw)

        self.node.create_subscription(msg_type, topic, on_message, qos, raw=True)

    def _discover(self):
        """Subscribe every new topic that another node publishes (as ros2 bag record -a)."""
        me = (self.node.get_name(), self.node.get_namespace())
        for topic, types in self.node.get_topic_names_and_types():
            stream = self.streams.get(topic)
            if (stream is not None and stream.qos_profiles) or topic in self.unrecorded \
                    or '/_' in topic or not types:
                continue            # known, hidden, or a service's event topic
            if topic in NOT_RECORDED:
                self.unrecorded[topic] = NOT_RECORDED[topic]
                continue
            if not self.images and types[0] == IMAGE_TYPE:
                self.unrecorded[topic] = IMAGES_LEFT_OUT
                continue
            publishers = [p for p in self.node.get_publishers_info_by_topic(topic)
                          if (p.node_name, p.node_namespace) != me]
            if not publishers:
                continue
            qos = [p.qos_profile for p in publishers]
            reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in qos)
            latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in qos)
            if stream is None:
                try:
                    msg_type = message_class(types[0])
                except (AttributeError, ModuleNotFoundError, ValueError):
                    self.unrecorded[topic] = f'{types[0]} is not installed here'
                    continue
                subscription = QoSProfile(
                    depth=IMAGES.depth if types[0] == IMAGE_TYPE else STREAM.depth,
                    reliability=(ReliabilityPolicy.RELIABLE if reliable
                                 else ReliabilityPolicy.BEST_EFFORT),
                    durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                                else DurabilityPolicy.VOLATILE))
                self._record(topic, msg_type, subscription)
                stream = self.streams[topic]
            stream.qos_profiles = [
                bag.qos_profile(q.reliability == ReliabilityPolicy.RELIABLE,
                                q.durability == DurabilityPolicy.TRANSIENT_LOCAL, q.depth)
                for q in qos]

    # -- callbacks
    def _on_tip(self, raw):
        stamp = header_stamp_ns(raw)
        with self.lock:
            self.sim_ns = max(self.sim_ns, stamp)

    def _on_goal_truth(self, raw):
        self.goal_truth = point_to_numpy(deserialize_message(raw, PointStamped).point)

    def _on_bottle_truth(self, raw):
        self.bottle_truth = point_to_numpy(deserialize_message(raw, PointStamped).point)

    def _on_obstacles_truth(self, raw):
        self.obstacles_truth = pose_array_to_numpy(deserialize_message(raw, PoseArray))

    def _on_goal_seen(self, raw):
        msg = deserialize_message(raw, PointStamped)
        self.goal_seen = point_to_numpy(msg.point)
        self.goal_seen_stamp = stamp_to_ns(msg.header.stamp)

    def _on_obstacles_seen(self, raw):
        self.obstacles_seen = pose_array_to_numpy(deserialize_message(raw, PoseArray))

    def _on_status(self, raw):
        text = deserialize_message(raw, String).data
        with self.lock:
            self.status.append((self.sim_ns, text))

    def _on_event(self, raw):
        found = events.from_message(deserialize_message(raw, DiagnosticArray))
        with self.lock:
            self.events.extend(found)

    def _on_camera_info(self, raw):
        if self.camera_info is None:
            self.camera_info = intrinsics_from_camera_info(deserialize_message(raw, CameraInfo))

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

    def events_of(self, node, kind):
        """Return the events of ``kind`` that ``node`` published so far, in order."""
        with self.lock:
            return events.of_kind(self.events, node, kind)

    def wait_for_event(self, node, kind, since=0, timeout=1.0):
        """Return the first event of ``kind`` from ``node`` after the first ``since`` (None)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = self.events_of(node, kind)
            if len(found) > since:
                return found[since]
            time.sleep(0.01)
        return None

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
        self.set_parameters('dmp_server', timeout, **values)

    def set_parameters(self, node, timeout=10.0, **values):
        """Set parameters of ``node`` (as ``ros2 param set``); raise RecorderError if refused."""
        client = self._parameter_clients.get(node)
        if client is None:
            client = self.node.create_client(SetParameters, f'/{node}/set_parameters')
            self._parameter_clients[node] = client
        if not client.wait_for_service(timeout_sec=timeout):
            raise RecorderError(f'/{node}/set_parameters is not available')
        request = SetParameters.Request(
            parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
        result = self._wait(client.call_async(request), timeout, f'/{node}/set_parameters')
        for name, r in zip(values, result.results):
            if not r.successful:
                raise RecorderError(f'{node} refused {name} = {values[name]!r}: {r.reason}')

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


def write_bag(path, recorder, workers=2):
    """
    Write everything ``recorder`` received to a rosbag2-compatible MCAP file at ``path``.

    Messages as received, in order of arrival (log time = receipt time); images
    (sensor_msgs/Image) as CompressedImage on ``<topic>/compressed`` (JPEG colour, PNG depth),
    compressed here on ``workers`` threads. Also writes ``metadata.yaml`` beside it
    (:class:`etdmp_ros.skills.recordings.BagWriter`). Return {topic: message count}; a topic
    whose message definition is not installed here is left out, with the reason in
    ``recorder.unrecorded``.
    """
    with recorder.lock:
        streams = {topic: (s.type_name, s.qos_profiles, list(s.messages))
                   for topic, s in recorder.streams.items()}
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for topic in [t for t, (type_name, _, _) in streams.items() if type_name == IMAGE_TYPE]:
            _, profiles, messages = streams.pop(topic)
            data = pool.map(compress_image_cdr, [raw for _, raw in messages])
            streams[topic + COMPRESSED_SUFFIX] = (
                COMPRESSED_IMAGE_TYPE, profiles,
                [(ns, cdr) for (ns, _), cdr in zip(messages, data)])
    with bag.BagWriter(path) as writer:
        for topic in sorted(streams):
            try:
                writer.add_topic(topic, streams[topic][0], streams[topic][1])
            except bag.BagError as err:     # its .msg file is not installed here: left out
                recorder.unrecorded[topic] = str(err)
                streams.pop(topic)
        merged = heapq.merge(*([(ns, topic, raw) for ns, raw in messages]
                               for topic, (_, _, messages) in streams.items()),
                             key=lambda m: m[0])
        for ns, topic, raw in merged:
            writer.write(topic, ns, raw)
    return {topic: len(messages) for topic, (_, _, messages) in streams.items()}


def read_streams(path):
    """
    Return the streams that :mod:`etdmp_ros.demo.metrics` measures, from a :func:`write_bag` file.

    ``tip``, ``reference``: (n, 4) header stamps (ns) and positions, sorted by stamp;
    ``reference_q`` (n, 4): the reference's orientations (x, y, z, w), in the same order;
    ``joints`` (n, 7): /joint_states' stamps (ns) and positions (JOINT_NAMES order), sorted;
    ``commands`` (n, 6) and ``command_time``: the simulated time when each arrived (the stamp
    of the latest pen tip received before it), ``command_wall_time``: its receipt time (s);
    ``status``: [(simulated ns at receipt, text)]. Also, in order of arrival: ``paths``, every
    /etdmp/path as (simulated ns at receipt, receipt ns, header stamp ns, pose stamps ns (n,),
    positions (n, 3)); ``goal_seen``: /etdmp/goal as (m, 6) rows of simulated ns at receipt,
    receipt ns, header stamp ns, x, y, z; ``bottle_seen``: /etdmp/bottle as those; ``events``:
    the nodes' events (:class:`etdmp_ros.ros.events.Event`, :data:`EVENT_TOPICS`; each carries
    the wall clock when it happened, the clock of the receipt times); ``contacts``: the
    simulation's contact ground truth as [(stamp ns, [(part, item, depth m), ...])], one entry
    per message (an empty list: none).
    """
    reader = _StreamReader()
    for topic, _, log_ns, data in bag.read_messages(path, MEASURED_TOPICS):
        reader.read(topic, log_ns, data)
    return reader.streams()


class _StreamReader:
    """The measured topics of a recording, read message by message (:func:`read_streams`)."""

    def __init__(self):
        self.tip, self.reference, self.joints, self.contacts = [], [], [], []
        self.commands, self.command_time, self.wall, self.status = [], [], [], []
        self.paths, self.goal_seen, self.bottle_seen, self.events = [], [], [], []
        self.sim_ns = 0     # the latest pen tip's stamp: the simulated time of receipt
        self._readers = {TIP_TOPIC: self._tip, REFERENCE_TOPIC: self._reference,
                         JOINTS_TOPIC: self._joints, COMMAND_TOPIC: self._command,
                         STATUS_TOPIC: self._status, PATH_TOPIC: self._path,
                         CONTACTS_TOPIC: self._contacts, GOAL_SEEN_TOPIC: self._goal_seen,
                         BOTTLE_SEEN_TOPIC: self._bottle_seen,
                         **dict.fromkeys(EVENT_TOPICS, self._event)}

    def read(self, topic, log_ns, data):
        """Take one message of ``topic`` received at ``log_ns`` (CDR bytes ``data``)."""
        self._readers[topic](log_ns, data)

    def _tip(self, log_ns, data):
        msg = deserialize_message(data, PointStamped)
        stamp = stamp_to_ns(msg.header.stamp)
        self.sim_ns = max(self.sim_ns, stamp)
        self.tip.append((stamp, msg.point.x, msg.point.y, msg.point.z))

    def _reference(self, log_ns, data):
        msg = deserialize_message(data, PoseStamped)
        p, o = msg.pose.position, msg.pose.orientation
        self.reference.append((stamp_to_ns(msg.header.stamp), p.x, p.y, p.z, o.x, o.y, o.z,
                               o.w))

    def _joints(self, log_ns, data):
        msg = deserialize_message(data, JointState)
        try:
            positions, _ = joint_state_arrays(msg)
        except ValueError:
            return
        self.joints.append((stamp_to_ns(msg.header.stamp), *positions))

    def _command(self, log_ns, data):
        self.commands.append(deserialize_message(data, Float64MultiArray).data)
        self.command_time.append(self.sim_ns)
        self.wall.append(log_ns * 1e-9)

    def _status(self, log_ns, data):
        self.status.append((self.sim_ns, deserialize_message(data, String).data))

    def _path(self, log_ns, data):
        msg = deserialize_message(data, PathMessage)
        _, positions, _ = path_to_numpy(msg)
        stamps = np.array([stamp_to_ns(p.header.stamp) for p in msg.poses], dtype=np.int64)
        self.paths.append((self.sim_ns, log_ns, stamp_to_ns(msg.header.stamp), stamps,
                           positions))

    def _contacts(self, log_ns, data):
        msg = deserialize_message(data, MarkerArray)
        stamp = stamp_to_ns(msg.markers[0].header.stamp) if msg.markers else self.sim_ns
        self.contacts.append((stamp, contacts_from_markers(msg)))

    def _point_row(self, log_ns, data):
        msg = deserialize_message(data, PointStamped)
        return (self.sim_ns, log_ns, stamp_to_ns(msg.header.stamp), msg.point.x, msg.point.y,
                msg.point.z)

    def _goal_seen(self, log_ns, data):
        self.goal_seen.append(self._point_row(log_ns, data))

    def _bottle_seen(self, log_ns, data):
        self.bottle_seen.append(self._point_row(log_ns, data))

    def _event(self, log_ns, data):
        self.events.extend(events.from_message(deserialize_message(data, DiagnosticArray)))

    def streams(self):
        """Return the streams read (:func:`read_streams`)."""
        tip = np.array(self.tip).reshape(-1, 4)
        reference = np.array(self.reference).reshape(-1, 8)
        reference = reference[np.argsort(reference[:, 0], kind='stable')]
        joints = np.array(self.joints, dtype=float).reshape(-1, 7)
        return {'tip': tip[np.argsort(tip[:, 0], kind='stable')],
                'reference': reference[:, :4], 'reference_q': reference[:, 4:],
                'joints': joints[np.argsort(joints[:, 0], kind='stable')],
                'command_time': np.array(self.command_time, dtype=float),
                'command_wall_time': np.array(self.wall, dtype=float),
                'commands': np.array(self.commands, dtype=float).reshape(-1, 6),
                'status': self.status, 'paths': self.paths,
                'goal_seen': np.array(self.goal_seen, dtype=float).reshape(-1, 6),
                'bottle_seen': np.array(self.bottle_seen, dtype=float).reshape(-1, 6),
                'events': self.events, 'contacts': self.contacts}


def save_recording(path, rec, plan, other, tracking_start, executed=None):
    """
    Write the recorded streams and the plans to ``path`` (``.npz``).

    ``rec``: :func:`read_streams`; ``plan``: (t, positions, ...) returned by /generalize;
    ``other``: (method, t, positions), t None when that plan was refused; ``tracking_start``:
    simulated s; ``executed``: (t, positions) of the plan as executed when dmp_server re-planned
    its remainder (a goal that moved), saved as ``executed_t`` and ``executed_x``.
    """
    _, other_t, other_x = other
    refused = other_t is None
    extra = {} if executed is None else {'executed_t': executed[0], 'executed_x': executed[1]}
    np.savez_compressed(path, tip=rec['tip'], reference=rec['reference'],
                        commands=rec['commands'], command_time=rec['command_time'],
                        plan_t=plan[0], plan_x=plan[1],
                        other_t=np.zeros(0) if refused else other_t,
                        other_x=np.zeros(0) if refused else other_x,
                        tracking_start=tracking_start, **extra)

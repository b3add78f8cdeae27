"""
perception as a user runs it: the installed executable in its own process, talked to with rclpy.

With the installed ur10_sim publishing the camera: the perceived goal and obstacles match the
simulation's ground truth of the same stamp within 5 mm, the obstacles' measured radii (on
/etdmp/obstacle_volumes, beside /etdmp/obstacles with the same stamp) the radii the simulation
was given (``ros2 param set /ur10_sim obstacle_radii``) within 1 mm, follow the goal when it is
moved with ``ros2 param set /ur10_sim goal_position``, and stop (goal) or empty (obstacles)
when the objects leave the view. Alone, fed by this test: frames with wrong encodings or sizes
are skipped with a warning and the node keeps working.
"""

import time

from conftest import NodeProcess
from etdmp_ros.ros.conversions import (camera_info_msg, cylinders_from_markers, image_msg,
                                       ns_to_stamp, point_to_numpy, pose_array_to_numpy,
                                       stamp_to_ns)
from etdmp_ros.ros.system import scene_config
from etdmp_ros.sim import UR10Sim
from geometry_msgs.msg import PointStamped, PoseArray
import numpy as np
import pytest
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image
from visualization_msgs.msg import Marker, MarkerArray

TOLERANCE = 0.005
RADIUS_TOLERANCE = 0.001
TIMEOUT = 20.0
COLOR = '/camera/camera/color/image_raw'
DEPTH = '/camera/camera/aligned_depth_to_color/image_raw'
INFO = '/camera/camera/color/camera_info'


class Client:
    """rclpy in this process, in its own context: what `ros2 topic echo / param set` do."""

    def __init__(self):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('perception_test_client', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.goals, self.obstacles, self.images, self.volumes = [], [], [], {}
        self.truth_goal, self.truth_obstacles = {}, {}
        sub = self.node.create_subscription
        sub(PointStamped, '/etdmp/goal',
            lambda m: self.goals.append((stamp_to_ns(m.header.stamp), point_to_numpy(m.point),
                                         m.header.frame_id)), 10)
        sub(PoseArray, '/etdmp/obstacles',
            lambda m: self.obstacles.append((stamp_to_ns(m.header.stamp),
                                             pose_array_to_numpy(m))), 10)
        sub(Image, '/etdmp/detections/image', self.images.append, 1)
        sub(MarkerArray, '/etdmp/obstacle_volumes',
            lambda m: self.volumes.__setitem__(stamp_to_ns(m.markers[0].header.stamp), m), 10)
        sub(PointStamped, '/ur10_sim/ground_truth/goal',
            lambda m: self.truth_goal.__setitem__(stamp_to_ns(m.header.stamp),
                                                  point_to_numpy(m.point)), 10)
        sub(PoseArray, '/ur10_sim/ground_truth/obstacles',
            lambda m: self.truth_obstacles.__setitem__(stamp_to_ns(m.header.stamp),
                                                       pose_array_to_numpy(m)), 10)
        self.sim_parameters = self.node.create_client(SetParameters, '/ur10_sim/set_parameters')

    def close(self):
        """Destroy the node and shut the context down."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)

    def spin_until(self, condition, timeout, what, *processes):
        """Spin until ``condition()`` is true; fail with the nodes' logs after ``timeout``."""
        deadline = time.monotonic() + timeout
        while not condition():
            for process in processes:
                assert process.process.poll() is None, f'node exited:\n{process.log()}'
            assert time.monotonic() < deadline, f'timeout: {what}\n' + '\n'.join(
                p.log() for p in processes)
            self.executor.spin_once(timeout_sec=0.02)

    def spin_for(self, seconds):
        """Process callbacks for a while."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def set_sim(self, name, value):
        """Set a ur10_sim parameter (what `ros2 param set /ur10_sim ...` does)."""
        assert self.sim_parameters.wait_for_service(timeout_sec=TIMEOUT)
        parameter = Parameter(name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in value])
        future = self.sim_parameters.call_async(
            SetParameters.Request(parameters=[parameter.to_parameter_msg()]))
        self.executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
        assert future.done() and future.result().results[0].successful

    def set_perception(self, **values):
        """Set perception parameters in one request; return the SetParametersResult list."""
        client = self.node.create_client(SetParameters, '/perception/set_parameters')
        assert client.wait_for_service(timeout_sec=TIMEOUT)
        future = client.call_async(SetParameters.Request(parameters=[
            Parameter(name, value=value).to_parameter_msg() for name, value in values.items()]))
        self.executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
        assert future.done()
        self.node.destroy_client(client)
        return future.result().results

    def goal_errors(self, since=0):
        """Return (stamp, error) of perceived goals against the ground truth of their stamp."""
        return [(stamp, np.linalg.norm(point - self.truth_goal[stamp]))
                for stamp, point, _ in self.goals if stamp > since and stamp in self.truth_goal]

    def obstacle_errors(self, since=0):
        """Return (stamp, count error, max distance) of perceived obstacles against the truth."""
        rows = []
        for stamp, points in self.obstacles:
            truth = self.truth_obstacles.get(stamp)
            if stamp <= since or truth is None:
                continue
            if len(truth) == 0 or len(points) == 0:
                rows.append((stamp, len(points) - len(truth), 0.0))
                continue
            distances = np.linalg.norm(truth[:, None] - points[None], axis=2).min(axis=1)
            rows.append((stamp, len(points) - len(truth), float(distances.max())))
        return rows


class CameraFeed:
    """
    Publishes colour, depth and camera_info from this test, as a RealSense driver would.

    Each :meth:`send` is one frame: the three messages with one stamp, 33 ms after the last.
    """

    def __init__(self, client, *processes):
        """Create the publishers; wait until perception (``processes``) subscribes to them."""
        self.client = client
        self.pubs = {topic: client.node.create_publisher(kind, topic, 10)
                     for topic, kind in ((COLOR, Image), (DEPTH, Image), (INFO, CameraInfo))}
        client.spin_until(lambda: all(p.get_subscription_count() for p in self.pubs.values()),
                          TIMEOUT, 'perception subscribes to the camera', *processes)
        self.stamp_ns = 1_000_000_000

    def send(self, color, depth, info, color_encoding='rgb8', depth_encoding='16UC1',
             edit=None):
        """
        Publish one frame (``info``: CameraIntrinsics); return its stamp (ns).

        ``edit(color_msg, depth_msg, info_msg)``, if given, changes the messages before they go
        out (a lying flag, a skewed camera matrix).
        """
        self.stamp_ns += 33_000_000
        stamp = ns_to_stamp(self.stamp_ns)
        messages = (image_msg(color, color_encoding, stamp),
                    image_msg(depth, depth_encoding, stamp), camera_info_msg(info, stamp))
        if edit is not None:
            edit(*messages)
        for topic, msg in zip((COLOR, DEPTH, INFO), messages):
            self.pubs[topic].publish(msg)
        self.client.spin_for(0.15)
        return self.stamp_ns

    def until(self, condition, what, process, frame, timeout=10.0):
        """
        Send ``frame`` (a dict of :meth:`send` arguments) until ``condition()``; return stamps.

        A camera streams: a throttled warning or the next goal shows after some frames. Fails
        with the node's log when ``process`` exits or after ``timeout``.
        """
        sent = []
        deadline = time.monotonic() + timeout
        while not condition():
            assert process.process.poll() is None, f'node exited:\n{process.log()}'
            assert time.monotonic() < deadline, f'timeout: {what}\n{process.log()}'
            sent.append(self.send(**frame))
        return sent


@pytest.fixture
def client(ros_env):
    """Return a Client in the test's isolated DDS domain; closed afterwards."""
    c = Client()
    yield c
    c.close()


def test_perception_follows_the_simulation(colcon_install, ros_env, tmp_path, client):
    """Goal and obstacles within 5 mm of the simulator's truth; they follow it when it moves."""
    sim = NodeProcess(colcon_install, ros_env, tmp_path, 'ur10_sim')
    perception = NodeProcess(colcon_install, ros_env, tmp_path, 'perception')
    nodes = (sim, perception)
    try:
        # The shipped scene: goal and two obstacles, the arm above the whiteboard.
        client.spin_until(lambda: len(client.goal_errors()) >= 10, 40.0, 'perceived goals',
                          *nodes)
        errors = [e for _, e in client.goal_errors()]
        assert max(errors) < TOLERANCE, errors
        assert {frame for _, _, frame in client.goals} == {'base_link'}
        client.spin_until(lambda: len(client.obstacle_errors()) >= 5, TIMEOUT, 'obstacles',
                          *nodes)
        rows = client.obstacle_errors()
        assert all(count == 0 for _, count, _ in rows), rows
        assert max(d for _, _, d in rows) < TOLERANCE, rows
        assert len(client.truth_obstacles[rows[-1][0]]) == 2
        # The annotated image (published while subscribed).
        client.spin_until(lambda: client.images, TIMEOUT, 'annotated image', *nodes)
        image = client.images[-1]
        assert (image.encoding, image.width, image.height) == ('rgb8', 640, 480)

        # Move the goal (ros2 param set /ur10_sim goal_position ...): the perceived one follows.
        new_goal = np.array([1.0, -0.15, 0.002])
        client.set_sim('goal_position', new_goal)
        client.spin_until(lambda: any(np.linalg.norm(p - new_goal) < TOLERANCE
                                      for _, p, _ in client.goals[-3:]),
                          TIMEOUT, f'perceived goal at {new_goal}', *nodes)
        moved = max(s for s, t in client.truth_goal.items()
                    if np.linalg.norm(t - new_goal) > 1e-9) + 1
        client.spin_for(0.5)
        errors = [e for _, e in client.goal_errors(since=moved)]
        assert len(errors) >= 3 and max(errors) < TOLERANCE, errors

        # Obstacles moved, then none: the PoseArray follows and ends empty.
        new_obstacles = [0.5, -0.2, 0.08, 0.95, 0.3, 0.08, 1.1, 0.05, 0.08]
        client.set_sim('obstacle_positions', new_obstacles)
        target = np.reshape(new_obstacles, (-1, 3))
        client.spin_until(lambda: client.obstacles and len(client.obstacles[-1][1]) == 3 and
                          np.all(np.linalg.norm(target[:, None] - client.obstacles[-1][1][None],
                                                axis=2).min(axis=1) < TOLERANCE),
                          TIMEOUT, 'three moved obstacles', *nodes)
        # Their sizes (ros2 param set /ur10_sim obstacle_radii ...): each measured within 1 mm,
        # on /etdmp/obstacle_volumes with the PoseArray's stamp, as cylinders at its points.
        radii = np.array([0.015, 0.04, 0.06])
        client.set_sim('obstacle_radii', radii)

        def sized():
            """Return (stamp, |radius errors|) of the volumes of the latest PoseArray."""
            stamp, points = client.obstacles[-1]
            if stamp not in client.volumes or len(points) != 3:
                return None
            msg = client.volumes[stamp]
            assert msg.markers[0].action == Marker.DELETEALL
            assert {m.header.frame_id for m in msg.markers} == {'base_link'}
            tops, measured = cylinders_from_markers(msg)
            np.testing.assert_allclose(tops, points, atol=1e-9)
            truth = radii[np.linalg.norm(target[:, None] - tops[None], axis=2).argmin(axis=0)]
            return stamp, np.abs(measured - truth)
        client.spin_until(lambda: (sized() is not None and sized()[1].max() < 0.01), TIMEOUT,
                          'obstacles of their new sizes', *nodes)
        changed = sized()[0]
        client.spin_for(1.0)
        errors = []
        for stamp, points in client.obstacles:
            if stamp < changed or stamp not in client.volumes:
                continue
            tops, measured = cylinders_from_markers(client.volumes[stamp])
            np.testing.assert_allclose(tops, points, atol=1e-9)
            truth = radii[np.linalg.norm(target[:, None] - tops[None], axis=2).argmin(axis=0)]
            errors += np.abs(measured - truth).tolist()
        print(f'radii measured through the node: {len(errors)}, max error '
              f'{max(errors) * 1e3:.2f} mm')
        assert len(errors) >= 9 and max(errors) < RADIUS_TOLERANCE, errors
        client.set_sim('obstacle_positions', [])
        client.spin_until(lambda: client.obstacles and len(client.obstacles[-1][1]) == 0,
                          TIMEOUT, 'empty obstacles', *nodes)
        last = client.obstacles[-1][0]
        client.spin_until(lambda: last in client.volumes, TIMEOUT, 'empty volumes', *nodes)
        assert len(cylinders_from_markers(client.volumes[last])[0]) == 0

        # Goal out of view (below the table top): no goal published, a warning instead.
        client.set_sim('goal_position', [0.7, 0.2, -0.3])
        client.spin_until(lambda: any(t[2] < 0 for t in client.truth_goal.values()), TIMEOUT,
                          'goal moved away', *nodes)
        gone = min(s for s, t in client.truth_goal.items() if t[2] < 0)
        count = len(client.obstacles)
        client.spin_for(1.5)
        assert len(client.obstacles) > count       # frames are still processed ...
        assert not [s for s, _, _ in client.goals if s >= gone]   # ... but no goal published
        client.spin_until(lambda: 'no goal marker visible' in perception.log(), 5.0,
                          'warning about the missing goal', *nodes)
        assert perception.process.poll() is None
    finally:
        codes = [node.stop() for node in nodes]
    assert codes == [0, 0], '\n'.join(node.log() for node in nodes)
    assert 'Traceback' not in perception.log()


def test_bad_frames_are_skipped(colcon_install, ros_env, tmp_path, client):
    """Wrong encodings or sizes: a warning and the frame is skipped; good frames still work."""
    # Warnings throttled to 0.1 s instead of 2 s, so that each bad frame gets its own quickly.
    perception = NodeProcess(colcon_install, ros_env, tmp_path, 'perception',
                             {'warn_period': 0.1})
    with UR10Sim(scene_config()) as sim:
        rgb, depth = sim.render_rgb_depth()
        intrinsics = sim.intrinsics
        truth = sim.goal_position
    camera = CameraFeed(client, perception)
    good = {'color': rgb, 'depth': depth, 'info': intrinsics}

    bad = [
        (rgb[:, :, 0].copy(), depth, {'color_encoding': 'mono8'}, "encoding 'mono8'"),
        (rgb, depth.astype(np.float32), {'depth_encoding': '32FC1'}, "encoding '32FC1'"),
        (rgb, depth[:240].copy(), {}, 'not aligned'),
        (rgb[:240].copy(), depth[:240].copy(), {}, 'camera_info is 640x480'),
    ]
    try:
        for color, depth_image, kwargs, message in bad:
            camera.until(lambda: message in perception.log(), f'no warning "{message}"',
                         perception, dict(good, color=color, depth=depth_image, **kwargs))
        assert client.goals == []
        assert perception.log().count('[WARN]') >= len(bad)
        sent = camera.until(lambda: client.goals, 'no goal from good frames', perception, good)
        stamp, point, _ = client.goals[-1]
        assert stamp in sent
        assert np.linalg.norm(point - truth) < TOLERANCE

        # Parameters at runtime (ros2 param set /perception ...): validated, then applied.
        results = client.set_perception(goal_hsv_low=[0, 0])
        assert not results[0].successful and 'goal_hsv_low' in results[0].reason
        results = client.set_perception(obstacle_hsv_high=[8, 255, 256])
        assert not results[0].successful and 'obstacle_hsv' in results[0].reason
        assert client.set_perception(min_blob_area=10**6)[0].successful   # nothing that big
        client.spin_for(0.5)            # goals of frames sent before
        count = len(client.goals)
        camera.until(lambda: 'no goal marker visible' in perception.log(), 'no warning',
                     perception, good)
        assert len(client.goals) == count
        assert client.set_perception(min_blob_area=40)[0].successful
        camera.until(lambda: len(client.goals) > count, 'no goal after min_blob_area 40',
                     perception, good)
    finally:
        code = perception.stop()
    assert code == 0, perception.log()
    assert 'Traceback' not in perception.log()

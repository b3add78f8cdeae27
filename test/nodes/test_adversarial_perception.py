"""
Attacks on perception through its camera topics, against the installed node.

One ``perception`` from the colcon install (warnings throttled to 0.1 s), fed by this test as a
RealSense driver would (:class:`test_perception_node.CameraFeed`) with frames the simulation
renders here. Each row of :data:`ATTACKS` is what an adversarial user with ``ros2 topic pub`` or a
small rclpy script sends: camera_info no D435 has (fx = fy = 1e-300 put the goal at 1e301 m), a
skewed camera matrix, an image size no D435 has, depth flagged big-endian with little-endian data
(goal at (-11.8, 1.0, -14.9)), depth in metres, an all-green frame (goal at z = 0.15), an all-red
one, the goal marker floating above the table. For every row:

- the node stays up and publishes nothing absurd: no goal of an attacking frame, and obstacles
  only where the true ones are;
- a WARN line names the reason;
- the next good frame gives a goal within :data:`TOLERANCE` of the simulation's truth.
"""

import dataclasses

from conftest import NodeProcess
import cv2
from etdmp_ros.geometry.camera import CameraIntrinsics
from etdmp_ros.ros.system import scene_config
from etdmp_ros.sim import UR10Sim
import numpy as np
import pytest
from test_perception_node import CameraFeed, Client

#: A good frame after an attack: its goal this close to the truth (m).
TOLERANCE = 0.003
#: Green of the goal marker and red of the obstacles (inside goal_hsv_low..high and
#: obstacle_hsv_low..high).
GREEN, RED = (25, 190, 50), (200, 25, 25)


def _scaled(frame, width, height):
    """Return ``frame`` resized (nearest pixel), intrinsics scaled with it."""
    k = frame['info']
    sx, sy = width / k.width, height / k.height
    return dict(frame, color=cv2.resize(frame['color'], (width, height),
                                        interpolation=cv2.INTER_NEAREST),
                depth=cv2.resize(frame['depth'], (width, height),
                                 interpolation=cv2.INTER_NEAREST),
                info=CameraIntrinsics(width, height, k.fx * sx, k.fy * sy,
                                      (k.cx + 0.5) * sx - 0.5, (k.cy + 0.5) * sy - 0.5))


def _skew(color, depth, info):
    k = list(info.k)
    k[1] = 50.0
    info.k = k


def _big_endian(color, depth, info):
    depth.is_bigendian = 1           # the data stays little-endian


#: name -> (frame from the good one, text the WARN must hold).
ATTACKS = {
    'camera_info fx = fy = 1e-300': (
        lambda f: dict(f, info=dataclasses.replace(f['info'], fx=1e-300, fy=1e-300)),
        'camera_info fx = 1e-300 px gives a horizontal field of view of 180.0 deg'),
    'camera_info principal point off the image': (
        lambda f: dict(f, info=dataclasses.replace(f['info'], cx=5000.0)),
        'camera_info principal point (5000, 239.5) px is more than 10%'),
    'camera_info with skew': (
        lambda f: dict(f, edit=_skew), 'camera_info K is not a pinhole camera matrix'),
    'image size no D435 has': (
        lambda f: _scaled(f, 160, 120), 'camera_info image size 160x120 is no D435 colour mode'),
    'depth flagged big-endian': (
        lambda f: dict(f, edit=_big_endian), 'depth 16UC1 image flagged big-endian'),
    'depth in metres': (
        lambda f: dict(f, depth=f['depth'] // 1000),
        'goal marker seen but not located: depth 0.001 m is outside what a D435 measures'),
    'all-green frame': (
        lambda f: dict(f, color=np.full_like(f['color'], GREEN)),
        'goal marker seen but not located: blob of 307200 px: more than a goal can cover'),
    'all-red frame': (
        lambda f: dict(f, color=np.full_like(f['color'], RED)),
        '1 obstacle blob(s) not reported: blob of 307200 px: more than an obstacle can cover'),
    'goal floating above the table': (
        lambda f: dict(f, color=f['floating'][0], depth=f['floating'][1]),
        'goal marker seen but not located: top face at z = 0.150 m, off the table plane'),
}


@pytest.fixture(scope='module')
def scene():
    """Return the good frame (and the goal floating 15 cm up) and the truth, rendered here."""
    with UR10Sim(scene_config()) as sim:
        rgb, depth = sim.render_rgb_depth()
        truth = (sim.goal_position.copy(), np.asarray(sim.obstacle_positions).copy())
        sim.set_goal((0.8, 0.1, 0.15))
        floating = sim.render_rgb_depth()
        return {'color': rgb, 'depth': depth, 'info': sim.intrinsics}, floating, truth


@pytest.fixture(scope='module')
def attacked(colcon_install, module_ros_env, tmp_path_factory):
    """Return (client, camera, perception): one node for every row, in the module's domain."""
    perception = NodeProcess(colcon_install, module_ros_env, tmp_path_factory.mktemp('adv'),
                             'perception', {'warn_period': 0.1})
    client = Client()
    try:
        yield client, CameraFeed(client, perception), perception
    finally:
        code = perception.stop()
        client.close()
        assert code == 0, perception.log()
        assert 'Traceback' not in perception.log()


@pytest.mark.parametrize('attack', ATTACKS)
def test_an_attack_is_refused_and_the_next_good_frame_gives_the_goal(attacked, scene, attack):
    client, camera, perception = attacked
    good, floating, (goal, obstacles) = scene
    make, reason = ATTACKS[attack]
    frame = make(dict(good, floating=floating))
    frame.pop('floating')
    logged = len(perception.log())
    goals, obstacle_sets = len(client.goals), len(client.obstacles)

    bad = set(camera.until(lambda: reason in perception.log()[logged:],
                           f'a warning "{reason}"', perception, frame))
    warnings = [line for line in perception.log()[logged:].splitlines() if reason in line]
    assert all('[WARN]' in line for line in warnings), warnings
    camera.until(lambda: any(s > max(bad) for s, _, _ in client.goals[goals:]),
                 'a goal from the good frames after the attack', perception, good)
    client.spin_for(0.3)   # the last frames' outputs

    assert perception.process.poll() is None
    assert not [s for s, _, _ in client.goals[goals:] if s in bad], 'a goal of an attacking frame'
    for stamp, point, frame_id in client.goals[goals:]:
        assert frame_id == 'base_link'
        assert np.linalg.norm(point - goal) < TOLERANCE, (stamp, point, goal)
    for stamp, points in client.obstacles[obstacle_sets:]:
        assert stamp in bad or len(points) == len(obstacles), (stamp, points)
        for point in points:     # none where no obstacle is
            assert np.min(np.linalg.norm(obstacles - point, axis=1)) < TOLERANCE, (stamp, point)

"""
The simulated camera of ur10_sim, in a process of its own (``ur10_sim`` starts and stops it).

Rendering a 640x480 colour + depth frame costs ~7 ms of CPU and publishing it holds Python's
interpreter lock for a millisecond or more (rclpy converts and sends the 1.5 MB while holding
it). In the simulation's process that made its loop late: at 500 Hz with an image subscriber,
1 to 11 ticks in 11 s came more than 3 periods late with the camera rendering there, 1 to 3
with it here, most of them in the first 0.1 s while this process starts (ur10_sim alone, its
own count, 2 runs each). So the simulation only takes a snapshot of the scene when a frame is due
(:meth:`UR10Sim.camera_state`, microseconds) and sends it here over a local socket, without
ever waiting: if this process is behind, it renders the newest snapshot and skips the others.

This process builds the same workcell from the same parameters (``ur10_sim``'s, passed as
JSON), renders each snapshot, and publishes the colour and depth images and their
camera_info under ur10_sim's topic names, stamped with the snapshot's simulated time; images
are rendered only while someone subscribes to them. Its node is named ``<ur10_sim>_camera``,
in ur10_sim's namespace, without parameter services (its parameters are ur10_sim's). It ends
when ur10_sim closes the socket (or dies); Ctrl-C is left to ur10_sim, which stops it.

It runs at the same CPU priority as the simulation, deliberately: a niced camera or perception
process (tried: niceness 10 and 5) made the simulation's loop stall for 100-350 ms next to a busy
core, one run in three. Fast DDS's shared-memory ports are guarded by mutexes shared between
processes: a low-priority reader preempted while holding its port's mutex blocks every writer
sending to it, the simulation's included (py-spy: its publish waiting in RTPSWriter::send_nts).
"""

import argparse
import json
import signal
import socket
import struct
import subprocess
import sys
import time

from etdmp_ros.ros import fastdds_files, topics
import numpy as np

#: Snapshot header: stamp (ns, int64), simulated time (s, float64), obstacles in use (int32).
_HEADER = struct.Struct('<qdi')


def encode(state, stamp_ns):
    """Return the bytes of a :class:`CameraState` and its stamp (what ur10_sim sends)."""
    return (_HEADER.pack(int(stamp_ns), state.time, state.obstacles)
            + np.concatenate([state.qpos, state.mocap_pos.ravel(), state.mocap_quat.ravel(),
                              state.obstacle_radii]).astype('<f8').tobytes())


def decode(data, nq, nmocap, nobstacles):
    """Return ``(CameraState, stamp ns)`` from :func:`encode`'s bytes; ValueError if malformed."""
    from etdmp_ros.sim import CameraState
    values = np.frombuffer(data, dtype='<f8', offset=_HEADER.size)
    if len(data) < _HEADER.size or values.size != nq + 7 * nmocap + nobstacles:
        raise ValueError(f'camera snapshot of {len(data)} bytes does not fit the model')
    stamp_ns, time, obstacles = _HEADER.unpack_from(data)
    mocap = values[nq:nq + 7 * nmocap]
    return (CameraState(time, values[:nq].copy(), mocap[:3 * nmocap].reshape(nmocap, 3),
                        mocap[3 * nmocap:].reshape(nmocap, 4), obstacles,
                        values[nq + 7 * nmocap:].copy()), stamp_ns)


class CameraPublishers:
    """
    The colour and depth images of one camera and their camera_info, on ``topics``.

    One piece for both places that publish frames: this process, and ur10_sim itself when it
    renders in the calling thread (``UR10SimNode.run_for``: benchmarks, in-process tests).
    """

    def __init__(self, node, topics, intrinsics):
        """Create the four publishers on ``node``; ``topics`` maps color, depth, *_info."""
        from etdmp_ros.robot import CAMERA_OPTICAL_FRAME as OPTICAL_FRAME
        from etdmp_ros.ros.conversions import camera_info_msg
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import CameraInfo, Image
        images = QoSProfile(depth=2)   # frames are big: never queue more than one behind
        self.color = node.create_publisher(Image, topics['color'], images)
        self.depth = node.create_publisher(Image, topics['depth'], images)
        self.infos = [node.create_publisher(CameraInfo, topics[name], QoSProfile(depth=10))
                      for name in ('color_info', 'depth_info')]
        self.info = camera_info_msg(intrinsics, frame_id=OPTICAL_FRAME)
        self.frame_id = OPTICAL_FRAME

    def publish(self, sim, state, stamp, times=None):
        """
        Publish a frame of ``sim`` in ``state``: images only while someone subscribes.

        ``times``, if given, gets the CPU seconds of rendering and of publishing the images
        added to its ``render`` and ``publish_images``.
        """
        from etdmp_ros.ros.conversions import image_msg
        if self.color.get_subscription_count() or self.depth.get_subscription_count():
            c0 = time.process_time()
            rgb, depth_mm = sim.render_rgb_depth(state)
            c1 = time.process_time()
            self.color.publish(image_msg(rgb, 'rgb8', stamp, self.frame_id))
            self.depth.publish(image_msg(depth_mm, '16UC1', stamp, self.frame_id))
            if times is not None:
                times['render'] += c1 - c0
                times['publish_images'] += time.process_time() - c1
        self.info.header.stamp = stamp
        for publisher in self.infos:
            publisher.publish(self.info)


def command(fd, parameters, topics, node_name, namespace):
    """Return the argv of the camera process (``fd``: its end of the socket)."""
    return [sys.executable, '-m', 'etdmp_ros.nodes._sim_camera', '--fd', str(fd),
            '--parameters', json.dumps(parameters), '--topics', json.dumps(topics),
            '--ros-args', '-r', f'__node:={node_name}', '-r', f'__ns:={namespace}']


class CameraProcess:
    """
    The camera process seen from the simulation's side: ``ur10_sim`` starts, feeds and stops it.

    :meth:`offer` never blocks: a snapshot that does not fit the socket's buffer (the camera
    process is stuck) is dropped (``stats['frames_dropped']``); one that the process is too
    slow to render is skipped there (it logs how many when it stops).
    """

    def __init__(self, node):
        """Start the camera process with the node's parameters and topic names."""
        self._node = node
        self._link, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._link.setblocking(False)
        parameters = {k: (list(v) if isinstance(v, tuple) else v)
                      for k, v in node._parameter_values.items()}
        argv = command(theirs.fileno(), parameters, topics.CAMERA,
                       f'{node.get_name()}_camera', node.get_namespace())
        self.process = subprocess.Popen(argv, pass_fds=(theirs.fileno(),))
        theirs.close()
        self._lost = False

    def offer(self, state, stamp_ns):
        """Send a camera state to be rendered (dropped if the process cannot take it now)."""
        if self._lost:
            return
        try:
            self._link.send(encode(state, stamp_ns))
        except BlockingIOError:
            self._node.stats['frames_dropped'] += 1
        except OSError as exc:   # the camera process has gone
            self._lost = True
            self._node.get_logger().error(
                f'camera process exited (code {self.process.poll()}): {exc}; no more camera '
                'frames')
        else:
            self._node.stats['frames'] += 1

    def stop(self):
        """Close the socket (the process finishes its frame and exits); kill it if it hangs."""
        self._link.close()
        try:
            self.process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            removed = fastdds_files.clean()     # what the killed process left in /dev/shm
            self._node.get_logger().warning(
                f'camera process did not exit within 5 s: killed; {len(removed)} of its Fast '
                'DDS files removed')


def _newest(link):
    """
    Wait for a snapshot on ``link``; return the newest one waiting and how many it replaced.

    Returns (b'', 0) when ur10_sim closed its end.
    """
    data, older = link.recv(65536), 0
    if not data:
        return data, 0
    link.setblocking(False)
    try:
        while True:
            newer = link.recv(65536)
            if not newer:
                break
            data, older = newer, older + 1
    except BlockingIOError:
        pass
    link.setblocking(True)
    return data, older


def main(argv=None):
    """Render and publish the snapshots that arrive on the socket until it closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # ur10_sim stops this process
    parser = argparse.ArgumentParser()
    parser.add_argument('--fd', type=int, required=True)
    parser.add_argument('--parameters', required=True)
    parser.add_argument('--topics', required=True)
    args, ros_args = parser.parse_known_args(argv)
    link = socket.socket(fileno=args.fd)

    from etdmp_ros.ros.spin import init
    from etdmp_ros.sim import MAX_OBSTACLES, UR10Sim
    from etdmp_ros.ros.conversions import ns_to_stamp
    import rclpy
    from rclpy.node import Node

    from etdmp_ros.ros.events import ERROR, EventPublisher

    init(ros_args)
    node = Node('camera', start_parameter_services=False)
    log = node.get_logger()
    events = EventPublisher(node)
    published = skipped = early = 0       # early: snapshots sent while this process started
    try:
        sim = UR10Sim.from_parameters(json.loads(args.parameters))
        camera = CameraPublishers(node, json.loads(args.topics), sim.intrinsics)
        nq, nmocap = sim.model.nq, sim.model.nmocap
        while rclpy.ok():
            data, older = _newest(link)
            if not data:
                break                        # ur10_sim closed its end: done
            if published:
                skipped += older
            else:
                early += older
            state, stamp_ns = decode(data, nq, nmocap, MAX_OBSTACLES)
            camera.publish(sim, state, ns_to_stamp(stamp_ns))
            published += 1
    except Exception as exc:   # noqa: B902 - say why the camera stopped, then exit
        log.error(f'camera stopped: {type(exc).__name__}: {exc}')
        events.publish('failed', f'camera stopped: {type(exc).__name__}: {exc}', ERROR,
                       reason=f'{type(exc).__name__}: {exc}')
        return 1
    finally:
        text = (f'camera stopped: {published} frames published, {skipped} skipped (rendering '
                f'slower than the camera rate), {early} sent before the camera was ready')
        log.info(text)
        events.publish('stopped', text, frames=published, skipped=skipped, early=early)
        if 'sim' in locals():
            sim.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""
dmp_server's /etdmp/markers: a plan, the other method's plan, the demonstration, tool frames.

Built and published by a worker thread after the service's response (the newest plan wins), so
that markers never delay a plan; a failure is logged, never raised (markers are a view).
"""

from dataclasses import replace
import threading

from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.ros.conversions import points_from_numpy
from etdmp_ros.skills.planning import place_demo, plan_path
import numpy as np
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray


class PlanMarkers:
    """The markers of dmp_server's plans, published on ``publisher`` by a worker thread."""

    def __init__(self, publisher, core_lock, logger):
        """Publish on ``publisher``; plan the comparison under ``core_lock`` (the skills')."""
        self._publisher, self._core_lock, self._logger = publisher, core_lock, logger
        self._lock = threading.Lock()
        self._pending = None
        self._thread = None

    def wanted(self):
        """Return whether anyone subscribes to the markers."""
        return self._publisher.get_subscription_count() > 0

    def request(self, settings, skill, plan, header):
        """Have the markers of a plan published by the worker thread (the newest plan wins)."""
        with self._lock:
            self._pending = (settings, skill, plan, header)
            if self._thread is not None:
                return   # it takes the newest pending plan when it is done with this one
            self._thread = threading.Thread(target=self._worker, daemon=True, name='markers')
            self._thread.start()

    def _worker(self):
        while True:
            with self._lock:
                pending, self._pending = self._pending, None
                if pending is None:
                    self._thread = None
                    return
            try:
                self._publish(*pending)
            except Exception as err:   # noqa: B902 - markers are a view: never take the node down
                self._logger.error(f'/etdmp/markers not published: {err}')

    def _publish(self, settings, skill, plan, header):
        """Publish the markers of ``plan``: it, the other method's plan, the demo, the frames."""
        other = 'dmp' if plan.method == 'etdmp' else 'etdmp'
        plane = settings.plane if skill.dim == 2 else None
        with self._core_lock:
            try:
                baseline = plan_path(skill, plan.start, plan.goal, plan.obstacles,
                                     replace(settings.plan, method=other),
                                     settings.plane).positions
            except ValueError:   # e.g. the plain DMP refuses a closed letter: show none
                baseline = None
            try:
                demo = place_demo(skill, plan.start, plan.goal, plane, settings.plan.mode,
                                  settings.plan.independent_axis)
            except ValueError:
                demo = None
        colours = {'etdmp': (0.1, 0.8, 0.2, 1.0), 'dmp': (1.0, 0.5, 0.0, 1.0)}
        markers = MarkerArray(markers=[
            _marker(header, 'demo', Marker.LINE_STRIP, demo, (0.6, 0.6, 0.6, 0.8), 0.003),
            _marker(header, f'plan_{plan.method}', Marker.LINE_STRIP, plan.positions,
                    colours[plan.method], 0.005),
            _marker(header, f'plan_{other}', Marker.LINE_STRIP, baseline, colours[other],
                    0.003),
            _marker(header, 'obstacles', Marker.SPHERE_LIST, plan.obstacles,
                    (0.9, 0.1, 0.1, 0.9), 0.03),
            _marker(header, 'start_goal', Marker.SPHERE_LIST, np.stack([plan.start, plan.goal]),
                    (0.2, 0.4, 1.0, 1.0), 0.015),
            _axes_marker(header, 'orientation', plan.positions, plan.orientations),
        ])
        self._publisher.publish(markers)


def _marker(header, ns, kind, points, rgba, size):
    """Return a base_link Marker showing ``points`` (n, 3), or deleting ``ns`` when None/empty."""
    marker = Marker(header=header, ns=ns, id=0, type=kind)
    if points is None or len(points) == 0:
        marker.action = Marker.DELETE
        return marker
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = float(size)
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = (float(c) for c in rgba)
    marker.points = points_from_numpy(points)
    return marker


#: Tool frames shown along a plan on /etdmp/markers (namespace ``orientation``), and the length
#: (m) and width of their axes.
MARKER_AXES, MARKER_AXIS_LENGTH, MARKER_AXIS_WIDTH = 12, 0.04, 0.003
_AXIS_COLOURS = (ColorRGBA(r=1.0, a=1.0), ColorRGBA(g=1.0, a=1.0), ColorRGBA(b=1.0, a=1.0))


def _axes_marker(header, ns, positions, orientations):
    """
    Return a LINE_LIST Marker of the tool's axes at MARKER_AXES poses evenly spread in time.

    Each frame is three lines from the pose's position along the tool's x (red), y (green) and
    z (blue) axes, MARKER_AXIS_LENGTH long: the orientation the plan gives the tool there.
    """
    if len(positions) == 0:
        return _marker(header, ns, Marker.LINE_LIST, None, None, 0.0)
    idx = np.unique(np.linspace(0, len(positions) - 1, MARKER_AXES).round().astype(int))
    axes = quat.to_matrix(quat.normalized(orientations[idx]))      # (k, 3, 3): columns x, y, z
    tips = positions[idx, None, :] + MARKER_AXIS_LENGTH * np.swapaxes(axes, 1, 2)
    points = np.stack([np.repeat(positions[idx, None, :], 3, axis=1), tips], axis=2)
    marker = _marker(header, ns, Marker.LINE_LIST, points.reshape(-1, 3), (1, 1, 1, 1),
                     MARKER_AXIS_WIDTH)
    marker.colors = [c for _ in idx for c in _AXIS_COLOURS for _ in range(2)]
    return marker

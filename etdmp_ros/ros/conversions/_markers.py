"""
visualization_msgs/MarkerArray <-> numpy: obstacle volumes and contacts.

Both are marker arrays so that RViz and Foxglove show them as they are, with no plugin: ROS 2's
common interfaces have no message for a cylinder obstacle (``moveit_msgs/CollisionObject`` with
a ``shape_msgs/SolidPrimitive`` would be one, but MoveIt's messages are not installed here) nor
for a contact (``gazebo_msgs/ContactsState`` and ``ros_gz_interfaces/Contacts`` belong to their
simulators). Each array starts with a DELETEALL marker, so a volume or contact that is gone
disappears from the display, and carries everything in standard fields:

- obstacle volumes (perception): one CYLINDER per obstacle, namespace ``obstacles``, id its
  index in ``/etdmp/obstacles``; ``pose.position`` the cylinder's centre (RViz's CYLINDER is
  centred on its pose), ``scale.x = scale.y`` its diameter, ``scale.z`` its height (from the
  table, z = 0, to its top face). The top-face centre of ``/etdmp/obstacles`` is
  ``pose.position + scale.z / 2`` up.
- contacts (the simulation's ground truth): one SPHERE per contact at its point, namespace
  ``contacts``, ``text`` ``"<part> <item> <depth mm>"`` (e.g. ``wrist_2_link obstacle_1
  3.2``); an empty array (the DELETEALL alone) says there is none.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from typing import Any

from builtin_interfaces.msg import Time
from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import ArrayLike
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ._geometry import ns_to_stamp

OBSTACLES_NS = 'obstacles'
CONTACTS_NS = 'contacts'
OBSTACLE_COLOR = ColorRGBA(r=0.9, g=0.1, b=0.1, a=0.5)
CONTACT_COLOR = ColorRGBA(r=1.0, g=0.0, b=1.0, a=1.0)
#: Diameter (m) of a contact's sphere (at least: a deeper contact shows as deep as it is).
CONTACT_SIZE = 0.01


def _header(marker: Marker, stamp: Time | int, frame_id: str) -> None:
    marker.header.stamp = stamp if not isinstance(stamp, int) else ns_to_stamp(stamp)
    marker.header.frame_id = frame_id


def _delete_all(stamp: Time | int, frame_id: str, ns: str) -> Marker:
    marker = Marker(ns=ns, action=Marker.DELETEALL)
    _header(marker, stamp, frame_id)
    return marker


def cylinder_markers(tops: ArrayLike, radii: ArrayLike, stamp: Time | int,
                     frame_id: str = 'base_link') -> MarkerArray:
    """
    Return the MarkerArray of upright cylinders standing on z = 0 (obstacle volumes).

    ``tops`` (n, 3): the centre of each top face (its z is the height); ``radii`` (n,) in m;
    ``stamp``: a builtin_interfaces Time or integer nanoseconds.
    """
    points = np.asarray(tops, dtype=float).reshape(-1, 3)
    sizes = np.asarray(radii, dtype=float).reshape(-1)
    if len(sizes) != len(points):
        raise ValueError(f'{len(points)} cylinders but {len(sizes)} radii')
    markers = [_delete_all(stamp, frame_id, OBSTACLES_NS)]
    for i, (top, radius) in enumerate(zip(points, sizes)):
        marker = Marker(ns=OBSTACLES_NS, id=i, type=Marker.CYLINDER, action=Marker.ADD)
        _header(marker, stamp, frame_id)
        height = max(float(top[2]), 0.0)
        marker.pose.position.x, marker.pose.position.y = float(top[0]), float(top[1])
        marker.pose.position.z = float(top[2]) - 0.5 * height
        marker.pose.orientation.w = 1.0
        marker.scale.x = marker.scale.y = 2.0 * float(radius)
        marker.scale.z = height
        marker.color = OBSTACLE_COLOR
        markers.append(marker)
    return MarkerArray(markers=markers)


def cylinders_from_markers(msg: MarkerArray, frame_ids: Collection[str] = ('', 'base_link')
                           ) -> tuple[Array, Array]:
    """
    Return ``(tops (n, 3), radii (n,))`` of the CYLINDER markers ADDed in a MarkerArray.

    Markers of other types or actions are skipped. Raises ValueError for a marker in a frame
    not in ``frame_ids``, a rotated or non-circular cylinder, or values that are not finite and
    positive where they must be.
    """
    tops: list[tuple[float, float, float]] = []
    radii: list[float] = []
    for marker in msg.markers:
        if marker.type != Marker.CYLINDER or marker.action != Marker.ADD:
            continue
        if marker.header.frame_id not in frame_ids:
            raise ValueError(f'a cylinder in frame {marker.header.frame_id!r}, not base_link')
        p, q, s = marker.pose.position, marker.pose.orientation, marker.scale
        values = np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w, s.x, s.y, s.z], dtype=float)
        if not np.all(np.isfinite(values)):
            raise ValueError('a cylinder with NaN or inf')
        norm = q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w
        if abs(q.x) + abs(q.y) > 1e-6 or abs(norm - 1.0) > 1e-3:
            raise ValueError('a cylinder that is not upright (its orientation must turn it '
                             'about z only)')
        if not (s.x > 0.0 and s.z >= 0.0) or abs(s.x - s.y) > 1e-6 * max(s.x, 1.0):
            raise ValueError(f'a cylinder of scale ({s.x:g}, {s.y:g}, {s.z:g}): it must be '
                             'round (x = y > 0) with a height >= 0')
        tops.append((p.x, p.y, p.z + 0.5 * s.z))
        radii.append(0.5 * s.x)
    return np.array(tops, dtype=float).reshape(-1, 3), np.array(radii, dtype=float)


def contact_markers(contacts: Iterable[Any], stamp: Time | int, frame_id: str = 'base_link'
                    ) -> MarkerArray:
    """
    Return the MarkerArray of contacts (:class:`etdmp_ros.sim.Contact` or alike).

    Each has ``part``, ``item``, ``position`` (3,) and ``depth`` (m).
    """
    markers = [_delete_all(stamp, frame_id, CONTACTS_NS)]
    for i, contact in enumerate(contacts):
        marker = Marker(ns=CONTACTS_NS, id=i, type=Marker.SPHERE, action=Marker.ADD)
        _header(marker, stamp, frame_id)
        marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = (
            float(v) for v in contact.position)
        marker.pose.orientation.w = 1.0
        size = max(CONTACT_SIZE, 2.0 * float(contact.depth))
        marker.scale.x = marker.scale.y = marker.scale.z = size
        marker.color = CONTACT_COLOR
        marker.text = f'{contact.part} {contact.item} {contact.depth * 1e3:.1f}'
        markers.append(marker)
    return MarkerArray(markers=markers)


def contacts_from_markers(msg: MarkerArray) -> list[tuple[str, str, float]]:
    """Return the contacts of :func:`contact_markers`' array: [(part, item, depth m)]."""
    found: list[tuple[str, str, float]] = []
    for marker in msg.markers:
        if marker.ns != CONTACTS_NS or marker.action != Marker.ADD:
            continue
        part, other, depth = marker.text.split()
        found.append((part, other, float(depth) * 1e-3))
    return found

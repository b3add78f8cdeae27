"""
Frames in: the checks a colour + depth frame passes, and the matching of its messages by stamp.

:class:`FrameSynchronizer` matches colour, depth and camera_info by stamp for the node (no
message_filters): it keeps the newest complete set only, so processing never falls behind.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
import math
from typing import Any

from etdmp_ros import limits
from etdmp_ros.geometry.camera import CameraIntrinsics
import numpy as np
from numpy.typing import ArrayLike


def check_frame(rgb: ArrayLike, depth_mm: ArrayLike, intrinsics: CameraIntrinsics) -> None:
    """
    Raise ValueError unless the frame can be processed.

    ``rgb``: uint8 (H, W, 3); ``depth_mm``: uint16 (H, W) aligned to it; ``intrinsics``: a
    :class:`CameraIntrinsics` of size W x H.
    """
    rgb = np.asarray(rgb)
    depth_mm = np.asarray(depth_mm)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f'colour image must be uint8 (H, W, 3), got {rgb.dtype} {rgb.shape}')
    if depth_mm.dtype != np.uint16 or depth_mm.ndim != 2:
        raise ValueError(f'depth image must be uint16 (H, W) millimetres, got {depth_mm.dtype} '
                         f'{depth_mm.shape}')
    if depth_mm.shape != rgb.shape[:2]:
        raise ValueError(f'depth {depth_mm.shape[1]}x{depth_mm.shape[0]} is not aligned to the '
                         f'colour image {rgb.shape[1]}x{rgb.shape[0]}')
    check_intrinsics(intrinsics)
    if (intrinsics.width, intrinsics.height) != (rgb.shape[1], rgb.shape[0]):
        raise ValueError(f'camera_info is {intrinsics.width}x{intrinsics.height} but the images '
                         f'are {rgb.shape[1]}x{rgb.shape[0]}')


def check_intrinsics(intrinsics: object) -> None:
    """
    Raise ValueError unless ``intrinsics`` can be a RealSense D435 colour camera's.

    Image size, the fields of view that fx and fy give, square pixels and a principal point
    near the image centre, within the limits of :mod:`etdmp_ros.limits` (a dozen float
    operations).
    """
    if not isinstance(intrinsics, CameraIntrinsics):
        raise ValueError(f'intrinsics must be a CameraIntrinsics, got {type(intrinsics).__name__}')
    k = intrinsics
    (w_low, w_high), (h_low, h_high) = limits.CAMERA_WIDTH_RANGE, limits.CAMERA_HEIGHT_RANGE
    if not (w_low <= k.width <= w_high and h_low <= k.height <= h_high):
        raise ValueError(f'camera_info image size {k.width}x{k.height} is no D435 colour mode '
                         f'({w_low}x{h_low} to {w_high}x{h_high})')
    for axis, size, f, (low, high) in (('horizontal', k.width, k.fx, limits.CAMERA_HFOV_RANGE),
                                       ('vertical', k.height, k.fy, limits.CAMERA_VFOV_RANGE)):
        fov = math.degrees(2.0 * math.atan(0.5 * size / f))
        if not low <= fov <= high:
            name = 'fx' if axis == 'horizontal' else 'fy'
            raise ValueError(f'camera_info {name} = {f:.6g} px gives a {axis} field of view of '
                             f'{fov:.1f} deg at {k.width}x{k.height}; a D435 sees {low:g} to '
                             f'{high:g} deg')
    if abs(k.fx - k.fy) > limits.MAX_FOCAL_ASPECT_ERROR * k.fx:
        raise ValueError(f'camera_info fx = {k.fx:.6g} and fy = {k.fy:.6g} px differ by more '
                         f'than {limits.MAX_FOCAL_ASPECT_ERROR:.0%} (a D435 has square pixels)')
    offset = limits.MAX_PRINCIPAL_POINT_OFFSET
    if abs(k.cx - 0.5 * (k.width - 1)) > offset * k.width or \
            abs(k.cy - 0.5 * (k.height - 1)) > offset * k.height:
        raise ValueError(f'camera_info principal point ({k.cx:.6g}, {k.cy:.6g}) px is more than '
                         f'{offset:.0%} of the image size from the centre of {k.width}x{k.height}')


class FrameSynchronizer:
    """
    Match messages of several streams (colour, depth, camera_info) by their stamps.

    :meth:`add` stores a message (keeping the last ``queue_size`` per stream) and returns the
    NEWEST complete set whose stamps are all within ``tolerance_ns`` of each other and newer
    than the last set returned, or None. Everything older than a returned set is dropped, so a
    slow consumer only ever sees the latest frame. Stamps are integer nanoseconds; a stamp more
    than ``reset_ns`` older than the last returned one means time went back (a restarted
    simulation, a looping bag): the synchronizer starts over.
    """

    def __init__(self, streams: Iterable[str], tolerance_ns: int, queue_size: int = 4,
                 reset_ns: int = 1_000_000_000) -> None:
        """Create empty queues for the named streams."""
        if not streams:
            raise ValueError('FrameSynchronizer needs at least one stream')
        if tolerance_ns < 0:
            raise ValueError(f'tolerance must be >= 0, got {tolerance_ns} ns')
        self.streams = tuple(streams)
        self.tolerance_ns = int(tolerance_ns)
        self.reset_ns = int(reset_ns)
        self._queues: dict[str, deque[tuple[int, Any]]] = {
            name: deque(maxlen=max(1, int(queue_size))) for name in self.streams}
        self.last_stamp: int | None = None
        self.dropped = 0

    def reset(self) -> None:
        """Forget all stored messages and the last returned stamp."""
        for queue in self._queues.values():
            queue.clear()
        self.last_stamp = None

    def add(self, stream: str, stamp_ns: int, message: Any
            ) -> tuple[int, dict[str, Any]] | None:
        """Store a message; return ``(stamp_ns, {stream: message})`` when a set completes."""
        stamp_ns = int(stamp_ns)
        if self.last_stamp is not None and stamp_ns <= self.last_stamp:
            if self.last_stamp - stamp_ns <= self.reset_ns:
                self.dropped += 1
                return None
            self.reset()
        self._queues[stream].append((stamp_ns, message))
        return self._match()

    def _match(self) -> tuple[int, dict[str, Any]] | None:
        first = self.streams[0]
        for stamp, message in sorted(self._queues[first], key=lambda item: -item[0]):
            found = {first: message}
            for name in self.streams[1:]:
                best = min(self._queues[name], key=lambda item: abs(item[0] - stamp),
                           default=None)
                if best is None or abs(best[0] - stamp) > self.tolerance_ns:
                    break
                found[name] = best[1]
            else:
                self._drop_through(stamp)
                return stamp, found
        return None

    def _drop_through(self, stamp: int) -> None:
        limit = stamp + self.tolerance_ns
        for queue in self._queues.values():
            kept = [item for item in queue if item[0] > limit]
            # Older sets that were never returned: the frames skipped to stay current.
            if queue is self._queues[self.streams[0]]:
                self.dropped += sum(item[0] < stamp - self.tolerance_ns for item in queue)
            queue.clear()
            queue.extend(kept)
        self.last_stamp = stamp

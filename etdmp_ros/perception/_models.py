"""
What perception works with and reports: colour classes, object models, settings, detections.

Every object of the workcell is an upright cylinder of known radius (:class:`ObjectModel`) whose
colour is a box in HSV space (:class:`HsvRange`); one frame's result is a :class:`Detections`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any

import cv2
from etdmp_ros.geometry.arrays import Array
import numpy as np
from numpy.typing import NDArray

#: Pixel box (x, y, width, height) of a blob.
Box = tuple[int, int, int, int]

#: Kinds of detected objects, as in :attr:`Detection.kind`.
GOAL = 'goal'
OBSTACLE = 'obstacle'
BOTTLE = 'bottle'


def _a(noun: str) -> str:
    """Return ``noun`` with its indefinite article (a goal, an obstacle)."""
    return ('an ' if noun[:1] in 'aeiou' else 'a ') + noun


@dataclass(frozen=True)
class HsvRange:
    """
    A colour class as a box in OpenCV's HSV space: ``low`` and ``high`` are ``(h, s, v)``.

    H is in 0..179 (degrees / 2), S and V in 0..255. When ``low[0] > high[0]`` the hue range wraps
    through 0 (red: e.g. low h = 170, high h = 8).
    """

    low: tuple[int, int, int]
    high: tuple[int, int, int]

    def __post_init__(self) -> None:
        """Validate: 3 integers each, H in 0..179, S and V in 0..255, S and V low <= high."""
        bounds = (179, 255, 255)
        values: list[tuple[int, ...]] = []
        for name, value in (('low', self.low), ('high', self.high)):
            try:
                triple = [float(v) for v in value]
            except (TypeError, ValueError):
                raise ValueError(f'HSV {name} must be 3 numbers [h, s, v], got {value!r}') \
                    from None
            if len(triple) != 3 or not all(v == int(v) and 0 <= v <= b
                                           for v, b in zip(triple, bounds)):
                raise ValueError(f'HSV {name} must be integers [h 0..179, s 0..255, v 0..255], '
                                 f'got {list(value)}')
            values.append(tuple(int(v) for v in triple))
        low, high = values
        if low[1] > high[1] or low[2] > high[2]:
            raise ValueError(f'HSV range: S and V need low <= high, got low {list(low)}, '
                             f'high {list(high)}')
        object.__setattr__(self, 'low', low)
        object.__setattr__(self, 'high', high)

    @property
    def wraps(self) -> bool:
        """Whether the hue range wraps through 0 (low h > high h)."""
        return self.low[0] > self.high[0]

    def mask(self, hsv: NDArray[np.uint8]) -> NDArray[Any]:
        """Return the uint8 image (255 inside the range) of an HSV image in OpenCV units."""
        if not self.wraps:
            return cv2.inRange(hsv, self.low, self.high)
        upper = cv2.inRange(hsv, self.low, (179, self.high[1], self.high[2]))
        lower = cv2.inRange(hsv, (0, self.low[1], self.low[2]), self.high)
        return cv2.bitwise_or(upper, lower)


@dataclass(frozen=True)
class ObjectModel:
    """
    A class of objects: its colour and shape, an upright cylinder (radius, height) in metres.

    The reported point of such an object is the centre of its top face. ``radius_range``:
    ``(low, high)`` when each object's radius is measured (obstacles), ``radius`` then being
    where the measurement starts and what is reported when the visible rim is too short to
    measure it; None when every object has ``radius`` (the goal marker, the bottle).
    """

    kind: str
    color: HsvRange
    radius: float
    height: float
    radius_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        """Validate radius, height and radius_range (positive, finite, low < high)."""
        for name in ('radius', 'height'):
            value = float(getattr(self, name))
            if not math.isfinite(value) or value <= 0:
                raise ValueError(f'{self.kind} {name} must be positive, got {value}')
            object.__setattr__(self, name, value)
        if self.radius_range is not None:
            try:
                low, high = (float(v) for v in self.radius_range)
            except (TypeError, ValueError):
                raise ValueError(f'{self.kind} radius range must be [low, high] (m), got '
                                 f'{self.radius_range!r}') from None
            if not (math.isfinite(high) and 0.0 < low < high):
                raise ValueError(f'{self.kind} radius range must be 0 < low < high (m), got '
                                 f'[{low}, {high}]')
            object.__setattr__(self, 'radius_range', (low, high))

    @property
    def max_radius(self) -> float:
        """Return the largest radius an object of this class can have (m)."""
        return self.radius if self.radius_range is None else max(self.radius,
                                                                 self.radius_range[1])

    @property
    def depth_extent(self) -> float:
        """Largest depth difference between two points of the object, plus 2 cm (m)."""
        return 2.0 * self.max_radius + self.height + 0.02


@dataclass(frozen=True)
class DetectorSettings:
    """
    Tuning of :class:`Detector` (pixels and metres).

    ``min_blob_area``: smaller colour blobs are ignored (noise, far or mostly hidden objects).
    ``min_depth_pixels``: a blob needs this many pixels with depth to be located.
    ``top_band``: thickness of the band below the highest points taken as the top face (more
    than the depth noise there). ``occlusion_gap``: an outline pixel next to something nearer to
    the camera by more than this is an occlusion edge, not the object's rim. ``min_rim_points``:
    fewer rim points than this and the top-face centroid is reported instead of the circle fit.
    ``max_rim_rms``: a circle fit worse than this (RMS, m) flags the blob as not one object.
    ``height_tolerance``: a located top face higher than this (m) above its object's height,
    or lower below the table top, is refused.
    """

    min_blob_area: int = 40
    min_depth_pixels: int = 20
    top_band: float = 0.005
    occlusion_gap: float = 0.01
    min_rim_points: int = 8
    max_rim_rms: float = 0.004
    height_tolerance: float = 0.02

    def __post_init__(self) -> None:
        """Validate the values."""
        for name in ('min_blob_area', 'min_depth_pixels', 'min_rim_points'):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f'{name} must be a positive integer, got {value}')
            object.__setattr__(self, name, int(value))
        for name in ('top_band', 'occlusion_gap', 'max_rim_rms', 'height_tolerance'):
            value = float(getattr(self, name))
            if not math.isfinite(value) or value <= 0:
                raise ValueError(f'{name} must be positive (m), got {value}')
            object.__setattr__(self, name, value)


@dataclass(frozen=True, eq=False)
class Detection:
    """
    One located object.

    ``position`` (3,): centre of the top face in base_link (m). ``pixel``: that point in the
    image (u, v). ``area``: blob pixels; ``bbox``: (x, y, w, h) of the blob. ``depth``: the
    blob's median depth (m); ``depth_fraction``: share of its pixels with depth. ``rim_points``:
    outline points used by the circle fit (0: top-face centroid instead); ``rim_rms``: the fit's
    RMS residual (m). ``single``: False when the fit is too poor for one cylinder (objects
    overlapping in the image). ``radius`` (m): measured by the fit (``radius_measured``) when
    its class's radius is measured and enough of the rim is seen, else its class's radius.
    """

    kind: str
    position: Array
    pixel: tuple[float, float]
    area: int
    bbox: Box
    depth: float
    depth_fraction: float
    rim_points: int
    rim_rms: float
    single: bool = True
    radius: float = float('nan')
    radius_measured: bool = False


@dataclass(frozen=True)
class Rejection:
    """A blob that was not reported: its kind, bbox (x, y, w, h), area and the reason."""

    kind: str
    bbox: Box
    area: int
    reason: str


@dataclass(eq=False)
class Detections:
    """Result of one frame: the goal and the bottle (or None), the obstacles, rejected blobs."""

    goal: Detection | None = None
    obstacles: list[Detection] = field(default_factory=list)
    rejected: list[Rejection] = field(default_factory=list)
    bottle: Detection | None = None

    def obstacle_positions(self) -> Array:
        """Return the obstacle points (N, 3) in base_link (N may be 0)."""
        if not self.obstacles:
            return np.zeros((0, 3))
        return np.array([d.position for d in self.obstacles])

    def obstacle_radii(self) -> Array:
        """Return the obstacles' radii (N,) in metres, in the order of obstacle_positions."""
        return np.array([d.radius for d in self.obstacles], dtype=float)

"""
Goal marker and obstacles from a colour image and an aligned depth image (OpenCV + numpy, no ROS).

What is reported. Every object of the workcell is an upright cylinder of known radius ``r``
(the goal marker is a 2 mm thin disc, an obstacle a can of height ``h``), and the point that
stands for it is the centre of its TOP face in base_link, as in the simulation's ground truth
(see :mod:`etdmp_ros.robot._scene`).

Pipeline of :meth:`Detector.detect`, per object class (goal, obstacle):

1. Segmentation: colour to HSV (OpenCV units: H 0..179, S and V 0..255), ``cv2.inRange`` with
   the class's :class:`HsvRange` (a hue range with low > high wraps through 0, as red needs),
   8-connected components of at least ``min_blob_area`` pixels, cut at depth steps (below).
2. Robust depth: the blob's pixels with depth (0 = no data, ignored); their median depth is the
   blob's depth, and pixels farther from it than the object can extend (2 r + h + 2 cm: the
   background seen through a hole, flying pixels at edges) are dropped. A blob with fewer than
   ``min_depth_pixels`` left is rejected ("no depth").
3. Deprojection of those pixels with the intrinsics (:meth:`CameraIntrinsics.deproject`) and
   transform to base_link with the camera pose (:meth:`CameraPose.to_base`).
4. Geometric correction from the known radius, so that the reported point is the top-face
   centre whatever part of the object the camera sees:

   - height of the top face ``z_top``: the median z of the points in the top band (within
     ``top_band`` below the 95th percentile of z). A camera above an obstacle sees its top
     face and its near side; the side's points are lower and left out.
   - axis (x, y): every point of the blob's OUTLINE lies at horizontal distance ``r`` from the
     axis: the far rim of the top face, the two silhouette lines of the side and the near rim
     of the bottom (for the goal disc, simply its rim). A circle of radius ``r`` is fitted to
     those outline points (Gauss-Newton, then once more without outliers), starting from the
     centroid of the top-face points, which lies inside the circle. Outline pixels that are
     not an edge of the object are left out: next to something nearer to the camera by more
     than ``occlusion_gap`` (the arm or another object in front: an occlusion edge), on the
     image border, or without depth. Outline pixels without depth on a flat object (the goal
     disc) are kept, placed where their pixel ray meets the plane ``z = z_top``. (Those with
     depth keep their own point: the disc's near outline is its 2 mm side, and moving it onto
     the top plane along the ray would shift it by ~2 mm towards the camera.) So an object
     partly hidden by the arm, cut by the image border or with holes in its depth is still
     located from the visible part of its rim.
   - fallback: with fewer than ``min_rim_points`` rim points, the centroid of the top-face
     points (``Detection.rim_points == 0``), which is exact only for a fully visible top face.

   The uncorrected estimate (blob centroid pixel deprojected at the median depth) is off by
   25-40 mm for an obstacle seen at 45 degrees; the corrected one is within 3 mm of the ground
   truth on rendered 640x480 frames, also partly occluded (median about 0.5 mm, slightly towards
   the camera: outline pixels lie up to a pixel inside the true rim; test/unit/test_vision.py).

Plausibility (limits in :mod:`etdmp_ros.limits`, section perception and camera input): the
intrinsics must be a D435 colour camera's (:func:`check_intrinsics`: image size, field of view,
square pixels, principal point near the centre), else the frame raises ValueError. A blob is
refused (a :class:`Rejection` naming the reason) when its median depth is outside the D435's
range, when it covers more of the image than its object can at that depth
(``MAX_BLOB_AREA_FACTOR``: checked before the blob is deprojected, so an all-green frame costs
little), or when the located object does not fit the workcell: its points spread wider than
the object, its top face is above the object's height or below the table top (z = 0) by more
than ``height_tolerance`` (lower than its height is what a partly hidden top face shows), or it
lies off the table. So no absurd position is ever reported.

Objects of one colour that overlap in the image (obstacles in a row towards the camera) form one
blob: it is cut where the depth steps by more than ``occlusion_gap`` between neighbouring pixels
(the nearer object's edge), and each part of at least ``min_blob_area`` pixels is an object.
Cylinders closer than that (touching or intersecting) stay one blob; its circle fit is poor and
the detection is flagged (``Detection.single`` False). Several goal blobs: the largest is the
goal, the others are rejected. Obstacles are reported in decreasing blob area.
"""

from __future__ import annotations

from collections.abc import Mapping
import math
from typing import Any

import cv2
from etdmp_ros import limits
from etdmp_ros.geometry.arrays import Array
from etdmp_ros.geometry.camera import CameraIntrinsics, CameraPose
from etdmp_ros.perception._circle import fit_circle, fit_circle_and_radius, rim_arc
from etdmp_ros.perception._frames import check_frame
from etdmp_ros.perception._models import (_a, BOTTLE, Detection, Detections, DetectorSettings,
                                          GOAL, HsvRange, ObjectModel, OBSTACLE, Rejection)
from etdmp_ros.robot._scene import GOAL_MARKER_THICKNESS, SceneConfig
import numpy as np
from numpy.typing import ArrayLike, NDArray

_RIM_KERNEL = np.ones((3, 3), np.uint8)
# An occluder this many pixels from an outline pixel makes it an occlusion edge (2: across the
# one-pixel line that _split removes between two objects of one colour).
_MARGIN = 2
_OCCLUDER_KERNEL = np.ones((2 * _MARGIN + 1, 2 * _MARGIN + 1), np.uint8)
_NO_DEPTH = np.float32(np.inf)
#: A measured radius needs rim points spanning at least this much of the circle (rad): on a
#: shorter arc circles of quite different radii fit about as well.
MIN_RIM_ARC = math.radians(180.0)
# Depth pixels of a blob whose median checks it against the D435's range (a subsample of bigger
# blobs: an all-green frame's median would cost 3 ms).
_DEPTH_SAMPLES = 4096
# Drawing colours (RGB) of the annotated image.
_DRAW = {GOAL: (255, 230, 0), OBSTACLE: (0, 230, 255), BOTTLE: (255, 0, 255),
         'rejected': (150, 150, 150)}


class Detector:
    """
    Locate the goal marker and the obstacles in colour + aligned depth frames.

    ``goal`` and ``obstacle`` are :class:`ObjectModel` instances, ``camera_pose`` the
    :class:`CameraPose` of the colour optical frame in base_link, ``table`` the table top
    ``(centre [x, y], size [x, y])`` (m, at z = 0) on which every object stands. ``bottle``:
    the :class:`ObjectModel` of the open bottle (an upright cylinder whose top face is its
    mouth: the reported point is the mouth's centre), or None not to look for it. Stateless
    between frames.
    """

    def __init__(self, goal: ObjectModel, obstacle: ObjectModel, camera_pose: CameraPose,
                 table: tuple[ArrayLike, ArrayLike], settings: DetectorSettings | None = None,
                 bottle: ObjectModel | None = None) -> None:
        """Keep the object models, the camera pose, the table and the settings."""
        if not isinstance(camera_pose, CameraPose):
            raise ValueError(f'camera_pose must be a CameraPose, got {type(camera_pose).__name__}')
        try:
            centre, size = (np.array(v, dtype=float).reshape(2) for v in table)
        except (TypeError, ValueError):
            raise ValueError(f'table must be (centre [x, y], size [x, y]), got {table!r}') \
                from None
        if not (np.all(np.isfinite(centre)) and np.all(np.isfinite(size)) and np.all(size > 0)):
            raise ValueError(f'table centre and size must be finite, the size positive, got '
                             f'{centre.tolist()}, {size.tolist()}')
        self.goal = goal
        self.obstacle = obstacle
        self.bottle = bottle
        self.camera_pose = camera_pose
        self.table = (centre, size)
        self._table_low, self._table_high = centre - 0.5 * size, centre + 0.5 * size
        self.settings = DetectorSettings() if settings is None else settings
        self._rotation = camera_pose.rotation
        self._position = np.asarray(camera_pose.position)

    @classmethod
    def from_scene(cls, scene: SceneConfig, goal_color: HsvRange, obstacle_color: HsvRange,
                   settings: DetectorSettings | None = None,
                   bottle_color: HsvRange | None = None,
                   obstacle_radius_range: tuple[float, float] | None = None) -> Detector:
        """
        Return a detector for a :class:`SceneConfig` (object sizes, camera pose).

        ``obstacle_radius_range``: (low, high) m to measure each obstacle's radius, None for
        obstacles of the scene's ``obstacle.radius``.
        """
        bottle = None if bottle_color is None else ObjectModel(
            BOTTLE, bottle_color, scene.bottle_radius, scene.bottle_height)
        return cls(ObjectModel(GOAL, goal_color, scene.goal_radius, GOAL_MARKER_THICKNESS),
                   ObjectModel(OBSTACLE, obstacle_color, scene.obstacle_radius,
                               scene.obstacle_height, obstacle_radius_range),
                   scene.camera_pose, (scene.table_center, scene.table_size), settings, bottle)

    def detect(self, rgb: NDArray[np.uint8], depth_mm: NDArray[np.uint16],
               intrinsics: CameraIntrinsics, bgr: bool = False) -> Detections:
        """
        Return the :class:`Detections` of one frame.

        ``rgb``: uint8 (H, W, 3), RGB order (BGR with ``bgr=True``); ``depth_mm``: uint16
        (H, W), z in the optical frame in millimetres, aligned to the colour image, 0 = no
        data; ``intrinsics``: :class:`CameraIntrinsics` of the colour camera. Raises
        ValueError for images that do not fit (see :func:`check_frame`).
        """
        check_frame(rgb, depth_mm, intrinsics)
        # Rows of a message with padding (step > width) are not contiguous; OpenCV needs them so.
        rgb, depth_mm = np.ascontiguousarray(rgb), np.ascontiguousarray(depth_mm)
        hsv = cv2.cvtColor(rgb, cv2.COLOR_BGR2HSV if bgr else cv2.COLOR_RGB2HSV)
        result = Detections()
        goals = self._detect_class(self.goal, hsv, depth_mm, intrinsics, result.rejected)
        if goals:
            goals.sort(key=lambda g: -g.area)
            result.goal = goals[0]
            for extra in goals[1:]:
                result.rejected.append(Rejection(GOAL, extra.bbox, extra.area,
                                                 'another goal blob is larger'))
        result.obstacles = self._detect_class(self.obstacle, hsv, depth_mm, intrinsics,
                                              result.rejected)
        if self.bottle is not None:
            bottles = self._detect_class(self.bottle, hsv, depth_mm, intrinsics,
                                         result.rejected)
            if bottles:     # the largest; a stirrer in it can cut it in two (_split)
                bottles.sort(key=lambda b: -b.area)
                result.bottle = bottles[0]
                for extra in bottles[1:]:
                    result.rejected.append(Rejection(BOTTLE, extra.bbox, extra.area,
                                                     'another bottle blob is larger'))
        return result

    def _detect_class(self, model: ObjectModel, hsv: NDArray[Any],
                      depth_mm: NDArray[np.uint16], intrinsics: CameraIntrinsics,
                      rejected: list[Rejection]) -> list[Detection]:
        mask = model.color.mask(hsv)
        # Labelling costs ~1 ms on a full frame; the objects cover a small part of it. The
        # region is MARGIN pixels larger than the mask's bounding box (clipped to the image),
        # so that it holds the margin that _rim_points looks at around every blob.
        rx, ry, rw, rh = cv2.boundingRect(mask)
        found: list[Detection] = []
        if rw == 0:
            return found
        height, width = mask.shape
        x0, y0 = max(rx - _MARGIN, 0), max(ry - _MARGIN, 0)
        x1, y1 = min(rx + rw + _MARGIN, width), min(ry + rh + _MARGIN, height)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(mask[y0:y1, x0:x1],
                                                                   connectivity=8)
        for index in np.argsort(-stats[1:, cv2.CC_STAT_AREA]) + 1:
            x, y, w, h, area = (int(v) for v in stats[index])
            if area < self.settings.min_blob_area:
                break
            # The blob in a region MARGIN pixels larger than it, in image coordinates.
            bx0, by0 = max(x + x0 - _MARGIN, 0), max(y + y0 - _MARGIN, 0)
            bx1, by1 = min(x + x0 + w + _MARGIN, width), min(y + y0 + h + _MARGIN, height)
            blob = labels[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0] == index
            depth = depth_mm[by0:by1, bx0:bx1]
            reason = self._implausible_blob(model, blob, depth, area, intrinsics)
            if reason:
                rejected.append(Rejection(model.kind, (x + x0, y + y0, w, h), area, reason))
                continue
            for part in self._split(model, blob, depth):
                detection = self._locate(model, part, depth, (bx0, by0), intrinsics)
                if isinstance(detection, Rejection):
                    rejected.append(detection)
                else:
                    found.append(detection)
        return found

    def _implausible_blob(self, model: ObjectModel, blob: NDArray[np.bool_],
                          depth: NDArray[np.uint16], area: int,
                          intrinsics: CameraIntrinsics) -> str:
        """
        Return why a blob cannot be an object of ``model`` seen by a D435, or ''.

        Its median depth (of at most _DEPTH_SAMPLES of its pixels) must be in the D435's range,
        and its area at most MAX_BLOB_AREA_FACTOR times that of the sphere around the object
        at that depth, as stretched by perspective in the image corners (module doc).
        """
        d = depth[blob]
        d = d[d > 0]
        if d.size < self.settings.min_depth_pixels:
            return ''   # _locate gives the reason: no depth
        z = float(np.median(d[::max(1, d.size // _DEPTH_SAMPLES)])) * 0.001
        low, high = limits.DEPTH_RANGE
        if not low <= z <= high:
            return f'depth {z:.3f} m is outside what a D435 measures ({low:g} to {high:g} m)'
        k = intrinsics
        sphere = math.hypot(model.max_radius, 0.5 * model.height)
        near = max(z - sphere, low)
        # A sphere seen off the optical axis at angle a looks 1 / cos(a)^3 larger.
        corner = math.hypot(0.5 * k.width / k.fx, 0.5 * k.height / k.fy)
        stretch = (1.0 + corner * corner) ** 1.5
        count = limits.MAX_MERGED_OBSTACLES if model.kind == OBSTACLE else 1
        most = (limits.MAX_BLOB_AREA_FACTOR * count * stretch * math.pi * k.fx * k.fy
                * sphere * sphere / max(near * near - sphere * sphere, 1e-6))
        if area > most:
            return (f'blob of {area} px: more than {_a(model.kind)} can cover at {z:.2f} m '
                    f'depth (at most {most:.0f} px)')
        return ''

    def _implausible_position(self, model: ObjectModel, points: Array,
                              position: Array, single: bool, radius: float) -> str:
        """
        Return why a located object does not fit the workcell, or ''.

        ``points`` (N, 3): the blob's points in base_link; ``position``: its top-face centre;
        ``radius``: its radius (measured, or its class's). At most MAX_OUTSIDE_FRACTION of the
        points may lie farther from its axis (horizontally) than its radius plus
        OBJECT_EXTENT_MARGIN (a merged obstacle blob: the farthest of
        MAX_MERGED_OBSTACLES obstacles in a row), the top face must be between the table top
        (z = 0) and the object's height, within ``height_tolerance``, and the centre on the
        table. No sorting: about 10 us for 1000 points.
        """
        if not np.all(np.isfinite(position)):
            return 'its position is not finite'
        count = 1 if single or model.kind != OBSTACLE else limits.MAX_MERGED_OBSTACLES
        reach = (2 * count - 1) * radius + limits.OBJECT_EXTENT_MARGIN
        dx, dy = points[:, 0] - position[0], points[:, 1] - position[1]
        outside = np.count_nonzero(dx * dx + dy * dy > reach * reach)
        if outside > limits.MAX_OUTSIDE_FRACTION * len(points):
            return (f'{outside} of its {len(points)} points are more than {reach * 1000:.0f} mm '
                    f'from its axis: larger than {_a(model.kind)}')
        # The highest points seen may be lower than the top face (the arm hides it), never
        # higher, and never below the table top.
        tolerance = self.settings.height_tolerance
        if not -tolerance <= position[2] <= model.height + tolerance:
            return (f'top face at z = {position[2]:.3f} m, off the table plane: '
                    f'{_a(model.kind)} on the table has it at {model.height:.3f} m (seen: 0 '
                    f'to {model.height:.3f} m, height_tolerance {tolerance:g} m)')
        if np.any(position[:2] < self._table_low) or np.any(position[:2] > self._table_high):
            (x0, y0), (x1, y1) = self._table_low, self._table_high
            return (f'at x, y = {position[0]:.3f}, {position[1]:.3f} m, off the table (x '
                    f'{x0:.2f} to {x1:.2f} m, y {y0:.2f} to {y1:.2f} m)')
        return ''

    def _split(self, model: ObjectModel, blob: NDArray[np.bool_], depth: NDArray[np.uint16]
               ) -> list[NDArray[np.bool_]]:
        """
        Return the blob cut at depth steps (objects of one colour overlapping in the image).

        Where neighbouring pixels' depths differ by more than ``occlusion_gap`` the farther
        pixel is removed; 4-connected parts of at least ``min_blob_area`` pixels are objects.
        With fewer than two such parts, the blob is returned whole.
        """
        d = depth.astype(np.float32)
        valid = blob & (depth > 0)
        gap = np.float32(self.settings.occlusion_gap * 1000.0)
        farther = np.zeros_like(blob)
        for axis in (0, 1):
            a = d[:-1] if axis == 0 else d[:, :-1]
            b = d[1:] if axis == 0 else d[:, 1:]
            both = (valid[:-1] & valid[1:]) if axis == 0 else (valid[:, :-1] & valid[:, 1:])
            step = both & (np.abs(a - b) > gap)
            if not step.any():
                continue
            if axis == 0:
                farther[:-1] |= step & (a > b)
                farther[1:] |= step & (b > a)
            else:
                farther[:, :-1] |= step & (a > b)
                farther[:, 1:] |= step & (b > a)
        if not farther.any():
            return [blob]
        count, labels, stats, _ = cv2.connectedComponentsWithStats(
            (blob & ~farther).view(np.uint8), connectivity=4)
        big = [i for i in range(1, count)
               if stats[i, cv2.CC_STAT_AREA] >= self.settings.min_blob_area]
        if len(big) < 2:
            return [blob]
        return [labels == i for i in sorted(big, key=lambda i: -stats[i, cv2.CC_STAT_AREA])]

    def _locate(self, model: ObjectModel, blob: NDArray[np.bool_], depth: NDArray[np.uint16],
                origin: tuple[int, int], intrinsics: CameraIntrinsics) -> Detection | Rejection:
        """
        Return the Detection of one blob, or a Rejection saying why it cannot be located.

        ``blob`` (bool) and ``depth`` (uint16 mm) cover the same region of the image, whose
        top-left pixel is ``origin`` (x, y); the blob keeps MARGIN pixels from its edges
        except at the image border.
        """
        s = self.settings
        vs, us = np.nonzero(blob)
        area = len(vs)
        bbox = (int(us.min()) + origin[0], int(vs.min()) + origin[1],
                int(us.max() - us.min()) + 1, int(vs.max() - vs.min()) + 1)
        d = depth[vs, us]
        valid = d > 0
        if np.count_nonzero(valid) < s.min_depth_pixels:
            return Rejection(model.kind, bbox, area, f'no depth ({np.count_nonzero(valid)} of '
                             f'{area} pixels have depth)')
        z_all = d[valid].astype(np.float32) * np.float32(0.001)
        median = float(np.median(z_all))
        near = np.abs(z_all - median) <= model.depth_extent
        if np.count_nonzero(near) < s.min_depth_pixels:
            return Rejection(model.kind, bbox, area, 'no consistent depth')
        z_cam = z_all[near]
        points = self._to_base(intrinsics.deproject(us[valid][near] + origin[0],
                                                    vs[valid][near] + origin[1], z_cam))
        z = points[:, 2]
        top = z >= np.percentile(z, 95) - s.top_band
        z_top = float(np.median(z[top]))
        centroid = points[top, :2].mean(axis=0)

        rim = self._rim_points(model, blob, depth, origin, median, z_top, intrinsics)
        rim_rms, radius, measured = 0.0, model.radius, False
        if len(rim) >= s.min_rim_points:
            rim, centre, radius, rim_rms, measured = self._fit_rim(model, rim, centroid)
            rim_count = len(rim)
        else:
            centre, rim_count = centroid, 0
        position = np.array([centre[0], centre[1], z_top])
        single = rim_count == 0 or rim_rms <= s.max_rim_rms
        reason = self._implausible_position(model, points, position, single, radius)
        low, high = model.radius_range or (0.0, math.inf)   # measured: a range is given
        if not reason and measured and not low <= radius <= high:
            reason = (f'its radius measures {radius * 1e3:.1f} mm, outside the range of '
                      f'{_a(model.kind)} ({low * 1e3:g} to {high * 1e3:g} mm)')
        if reason:
            return Rejection(model.kind, bbox, area, reason)
        pixel = intrinsics.project(self.camera_pose.from_base(position))[0]
        return Detection(model.kind, position, (float(pixel[0]), float(pixel[1])), area,
                         bbox, median, float(np.count_nonzero(valid)) / area, rim_count,
                         rim_rms, single, radius, measured)

    def _fit_rim(self, model: ObjectModel, rim: Array, inside: Array
                 ) -> tuple[Array, Array, float, float, bool]:
        """
        Return (rim points kept, centre (2,), radius, rms, radius measured) of a blob's rim.

        ``inside``: a point inside the circle (the top face's centroid) to start from. A class
        of known radius: that radius is fitted; one whose radius is measured: the radius too,
        when the points kept span at least MIN_RIM_ARC of the circle (else its class's radius).
        Either way once more without outliers (residuals beyond 3 robust sigmas, 2 mm at
        least: an edge of something else).
        """
        s = self.settings
        free = model.radius_range is not None

        def fit(points: Array, start: Array, radius: float
                ) -> tuple[Array, float, float]:
            """Return (centre, radius, rms); the class's radius unless it is measured."""
            if free:
                centre, radius, rms = fit_circle_and_radius(points, start, radius)
                if np.all(np.isfinite(centre)) and math.isfinite(radius) and radius > 0.0:
                    return centre, radius, rms
            centre, rms = fit_circle(points, model.radius, start)
            return centre, model.radius, rms

        centre, radius, rms = fit(rim, inside, model.radius)
        residual = np.abs(np.hypot(*(rim - centre).T) - radius)
        mad = float(np.median(np.abs(residual - np.median(residual))))
        inliers = residual <= max(3.0 * 1.4826 * mad, 0.002)
        if s.min_rim_points <= np.count_nonzero(inliers) < len(rim):
            rim = rim[inliers]
            centre, radius, rms = fit(rim, centre, radius)
        if free and radius != model.radius and rim_arc(rim, centre) >= MIN_RIM_ARC:
            return rim, centre, radius, rms, True
        if free:            # too short an arc to measure the radius: the class's radius
            centre, rms = fit_circle(rim, model.radius, inside)
        return rim, centre, model.radius, rms, False

    def _rim_points(self, model: ObjectModel, blob: NDArray[np.bool_], depth: NDArray[np.uint16],
                    origin: tuple[int, int], median: float, z_top: float,
                    intrinsics: CameraIntrinsics) -> Array:
        """Return the blob's real outline points (N, 2): x, y in base_link, see module doc."""
        s = self.settings
        blob8 = blob.view(np.uint8)
        # Outline pixels: in the blob with a neighbour outside it. Erosion treats pixels beyond
        # the image as blob, so a blob cut by the image border has no outline there.
        outline = blob & (cv2.erode(blob8, _RIM_KERNEL) == 0)
        outside = np.where(~blob & (depth > 0), depth.astype(np.float32), _NO_DEPTH)
        nearest_outside = cv2.erode(outside, _OCCLUDER_KERNEL)
        vs, us = np.nonzero(outline)
        d = depth[vs, us].astype(np.float32)
        has_depth = d > 0
        reference = np.where(has_depth, d, np.float32(median * 1000.0))
        edge = nearest_outside[vs, us] >= reference - np.float32(s.occlusion_gap * 1000.0)
        # Depth of the outline pixel must agree with the blob (flying pixels do not).
        has_depth &= np.abs(d * np.float32(0.001) - median) <= model.depth_extent
        flat = model.height <= s.top_band
        keep = edge & (has_depth | flat)
        if not np.any(keep):
            return np.zeros((0, 2))
        # The outward normal of the outline (the blurred mask's gradient points inwards).
        smooth = cv2.GaussianBlur(blob.astype(np.float32), (5, 5), 1.0)
        gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3)[vs[keep], us[keep]]
        gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)[vs[keep], us[keep]]
        us, vs, d, has_depth = us[keep] + origin[0], vs[keep] + origin[1], d[keep], has_depth[keep]
        rays = self._to_base_directions(intrinsics.deproject(us, vs, 1.0))
        points = self._position + rays * np.where(has_depth, d * 0.001, 0.0)[:, None]
        # Outline pixels on the top face of a cylinder (its rim): where the ray through the
        # object's edge meets the top face's plane. A pixel belongs to the blob when its centre
        # falls on the object, so the edge lies on average half a pixel beyond an outline
        # pixel's centre, along the outward normal: without this the rim is seen 0.5-1 mm
        # inside. (Pixels on the side lie on it, at the radius already.) A flat object (the
        # goal disc): its outline pixels with depth keep their own point (its near outline is
        # its 2 mm side: moved onto the top plane along the ray it would come ~2 mm towards
        # the camera, 0.85 mm in the median goal error where it is 0.5 mm so), those without
        # depth where their own ray meets the top plane.
        if flat:
            on_top = ~has_depth
            edge_rays = rays
        else:
            on_top = ~has_depth | (np.abs(points[:, 2] - z_top) <= s.top_band)
            norm = np.hypot(gx, gy)
            half = np.where(norm > 0.0, -0.5 / np.maximum(norm, 1e-12), 0.0)
            edge_rays = self._to_base_directions(intrinsics.deproject(
                us + half * gx, vs + half * gy, 1.0))
        down = edge_rays[:, 2]
        with np.errstate(divide='ignore', invalid='ignore'):
            t = (z_top - self._position[2]) / down
        on_top &= np.isfinite(t) & (t > 0)
        points[on_top] = self._position + edge_rays[on_top] * t[on_top, None]
        return points[has_depth | on_top, :2]

    def _to_base(self, points_cam: Array) -> Array:
        return points_cam @ self._rotation.T + self._position

    def _to_base_directions(self, vectors_cam: Array) -> Array:
        return vectors_cam @ self._rotation.T

    def annotate(self, rgb: ArrayLike, detections: Detections, intrinsics: CameraIntrinsics,
                 bgr: bool = False) -> NDArray[np.uint8]:
        """
        Return a copy of the colour image with the detections drawn on it (same channel order).

        Goal: yellow, obstacles: cyan, bottle: magenta (the fitted top-face circle, its centre
        and x, y, z in mm); rejected blobs: grey boxes with the reason.
        """
        image = np.array(rgb, dtype=np.uint8, copy=True)
        palette = {key: value[::-1] if bgr else value for key, value in _DRAW.items()}
        items = ([detections.goal] if detections.goal is not None else []) + \
            list(detections.obstacles) + \
            ([detections.bottle] if detections.bottle is not None else [])
        angles = np.linspace(0.0, 2.0 * np.pi, 32, endpoint=False)
        models = {m.kind: m for m in (self.goal, self.obstacle, self.bottle) if m is not None}
        for det in items:
            model = models[det.kind]
            color = palette[det.kind]
            radius = det.radius if math.isfinite(det.radius) else model.radius
            circle = det.position + radius * np.stack(
                [np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
            uv = intrinsics.project(self.camera_pose.from_base(circle))
            if np.all(np.isfinite(uv)):
                cv2.polylines(image, [np.round(uv).astype(np.int32)], True, color, 1,
                              cv2.LINE_AA)
            centre = tuple(int(round(c)) for c in det.pixel)
            cv2.drawMarker(image, centre, color, cv2.MARKER_CROSS, 10, 1)
            x, y, w, h = det.bbox
            x_mm, y_mm, z_mm = det.position * 1000.0
            label = (f'{det.kind} {x_mm:.0f} {y_mm:.0f} {z_mm:.0f} mm'
                     + (f' r {det.radius * 1000.0:.1f}' if det.radius_measured else '')
                     + ('' if det.single else ' (merged?)'))
            cv2.putText(image, label, (x, max(y - 4, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                        color, 1, cv2.LINE_AA)
        for rejection in detections.rejected:
            x, y, w, h = rejection.bbox
            cv2.rectangle(image, (x, y), (x + w - 1, y + h - 1), palette['rejected'], 1)
            cv2.putText(image, f'{rejection.kind}: {rejection.reason}', (x, max(y - 4, 10)),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.35, palette['rejected'], 1, cv2.LINE_AA)
        return image


#: Flat parameter names (config/scene.yaml + config/perception.yaml) that
#: :func:`detector_from_parameters` reads.
DETECTOR_PARAMETERS = (
    'camera.position', 'camera.orientation', 'goal_marker.radius', 'obstacle.radius',
    'obstacle.height', 'goal_hsv_low', 'goal_hsv_high', 'obstacle_hsv_low', 'obstacle_hsv_high',
    'table.center', 'table.size', 'min_blob_area', 'min_depth_pixels', 'top_band',
    'occlusion_gap', 'min_rim_points', 'max_rim_rms', 'height_tolerance',
    'obstacle_radius_range',
)
#: Optional ones: with all four (and ``detect_bottle`` not false) the detector also looks for
#: the bottle (the centre of its mouth).
BOTTLE_PARAMETERS = ('bottle.radius', 'bottle.height', 'bottle_hsv_low', 'bottle_hsv_high')


def detector_from_parameters(params: Mapping[str, Any]) -> Detector:
    """
    Return the :class:`Detector` described by flat parameters (see DETECTOR_PARAMETERS).

    The camera pose and object sizes are the scene's (config/scene.yaml: the ones the
    simulation renders with), colours and tuning the perception node's. Raises ValueError
    naming the first missing or invalid parameter.
    """
    missing = [name for name in DETECTOR_PARAMETERS if name not in params]
    if missing:
        raise ValueError(f'perception parameters missing: {", ".join(missing)}')
    p = params
    try:
        pose = CameraPose(p['camera.position'], p['camera.orientation'])
    except (TypeError, ValueError) as exc:
        raise ValueError(f'camera pose: {exc}') from None
    colors = {}
    for kind in (GOAL, OBSTACLE):
        try:
            colors[kind] = HsvRange(p[f'{kind}_hsv_low'], p[f'{kind}_hsv_high'])
        except ValueError as exc:
            raise ValueError(f'{kind}_hsv_low/high: {exc}') from None
    try:
        settings = DetectorSettings(**{name: p[name] for name in (
            'min_blob_area', 'min_depth_pixels', 'top_band', 'occlusion_gap', 'min_rim_points',
            'max_rim_rms', 'height_tolerance')})
        bottle = None
        if p.get('detect_bottle', True) and all(p.get(name) is not None
                                                for name in BOTTLE_PARAMETERS):
            try:
                color = HsvRange(p['bottle_hsv_low'], p['bottle_hsv_high'])
            except ValueError as exc:
                raise ValueError(f'bottle_hsv_low/high: {exc}') from None
            bottle = ObjectModel(BOTTLE, color, p['bottle.radius'], p['bottle.height'])
        return Detector(
            ObjectModel(GOAL, colors[GOAL], p['goal_marker.radius'], GOAL_MARKER_THICKNESS),
            ObjectModel(OBSTACLE, colors[OBSTACLE], p['obstacle.radius'], p['obstacle.height'],
                        p['obstacle_radius_range']),
            pose, (p['table.center'], p['table.size']), settings, bottle)
    except TypeError as exc:   # a list where a number belongs, None
        raise ValueError(f'perception parameters: {exc}') from None

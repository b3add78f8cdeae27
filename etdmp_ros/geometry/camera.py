"""
Pinhole camera model (ROS conventions) and camera poses: the link between pixels and base_link.

Conventions are those of ``sensor_msgs/CameraInfo`` and REP-103/105:

- The optical frame (``camera_color_optical_frame``) has z forward along the optical axis, x to
  the right of the image and y down. Pixel ``(u, v)`` is column ``u``, row ``v``, and integer
  coordinates are pixel CENTRES (OpenCV), so a centred principal point is ``((W-1)/2, (H-1)/2)``.
- A depth image holds, per pixel, the z coordinate of the seen point in the optical frame (not
  the distance along the ray), as a RealSense does.
- A :class:`CameraPose` is the pose of the optical frame in base_link: ``p_base = R p_cam + t``.
  Orientations are quaternions ``[x, y, z, w]`` (ROS order).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Array, Points3, Rotations
import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class CameraIntrinsics:
    """
    Pinhole intrinsics of an undistorted camera: image size and K = [[fx, 0, cx], [0, fy, cy]].

    ``K`` and ``P`` are the matrices of ``sensor_msgs/CameraInfo``. :meth:`from_fovy` gives
    the intrinsics of a MuJoCo (OpenGL) camera: square pixels, principal point at the image
    centre.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        """Validate the values (positive size and focal lengths, finite numbers)."""
        if int(self.width) != self.width or int(self.height) != self.height or \
                self.width < 1 or self.height < 1:
            raise ValueError(f'image size must be positive integers, got '
                             f'{self.width}x{self.height}')
        values = (self.fx, self.fy, self.cx, self.cy)
        if not all(math.isfinite(v) for v in values) or self.fx <= 0 or self.fy <= 0:
            raise ValueError(f'focal lengths must be positive and finite, got {values}')

    @classmethod
    def from_fovy(cls, width: int, height: int, fovy_deg: float) -> CameraIntrinsics:
        """
        Return the intrinsics of an OpenGL/MuJoCo camera with vertical field of view ``fovy_deg``.

        f = (height / 2) / tan(fovy / 2) for both axes. OpenGL maps the image's outer pixel
        EDGES to the frustum, so the optical axis passes between the two middle pixels:
        c = ((W - 1) / 2, (H - 1) / 2) with pixel centres at integer coordinates.
        """
        if not 0.0 < fovy_deg < 180.0:
            raise ValueError(f'fovy must be in (0, 180) degrees, got {fovy_deg}')
        f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2.0)
        return cls(int(width), int(height), f, f, (width - 1) / 2.0, (height - 1) / 2.0)

    @property
    def fovy_deg(self) -> float:
        """Vertical field of view in degrees (edge to edge)."""
        return math.degrees(2.0 * math.atan(0.5 * self.height / self.fy))

    @property
    def fovx_deg(self) -> float:
        """Horizontal field of view in degrees (edge to edge)."""
        return math.degrees(2.0 * math.atan(0.5 * self.width / self.fx))

    @property
    def K(self) -> Array:   # noqa: N802 - the matrix's name in CameraInfo, textbooks
        """Camera matrix (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def P(self) -> Array:   # noqa: N802 - CameraInfo's name
        """Projection matrix (3, 4) of a monocular camera: [K | 0]."""
        return np.hstack([self.K, np.zeros((3, 1))])

    def project(self, points: ArrayLike) -> Array:
        """Return pixel coordinates (N, 2) ``(u, v)`` of points (N, 3) in the optical frame."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        z = p[:, 2]
        return np.stack([self.fx * p[:, 0] / z + self.cx, self.fy * p[:, 1] / z + self.cy], axis=1)

    def deproject(self, u: ArrayLike, v: ArrayLike, depth: ArrayLike) -> Points3:
        """
        Return points (N, 3) in the optical frame seen at pixels ``(u, v)`` with depth z (metres).

        ``u``, ``v`` and ``depth`` broadcast together (scalars or arrays).
        """
        u, v, z = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float),
                                      np.asarray(depth, dtype=float))
        x = (u - self.cx) / self.fx * z
        y = (v - self.cy) / self.fy * z
        return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


@dataclass(frozen=True)
class CameraPose:
    """
    Pose of the camera's optical frame in base_link: ``position`` (3,), ``orientation`` [x,y,z,w].

    :attr:`rotation` maps optical-frame vectors to base_link: ``p_base = R p_cam + position``.
    """

    position: Sequence[float] | Array
    orientation: Sequence[float] | Array

    def __post_init__(self) -> None:
        """Validate and normalize (position finite, quaternion non-zero)."""
        position = np.asarray(self.position, dtype=float).reshape(-1)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f'camera position must be 3 finite numbers, got {self.position}')
        orientation = np.asarray(self.orientation, dtype=float).reshape(-1)
        if orientation.shape != (4,):
            raise ValueError(f'camera orientation must be a quaternion [x, y, z, w], got '
                             f'{self.orientation}')
        rotation = quat.to_matrix(quat.normalized(orientation))
        object.__setattr__(self, 'position', tuple(position.tolist()))
        object.__setattr__(self, 'orientation',
                           tuple(quat.from_matrix(rotation).tolist()))

    @classmethod
    def look_at(cls, eye: ArrayLike, target: ArrayLike,
                up: ArrayLike = (0.0, 0.0, 1.0)) -> CameraPose:
        """Return the pose of a camera at ``eye`` looking at ``target``, image top towards up."""
        eye = np.asarray(eye, dtype=float)
        z = np.asarray(target, dtype=float) - eye
        z /= np.linalg.norm(z)
        x = np.cross(z, np.asarray(up, dtype=float))
        if np.linalg.norm(x) < 1e-9:
            raise ValueError('look_at: the viewing direction is parallel to up')
        x /= np.linalg.norm(x)
        y = np.cross(z, x)   # optical y points down the image
        return cls(tuple(eye), tuple(quat.from_matrix(np.stack([x, y, z], axis=1))))

    @property
    def rotation(self) -> Rotations:
        """Rotation matrix (3, 3) from the optical frame to base_link."""
        return quat.to_matrix(quat.normalized(self.orientation))

    def to_base(self, points: ArrayLike) -> Points3:
        """Return points (N, 3) given in the optical frame expressed in base_link."""
        return np.atleast_2d(points) @ self.rotation.T + np.asarray(self.position)

    def from_base(self, points: ArrayLike) -> Points3:
        """Return points (N, 3) given in base_link expressed in the optical frame."""
        return (np.atleast_2d(points) - np.asarray(self.position)) @ self.rotation

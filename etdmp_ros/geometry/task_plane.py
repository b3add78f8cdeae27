"""
The task plane: where 2D skills (letters, wiping) are executed, and how points map onto it.

A 2D skill is learned in demo units (the built-in letters are about 10 units tall). The plane has
an ``origin`` and two orthonormal axes ``x_axis``, ``y_axis`` in base_link (metres) and a
``scale`` in metres per demo unit. A base_link point ``p`` maps to the demo-unit coordinates

    u = ((p - origin) . x_axis, (p - origin) . y_axis) / scale

(its orthogonal projection onto the plane, in demo units) and back with
``p = origin + scale (u_0 x_axis + u_1 y_axis)``, which lies on the plane. Orientations of a 2D
skill are expressed in the plane's frame (x_axis, y_axis and the normal as z):
``q_base = q_P q_plane`` (:meth:`TaskPlane.orientation_from_plane`, docs/orientation.md).

ET-DMP scales the movement by ``|x0 - g|``, so the scale does not change a plan between given
points; it fixes the size of demonstrations recorded in metres (a taught path becomes a skill in
demo units) and of the demonstration drawn "in place" next to a plan.

The *relative quadrant* of a start (paper Table 2) is the quadrant of ``x0 - g`` in the plane's
coordinates (:func:`quadrant`): half-open angular sectors of ``atan2(y, x)``, I = [0, 90) deg,
II = [90, 180), III = [180, 270), IV = [270, 360), so a vector exactly on an axis belongs to the
sector that begins there.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from etdmp_ros import limits
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Array, Points2, Points3, Quaternions, Rotations
import numpy as np
from numpy.typing import ArrayLike

#: Largest ``|x_axis . y_axis|`` accepted for the (normalised) plane axes.
ORTHOGONALITY_TOLERANCE = 1e-3
QUADRANTS = ('I', 'II', 'III', 'IV')


def quadrant(relative: ArrayLike) -> str:
    """
    Return the relative quadrant, "I" to "IV", of a 2D vector such as ``x0 - g``.

    Raises ValueError for anything but a finite, non-zero 2D vector.
    """
    rel = np.asarray(relative, dtype=float)
    if rel.shape != (2,) or not np.all(np.isfinite(rel)):
        raise ValueError(f'quadrants need a finite 2D vector, got {rel.tolist()}')
    if np.hypot(*rel) == 0.0:
        raise ValueError('start and goal coincide: the relative quadrant is undefined')
    angle = math.atan2(rel[1], rel[0]) % (2.0 * math.pi)
    return QUADRANTS[min(int(angle // (0.5 * math.pi)), 3)]


@dataclass(frozen=True, eq=False)
class TaskPlane:
    """
    A plane in base_link: ``origin`` (3,), unit axes ``x_axis``, ``y_axis`` (3,), ``scale``.

    Build it with :meth:`create`, which validates and normalises the axes.
    """

    origin: Points3
    x_axis: Points3
    y_axis: Points3
    scale: float

    @classmethod
    def create(cls, origin: ArrayLike, x_axis: ArrayLike, y_axis: ArrayLike,
               scale: float = 0.02) -> TaskPlane:
        """
        Validate and build a plane; raise ValueError saying what is wrong.

        The origin must be within MAX_REQUEST_COORDINATE of base_link's. The axes are
        normalised; they must be finite, non-zero and orthogonal (within
        ORTHOGONALITY_TOLERANCE after normalisation). ``scale`` is metres per demo unit, > 0.
        """
        vectors = {}
        for name, value in (('origin', origin), ('x_axis', x_axis), ('y_axis', y_axis)):
            try:
                array = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f'task_plane.{name} must be 3 numbers, got {value!r}') from None
            if array.shape != (3,) or not np.all(np.isfinite(array)):
                raise ValueError(f'task_plane.{name} must be 3 finite numbers, got {value!r}')
            vectors[name] = array
        far = np.abs(vectors['origin']).max()
        if far > limits.MAX_REQUEST_COORDINATE:
            # [1e308, 0, 0] was accepted, then every plan failed: "overflow in divide".
            raise ValueError(f'task_plane.origin has a coordinate of {far:.3g} m, beyond '
                             f'{limits.MAX_REQUEST_COORDINATE:g} m (MAX_REQUEST_COORDINATE): '
                             'no place of the workcell')
        for name in ('x_axis', 'y_axis'):
            unit, norm = quat.unit_and_norm(vectors[name])
            if not norm > 1e-9:
                raise ValueError(f'task_plane.{name} must not be zero')
            vectors[name] = unit
        dot = float(vectors['x_axis'] @ vectors['y_axis'])
        if abs(dot) > ORTHOGONALITY_TOLERANCE:
            raise ValueError(f'task_plane.x_axis and y_axis must be orthogonal '
                             f'(cosine of their angle: {dot:.3g})')
        if not (np.isfinite(scale) and scale > 0.0):
            raise ValueError(f'task_plane.scale (metres per demo unit) must be > 0, got {scale!r}')
        for array in vectors.values():
            array.flags.writeable = False
        return cls(vectors['origin'], vectors['x_axis'], vectors['y_axis'], float(scale))

    @property
    def normal(self) -> Points3:
        """Return the unit normal ``x_axis x y_axis`` (3,)."""
        return np.cross(self.x_axis, self.y_axis)

    @property
    def axes(self) -> Array:
        """Return the (2, 3) matrix whose rows are ``x_axis`` and ``y_axis``."""
        return np.stack([self.x_axis, self.y_axis])

    def to_plane(self, points: ArrayLike) -> Points2:
        """Map base_link points (..., 3) to demo units on the plane (..., 2) (projection)."""
        points = np.asarray(points, dtype=float)
        return (points - self.origin) @ self.axes.T / self.scale

    def from_plane(self, uv: ArrayLike) -> Points3:
        """Map demo-unit plane coordinates (..., 2) to base_link points (..., 3) on the plane."""
        uv = np.asarray(uv, dtype=float)
        return self.origin + (self.scale * uv) @ self.axes

    def distance(self, points: ArrayLike) -> Array:
        """Return the signed distances (...) of base_link points (..., 3) from the plane (m)."""
        return (np.asarray(points, dtype=float) - self.origin) @ self.normal

    @property
    def rotation(self) -> Rotations:
        """
        Return the plane's frame in base_link (3, 3): columns x_axis, y_axis, normal.

        ``y_axis`` is made exactly orthogonal to ``x_axis`` first (the axes are accepted within
        ORTHOGONALITY_TOLERANCE), so the matrix is a rotation.
        """
        y = self.y_axis - (self.y_axis @ self.x_axis) * self.x_axis
        y = y / np.linalg.norm(y)
        return np.stack([self.x_axis, y, np.cross(self.x_axis, y)], axis=1)

    def orientation_to_plane(self, q: ArrayLike) -> Quaternions:
        """Express base_link orientations (..., 4) (x, y, z, w) in the plane's frame."""
        return quat.multiply(quat.conjugate(quat.from_matrix(self.rotation)), q)

    def orientation_from_plane(self, q: ArrayLike) -> Quaternions:
        """Express orientations (..., 4) given in the plane's frame in base_link."""
        return quat.multiply(quat.from_matrix(self.rotation), q)

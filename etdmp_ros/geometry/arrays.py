"""
Names for the float arrays in signatures: what an array holds, its shape and its unit.

numpy's types carry the dtype, not the shape, so to a type checker each name below is
``NDArray[np.floating[Any]]`` (float64 in practice); the name tells a reader the shape and unit,
and a docstring names the sizes (``n`` samples, ``d`` coordinates, ``B`` systems of a batch).
Arguments are usually typed ``numpy.typing.ArrayLike`` (lists, tuples and arrays alike); results
are one of these.
"""

from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Floats of the shape the docstring states, e.g. a path (n, d) or a batch of them (B, n, d).
Array = NDArray[np.floating[Any]]
#: Unit quaternions (..., 4) in ROS order (x, y, z, w).
Quaternions = NDArray[np.floating[Any]]
#: Rotation vectors (..., 3): the axis times the angle in radians.
RotationVectors = NDArray[np.floating[Any]]
#: Rotation matrices (..., 3, 3) (or (..., d, d) in d dimensions).
Rotations = NDArray[np.floating[Any]]
#: Points or vectors (..., 3) in a Cartesian frame, metres.
Points3 = NDArray[np.floating[Any]]
#: Points (..., 2) on a task plane, in demo units (the plane's ``scale`` metres each).
Points2 = NDArray[np.floating[Any]]

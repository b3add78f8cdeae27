"""Errors of the DMP core (ValueErrors with a message for users), and the check behind most."""

from __future__ import annotations

from etdmp_ros.geometry.arrays import Array
import numpy as np


class DemonstrationError(ValueError):
    """A demonstration is empty, malformed, too short, non-finite or otherwise unusable."""


class GeneralizationError(ValueError):
    """A generalization request cannot be served (bad start, goal, obstacles; degeneracy)."""


def finite_array(value: object, name: str) -> Array:
    """Convert a request argument to a finite float array or raise GeneralizationError."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GeneralizationError(f'{name} must be numeric: {exc}') from None
    if not np.all(np.isfinite(arr)):
        raise GeneralizationError(f'{name} contains NaN or inf')
    return arr

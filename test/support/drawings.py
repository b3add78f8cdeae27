"""
Drawings as the teaching page sends them, for the tests (no test module).

A person slows down at a corner, as the pen changes direction; :func:`letter_z` draws each
straight part of a Z with a minimum-jerk speed profile (at rest at every corner).
"""

import numpy as np

#: The Z's corners in canvas pixels (640 x 480 canvas): top left, top right, bottom left,
#: bottom right; 0.125 m wide on the default 0.4 m canvas.
Z_CORNERS = ((220.0, 130.0), (420.0, 130.0), (220.0, 350.0), (420.0, 350.0))


def letter_z(points_per_part=25, corners=Z_CORNERS):
    """Return the Z's points (n, 2) in canvas pixels, each part minimum-jerk in its index."""
    corners = np.asarray(corners, dtype=float)
    s = np.linspace(0.0, 1.0, points_per_part, endpoint=False)
    s = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5
    parts = [a + s[:, None] * (b - a) for a, b in zip(corners[:-1], corners[1:])]
    return np.concatenate(parts + [corners[-1:]])


def stroke(points, period_ms=16.7, start_ms=1000.0):
    """Return one stroke as the page sends it: [[x, y, t_ms], ...] at a fixed event period."""
    t = start_ms + period_ms * np.arange(len(points))
    return [[float(x), float(y), float(ti)] for (x, y), ti in zip(points, t)]


def request(name='Z', strokes=None):
    """Return the page's POST /api/teach body (a Z if no strokes are given)."""
    return {'name': name, 'strokes': [stroke(letter_z())] if strokes is None else strokes}

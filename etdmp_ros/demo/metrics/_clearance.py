"""
How close the pen came to things, and what the arm touched: clearances and contacts.

Definitions: ``min_clearance``, ``contacts`` (:mod:`._definitions`).
"""

from etdmp_ros.robot import obstacle_radii_for, PEN_TIP_RADIUS
import numpy as np


def obstacle_radii(run):
    """Return the radius (m,) of each of the run's true obstacles (the scenario's)."""
    scene = run.scene.scene
    radii = getattr(run.scene, 'obstacle_radii', None)
    if radii is None or len(radii) != len(np.reshape(run.obstacles_truth, (-1, 3))):
        radii = obstacle_radii_for(len(np.reshape(run.obstacles_truth, (-1, 3))),
                                   scene.get('obstacle_radii') or [], scene['obstacle.radius'])
    return np.asarray(radii, dtype=float)


def cylinder_gap(points, obstacles, radius):
    """
    Return the distance (n,) from points to the nearest upright cylinder's surface.

    Each obstacle point (m, 3) is the centre of a cylinder's top face; the cylinder of
    ``radius`` (one for all, or one per obstacle) stands on the table (z = 0) up to that
    point. Negative inside a cylinder.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    obstacles = np.asarray(obstacles, dtype=float).reshape(-1, 3)
    if not len(obstacles):
        return np.full(len(points), np.inf)
    radial = np.linalg.norm(points[:, None, :2] - obstacles[None, :, :2], axis=2) - radius
    above = points[:, None, 2] - obstacles[None, :, 2]
    outside = np.where(above > 0.0, np.hypot(np.maximum(radial, 0.0), above), radial)
    inside = np.where(above > 0.0, above, np.maximum(radial, above))
    gap = np.where((radial > 0.0) | (above > 0.0), outside, inside)
    return gap.min(axis=1)


def clearance_mm(points, obstacles, radius):
    """Return the smallest gap (mm) between the pen tip's surface at ``points`` and a cylinder."""
    return float((cylinder_gap(points, obstacles, radius).min() - PEN_TIP_RADIUS) * 1e3)


def matched_errors(seen, truth):
    """Return, per true point, the distance (mm) to the nearest perceived one."""
    if seen is None or truth is None or not len(truth):
        return []
    seen = np.asarray(seen).reshape(-1, 3)
    if not len(seen):
        return [None] * len(truth)
    return [float(np.min(np.linalg.norm(seen - p, axis=1)) * 1e3) for p in truth]


def bottle_clearances(scene, trace, plan_x, trace_mouths=None, plan_mouths=None):
    """
    Stirring: how close the pen tip came to the bottle's wall while inside it (mm).

    ``trace_mouths``, ``plan_mouths`` ((n, 3) or None): where the bottle's mouth was at each
    point (a bottle that moved); None: where the scene puts it.
    """
    r_b = float(scene.scene['bottle.radius'])
    out = {}
    for key, points, mouths in (('bottle_wall_clearance_mm', trace, trace_mouths),
                                ('bottle_wall_clearance_plan_mm', plan_x, plan_mouths)):
        mouths = np.broadcast_to(scene.bottle_mouth if mouths is None else mouths,
                                 points.shape)
        inside = points[:, 2] < mouths[:, 2]
        gap = r_b - np.linalg.norm(points[inside, :2] - mouths[inside, :2], axis=1) \
            - PEN_TIP_RADIUS
        out[key] = float(gap.min() * 1e3) if len(gap) else None
    return out


def contact_figures(rec):
    """Return the contact figures of the recorded streams (``contacts``)."""
    messages = rec.get('contacts', [])
    if not messages:
        return {'contacts': None, 'contact_pairs': [], 'contact_max_depth_mm': None}
    touching = [found for _, found in messages if found]
    depths = [depth for found in touching for _, _, depth in found]
    return {'contacts': len(touching),
            'contact_pairs': sorted({f'{part}/{item}' for found in touching
                                     for part, item, _ in found}),
            'contact_max_depth_mm': float(max(depths) * 1e3) if depths else 0.0}

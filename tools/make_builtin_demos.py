#!/usr/bin/env python3
"""
Author the built-in demonstrations in ``etdmp_ros/dmp/data/`` (original work, no copied data).

Each demonstration is one continuous stroke designed here from hand-placed control points:

- "G", "P", "R", "W": handwritten letters, 10 demo units tall, 200 samples over 2 s.
- "wipe": back-and-forth wiping over a ~10 x 6 unit board area, corner to centre; 400 samples
  over 4 s.
- "stir": stirring in a bottle, metres, z up, origin on the bottle axis at the mouth: from 0.12 m
  above and 0.08 m beside the mouth, in, a 2.5 cm spiral down, ending on the axis near the bottom;
  500 samples over 5 s.

"wipe" and "stir" also carry the tool's orientation (columns ``qx,qy,qz,qw``, ROS order), made
from the positions as written to the file (the positions themselves are exactly what they were
before orientations were added; docs/orientation.md). The tool frame is the one of dmp_server's
``tool_orientation`` default, ``TOOL_DOWN``: tool z points down into the board or bottle.

- "wipe" (in the task plane's axes): the tool turns about the plane's normal so that the
  sponge's long side (the tool's y axis) lies along the stroke it wipes: the undirected angle of
  each straight run between two corners (chosen nearest the previous one, so that a turnaround
  is no half turn), blended from one run to the next by a Gaussian step (sigma 0.08 s) at the time
  the path passes the corner.
- "stir" (base_link): the stirrer tilts so that its shaft points from the tip to a spot on the
  bottle axis 0.12 m above the tip: upright on the axis, tilted by atan(r / 0.12) at radius r,
  the tilt circling with the spiral (9.5 to 12 degrees while stirring, 34 degrees at the start
  beside the mouth, upright at the goal). The tilt is the shortest rotation from upright, so the
  stirrer does not spin about its own axis.

How a stroke is made:

1. A polyline of control points (straight runs densified so that the spline follows them, turns
   sharpened by the local point spacing) becomes a uniform cubic B-spline, which is C2; phantom end
   points make it start and end exactly at the first and last control points.
2. It is re-timed along its arc length. The speed follows the two-thirds power law of human
   movement (speed ~ curvature^(-1/3), curvature smoothed along the path so that accelerations
   stay continuous), times a time law that rises from rest and falls back to rest with
   minimum-jerk-shaped ramps (zero velocity and acceleration at both ends).

The script is deterministic (no randomness is used). It checks every demonstration (rest at both
ends, start and goal at least 20 % of the size apart in every dimension, finite) and prints the
key numbers. Usage::

    python3 tools/make_builtin_demos.py [--out etdmp_ros/dmp/data] [--plot /tmp/builtin_demos.png]
"""

import argparse
from pathlib import Path
import sys

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / 'etdmp_ros' / 'dmp' / 'data'

# The plain DMP baseline scales its forcing term by (goal - start) per dimension; a component near
# zero makes it ill-posed, so every demo keeps them apart.
MIN_SEPARATION = 0.2
REST_FRACTION = 0.02
LETTER_HEIGHT = 10.0


# ----------------------------------------------------------------------------- geometry helpers

def densify(points, step):
    """Insert points along each segment of a polyline so that no gap exceeds ``step``."""
    points = np.asarray(points, dtype=float)
    out = [points[0]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        for k in range(1, n + 1):
            out.append(a + (b - a) * k / n)
    return np.array(out)


def arc(center, radii, deg_from, deg_to, step):
    """
    Points about ``step`` apart on an ellipse from angle ``deg_from`` to ``deg_to`` (degrees).

    Arcs are sampled directly rather than densified: points added on a chord lie inside the
    curve and would make the spline's curvature ripple.
    """
    span = np.radians(abs(deg_to - deg_from)) * max(radii)
    a = np.radians(np.linspace(deg_from, deg_to, max(2, int(np.ceil(span / step)) + 1)))
    return np.c_[center[0] + radii[0] * np.cos(a), center[1] + radii[1] * np.sin(a)]


def chain(*pieces):
    """Concatenate point lists, dropping a point that repeats the previous one."""
    out = []
    for piece in pieces:
        for p in np.atleast_2d(np.asarray(piece, dtype=float)):
            if not out or np.linalg.norm(p - out[-1]) > 1e-9:
                out.append(p)
    return np.array(out)


class BSpline:
    """Uniform cubic B-spline through phantom-extended control points (interpolates both ends)."""

    def __init__(self, control):
        """Build the curve from control points (m, d), m >= 2."""
        control = np.asarray(control, dtype=float)
        # Reflected phantoms put the curve's ends on the first/last control points with zero
        # curvature there.
        self.q = np.vstack([2 * control[0] - control[1], control, 2 * control[-1] - control[-2]])
        self.segments = len(control) - 1

    def __call__(self, u, derivative=0):
        """Point (or derivative) at global parameters ``u`` in [0, segments]."""
        u = np.asarray(u, dtype=float)
        i = np.clip(np.floor(u).astype(int), 0, self.segments - 1)
        s = (u - i)[:, None]
        if derivative == 0:
            b = [(1 - s) ** 3 / 6, (3 * s ** 3 - 6 * s ** 2 + 4) / 6,
                 (-3 * s ** 3 + 3 * s ** 2 + 3 * s + 1) / 6, s ** 3 / 6]
        elif derivative == 1:
            b = [-(1 - s) ** 2 / 2, 1.5 * s ** 2 - 2 * s, -1.5 * s ** 2 + s + 0.5, s ** 2 / 2]
        else:
            b = [1 - s, 3 * s - 2, 1 - 3 * s, s]
        return sum(bk * self.q[i + k] for k, bk in enumerate(b))


def smooth(values, sigma_samples):
    """Gaussian smoothing with reflected ends."""
    half = int(np.ceil(4 * sigma_samples))
    kernel = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma_samples) ** 2)
    kernel /= kernel.sum()
    padded = np.pad(values, half, mode='reflect')
    return np.convolve(padded, kernel, mode='valid')


def rest_to_rest(tau, ramp):
    """
    Normalised progress (0..1) of a time law with minimum-jerk ramps over ``ramp`` at each end.

    Its speed rises from rest as the minimum-jerk profile 10x^3 - 15x^4 + 6x^5, stays constant,
    and falls back to rest symmetrically: velocity and acceleration are zero at both ends.
    """
    def ramp_area(x):
        # Integral of the minimum-jerk profile from 0 to x.
        return 2.5 * x ** 4 - 3 * x ** 5 + x ** 6

    tau = np.asarray(tau, dtype=float)
    total = 1.0 - ramp
    progress = np.where(
        tau < ramp, ramp * ramp_area(tau / ramp),
        np.where(tau > 1 - ramp, total - ramp * ramp_area((1 - tau) / ramp),
                 ramp / 2 + (tau - ramp)))
    return progress / total


def retime(curve, n_samples, duration, size, ramp=0.2, power=1.0 / 3.0, grid=40000):
    """
    Sample ``curve`` at ``n_samples`` uniform times over ``duration`` with a handwriting speed.

    Speed ~ (kappa + kappa0)^(-power) along the path (two-thirds power law for power = 1/3),
    scaled by the rest-to-rest time law; kappa is smoothed over 4 % of ``size`` so that the speed
    changes smoothly.
    """
    u = np.linspace(0.0, curve.segments, curve.segments * 200 + 1)
    d1, d2 = curve(u, 1), curve(u, 2)
    speed_u = np.linalg.norm(d1, axis=1)
    cross = np.sqrt(np.maximum((speed_u ** 2) * np.sum(d2 ** 2, axis=1)
                               - np.sum(d1 * d2, axis=1) ** 2, 0.0))
    kappa = cross / np.maximum(speed_u, 1e-12) ** 3
    arclen = np.concatenate([[0.0], np.cumsum(0.5 * (speed_u[1:] + speed_u[:-1]) * np.diff(u))])
    length = arclen[-1]

    sigma = np.linspace(0.0, length, grid)
    kappa_s = smooth(np.interp(sigma, arclen, kappa), 0.04 * size / (sigma[1] - sigma[0]))
    kappa0 = 1.0 / (0.25 * size)
    inv_speed = (kappa_s + kappa0) ** power
    phi = np.concatenate([[0.0], np.cumsum(0.5 * (inv_speed[1:] + inv_speed[:-1])
                                           * np.diff(sigma))])

    t = np.linspace(0.0, duration, n_samples)
    sigma_k = np.interp(rest_to_rest(t / duration, ramp) * phi[-1], phi, sigma)
    u_k = np.interp(sigma_k, arclen, u)
    u_k[0], u_k[-1] = 0.0, curve.segments
    return t, curve(u_k), length


# ----------------------------------------------------------------------------- the strokes

def letter_g():
    """G: a C-like arc from the upper right, round the left, up the right side, then inwards."""
    return chain(arc((0.0, 0.0), (4.0, 5.0), 38, 330, 0.5),
                 densify([[4.0, -2.4], [4.2, -0.9], [4.25, 0.35]], 0.5),
                 densify([[4.25, 0.35], [3.0, 0.35], [0.4, 0.35]], 0.5)[1:])


def _p_stroke():
    """Slanted stem down, back up just beside it, round the bowl to the stem at mid-height."""
    stem_down = densify([[2.2, 10.0], [0.0, 0.0]], 0.6)
    turn = [[0.05, -0.15], [0.25, -0.05]]
    stem_up = densify([[0.25, -0.05], [2.25, 9.5]], 0.6)
    bowl = arc((3.4, 7.5), (2.8, 2.5), 100, -90, 0.5)
    return chain(stem_down, turn, stem_up, bowl)


def letter_p():
    """P: the P stroke, closing the bowl across the stem."""
    return chain(_p_stroke(), densify([[3.4, 5.0], [1.6, 4.95], [0.0, 4.85]], 0.6))


def letter_r():
    """R: the P stroke back to the stem, then the leg out to the lower right."""
    back = densify([[3.4, 5.0], [1.4, 5.0]], 0.6)
    leg = densify([[1.4, 5.0], [3.0, 4.2], [6.4, 0.0]], 0.6)
    return chain(_p_stroke(), back, leg)


def letter_w():
    """W: down, up, down, up; the last arm ends lower than the first began."""
    return densify([[0.0, 10.0], [1.9, 0.0], [3.9, 7.0], [5.9, 0.0], [8.2, 7.4]], 0.5)


WIPE_CORNERS = [[0.0, 6.0], [10.0, 5.3], [0.3, 4.2], [9.9, 3.1], [0.2, 2.0], [9.8, 0.9],
                [0.4, 0.0], [5.0, 3.0]]


def wipe():
    """Wipe: from the top-left corner of a 10 x 6 area, back and forth, ending at its centre."""
    return densify(WIPE_CORNERS, 0.5)


def stir():
    """Stir: from above and beside the mouth, in, spiral down (r = 2.5 cm), stop on the axis."""
    start = np.array([0.08 * np.sqrt(0.5), 0.08 * np.sqrt(0.5), 0.12])
    # A quadratic Bezier from the start that arrives vertically at the mouth.
    b = np.linspace(0.0, 1.0, 14)[:, None]
    approach = ((1 - b) ** 2 * start + 2 * b * (1 - b) * np.array([0.0, 0.0, 0.07])
                + b ** 2 * np.array([0.0, 0.0, 0.0]))
    radius, turns, z_top, z_bottom, goal_z = 0.025, 3.5, -0.015, -0.11, -0.13
    per_turn = 16
    # A B-spline through a regular polygon shrinks it by (4 + 2 cos(dtheta)) / 6; undo that so the
    # stirring radius is the requested one.
    shrink = (4 + 2 * np.cos(2 * np.pi / per_turn)) / 6
    n = int(turns * per_turn)
    k = np.arange(1, n + 1)
    angle = np.arctan2(start[1], start[0]) + 2 * np.pi * k / per_turn
    envelope = np.minimum(1.0, np.minimum(k / (per_turn / 2), (n - k) / (per_turn / 2) + 0.15))
    r = radius / shrink * np.clip(envelope, 0.0, 1.0)
    z = z_top + (z_bottom - z_top) * k / n
    spiral = np.c_[r * np.cos(angle), r * np.sin(angle), z]
    finish = densify([spiral[-1], [0.0, 0.0, goal_z]], 0.01)
    return chain(approach, spiral, finish)


# ----------------------------------------------------------------------------- orientations

#: dmp_server's default tool orientation (x, y, z, w): tool z down, tool x along -y, y along -x.
TOOL_DOWN = np.array([-np.sqrt(0.5), np.sqrt(0.5), 0.0, 0.0])
WIPE_BLEND_SECONDS = 0.08
STIR_LEVER = 0.12


def quaternion_multiply(p, q):
    """Hamilton products ``p q`` of quaternions (..., 4) in ROS order (x, y, z, w)."""
    px, py, pz, pw = np.moveaxis(np.asarray(p, dtype=float), -1, 0)
    qx, qy, qz, qw = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack([pw * qx + px * qw + py * qz - pz * qy, pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw, pw * qw - px * qx - py * qy - pz * qz],
                    axis=-1)


def wipe_orientations(t, x):
    """Sponge's long side along each straight run of the wipe, blended at the corners."""
    from math import erf
    corners = np.array(WIPE_CORNERS)
    runs = np.diff(corners, axis=0)
    angles = [np.arctan2(runs[0, 1], runs[0, 0])]
    for run in runs[1:]:
        a = np.arctan2(run[1], run[0])
        angles.append(a + np.pi * np.round((angles[-1] - a) / np.pi))   # undirected: mod pi
    # When the path passes each inner corner (the corners are visited in order).
    times, first = [], 0
    for corner in corners[1:-1]:
        k = first + int(np.argmin(np.linalg.norm(x[first:] - corner, axis=1)))
        times.append(t[k])
        first = k + 1
    psi = np.full(len(t), angles[0])
    for when, before, after in zip(times, angles[:-1], angles[1:]):
        step = np.array([0.5 * (1.0 + erf((tk - when) / (np.sqrt(2) * WIPE_BLEND_SECONDS)))
                         for tk in t])
        psi += (after - before) * step
    yaw = np.c_[np.zeros((len(t), 2)), np.sin(psi / 2), np.cos(psi / 2)]
    return quaternion_multiply(yaw, TOOL_DOWN)


def stir_orientations(t, x):
    """Stirrer's shaft from the tip towards the bottle axis STIR_LEVER above it (no spin)."""
    shaft = np.c_[x[:, :2], np.full(len(x), -STIR_LEVER)]
    shaft /= np.linalg.norm(shaft, axis=1, keepdims=True)
    down = np.array([0.0, 0.0, -1.0])
    # Shortest rotation from down to the shaft: (down x shaft, 1 + down . shaft), normalised.
    tilt = np.c_[np.cross(down, shaft), 1.0 + shaft @ down]
    tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    return quaternion_multiply(tilt, TOOL_DOWN)


ORIENTATIONS = {'wipe': wipe_orientations, 'stir': stir_orientations}
QUATERNION_DECIMALS = 9


def scale_to_height(control, height):
    """Scale control points uniformly so that the spline's height (y extent) is ``height``."""
    y = BSpline(control)(np.linspace(0, len(control) - 1, 20000))[:, 1]
    return control * (height / (y.max() - y.min()))


# ----------------------------------------------------------------------------- build and check

DEMOS = {
    # name: (control points, samples, duration [s], decimals, letter height or None)
    'G': (letter_g, 200, 2.0, 6, LETTER_HEIGHT),
    'P': (letter_p, 200, 2.0, 6, LETTER_HEIGHT),
    'R': (letter_r, 200, 2.0, 6, LETTER_HEIGHT),
    'W': (letter_w, 200, 2.0, 6, LETTER_HEIGHT),
    'wipe': (wipe, 400, 4.0, 6, None),
    # Metres: 8 decimals (0.01 um) keep finite-difference accelerations as clean as 6 decimals
    # do for the ~10 unit letters.
    'stir': (stir, 500, 5.0, 8, None),
}


def build(name):
    """Return (t, positions, path length) for one demonstration, rounded as written to file."""
    make, n_samples, duration, decimals, height = DEMOS[name]
    control = make()
    if height is not None:
        control = scale_to_height(control, height)
    curve = BSpline(control)
    span = np.ptp(curve(np.linspace(0, curve.segments, 20000)), axis=0)
    t, x, length = retime(curve, n_samples, duration, size=float(span.max()))
    if height is not None:
        x = x - (x.min(axis=0) + x.max(axis=0)) / 2
    # + 0.0 turns -0.0 into 0.0 so that the files do not show "-0.000000".
    return np.round(t, 9) + 0.0, np.round(x, decimals) + 0.0, length


def check_orientations(name, t, q):
    """Assert unit, sign-continuous quaternions at rest at both ends; return the turn (deg)."""
    assert np.all(np.isfinite(q)), name
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-8), name
    assert np.all(np.sum(q[1:] * q[:-1], axis=1) > 0.99), f'{name}: orientation jumps'
    dq = np.gradient(q, t, axis=0)
    omega = 2.0 * quaternion_multiply(dq, q * [-1, -1, -1, 1])[:, :3]
    speed = np.linalg.norm(omega, axis=1)
    assert speed[0] < 0.02 * speed.max() and speed[-1] < 0.02 * speed.max(), (
        f'{name}: orientation not at rest at the ends ({speed[0]}, {speed[-1]})')
    relative = quaternion_multiply(q, q[-1] * [-1, -1, -1, 1])
    return np.degrees(2 * np.arccos(np.clip(np.abs(relative[:, 3]), 0, 1)).max())


def check(name, t, x):
    """Assert the properties the package relies on; return the printed statistics."""
    assert np.all(np.isfinite(x)) and np.all(np.diff(t) > 0), name
    v = np.gradient(x, t, axis=0)
    a = np.gradient(v, t, axis=0)
    speed = np.linalg.norm(v, axis=1)
    accel = np.linalg.norm(a, axis=1)
    size = float(np.ptp(x, axis=0).max())
    separation = np.abs(x[-1] - x[0])
    assert np.all(separation >= MIN_SEPARATION * size), (
        f'{name}: start {x[0]} and goal {x[-1]} closer than {MIN_SEPARATION:.0%} of size {size}')
    assert speed[0] < REST_FRACTION * speed.max() and speed[-1] < REST_FRACTION * speed.max(), (
        f'{name}: not at rest at the ends ({speed[0]}, {speed[-1]} vs peak {speed.max()})')
    return {'size': np.ptp(x, axis=0), 'peak_speed': speed.max(), 'mean_speed': speed.mean(),
            'peak_accel': accel.max(), 'end_accel': (accel[0], accel[-1]),
            'separation': separation / size}


def write_csv(path, t, x, decimals, q=None):
    """Write ``t,x,y[,z]`` (then ``qx,qy,qz,qw`` if ``q`` is given), fixed decimals."""
    names = ['x', 'y', 'z'][:x.shape[1]] + ([] if q is None else ['qx', 'qy', 'qz', 'qw'])
    lines = [','.join(['t'] + names)]
    for k, (tk, row) in enumerate(zip(t, x)):
        quaternion = [] if q is None else [f'{v:.{QUATERNION_DECIMALS}f}' for v in q[k] + 0.0]
        lines.append(','.join([f'{tk:.9f}'.rstrip('0').rstrip('.') or '0']
                              + [f'{v:.{decimals}f}' for v in row] + quaternion))
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')


def plot(results, path):
    """Draw every demonstration (letters and wipe in x-y, stir in 3D) with its speed profile."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(18, 10))
    for k, (name, (t, x, _)) in enumerate(results.items()):
        speed = np.linalg.norm(np.gradient(x, t, axis=0), axis=1)
        if x.shape[1] == 3:
            ax = fig.add_subplot(2, 6, k + 1, projection='3d')
            ax.scatter(x[:, 0], x[:, 1], x[:, 2], c=speed, s=4, cmap='viridis')
            ax.plot(x[:, 0], x[:, 1], x[:, 2], lw=0.5, color='gray')
            ax.set_box_aspect(np.ptp(x, axis=0))
            ax.locator_params(nbins=3)
        else:
            ax = fig.add_subplot(2, 6, k + 1)
            ax.scatter(x[:, 0], x[:, 1], c=speed, s=6, cmap='viridis')
            ax.plot(x[:, 0], x[:, 1], lw=0.5, color='gray')
            ax.set_aspect('equal')
        ax.plot(*x[0], 'go')
        ax.plot(*x[-1], 'rs')
        ax.set_title(f'{name} (green start, red goal)')
        ax2 = fig.add_subplot(2, 6, k + 7)
        ax2.plot(t, speed)
        ax2.set_xlabel('t [s]')
        ax2.set_title(f'{name} speed')
    fig.tight_layout()
    fig.savefig(path, dpi=80)


def main(argv=None):
    """Build, check and write all built-in demonstrations."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT, help='output folder')
    parser.add_argument('--plot', type=Path, default=None, help='also draw them into this PNG')
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results = {}
    for name, (_, _, duration, decimals, _) in DEMOS.items():
        t, x, length = build(name)
        stats = check(name, t, x)
        q = ORIENTATIONS[name](t, x) if name in ORIENTATIONS else None
        turn = '' if q is None else f' turn={check_orientations(name, t, q):.1f}deg'
        write_csv(args.out / f'{name}.csv', t, x, decimals, q)
        results[name] = (t, x, length)
        print(f'{name:5s} T={len(t)} tau={duration:g}s size={np.round(stats["size"], 4)} '
              f'length={length:.4g} start={x[0]} goal={x[-1]} '
              f'|goal-start|/size={np.round(stats["separation"], 2)} '
              f'speed peak={stats["peak_speed"]:.4g} mean={stats["mean_speed"]:.4g} '
              f'accel peak={stats["peak_accel"]:.4g} ends={np.round(stats["end_accel"], 4)}'
              f'{turn}')
    if args.plot is not None:
        plot(results, args.plot)
        print(f'picture: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""
Does the arm touch an obstacle along a plan? Spheres enclosing the UR10 and its tool, no ROS.

The plan is for the tool tip; the planner keeps the tip clear of the obstacles, but not the
elbow, the wrists or the tool's body. :class:`ArmGeometry` covers every link of the UR10 by
spheres and :func:`arm_obstacle_violation` measures them against the obstacle cylinders at the
joint positions the plan's inverse kinematics gives (dmp_server already solves it for its
timing check: :func:`etdmp_ros.robot._timing.plan_joints`).

The spheres, built once from the same URDF the simulation collides with:

- a link's collision mesh (``example-robot-data``'s STL, loaded by Pinocchio with coal), as
  MuJoCo collides it: its convex hull (coal's qhull), cut into slices ``slice_length`` long
  along its principal axis. A slice of a convex polytope is the convex polytope of its
  vertices in the slice and the points where its edges cross the two cutting planes, and the
  point of a convex polytope farthest from any centre is one of its vertices: so the sphere
  centred on the slice (bounding box of those points across the axis, the slice's middle
  along it) and reaching the farthest of them encloses that part of the hull exactly. The
  base link is left out (it is fixed to the table; nothing stands on it);
- the tool (the simulation's, :data:`etdmp_ros.robot.PEN_RADIUS` ...): a row of spheres along
  its axis, enclosing its body and its tip.

Spheres over-cover a hull where a slice is not round (by up to a few centimetres at the
joints' housings), never under-cover it. Obstacles are upright cylinders standing on the table
(z = 0) up to their top face, as perceived (``/etdmp/obstacle_volumes``); a point obstacle
(radius 0) is a vertical segment from the table to its point. The distance from a sphere to a
cylinder is closed-form; the spheres of every configuration and every obstacle go in one numpy
computation.

Where: the links' spheres at the solved poses and between them, the joints interpolated
linearly so finely that no link sphere moves more than ``step`` (2 cm) from one checked
configuration to the next (a link's spheres are 9 to 23 cm across); the tool's, when asked, at
every pose of the plan (the plan gives the tool's pose: no IK needed). dmp_server checks the
links: keeping the tool clear is the plan's own job (the clearance it keeps from an obstacle's
centre counts the tool's radius), which it does for the tool's whole length while the tool is
upright, as for writing; a tilted tool's body above its tip is not checked.
"""

from __future__ import annotations

from dataclasses import dataclass

from etdmp_ros.geometry.arrays import Array, Points3
import numpy as np
from numpy.typing import ArrayLike, NDArray
import pinocchio as pin

from ._scene import PEN_RADIUS, PEN_TIP_LENGTH, PEN_TIP_RADIUS
from ._ur10 import Joints, robot_data_dir, UR10Model

#: Links whose meshes are covered (the base is fixed to the table).
LINKS = ('shoulder_link', 'upper_arm_link', 'forearm_link', 'wrist_1_link', 'wrist_2_link',
         'wrist_3_link')
#: Part names of the tool's spheres (as the simulation's contacts name them).
TOOL, TOOL_TIP = 'tool', 'tool_tip'


@dataclass(frozen=True)
class ArmViolation:
    """
    Where a plan takes a part of the arm too close to an obstacle.

    ``part``: the link (URDF name) or ``tool`` / ``tool_tip``; ``obstacle``: its index;
    ``t``: when (s, the plan's time); ``gap``: the distance from the part's spheres to the
    cylinder (m; negative: they overlap).
    """

    part: str
    obstacle: int
    t: float
    gap: float


def _slice_spheres(vertices: Points3, triangles: NDArray[np.intp], slice_length: float,
                   margin: float) -> tuple[Points3, Array]:
    """
    Return (centres (k, 3), radii (k,)) of spheres enclosing a convex hull slice by slice.

    ``vertices`` (n, 3) and ``triangles`` (t, 3): the hull; ``margin`` (m) is added to every
    radius (rounding).
    """
    mean = vertices.mean(axis=0)
    axis = np.linalg.svd(vertices - mean, full_matrices=False)[2][0]
    along = (vertices - mean) @ axis
    low, high = along.min(), along.max()
    count = max(1, int(np.ceil((high - low) / slice_length)))
    planes = np.linspace(low, high, count + 1)
    # The hull's edges and where they cross each cutting plane.
    edges = np.unique(np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                              triangles[:, [2, 0]]]), axis=1), axis=0)
    ta, tb = along[edges[:, 0]], along[edges[:, 1]]
    crossings = []
    for plane in planes:
        crossing = (np.minimum(ta, tb) < plane) & (np.maximum(ta, tb) > plane)
        a, b = edges[crossing, 0], edges[crossing, 1]
        s = ((plane - along[a]) / (along[b] - along[a]))[:, None]
        crossings.append(vertices[a] + s * (vertices[b] - vertices[a]))
    centres, radii = [], []
    for k in range(count):
        inside = (along >= planes[k]) & (along <= planes[k + 1])
        part = np.vstack([vertices[inside], crossings[k], crossings[k + 1]])
        if not len(part):
            continue
        t = (part - mean) @ axis
        across = (part - mean) - np.outer(t, axis)             # components across the axis
        middle = 0.5 * (across.min(axis=0) + across.max(axis=0))
        middle -= (middle @ axis) * axis
        centre = mean + middle + 0.5 * (t.min() + t.max()) * axis
        centres.append(centre)
        radii.append(np.linalg.norm(part - centre, axis=1).max() + margin)
    return np.array(centres), np.array(radii)


def _link_spheres(model: UR10Model, slice_length: float,
                  margin: float) -> tuple[list[str], list[int], list[Points3], list[Array]]:
    """Return the links' spheres: part names, joints, centres (k, 3) and radii per mesh."""
    geometry = pin.buildGeomFromUrdf(model.model, str(model.urdf_path),
                                     pin.GeometryType.COLLISION,
                                     package_dirs=[str(robot_data_dir().parent.parent)])
    parts: list[str] = []
    joints: list[int] = []
    local: list[Points3] = []
    radii: list[Array] = []
    for obj in geometry.geometryObjects:
        link = model.model.frames[obj.parentFrame].name
        if link not in LINKS or not hasattr(obj.geometry, 'vertices'):
            continue
        mesh = obj.geometry
        mesh.buildConvexHull(True, 'Qt')        # what MuJoCo collides: the convex hull
        hull = mesh.convex
        vertices = np.asarray(hull.points()) * np.asarray(obj.meshScale)
        triangles = np.array([[hull.polygons(i)[k] for k in range(3)]
                              for i in range(hull.num_polygons)])
        # In the frame of the joint that moves the link.
        vertices = vertices @ obj.placement.rotation.T + obj.placement.translation
        centres, r = _slice_spheres(vertices, triangles, slice_length, margin)
        parts += [link] * len(r)
        joints += [obj.parentJoint] * len(r)
        local.append(centres)
        radii.append(r)
    missing = set(LINKS) - set(parts)
    if missing:
        raise RuntimeError(f'no collision mesh for {sorted(missing)} in {model.urdf_path}')
    return parts, joints, local, radii


def _tool_spheres(tool_offset: ArrayLike,
                  tool_step: float) -> tuple[list[str], list[Points3], list[Array]]:
    """
    Return the tool's spheres: part names, centres (k, 3) and radii in pieces.

    Along tool0's z axis to the tool tip (its tip: the last PEN_TIP_LENGTH); centres in the
    tool tip's frame (tool0's axes, at the tip).
    """
    offset = np.asarray(tool_offset, dtype=float)
    length = float(np.linalg.norm(offset))
    tool_parts: list[str] = []
    tool_local: list[Points3] = [np.zeros((0, 3))]
    tool_radii: list[Array] = [np.zeros(0)]
    if length > 1e-6:
        direction = offset / length
        tip_start = max(0.0, length - PEN_TIP_LENGTH)
        for name, (a, b), radius in ((TOOL, (0.0, tip_start), PEN_RADIUS),
                                     (TOOL_TIP, (tip_start, length), PEN_TIP_RADIUS)):
            if b - a < 1e-6:
                continue
            n = max(1, int(np.ceil((b - a) / tool_step)))
            half = 0.5 * (b - a) / n
            along = a + half * (2 * np.arange(n) + 1)
            tool_parts += [name] * n
            tool_local.append(along[:, None] * direction[None] - offset)
            tool_radii.append(np.full(n, np.hypot(radius, half)))
    return tool_parts, tool_local, tool_radii


def _chain(model: UR10Model) -> tuple[list[Array], list[int]]:
    """
    Return each joint's placement (4, 4) in its parent's frame and the axis (0-2) it turns about.

    For forward kinematics of many configurations at once; RuntimeError unless the URDF is a
    serial chain of revolute joints about x, y or z.
    """
    chain = model.model
    placements, axes = [], []
    for j in range(1, chain.njoints):
        kind = chain.joints[j].shortname()
        revolute = kind in ('JointModelRX', 'JointModelRY', 'JointModelRZ')
        if chain.parents[j] != j - 1 or not revolute:
            raise RuntimeError(f'unexpected joint {chain.names[j]} ({kind}) in '
                               f'{model.urdf_path}: a serial chain of revolute joints '
                               'about x, y or z was expected')
        placements.append(chain.jointPlacements[j].homogeneous)
        axes.append('XYZ'.index(kind[-1]))
    return placements, axes


class ArmGeometry:
    """
    Spheres enclosing the UR10's links and its tool, attached to the joints that move them.

    ``model``: the :class:`UR10Model` (its ``tool_offset`` places the tool tip). Building loads
    the collision meshes (about 0.3 s). The links' spheres: :attr:`parts`, :attr:`radii` and
    :attr:`local` (part name, m, centre in its joint's frame), placed by :meth:`centres`; the
    tool's: :attr:`tool_parts`, :attr:`tool_radii`, :attr:`tool_local` (centre in the tool
    tip's frame), placed by :meth:`tool_centres`.
    """

    def __init__(self, model: UR10Model, slice_length: float = 0.03, margin: float = 0.0005,
                 tool_step: float = 0.005) -> None:
        """Cover the hulls (slices ``slice_length`` long, radii + ``margin``) and the tool."""
        self.model = model
        parts, joints, local, radii = _link_spheres(model, slice_length, margin)
        self.parts = np.array(parts)
        self.joints = np.array(joints)
        self.local = np.vstack(local)
        self.radii = np.concatenate(radii)
        tool_parts, tool_local, tool_radii = _tool_spheres(model.tool_offset, tool_step)
        self.tool_parts = np.array(tool_parts)
        self.tool_local = np.vstack(tool_local)
        self.tool_radii = np.concatenate(tool_radii)
        self._placements, self._axes = _chain(model)
        self._which = self.joints - 1           # joint index (0-5) of each sphere

    def joint_frames(self, joints: ArrayLike) -> Array:
        """Return each joint's frame (n, 6, 4, 4) in base_link for joint positions (n, 6)."""
        q = np.asarray(joints, dtype=float).reshape(-1, 6)
        frames = np.empty((len(q), 6, 4, 4))
        current = np.broadcast_to(np.eye(4), (len(q), 4, 4))
        for j, (placement, axis) in enumerate(zip(self._placements, self._axes)):
            c, s = np.cos(q[:, j]), np.sin(q[:, j])
            turn = np.zeros((len(q), 4, 4))
            turn[:, axis, axis] = turn[:, 3, 3] = 1.0
            a, b = [(1, 2), (2, 0), (0, 1)][axis]       # the plane it turns in
            turn[:, a, a] = turn[:, b, b] = c
            turn[:, a, b], turn[:, b, a] = -s, s
            current = current @ placement @ turn
            frames[:, j] = current
        return frames

    def centres(self, joints: ArrayLike) -> Points3:
        """Place the spheres: return their centres' positions (n, k, 3) at joints (n, 6)."""
        frames = self.joint_frames(joints)[:, self._which]
        return np.matmul(frames[..., :3, :3], self.local[None, :, :, None])[..., 0] + \
            frames[..., :3, 3]

    def tool_centres(self, positions: ArrayLike, rotations: ArrayLike) -> Points3:
        """Return the tool's sphere centres (n, k, 3) for tool tip poses (n, 3), (n, 3, 3)."""
        positions = np.asarray(positions, dtype=float).reshape(-1, 3)
        rotations = np.broadcast_to(np.asarray(rotations, dtype=float), (len(positions), 3, 3))
        return np.matmul(rotations, self.tool_local.T).transpose(0, 2, 1) + positions[:, None]


def cylinder_gaps(centres: Points3, radii: ArrayLike, tops: ArrayLike,
                  obstacle_radii: ArrayLike) -> Array:
    """
    Return the distances (n, k, m) from spheres to upright cylinders (negative: they overlap).

    ``centres`` (n, k, 3) and ``radii`` (k,): spheres; ``tops`` (m, 3): the centre of each
    cylinder's top face (it stands on z = 0 up to there); ``obstacle_radii`` (m,). A
    cylinder's distance: the horizontal distance beyond its radius and the vertical one beyond
    its ends, combined (0 inside; a sphere whose centre is inside counts as overlapping by its
    radius).
    """
    tops = np.asarray(tops, dtype=float).reshape(-1, 3)
    dx = centres[:, :, 0, None] - tops[:, 0]
    dy = centres[:, :, 1, None] - tops[:, 1]
    outward = np.sqrt(dx * dx + dy * dy) - np.asarray(obstacle_radii, dtype=float)
    np.maximum(outward, 0.0, out=outward)
    z = centres[:, :, 2, None]
    vertical = np.maximum(np.maximum(z - tops[:, 2], -z), 0.0)
    return np.sqrt(outward * outward + vertical * vertical) - np.asarray(radii)[None, :, None]


def densified(joints: ArrayLike, times: ArrayLike, displacement: ArrayLike,
              step: float) -> tuple[Joints, Array]:
    """
    Return joints (p, 6) and times (p,) with configurations added between the rows of ``joints``.

    ``joints`` (n, 6) at ``times`` (n,); ``displacement`` (n - 1,): how far the spheres move
    (m) from each row to the next. Linear in the joints and in time, ``ceil(displacement /
    step)`` steps per interval.
    """
    joints = np.asarray(joints, dtype=float).reshape(-1, 6)
    times = np.asarray(times, dtype=float)
    if len(joints) < 2:
        return joints, times
    counts = np.maximum(1, np.ceil(np.asarray(displacement) / step)).astype(int)
    rows, when = [joints[:1]], [times[:1]]
    for k, n in enumerate(counts):
        s = np.arange(1, n + 1) / n
        rows.append(joints[k] + s[:, None] * (joints[k + 1] - joints[k]))
        when.append(times[k] + s * (times[k + 1] - times[k]))
    return np.vstack(rows), np.concatenate(when)


def checked_configurations(geometry: ArmGeometry, joints: ArrayLike, times: ArrayLike, step: float,
                           rounds: int = 4) -> tuple[Joints, Array, Points3]:
    """
    Return (joints (p, 6), times (p,), centres (p, k, 3)): the configurations the check uses.

    The solved ``joints`` (n, 6) at ``times`` (n,), and between them as many as make every
    link sphere move at most ``step`` (m) from one to the next (:func:`densified`, refined
    where a sphere's path bends: up to ``rounds`` times).
    """
    rows = np.asarray(joints, dtype=float).reshape(-1, 6)
    when = np.asarray(times, dtype=float)
    centres = geometry.centres(rows)
    for _ in range(rounds):
        moved = np.linalg.norm(np.diff(centres, axis=0), axis=2).max(axis=1) \
            if len(rows) > 1 else np.zeros(0)
        if not len(moved) or moved.max() <= step:
            break
        rows, when = densified(rows, when, moved, step)
        centres = geometry.centres(rows)
    return rows, when, centres


def _first(gaps: Array, times: Array, parts: NDArray[np.str_],
           clearance: float) -> ArmViolation | None:
    """Return the ArmViolation of the first row with a gap below ``clearance``, or None."""
    worst = gaps.min(axis=(1, 2))
    bad = np.flatnonzero(worst < clearance)
    if not len(bad):
        return None
    i = int(bad[0])
    k, j = np.unravel_index(np.argmin(gaps[i]), gaps[i].shape)
    return ArmViolation(str(parts[k]), int(j), float(times[i]), float(gaps[i, k, j]))


def arm_obstacle_violation(geometry: ArmGeometry, joints: ArrayLike, times: ArrayLike,
                           tops: ArrayLike, obstacle_radii: ArrayLike, clearance: float,
                           tool_poses: tuple[ArrayLike, ArrayLike, ArrayLike] | None = None,
                           step: float = 0.02) -> ArmViolation | None:
    """
    Return the earliest :class:`ArmViolation` of a plan, or None.

    ``joints`` (n, 6): the arm's configurations solved along the plan at ``times`` (n,): the
    links are checked there and between; ``tool_poses``: ``(t (p,), positions (p, 3),
    rotations (p, 3, 3))`` of the plan's every tool tip pose, to check the tool's spheres there
    too (None: the links only);
    ``tops`` (m, 3) and ``obstacle_radii`` (m,): the obstacle cylinders; ``clearance`` (m): a
    sphere closer than this to a cylinder is a violation. Of the earliest configuration with
    one, the part and obstacle of the smallest gap.
    """
    tops = np.asarray(tops, dtype=float).reshape(-1, 3)
    joints = np.asarray(joints, dtype=float).reshape(-1, 6)
    if not len(tops) or not len(joints):
        return None
    _, when, centres = checked_configurations(geometry, joints, times, step)
    found = [_first(cylinder_gaps(centres, geometry.radii, tops, obstacle_radii), when,
                    geometry.parts, clearance)]
    if tool_poses is not None and len(geometry.tool_radii):
        t, positions, rotations = tool_poses
        found.append(_first(cylinder_gaps(geometry.tool_centres(positions, rotations),
                                          geometry.tool_radii, tops, obstacle_radii),
                            np.asarray(t, dtype=float), geometry.tool_parts, clearance))
    violations = [v for v in found if v is not None]
    return min(violations, key=lambda v: v.t) if violations else None

"""
Planning for the DMP server: (skill, start, goal, obstacles, settings) → a timed base_link path.

One function, :func:`plan_path`, does what a ``/generalize`` request needs after its inputs have
been resolved to base_link points: map them into the skill's space, check the request, call the
ET-DMP core and map the result back.

- 2D skills (2 coordinates, demo units) run in the task plane (:class:`TaskPlane`): start, goal
  and obstacles are projected onto it, the path lies on it. 3D skills use base_link directly.
- Obstacles: centres, and optionally radii in metres (the clearance the path must keep from each
  centre: the caller adds the tool's radius and a margin), divided by the task plane's scale for
  2D skills. With radii the core's detour avoids them (the ``avoidance`` setting, empty: the
  detour with radii, the paper's point obstacles without; docs/design.md#obstacles-with-a-size).
- Checks, each a :class:`PlanningError` whose message is the reason given to the user: NaN or inf,
  a coordinate beyond ``MAX_REQUEST_COORDINATE`` (:func:`bounded`), start = goal (closer than
  ``min_distance``), an obstacle on the goal (closer than ``goal_clearance``), a goal or a path
  point outside the :class:`Workspace`, and whatever the core refuses (``GeneralizationError``:
  for the detour, also a start or goal inside an obstacle and a clearance it cannot keep).
- Obstacle sizes: each obstacle's radius (m, as perceived; 0 for a point) plus the
  ``tool_radius`` and ``obstacle_clearance`` settings is the clearance the plan must keep from
  its centre (:attr:`Plan.obstacle_radii`, in metres; divided by the task plane's scale in a
  2D skill's units).
- Timing: samples every ``output_period`` seconds from 0 to ``tau (1 + margin)``, with ``tau`` the
  ``duration`` setting (0: the demonstration's own duration) and ``margin`` the
  ``obstacle_margin`` when the paper's coupling avoids obstacles (its detour arrives later), else
  0 (the detour keeps the obstacle-free timing).
- Orientation (docs/orientation.md#modes): a skill with orientations gives every pose its own,
  the core's ``Trajectory.q`` (mode ``demo``: the demonstrated orientations turned with the
  motion; ``goal``: converging to a requested goal orientation), in base_link: a 2D skill's
  orientations are in the task plane's frame, ``q_base = q_P q_plane``
  (:meth:`TaskPlane.orientation_from_plane`), a 3D skill's in base_link. A position-only skill,
  or the ``orientation_mode`` setting ``tool``, gives every pose the one ``orientation`` setting
  (mode ``tool``).
"""

from dataclasses import dataclass, field, replace
from typing import Optional, Tuple, Union

from etdmp_ros import limits
from etdmp_ros.dmp import (AVOIDANCES, euclidean_transform, GeneralizationError, METHODS,
                           ObstacleGains, Skill, Trajectory)
from etdmp_ros.geometry.arrays import Array
from etdmp_ros.geometry.quaternion import unit_and_norm
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.robot import PEN_RADIUS
import numpy as np
from numpy.typing import ArrayLike


#: Tool orientation (x, y, z, w) in base_link that points the tool's z axis down (-z of
#: base_link), as at the scene's initial joint positions: the pen/stirrer points at the table.
TOOL_DOWN = (-0.7071067811865476, 0.7071067811865476, 0.0, 0.0)


#: How a plan's tool orientation is chosen (the ``orientation_mode`` setting): ``demo`` the
#: skill's own orientations when it has them (``goal`` when a goal orientation is requested),
#: else ``tool``; ``tool`` always the one ``orientation`` setting.
PLAN_ORIENTATION_MODES = ('demo', 'tool')


class PlanningError(ValueError):
    """A request that cannot be planned; the message says why (it is logged for the user)."""


@dataclass(frozen=True)
class Workspace:
    """
    A simple, honest reach criterion for the UR10's tool tip; not inverse kinematics.

    A point ``p`` (base_link) passes when

    - ``|p - shoulder| <= reach - margin``: the UR10's reach is 1.3 m (datasheet) about the
      shoulder, whose lift axis is 0.1273 m above the base (the URDF's shoulder_pan joint);
      the margin leaves room for the wrist and the tool (default 0.15 m);
    - its distance from the base's z axis is at least ``min_radius``: close to that axis the arm
      is near its shoulder singularity and cannot move the tool freely;
    - ``z >= min_height``: not below the table top (z = 0), up to a small tolerance.

    Passing is necessary, not sufficient: the controller's IK has the last word (orientation,
    joint limits).
    """

    shoulder: Tuple[float, float, float] = (0.0, 0.0, 0.1273)
    reach: float = 1.3
    margin: float = 0.15
    min_radius: float = 0.2
    min_height: float = -0.005

    def __post_init__(self) -> None:
        """Validate the numbers."""
        shoulder = np.asarray(self.shoulder, dtype=float)
        if shoulder.shape != (3,) or not np.all(np.isfinite(shoulder)):
            raise ValueError(f'workspace shoulder must be 3 finite numbers, got {self.shoulder!r}')
        for name in ('reach', 'margin', 'min_radius', 'min_height'):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f'workspace {name} must be finite')
        if not self.reach - self.margin > self.min_radius >= 0.0:
            raise ValueError(f'workspace needs reach - margin > min_radius >= 0, got reach '
                             f'{self.reach}, margin {self.margin}, min_radius {self.min_radius}')

    def violation(self, points: ArrayLike) -> Optional[Tuple[int, str]]:
        """
        Return (index, reason) of the first point (n, 3) outside the workspace, or None.

        The reason names the criterion and the numbers.
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        limit = self.reach - self.margin
        dist = np.linalg.norm(points - np.asarray(self.shoulder), axis=1)
        radius = np.hypot(points[:, 0], points[:, 1])
        checks = (
            (dist > limit, lambda i: f'{dist[i]:.3f} m from the shoulder, more than the reach '
                                     f'{self.reach:g} m minus margin {self.margin:g} m'),
            (radius < self.min_radius, lambda i: f'{radius[i]:.3f} m from the base axis, closer '
                                                 f'than {self.min_radius:g} m'),
            (points[:, 2] < self.min_height, lambda i: f'below the table (z = {points[i, 2]:.3f} '
                                                       f'm < {self.min_height:g} m)'),
        )
        first = None
        for bad, reason in checks:
            hits = np.flatnonzero(bad)
            if hits.size and (first is None or hits[0] < first[0]):
                first = (int(hits[0]), reason(int(hits[0])))
        return first


def _quaternion(value):
    q = np.asarray(value, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f'tool_orientation must be 4 finite numbers (x, y, z, w), got {value!r}')
    unit, norm = unit_and_norm(q)
    if not norm > 1e-6:
        raise ValueError('tool_orientation must be a non-zero quaternion (x, y, z, w)')
    return tuple(float(c) for c in unit)


@dataclass(frozen=True)
class PlanSettings:
    """
    How to plan (every field is a dmp_server parameter of the same name).

    ``obstacle_k`` is in 1/m; 0 keeps the core's default, ``k = gains.k_relative / |x0 - g|``.
    ``avoidance``: one of the core's AVOIDANCES, or empty for the detour when the obstacles have
    radii and the paper's coupling when they do not.
    ``orientation`` is normalised; ``orientation_mode`` one of PLAN_ORIENTATION_MODES.
    ``tool_radius`` and ``obstacle_clearance`` (m) add to each obstacle's radius: the clearance
    the plan keeps from its centre. Construction raises ValueError for bad values.
    """

    method: str = 'etdmp'
    mode: int = 1
    independent_axis: int = 2
    duration: float = 0.0
    output_period: float = 0.01
    gains: ObstacleGains = field(default_factory=ObstacleGains)
    obstacle_k: float = 0.0
    obstacle_margin: float = 0.5
    avoidance: str = ''
    goal_clearance: float = 0.02
    min_distance: float = 0.005
    orientation: Tuple[float, float, float, float] = TOOL_DOWN
    orientation_mode: str = 'demo'
    workspace: Workspace = field(default_factory=Workspace)
    tool_radius: float = PEN_RADIUS
    obstacle_clearance: float = 0.008

    def __post_init__(self) -> None:
        """Validate and normalise."""
        if self.method not in METHODS:
            raise ValueError(f'method must be one of {METHODS}, got {self.method!r}')
        if self.avoidance not in ('',) + AVOIDANCES:
            raise ValueError(f"avoidance must be '' or one of {AVOIDANCES}, got "
                             f'{self.avoidance!r}')
        if self.orientation_mode not in PLAN_ORIENTATION_MODES:
            raise ValueError(f'orientation_mode must be one of {PLAN_ORIENTATION_MODES}, got '
                             f'{self.orientation_mode!r}')
        if self.mode not in (1, 2):
            raise ValueError(f'mode must be 1 or 2, got {self.mode!r}')
        if self.independent_axis not in (0, 1, 2):
            raise ValueError(f'independent_axis must be 0, 1 or 2, got {self.independent_axis!r}')
        positive = ('output_period',)
        non_negative = ('duration', 'obstacle_k', 'obstacle_margin', 'goal_clearance',
                        'min_distance', 'tool_radius', 'obstacle_clearance')
        for name in positive + non_negative:
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0.0 or (name in positive and value == 0.0):
                bound = '> 0' if name in positive else '>= 0'
                raise ValueError(f'{name} must be {bound}, got {value!r}')
        self.gains.validate()
        object.__setattr__(self, 'orientation', _quaternion(self.orientation))

    def skill_gains(self, scale: float) -> ObstacleGains:
        """Return the obstacle gains for a skill of ``scale`` metres per unit (obstacle_k)."""
        if self.obstacle_k > 0.0:   # 1/m → 1/skill unit: exp(-k d) with d = d_units * scale
            return replace(self.gains, k=self.obstacle_k * scale)
        return self.gains


@dataclass(frozen=True, eq=False)
class Plan:
    """
    A planned tool path in base_link.

    ``t`` (n,) seconds from the start; ``positions``, ``velocities`` (n, 3); ``orientation``:
    one (x, y, z, w) tuple for every pose (mode ``tool``) or an (n, 4) array, one unit
    quaternion per pose (a skill with orientations), base_link; :attr:`orientations` is (n, 4)
    either way. ``start``, ``goal`` and ``obstacles`` (m, 3) as used (projected onto the task
    plane for 2D skills); ``trajectory``: the core's result in the skill's space;
    ``obstacle_radii`` (m,): the clearance (m) the plan keeps from each obstacle's centre (its
    radius + the tool's + ``obstacle_clearance``), None when the obstacles were given without
    radii; ``avoidance`` as used.
    """

    t: Array
    positions: Array
    velocities: Array
    orientation: Union[Tuple[float, ...], Array]
    start: Array
    goal: Array
    obstacles: Array
    method: str
    trajectory: Optional[Trajectory]
    obstacle_radii: Optional[Array] = None
    avoidance: str = 'paper'

    @property
    def orientations(self) -> Array:
        """Return the orientation of every pose (n, 4), (x, y, z, w) in base_link."""
        return pose_orientations(self.orientation, len(self.t))


def pose_orientations(orientation: Union[Tuple[float, ...], ArrayLike], n: int) -> Array:
    """Return ``orientation`` (a (4,) tuple or an (n, 4) array) as an (n, 4) array."""
    if isinstance(orientation, tuple):
        return np.tile(np.asarray(orientation, dtype=float), (n, 1))
    return np.asarray(orientation, dtype=float)


def checked_points(value: ArrayLike, what: str, shape: Optional[Tuple[int, ...]]) -> Array:
    """
    Return a request's point (``shape`` (3,)) or points (else: (m, 3)), checked (:func:`bounded`).

    Raises PlanningError saying ``what`` is wrong.
    """
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise PlanningError(f'{what} must be numbers, got {value!r}') from None
    if shape == (3,) and array.shape != (3,):
        raise PlanningError(f'{what} must be a point (x, y, z), got shape {array.shape}')
    if shape != (3,):
        array = array.reshape(-1, 3) if array.size else np.zeros((0, 3))
    return bounded(array, what)


def bounded(points: ArrayLike, what: str) -> Array:
    """
    Return ``points`` (any shape, base_link metres) as a float array, checked as a request's.

    Raises PlanningError for NaN or inf, and for a coordinate beyond MAX_REQUEST_COORDINATE (a
    finite 1e308 overflowed in every plan it reached: as an obstacle, "overflow encountered
    in divide").
    """
    points = np.asarray(points, dtype=float)
    if not np.all(np.isfinite(points)):
        raise PlanningError(f'{what} contains NaN or inf')
    big = np.abs(points) > limits.MAX_REQUEST_COORDINATE
    if np.any(big):
        value = points[np.unravel_index(np.flatnonzero(big)[0], points.shape)]
        raise PlanningError(f'{what} has a coordinate of {value:.3g} m, beyond '
                            f'{limits.MAX_REQUEST_COORDINATE:g} m (MAX_REQUEST_COORDINATE): no '
                            'place of the workcell')
    return points


def _avoidance(settings, radii):
    """Return the avoidance a plan uses: the setting, or by whether radii were given."""
    return settings.avoidance or ('paper' if radii is None else 'detour')


class SkillSpace:
    """
    The skill's coordinates: demo units in the task plane (2D) or base_link metres (3D).

    ``plane``: the TaskPlane of a 2D skill (None, and ignored, for a 3D one); ``scale``: metres
    per skill unit (1 in 3D). Points and vectors are (..., 3) in base_link and (..., d) in the
    skill's space; orientations (..., 4), (x, y, z, w).
    """

    def __init__(self, skill: Skill, plane: Optional[TaskPlane]) -> None:
        """Take the space of ``skill``; raise PlanningError for a 2D skill without a plane."""
        if skill.dim == 2:
            if plane is None:
                raise PlanningError('a 2D skill needs a task plane')
            self.plane, self.scale = plane, plane.scale
        elif skill.dim == 3:
            self.plane, self.scale = None, 1.0
        else:
            raise PlanningError(f'a skill must have 2 or 3 coordinates, this one has {skill.dim}')

    def inward(self, points: Array) -> Array:
        """Return base_link points in the skill's space (projected onto the plane, 2D)."""
        return points if self.plane is None else self.plane.to_plane(points)

    def outward(self, points: Array) -> Array:
        """Return points of the skill's space in base_link."""
        return points if self.plane is None else self.plane.from_plane(points)

    def outward_vectors(self, vectors: Array) -> Array:
        """Return vectors (velocities) of the skill's space in base_link (metres)."""
        return vectors if self.plane is None else (self.scale * vectors) @ self.plane.axes

    def inward_orientations(self, q: Array) -> Array:
        """Return base_link orientations in the skill's frame (the task plane's, 2D)."""
        return q if self.plane is None else self.plane.orientation_to_plane(q)

    def outward_orientations(self, q: Array) -> Array:
        """Return orientations of the skill's frame in base_link."""
        return q if self.plane is None else self.plane.orientation_from_plane(q)


def goal_orientation_of(skill: Skill, value: Optional[ArrayLike],
                        settings: PlanSettings) -> Optional[Array]:
    """
    Return the requested goal orientation (4,) as the plan uses it, or None for none.

    ``value``: None, or (x, y, z, w) in base_link. All zeros means "no goal orientation", and
    so does exactly ``(0, 0, 0, 1)``, the default of a ROS Quaternion message (a request that
    sets only the goal's position); ask for the identity itself with ``(0, 0, 0, -1)``. Raises
    PlanningError for NaN, inf or a non-unit quaternion (norm off 1 by more than 1e-3), and
    for a goal orientation given for a skill without orientations or with the
    ``orientation_mode`` setting ``tool``.
    """
    if value is None:
        return None
    try:
        q = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise PlanningError(f'goal orientation must be 4 numbers (x, y, z, w), got {value!r}') \
            from None
    if q.shape != (4,):
        raise PlanningError(f'goal orientation must be 4 numbers (x, y, z, w), got shape '
                            f'{q.shape}')
    if not np.all(np.isfinite(q)):
        raise PlanningError(f'goal orientation {q.tolist()} contains NaN or inf')
    if not np.any(q) or np.array_equal(q, (0.0, 0.0, 0.0, 1.0)):
        return None
    unit, norm = unit_and_norm(q)
    if abs(norm - 1.0) > GOAL_ORIENTATION_NORM_TOLERANCE:
        # (1e308, 1e308, 0, 1) was refused as "overflow encountered in dot" before.
        raise PlanningError(f'goal orientation {format_point(q)} is not a unit quaternion (norm '
                            f'{norm:.4g}); send a unit one, or all zeros for no goal '
                            'orientation')
    if not skill.has_orientation:
        raise PlanningError('a goal orientation was given, but the skill has no orientations '
                            '(its tool keeps tool_orientation); send all zeros for none')
    if settings.orientation_mode == 'tool':
        raise PlanningError("a goal orientation was given, but orientation_mode is 'tool' (the "
                            'tool keeps tool_orientation); send all zeros for none')
    return unit


#: Largest deviation from 1 of the norm of a requested goal orientation.
GOAL_ORIENTATION_NORM_TOLERANCE = 1e-3


def format_point(point: ArrayLike) -> str:
    """Return a point as ``(x, y, z)`` in millimetre figures (metres), for a message."""
    return '(' + ', '.join(f'{c:.3f}' if abs(c) < 1e6 else f'{c:.3g}' for c in point) + ')'


def obstacle_clearances(radii: Optional[ArrayLike], settings: PlanSettings,
                        count: int) -> Optional[Array]:
    """
    Return the clearance (count,) a plan keeps from each obstacle's centre (m), or None.

    ``radii``: each obstacle's radius (m; 0 for a point), None when not known; the tool's radius
    and the safety margin (``settings``) are added. Raises PlanningError for radii that do not
    match the obstacles or are not finite and >= 0.
    """
    if radii is None:
        return None
    try:
        radii = np.asarray(radii, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise PlanningError(f'obstacle radii must be numbers, got {radii!r}') from None
    if len(radii) != count:
        raise PlanningError(f'{count} obstacles but {len(radii)} obstacle radii')
    if not np.all(np.isfinite(radii)) or np.any(radii < 0.0):
        raise PlanningError(f'obstacle radii must be finite and >= 0 (m), got {radii.tolist()}')
    return radii + settings.tool_radius + settings.obstacle_clearance


def _check_request(start, goal, obstacles, settings, where):
    """Refuse a goal out of reach, on the start or on an obstacle (base_link points)."""
    outside = settings.workspace.violation(goal)
    if outside is not None:
        raise PlanningError(f"goal {format_point(goal)}{where} is out of the UR10's reach: "
                            f'{outside[1]}')
    gap = float(np.linalg.norm(start - goal))
    if gap < settings.min_distance:
        raise PlanningError(f'start equals goal{where}: they are {gap * 1000:.1f} mm apart, less '
                            f'than min_distance {settings.min_distance * 1000:g} mm; there is no '
                            'movement to make')
    if len(obstacles):
        to_goal = np.linalg.norm(obstacles - goal, axis=1)
        i = int(np.argmin(to_goal))
        if to_goal[i] < settings.goal_clearance:
            raise PlanningError(f'obstacle {format_point(obstacles[i])}{where} lies on the goal: '
                                f'{to_goal[i] * 1000:.1f} mm from it, less than goal_clearance '
                                f'{settings.goal_clearance * 1000:g} mm')


def plan_path(skill: Skill, start: ArrayLike, goal: ArrayLike, obstacles: ArrayLike = (),
              settings: Optional[PlanSettings] = None, plane: Optional[TaskPlane] = None,
              goal_orientation: Optional[ArrayLike] = None,
              obstacle_radii: Optional[ArrayLike] = None) -> Plan:
    """
    Plan ``skill`` (an ``etdmp_ros.dmp.Skill``) from ``start`` to ``goal`` around ``obstacles``.

    ``start``, ``goal``: base_link points (3,); ``obstacles``: (m, 3) base_link points (the
    centres); ``settings``: PlanSettings; ``plane``: the TaskPlane (needed for 2D skills);
    ``goal_orientation``: None or (x, y, z, w) in base_link (see :func:`goal_orientation_of`:
    all zeros for none); ``obstacle_radii``: (m,) each obstacle's radius in metres (0: a point),
    None for obstacles of unknown size. Returns a Plan; raises PlanningError with the reason
    when the request cannot be served.
    """
    settings = PlanSettings() if settings is None else settings
    goal_q = goal_orientation_of(skill, goal_orientation, settings)
    start = checked_points(start, 'start', (3,))
    goal = checked_points(goal, 'goal', (3,))
    obstacles = checked_points(obstacles, 'obstacles', None)
    avoidance = _avoidance(settings, obstacle_radii)
    clearances = obstacle_clearances(obstacle_radii, settings, len(obstacles))
    if clearances is None and avoidance == 'detour':   # points of unknown size: the tool's
        clearances = obstacle_clearances(np.zeros(len(obstacles)), settings, len(obstacles))
    space = SkillSpace(skill, plane)
    start_s, goal_s, obstacles_s = (space.inward(p) for p in (start, goal, obstacles))
    start_b, goal_b, obstacles_b = (space.outward(p) for p in (start_s, goal_s, obstacles_s))
    _check_request(start_b, goal_b, obstacles_b, settings,
                   ' (projected onto the task plane)' if space.plane is not None else '')
    try:
        traj = skill.generalize(
            start_s, goal_s, obstacles_s, method=settings.method, mode=settings.mode,
            independent_axis=settings.independent_axis, dt=settings.output_period,
            tau=settings.duration or None,
            margin=settings.obstacle_margin if len(obstacles_s) and avoidance == 'paper' else 0.0,
            gains=settings.skill_gains(space.scale), avoidance=avoidance,
            obstacle_radii=None if clearances is None else clearances / space.scale,
            goal_orientation=None if goal_q is None else space.inward_orientations(goal_q))
    except GeneralizationError as err:
        raise PlanningError(str(err)) from None
    if traj.q is not None and settings.orientation_mode == 'demo':
        orientation = space.outward_orientations(traj.q)
        orientation /= np.linalg.norm(orientation, axis=1, keepdims=True)
    else:
        orientation = settings.orientation
    positions = space.outward(traj.x)
    outside = settings.workspace.violation(positions)
    if outside is not None:
        i, reason = outside
        raise PlanningError(f"the plan leaves the UR10's reach at t = {traj.t[i]:.2f} s, "
                            f'{format_point(positions[i])}: {reason}')
    return Plan(traj.t, positions, space.outward_vectors(traj.v), orientation,
                start_b, goal_b, obstacles_b, settings.method, traj, clearances, avoidance)


def place_demo(skill: Skill, start: ArrayLike, goal: ArrayLike,
               plane: Optional[TaskPlane] = None, mode: int = 1,
               independent_axis: int = 2) -> Array:
    """
    Return the demonstration (T, 3) turned and scaled so it runs from start to goal.

    This is where ET-DMP's plan lies without obstacles: the demonstration drawn in place, for
    display. ``start``, ``goal``: base_link points; ``plane`` for 2D skills; ``mode``,
    ``independent_axis``: a 3D skill's transform (mode 2 scales each block by its own ratio).
    """
    space = SkillSpace(skill, plane)
    start_s, goal_s = space.inward(checked_points(start, 'start', (3,))), space.inward(
        checked_points(goal, 'goal', (3,)))
    i_demo = skill.start - skill.goal
    i_current = start_s - goal_s
    try:
        transform = euclidean_transform(i_demo, i_current, mode if len(i_demo) == 3 else 1,
                                        independent_axis, size=skill.size)
    except GeneralizationError as err:
        raise PlanningError(str(err)) from None
    # Row-vector form of x = g + R^T (scale * (y - g_D)).
    return space.outward(goal_s + (transform.scale * (skill.demo - skill.goal)) @ transform.R)

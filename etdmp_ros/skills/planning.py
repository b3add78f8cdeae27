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
import math

from etdmp_ros import limits
from etdmp_ros.dmp import (AVOIDANCES, euclidean_transform, GeneralizationError, METHODS,
                           ObstacleGains)
from etdmp_ros.geometry.quaternion import unit_and_norm
from etdmp_ros.robot._scene import PEN_RADIUS
import numpy as np

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

    shoulder: tuple = (0.0, 0.0, 0.1273)
    reach: float = 1.3
    margin: float = 0.15
    min_radius: float = 0.2
    min_height: float = -0.005

    def __post_init__(self):
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

    def violation(self, points):
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
    orientation: tuple = TOOL_DOWN
    orientation_mode: str = 'demo'
    workspace: Workspace = field(default_factory=Workspace)
    tool_radius: float = PEN_RADIUS
    obstacle_clearance: float = 0.008

    def __post_init__(self):
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

    t: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    orientation: tuple
    start: np.ndarray
    goal: np.ndarray
    obstacles: np.ndarray
    method: str
    trajectory: object
    obstacle_radii: np.ndarray = None
    avoidance: str = 'paper'

    @property
    def orientations(self):
        """Return the orientation of every pose (n, 4), (x, y, z, w) in base_link."""
        return pose_orientations(self.orientation, len(self.t))


def pose_orientations(orientation, n):
    """Return ``orientation`` (a (4,) tuple or an (n, 4) array) as an (n, 4) array."""
    if isinstance(orientation, tuple):
        return np.tile(np.asarray(orientation, dtype=float), (n, 1))
    return np.asarray(orientation, dtype=float)


def _points(value, what, shape):
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise PlanningError(f'{what} must be numbers, got {value!r}') from None
    if shape == (3,) and array.shape != (3,):
        raise PlanningError(f'{what} must be a point (x, y, z), got shape {array.shape}')
    if shape != (3,):
        array = array.reshape(-1, 3) if array.size else np.zeros((0, 3))
    return bounded(array, what)


def bounded(points, what):
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


class _Space:
    """The skill's coordinates: demo units in the task plane (2D) or base_link metres (3D)."""

    def __init__(self, skill, plane):
        if skill.dim == 2:
            if plane is None:
                raise PlanningError('a 2D skill needs a task plane')
            self.plane, self.scale = plane, plane.scale
        elif skill.dim == 3:
            self.plane, self.scale = None, 1.0
        else:
            raise PlanningError(f'a skill must have 2 or 3 coordinates, this one has {skill.dim}')

    def inward(self, points):
        return points if self.plane is None else self.plane.to_plane(points)

    def outward(self, points):
        return points if self.plane is None else self.plane.from_plane(points)

    def outward_vectors(self, vectors):
        return vectors if self.plane is None else (self.scale * vectors) @ self.plane.axes

    def inward_orientations(self, q):
        return q if self.plane is None else self.plane.orientation_to_plane(q)

    def outward_orientations(self, q):
        return q if self.plane is None else self.plane.orientation_from_plane(q)


def goal_orientation_of(skill, value, settings):
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
        raise PlanningError(f'goal orientation {_fmt(q)} is not a unit quaternion (norm '
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


def _fmt(point):
    return '(' + ', '.join(f'{c:.3f}' if abs(c) < 1e6 else f'{c:.3g}' for c in point) + ')'


def obstacle_clearances(radii, settings, count):
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


def plan_path(skill, start, goal, obstacles=(), settings=None, plane=None,
              goal_orientation=None, obstacle_radii=None):
    """
    Plan ``skill`` (an ``etdmp_ros.dmp.Skill``) from ``start`` to ``goal`` around ``obstacles``.

    ``start``, ``goal``: base_link points (3,); ``obstacles``: (m, 3) base_link points (the
    centres); ``obstacle_radii``: None or (m,) metres, the clearance to keep from each centre;
    ``settings``: PlanSettings; ``plane``: the TaskPlane (needed for 2D skills);
    ``goal_orientation``: None or (x, y, z, w) in base_link (see :func:`goal_orientation_of`:
    all zeros for none); ``obstacle_radii``: (m,) each obstacle's radius in metres (0: a point),
    None for obstacles of unknown size. Returns a Plan; raises PlanningError with the reason
    when the request cannot be served.
    """
    settings = PlanSettings() if settings is None else settings
    goal_q = goal_orientation_of(skill, goal_orientation, settings)
    start = _points(start, 'start', (3,))
    goal = _points(goal, 'goal', (3,))
    obstacles = _points(obstacles, 'obstacles', None)
    avoidance = _avoidance(settings, obstacle_radii)
    clearances = obstacle_clearances(obstacle_radii, settings, len(obstacles))
    if clearances is None and avoidance == 'detour':   # points of unknown size: the tool's
        clearances = obstacle_clearances(np.zeros(len(obstacles)), settings, len(obstacles))
    space = _Space(skill, plane)
    start_s, goal_s, obstacles_s = (space.inward(p) for p in (start, goal, obstacles))
    start_b, goal_b, obstacles_b = (space.outward(p) for p in (start_s, goal_s, obstacles_s))
    where = ' (projected onto the task plane)' if space.plane is not None else ''

    outside = settings.workspace.violation(goal_b)
    if outside is not None:
        raise PlanningError(f"goal {_fmt(goal_b)}{where} is out of the UR10's reach: "
                            f'{outside[1]}')
    gap = float(np.linalg.norm(start_b - goal_b))
    if gap < settings.min_distance:
        raise PlanningError(f'start equals goal{where}: they are {gap * 1000:.1f} mm apart, less '
                            f'than min_distance {settings.min_distance * 1000:g} mm; there is no '
                            'movement to make')
    if len(obstacles_b):
        to_goal = np.linalg.norm(obstacles_b - goal_b, axis=1)
        i = int(np.argmin(to_goal))
        if to_goal[i] < settings.goal_clearance:
            raise PlanningError(f'obstacle {_fmt(obstacles_b[i])}{where} lies on the goal: '
                                f'{to_goal[i] * 1000:.1f} mm from it, less than goal_clearance '
                                f'{settings.goal_clearance * 1000:g} mm')

    gains = settings.gains
    if settings.obstacle_k > 0.0:   # 1/m → 1/skill unit: exp(-k d) with d = d_units * scale
        gains = replace(gains, k=settings.obstacle_k * space.scale)
    try:
        traj = skill.generalize(
            start_s, goal_s, obstacles_s, method=settings.method, mode=settings.mode,
            independent_axis=settings.independent_axis, dt=settings.output_period,
            tau=settings.duration or None,
            margin=settings.obstacle_margin if len(obstacles_s) and avoidance == 'paper' else 0.0,
            gains=gains, avoidance=avoidance,
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
                            f'{_fmt(positions[i])}: {reason}')
    return Plan(traj.t, positions, space.outward_vectors(traj.v), orientation,
                start_b, goal_b, obstacles_b, settings.method, traj, clearances, avoidance)


def place_demo(skill, start, goal, plane=None, mode=1, independent_axis=2):
    """
    Return the demonstration (T, 3) turned and scaled so it runs from start to goal.

    This is where ET-DMP's plan lies without obstacles: the demonstration drawn in place, for
    display. ``start``, ``goal``: base_link points; ``plane`` for 2D skills; ``mode``,
    ``independent_axis``: a 3D skill's transform (mode 2 scales each block by its own ratio).
    """
    space = _Space(skill, plane)
    start_s, goal_s = space.inward(_points(start, 'start', (3,))), space.inward(
        _points(goal, 'goal', (3,)))
    i_demo = skill.start - skill.goal
    i_current = start_s - goal_s
    try:
        transform = euclidean_transform(i_demo, i_current, mode if len(i_demo) == 3 else 1,
                                        independent_axis, size=skill.size)
    except GeneralizationError as err:
        raise PlanningError(str(err)) from None
    # Row-vector form of x = g + R^T (scale * (y - g_D)).
    return space.outward(goal_s + (transform.scale * (skill.demo - skill.goal)) @ transform.R)


#: Consecutive perception messages that must agree on a moved goal or obstacle set before a
#: plan in execution follows it (dmp_server): a frame rendered while the marker moved can show
#: it in between, or an obstacle hidden by the arm (about 0.1 s at the camera's 30 Hz).
FOLLOW_CONFIRMATIONS = 3


class FollowedPlan:
    """
    A plan being executed whose goal and obstacles may still move (online ET-DMP, issue 14).

    Made from the :class:`Plan` that :func:`plan_path` returned, with the same arguments. It
    keeps the skill's online rollout (:meth:`etdmp_ros.dmp.Skill.online`) in step with the
    plan: the online run reproduces the plan while nothing moves. :meth:`update` changes the
    goal or the obstacles from path time ``t_switch`` on and returns the new remainder; each
    update starts from the state the previous ones left, so the path stays continuous in
    position and velocity however often it changes (the goal filter keeps the acceleration
    bounded). ``t`` and ``positions`` are the whole path as it stands (the plan's own time base).

    Orientation: ``orientation`` is the plan's one tuple (mode ``tool``) or an (n, 4) array
    matching ``t``. The online rollout does not carry orientations, so a re-planned remainder
    takes the plan's orientation at the same path time, which is the same phase (the phase
    depends on time only, not on the goal or obstacles), and the plan's last orientation after
    the plan's end: the tool keeps the orientation pattern it was given (and reaches a requested
    goal orientation) even when the goal moves; it is not turned again with the moved goal.
    """

    def __init__(self, skill, plan, settings=None, plane=None):
        """Start following ``plan`` (planned for ``skill`` with ``settings`` and ``plane``)."""
        settings = PlanSettings() if settings is None else settings
        self.skill, self.settings = skill, settings
        self._space = _Space(skill, plane)
        space = self._space
        gains = settings.gains
        if settings.obstacle_k > 0.0:
            gains = replace(gains, k=settings.obstacle_k * space.scale)
        radii = np.zeros(len(plan.obstacles)) if plan.obstacle_radii is None else \
            plan.obstacle_radii
        try:
            self._run = skill.online(
                space.inward(plan.start), space.inward(plan.goal), space.inward(plan.obstacles),
                method=settings.method, mode=settings.mode,
                independent_axis=settings.independent_axis, dt=settings.output_period,
                tau=settings.duration or None, gains=gains,
                obstacle_radii=radii / space.scale, avoidance=plan.avoidance)
        except GeneralizationError as err:
            raise PlanningError(str(err)) from None
        self.t, self.positions = plan.t.copy(), plan.positions.copy()
        self.velocities = plan.velocities.copy()
        self.goal, self.obstacles = plan.goal.copy(), plan.obstacles.copy()
        self.obstacle_radii = np.array(radii, dtype=float)
        #: Each obstacle's own radius (m): the clearance less the tool's and the margin.
        added = settings.tool_radius + settings.obstacle_clearance
        self.obstacle_sizes = np.zeros(len(plan.obstacles)) if plan.obstacle_radii is None else \
            np.maximum(0.0, plan.obstacle_radii - added)
        self.orientation = plan.orientation
        self._plan_t, self._plan_orientation = plan.t, plan.orientation
        self.updates = 0
        self._run.warm()
        # The samples the run will step through while nothing moves, and the run they start
        # from: at first the plan's own (the offline rollout that the run reproduces), then
        # those of the last update; update() takes its state at the switch from them.
        self._base, self._rows = self._run, None
        traj = plan.trajectory
        if traj is not None and len(traj.t) == len(plan.t) and len(traj.t) > 1:
            self._rows = self._run._replayed(traj.x[1:], traj.v[1:], traj.a[1:])

    def placed(self, points):
        """Return base_link ``points`` (..., 3) as the plan uses them (on the task plane, 2D)."""
        points = np.asarray(points, dtype=float)
        return self._space.outward(self._space.inward(points.reshape(-1, 3))).reshape(
            points.shape)

    @property
    def duration(self):
        """Path time (s) of the path's last pose."""
        return float(self.t[-1])

    def index(self, t):
        """Return the index of the pose at path time ``t`` (the last one at or before it)."""
        return int(np.clip(np.searchsorted(self.t, t + 1e-9) - 1, 0, len(self.t) - 1))

    def orientations_at(self, t):
        """Return the plan's orientations (len(t), 4) at path times ``t`` (its last after it)."""
        i = np.clip(np.searchsorted(self._plan_t, np.asarray(t) + 1e-9) - 1, 0,
                    len(self._plan_t) - 1)
        return pose_orientations(self._plan_orientation, len(self._plan_t))[i]

    def _at(self, t):
        """
        Return the online run at path time ``t`` (at or after the run's own time).

        A sample of the rows kept, where ``t`` is one of theirs (no integration: the sample is
        the one the path holds), else the run advanced to ``t``.
        """
        base, rows = self._base, self._rows
        if rows is not None:
            i = int(round((t - base.t) / base.dt)) - 1
            if -1 <= i < len(rows.t):
                run = base.copy()
                if i >= 0:
                    run._set_row(rows, i)
                return run
        self._run.run(t)
        return self._run

    def update(self, t_switch, goal=None, obstacles=None, t_max=None, obstacle_radii=None):
        """
        Move the goal to ``goal`` and/or the obstacles to ``obstacles`` from ``t_switch`` on.

        ``goal`` (3,) and ``obstacles`` (m, 3) are base_link points (projected onto the task
        plane for 2D skills), None for unchanged; ``obstacle_radii`` (m,) each obstacle's radius
        in metres (the tool's radius and ``obstacle_clearance`` are added, as in
        :func:`plan_path`), None for those in force (the same number of obstacles) or, for the
        paper's points, none. Return
        the index of the first changed pose: the path from there on (``t``, ``positions``,
        ``velocities``) is new; before it, it is as it was. The new path runs until the online
        run is done or ``t_max`` (default: the old end plus the skill's duration). Raises
        PlanningError, leaving the path as it was, for a goal out of reach or on the start, an
        obstacle on the goal, a new path that leaves the workspace or, for the detour, a
        clearance it cannot keep.
        """
        space, settings = self._space, self.settings
        goal_s = None if goal is None else space.inward(_points(goal, 'goal', (3,)))
        obstacles_s = None if obstacles is None else space.inward(
            _points(obstacles, 'obstacles', None))
        radii = None if obstacle_radii is None or obstacles_s is None else \
            obstacle_clearances(obstacle_radii, settings, len(obstacles_s))
        if goal_s is not None:
            goal_b = space.outward(goal_s)
            outside = settings.workspace.violation(goal_b)
            if outside is not None:
                raise PlanningError(f"goal {_fmt(goal_b)} is out of the UR10's reach: "
                                    f'{outside[1]}')
        k = self.index(max(t_switch, self._run.t))
        run = self._at(self.t[k])   # in step with the path as it stands
        t_max = self.duration + self._run.tau if t_max is None else t_max
        trial = run.copy()      # what-if: the run itself changes only on success
        try:
            with np.errstate(over='raise', invalid='raise', divide='raise'):
                # The step that takes the new input and the rest of the movement in one
                # call of the numba loop (what a step() and a run() give, to rounding).
                trial._take(goal=goal_s, obstacles=obstacles_s,
                            obstacle_radii=None if radii is None else radii / space.scale)
                rows = trial._rows(int(math.floor((t_max - trial.t) / trial.dt + 0.5)))
                if rows is not None and len(rows.t):
                    after = trial.copy()
                    after._set_row(rows, 0)
                    xs, vs, _ = trial._outputs(rows)
                    kept = trial, rows
                else:           # only step() can (the filtered goal passes by the start)
                    kept = None, None
                    trial = run.copy()
                    x, v, _ = trial.step(
                        goal=goal_s, obstacles=obstacles_s,
                        obstacle_radii=None if radii is None else radii / space.scale)
                    after = trial.copy()
                    _, xs, vs, _ = trial.run(t_max)
                    xs, vs = np.vstack([x[None], xs]), np.vstack([v[None], vs])
        except (GeneralizationError, ArithmeticError) as err:
            raise PlanningError(str(err)) from None
        positions = space.outward(xs)
        outside = settings.workspace.violation(positions)
        if outside is not None:
            i, reason = outside
            raise PlanningError(f"the new path leaves the UR10's reach at "
                                f'{_fmt(positions[i])}: {reason}')
        t_new = run.t + run.dt * np.arange(1, len(xs) + 1)
        keep = k + 1
        self.t = np.concatenate([self.t[:keep], t_new])
        self.positions = np.concatenate([self.positions[:keep], positions])
        self.velocities = np.concatenate([self.velocities[:keep],
                                          space.outward_vectors(vs)])
        if not isinstance(self.orientation, tuple):
            self.orientation = np.concatenate([self.orientation[:keep],
                                               self.orientations_at(t_new)])
        self._run = after
        self._base, self._rows = kept
        if goal_s is not None:
            self.goal = space.outward(goal_s)
        if obstacles_s is not None:
            self.obstacles = space.outward(obstacles_s)
            self.obstacle_radii = self._run.obstacle_radii * space.scale
            if obstacle_radii is not None:
                self.obstacle_sizes = np.asarray(obstacle_radii, dtype=float).reshape(-1)
        self.updates += 1
        return keep

"""Learning a skill from one demonstration and generalizing it with DMP or ET-DMP."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from etdmp_ros import limits
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.arrays import Array, Quaternions, Rotations
import numpy as np
from numpy.typing import ArrayLike

from ._clearance import distances
from ._demos import Demonstration
from ._detour import candidate_directions, keep_clear, Obstacles
from ._errors import DemonstrationError, finite_array, GeneralizationError
from ._forcing_term import ForcingTerm, phase
from ._integrate import MAX_SUBSTEP, rollout
from ._obstacles import ObstacleGains
from ._online import OnlineGains, OnlineRun
from ._orientation import check_goal_orientation, OrientationDMP, turn_quaternions
from ._retime import come_to_rest
from ._transform import EPS, EuclideanTransform, transforms

FORMULATIONS = ('ijspeert', 'hoffmann')
METHODS = ('etdmp', 'dmp')
#: How the methods are named in reports, plots and logs.
METHOD_LABELS = {'etdmp': 'ET-DMP', 'dmp': 'DMP'}
#: Below this fraction of the demonstration's size, ``(g_D - x0_D)_i`` counts as zero for the
#: plain Ijspeert DMP, whose per-dimension scaling would divide by it.
PLAIN_DMP_MIN_OFFSET = 1e-3
#: Default extra time, as a fraction of tau, given to a movement that avoids obstacles with the
#: paper's coupling (avoidance "paper"): its detour delays arrival at the goal. The default
#: avoidance ("detour") keeps the obstacle-free timing and needs none.
OBSTACLE_MARGIN = 0.5
#: How obstacles are avoided (docs/design.md#obstacles-with-a-size): "detour", obstacles with a
#: size (``obstacle_radii``) passed by a local smooth detour of the obstacle-free plan whose
#: clearance is checked (the default when radii are given); "paper", the paper's point-obstacle
#: coupling Eq. 22-27 (the baseline, and the default without radii: today's behaviour).
AVOIDANCES = ('detour', 'paper')
#: Most output samples one rollout may produce (guards against absurd dt).
MAX_SAMPLES = 2_000_000


@dataclass(frozen=True)
class Trajectory:
    """
    A generalized movement.

    ``x``, ``v`` (dx/dt) and ``a`` (d2x/dt2) have shape (n, d) for one start or (B, n, d) for a
    batch; ``t`` has shape (n,). ``rotation`` is the Euclidean transform R ((d, d) or (B, d, d)),
    the identity for plain DMPs; ``virtual_start`` is ``x0' = R I_C + g``. For a skill with
    orientations, ``q`` ((n, 4) or (B, n, 4)) holds unit quaternions (x, y, z, w) and ``omega``
    ((n, 3) or (B, n, 3)) the angular velocity in rad/s, both in the skill's frame
    (docs/orientation.md); both are None for a position-only skill.
    """

    t: Array
    x: Array
    v: Array
    a: Array
    start: Array
    goal: Array
    method: str
    rotation: Rotations
    virtual_start: Array
    q: Quaternions | None = None
    omega: Array | None = None


class _Request(NamedTuple):
    """A checked :meth:`Skill.generalize` request (see :meth:`Skill._check_request`)."""

    starts: Array
    goals: Array
    obstacles: Array
    radii: Array
    avoidance: str
    single: bool
    gains: ObstacleGains
    tau: float
    dt: float
    n_out: int


def learn(positions: ArrayLike | Demonstration, orientations: ArrayLike | None = None,
          dt: float | None = None, t: ArrayLike | None = None, n_basis: int = 100,
          K: float = 156.25, D: float = 25.0, alpha: float = 4.0, formulation: str = 'ijspeert',
          regularization: float = 1e-8) -> Skill:
    """
    Learn a skill from one demonstration.

    ``positions`` is a (T, d) or (T,) array or a :class:`Demonstration`. ``orientations``
    (T, 4), optional, are the tool's unit quaternions in ROS order (x, y, z, w), for d = 2 (in
    the task plane's axes) or d = 3 (docs/orientation.md); a Demonstration brings its own. Give
    the sample period ``dt`` (tau = (T - 1) dt) or the timestamps ``t`` (may be non-uniform);
    with neither, tau = 1 (or the Demonstration's own times). Raises DemonstrationError for
    unusable input.
    """
    if isinstance(positions, Demonstration):
        if orientations is None:
            orientations = positions.orientations
        t = positions.t if t is None else t
        positions = positions.positions
    if t is None and dt is not None:
        if not (np.isfinite(dt) and dt > 0.0):
            raise DemonstrationError(f'dt must be a positive number, got {dt!r}')
        t = np.arange(len(np.atleast_1d(positions))) * float(dt)
    demo = Demonstration('demonstration', positions, t, orientations)  # type: ignore[arg-type]
    if demo.has_orientation and demo.dim not in (2, 3):
        raise DemonstrationError(f'orientations need a 2D (task plane) or 3D skill, this one has '
                                 f'{demo.dim} coordinate(s)')
    if formulation not in FORMULATIONS:
        raise DemonstrationError(f'formulation must be one of {FORMULATIONS}, got {formulation!r}')
    for name, value in (('K', K), ('D', D), ('alpha', alpha)):
        if not (np.isfinite(value) and value > 0.0):
            raise DemonstrationError(f'{name} must be a positive number, got {value!r}')
    return Skill(np.array(demo.positions), demo.t - demo.t[0], int(n_basis), float(K), float(D),
                 float(alpha), formulation, float(regularization), demo.orientations)


class Skill:
    """
    A movement learned from one demonstration; generalize it with :meth:`generalize`.

    The forcing is stored normalised by the demonstration's size ``L`` (its largest distance from
    its goal), never by ``g_D - x0_D`` per dimension, so demonstrations that start and end at the
    same value in some dimension (a closed letter, a vertical stroke) are learned without dividing
    by ~0. The Ijspeert per-dimension scaling is applied only when the plain DMP is asked for.
    """

    def __init__(self, y: Array, t: Array, n_basis: int, K: float, D: float, alpha: float,
                 formulation: str, regularization: float,
                 orientations: Quaternions | None = None) -> None:
        if orientations is not None:
            orientations = quat.continuous(orientations)
        #: The demonstration as learned (``demo``, ``demo_t``): re-timed to start and end at rest
        #: along its own path (docs/design.md#coming-to-rest); ``retiming`` says what changed.
        t, y, orientations, self.retiming = come_to_rest(t, y, orientations)
        self.demo, self.demo_t = y, t
        self.K, self.D, self.alpha = K, D, alpha
        self.formulation = formulation
        self.tau = float(t[-1])
        self.dim = y.shape[1]
        self.dt = self.tau / (len(t) - 1)
        self.start, self.goal = y[0].copy(), y[-1].copy()
        self.size = float(np.max(np.linalg.norm(y - self.goal, axis=1)))
        if not self.size > 0.0:
            raise DemonstrationError('demonstration does not move')
        if not self.size >= limits.MIN_DEMO_EXTENT:
            raise DemonstrationError(f'demonstration hardly moves: its extent {self.size:.3g} is '
                                     f'below MIN_DEMO_EXTENT = {limits.MIN_DEMO_EXTENT:g}')
        self.forcing = ForcingTerm(n_basis, alpha, K, D)
        # Paper Eq. 6 with v = tau dx/dt: the forcing the demonstration needed at each sample.
        xd = np.gradient(y, t, axis=0, edge_order=2)
        xdd = np.gradient(xd, t, axis=0, edge_order=2)
        s = phase(t, self.tau, alpha)
        needed = self.tau ** 2 * xdd + D * self.tau * xd - K * (self.goal - y)
        offset = self.goal - self.start
        end: tuple[Array, float, Callable[[Array], Array] | None]
        if formulation == 'ijspeert':
            target = needed / self.size
            end = (-offset, self.size, None)
        else:  # Hoffmann: tau dv = K(g - x) - D v - K (g - x0) s + K f(s)
            # Hoffmann's term, made to end at tau (_forcing_term.hoffmann_term).
            target = (needed / K + offset * self.forcing.phase_term(s)[:, None]) / self.size
            end = (-offset, K * self.size,
                   lambda s_end: -K * offset * self.forcing.phase_term(s_end)[:, None])
        with np.errstate(all='ignore'):   # an overflow is reported just below, not warned of
            # The reproduction ends at its goal at rest (docs/design.md#coming-to-rest).
            self.forcing.fit(s, target, regularization, end=end)
            finite = np.all(np.isfinite(target)) and np.all(np.isfinite(self.forcing(s)))
        if not finite:
            raise DemonstrationError('learning this demonstration overflows (its coordinates or '
                                     'accelerations are too large to be represented)')
        #: The orientation DMP (docs/orientation.md), or None for a position-only skill.
        self.orientation: OrientationDMP | None = None if orientations is None else OrientationDMP(
            orientations, t, self.tau, K, D, alpha, n_basis, regularization)

    @property
    def has_orientation(self) -> bool:
        """Return True if the skill was learned with orientations."""
        return self.orientation is not None

    def __repr__(self) -> str:
        return (f'Skill(dim={self.dim}, tau={self.tau:.3g}, samples={len(self.demo)}, '
                f'formulation={self.formulation!r}, n_basis={self.forcing.n_basis})')

    # -- generalization -------------------------------------------------------------------------

    def reproduce(self, dt: float | None = None) -> Trajectory:
        """Roll out the plain DMP from the demonstration's own start to its own goal."""
        return self.generalize(self.start, self.goal, method='dmp', dt=dt)

    def generalize(self, start: ArrayLike, goal: ArrayLike, obstacles: ArrayLike = (),
                   method: str = 'etdmp', mode: int = 1, independent_axis: int = 2,
                   dt: float | None = None, tau: float | None = None,
                   margin: float | None = None, gains: ObstacleGains | None = None,
                   fast: bool = True, goal_orientation: ArrayLike | None = None,
                   obstacle_radii: ArrayLike | None = None,
                   avoidance: str | None = None) -> Trajectory:
        """
        Generalize the skill from ``start`` to ``goal``.

        ``start``: (d,) for one movement or (B, d) for a batch; ``goal``: (d,) or (B, d);
        ``obstacles``: (n_obs, d) centres (2D/3D); ``obstacle_radii``: (n_obs,) the clearance the
        plan must keep from each centre (the caller adds the tool's radius and a safety margin), or
        None for the paper's point obstacles. ``avoidance`` (AVOIDANCES): "detour", the default
        with radii (docs/design.md#obstacles-with-a-size: no sample closer to a centre than its
        radius, checked; obstacles farther than their radius plus ``gains.clearance_margin`` from
        the obstacle-free plan change nothing), or "paper", the paper's coupling Eq. 22-27, the
        default without radii (radii are then not used). ``method``: "etdmp" (Euclidean
        transformation, ``mode`` 1 or 2 in 3D) or "dmp" (the plain baseline). The output is sampled
        every ``dt`` (default: the demonstration's mean sample period) from 0 to ``tau * (1 +
        margin)``; the default margin is 0 (the output is phase-aligned with the demonstration),
        OBSTACLE_MARGIN with the paper's coupling, since its detour delays arrival at the goal. For
        a skill with orientations the output also carries ``q`` and ``omega``: the demonstrated
        orientations turned with the motion or, given ``goal_orientation`` (x, y, z, w), (4,) or
        (B, 4), converging to it (docs/orientation.md). Raises GeneralizationError on bad or
        degenerate input, and when the detour cannot keep the clearance (never a plan that enters
        an obstacle).
        """
        r = self._check_request(start, goal, obstacles, method, dt, tau, margin, gains,
                                obstacle_radii, avoidance)
        if goal_orientation is not None or self.orientation is not None:
            goal_q = check_goal_orientation(self.orientation, goal_orientation, len(r.starts))
        B = len(r.starts)
        transform, virtual_start, A, M = self._placement(r.starts, r.goals, method, mode,
                                                         independent_axis)
        i_current = r.starts - r.goals
        coupled = r.obstacles if r.avoidance == 'paper' else r.obstacles[:0]
        virtual_obs = transform.to_virtual(np.broadcast_to(coupled, (B,) + coupled.shape),
                                           r.goals[:, None])
        substeps = max(1, int(np.ceil(r.dt / (MAX_SUBSTEP * r.tau))))
        s_mid, f_mid, s_out, f_out = self._forcing_table(r.tau, r.dt, r.n_out, substeps)
        gaps = np.linalg.norm(i_current, axis=1)
        k = r.gains.decay(gaps) if len(coupled) else np.zeros(B)
        x, v, a = rollout(virtual_start, r.goals, A, M, s_mid, f_mid, s_out, f_out, virtual_obs,
                          (r.gains.gamma, r.gains.beta, r.gains.gamma2, k), self.K, self.D,
                          r.tau, r.dt / substeps, substeps, transform.R, fast=fast)
        t = np.arange(r.n_out) * r.dt
        if r.avoidance == 'detour' and len(r.obstacles):
            self._detour(t, x, v, a, r, transform.R, fast)
        q = omega = None
        if self.orientation is not None:
            q, omega = self.orientation.generalize(
                turn_quaternions(transform.R, method, mode, independent_axis), goal_q, r.tau,
                r.dt, r.n_out, substeps, fast)
        if r.single:
            return Trajectory(t, x[0], v[0], a[0], r.starts[0], r.goals[0], method,
                              transform.R[0], virtual_start[0],
                              None if q is None else q[0], None if omega is None else omega[0])
        return Trajectory(t, x, v, a, r.starts, r.goals, method, transform.R, virtual_start, q,
                          omega)

    def _detour(self, t: Array, x: Array, v: Array, a: Array, r: _Request, R: Rotations,
                fast: bool = True) -> None:
        """
        Displace the obstacle-free rollouts ``x``, ``v``, ``a`` (B, n, d) around the obstacles.

        In place, system by system; a system that no obstacle comes near is left as it is, bit
        for bit. The candidate directions are fixed in the virtual situation (row form of
        ``R^T n``), so the detour commutes with the Euclidean transform. Raises
        GeneralizationError (naming the start) when a clearance cannot be kept.
        """
        obstacles = Obstacles(r.obstacles, r.radii)
        directions = candidate_directions(self.dim)
        sizes = self._placed_size(r.starts, r.goals)
        reach = r.radii + r.gains.clearance_margin * sizes[:, None]           # (B, m)
        near = np.any(distances(x, r.obstacles, fast) < reach[:, None], axis=1).any(axis=1)
        for b in np.flatnonzero(near):
            try:
                peak = float(np.max(np.linalg.norm(a[b], axis=1)))
                shift, values = keep_clear(
                    t, x[b], obstacles, r.gains.clearance_margin * sizes[b], r.gains.ramp,
                    directions @ R[b], sizes[b], fast=fast,
                    acceleration=r.gains.detour_acceleration * peak)
                if shift is None or values is None:     # both None: no obstacle in the way
                    continue
                delta, delta_v, delta_a = values
                x[b] += delta
                v[b] += delta_v
                a[b] += delta_a
            except GeneralizationError as err:
                which = '' if r.single else f' (start #{b})'
                raise GeneralizationError(f'{err}{which}') from None

    def online(self, start: ArrayLike, goal: ArrayLike, obstacles: ArrayLike = (),
               method: str = 'etdmp', mode: int = 1, independent_axis: int = 2,
               dt: float | None = None, tau: float | None = None,
               gains: ObstacleGains | None = None, online: OnlineGains | None = None,
               fast: bool = True, obstacle_radii: ArrayLike | None = None,
               avoidance: str | None = None) -> OnlineRun:
        """
        Start an online rollout from ``start`` to ``goal``: the goal may move while it runs.

        The arguments are those of :meth:`generalize` for one start (``start`` and ``goal`` of
        shape (d,)); ``online`` is an :class:`OnlineGains` (goal filter, phase stopping). Returns
        an :class:`OnlineRun`; ``run.step(goal=None, obstacles=None, actual=None,
        obstacle_radii=None)`` advances it by ``dt`` and returns ``(x, v, a)``. With a goal and
        obstacles that never change the samples are those of :meth:`generalize`. The method:
        docs/design.md#online-goal (and #obstacles-with-a-size for the detour, which is planned
        again on the remainder when the goal or an obstacle moves). Raises GeneralizationError
        on bad or degenerate input.
        """
        return OnlineRun(self, start, goal, obstacles, method, mode, independent_axis, dt, tau,
                         gains, online, fast, obstacle_radii, avoidance)

    def _placement(self, starts: Array, goals: Array, method: str, mode: int,
                   independent_axis: int) -> tuple[EuclideanTransform, Array, Array, Array]:
        """
        Place the skill between ``starts`` and ``goals`` (both (B, d)): the transform and A, M.

        Returns the :class:`EuclideanTransform` (the identity with Ijspeert's per-dimension scale
        for the plain DMP), the virtual starts ``x0' = R I_C + g`` and the coefficients ``A``,
        ``M`` (B, d) of the integrated system (docs/design.md#dmp-formulations). Raises
        GeneralizationError where the placement is undefined.
        """
        i_current = starts - goals
        if method == 'etdmp':
            transform = transforms(self.start - self.goal, i_current, mode, independent_axis,
                                   self.size)
        else:
            d, B = self.dim, len(starts)
            transform = EuclideanTransform(np.broadcast_to(np.eye(d), (B, d, d)).copy(),
                                           self._plain_scale(i_current))
        virtual_start = transform.to_virtual(starts[:, None], goals[:, None])[:, 0]
        if self.formulation == 'ijspeert':
            A = np.zeros_like(starts)
            M = transform.scale * self.size
        else:
            A = -self.K * (goals - virtual_start)
            M = np.full_like(starts, self.K * self.size)
        return transform, virtual_start, A, M

    def _placed_size(self, starts: ArrayLike, goals: ArrayLike) -> Array:
        """
        Return the size of the movement placed between ``starts`` and ``goals`` ((B,) or ()).

        ``|x0 - g|`` times the demonstration's size over ``|I_D|`` (ET-DMP's uniform scale; for
        the plain DMP, the same ratio as a measure), or ``|x0 - g|`` when ``|I_D|`` is ~0.
        """
        n_demo = float(np.linalg.norm(self.start - self.goal))
        ratio = self.size / n_demo if n_demo > EPS * self.size else 1.0
        return np.linalg.norm(np.asarray(starts) - np.asarray(goals), axis=-1) * ratio

    def _check_request(self, start: ArrayLike, goal: ArrayLike, obstacles: ArrayLike,
                       method: str, dt: float | None, tau: float | None, margin: float | None,
                       gains: ObstacleGains | None, obstacle_radii: ArrayLike | None = None,
                       avoidance: str | None = None) -> _Request:
        """
        Validate the arguments of :meth:`generalize` and return them as a :class:`_Request`.

        Shapes become batches: ``starts`` and ``goals`` (B, d), ``obstacles`` (n_obs, d),
        ``radii`` (n_obs,). The defaults of ``dt``, ``tau``, ``margin``, ``gains`` and
        ``avoidance`` are filled in. ``mode`` and
        ``independent_axis`` are checked by the transform, which alone uses them. Raises
        GeneralizationError for the first problem found.
        """
        starts, goals, single = self._check_ends(start, goal)
        obs = self._check_centres(obstacles)
        if method not in METHODS:
            raise GeneralizationError(f'method must be one of {METHODS}, got {method!r}')
        radii = self._check_radii(obstacle_radii, len(obs))
        if avoidance is None:
            avoidance = 'paper' if obstacle_radii is None else 'detour'
        if avoidance not in AVOIDANCES:
            raise GeneralizationError(f'avoidance must be one of {AVOIDANCES}, got '
                                      f'{avoidance!r}')
        gains = ObstacleGains() if gains is None else gains
        try:
            gains.validate()
        except ValueError as exc:
            raise GeneralizationError(str(exc)) from None
        tau = self.tau if tau is None else tau
        dt = self.dt if dt is None else dt
        if margin is None:
            margin = OBSTACLE_MARGIN if len(obs) and avoidance == 'paper' else 0.0
        n_out = self._check_timing(tau, dt, margin)
        self._check_placement(starts, goals, obs, radii, avoidance == 'detour', single)
        return _Request(starts, goals, obs, radii, avoidance, single, gains, tau, dt, n_out)

    def _check_ends(self, start: ArrayLike, goal: ArrayLike) -> tuple[Array, Array, bool]:
        """Return ``starts`` and ``goals`` (B, d) and whether one start was given (not a batch)."""
        d = self.dim
        start = finite_array(start, 'start')
        goal = finite_array(goal, 'goal')
        single = start.ndim <= 1
        starts = start.reshape(1, -1) if single else start
        if starts.ndim != 2 or starts.shape[1] != d or len(starts) == 0:
            raise GeneralizationError(
                f'start must have shape ({d},) or (B, {d}), got {start.shape}')
        if goal.shape in ((d,), (1, d)):
            goals = np.repeat(goal.reshape(1, d), len(starts), axis=0)
        elif goal.shape == starts.shape:
            goals = goal.copy()
        else:
            raise GeneralizationError(f'goal must have shape ({d},) or ({len(starts)}, {d}), '
                                      f'got {goal.shape}')
        return starts, goals, single

    def _check_centres(self, obstacles: ArrayLike) -> Array:
        """Return the obstacles' centres as (n_obs, d); raise for bad ones."""
        d = self.dim
        obs = finite_array(obstacles, 'obstacles')
        if obs.size == 0:
            obs = np.zeros((0, d))
        elif obs.ndim > 2 or obs.shape[-1] != d:
            raise GeneralizationError(f'obstacles must have shape (n, {d}), got {obs.shape}')
        obs = obs.reshape(-1, d)
        if len(obs) and d not in (2, 3):
            raise GeneralizationError(f'obstacle avoidance needs 2 or 3 dimensions, skill has {d}')
        return obs

    @staticmethod
    def _check_timing(tau: float, dt: float, margin: float) -> int:
        """Return the number of output samples of ``tau`` (s) plus ``margin`` every ``dt`` (s)."""
        for name, value in (('tau', tau), ('dt', dt)):
            if not (np.isfinite(value) and value > 0.0):
                raise GeneralizationError(f'{name} must be a positive number, got {value!r}')
        if not (np.isfinite(margin) and margin >= 0.0):
            raise GeneralizationError(f'margin must be >= 0, got {margin!r}')
        n_out = int(round(tau * (1.0 + margin) / dt)) + 1
        if n_out < 2:
            raise GeneralizationError(f'tau = {tau:g} s is shorter than the output period dt = '
                                      f'{dt:g} s: the movement would have {n_out} sample; make '
                                      'tau (the duration) at least twice dt')
        if n_out > MAX_SAMPLES:
            raise GeneralizationError(f'{n_out} samples requested (dt={dt:g}, tau={tau:g}); '
                                      f'at most {MAX_SAMPLES}')
        return n_out

    def _check_placement(self, starts: Array, goals: Array, obs: Array, radii: Array,
                         detour: bool, single: bool) -> None:
        """Raise unless every start leaves its goal and no obstacle holds a goal (or start)."""
        gaps = np.linalg.norm(starts - goals, axis=1)
        if np.any(gaps <= EPS * self.size):
            b = int(np.argmin(gaps))
            raise GeneralizationError(
                f'start equals goal (|x0 - g| = {gaps[b]:.3g}) for start #{b}: there is no '
                'movement to generalize')
        if not len(obs):
            return
        to_goal = np.linalg.norm(obs[None] - goals[:, None], axis=2)
        if np.any(to_goal <= EPS * self.size):
            raise GeneralizationError('an obstacle lies on the goal: the goal is unreachable')
        if not detour:
            return
        for name, points in (('goal', goals), ('start', starts)):
            gap = np.linalg.norm(obs[None] - points[:, None], axis=2) - radii
            if np.any(gap < 0.0):
                b, j = (int(i[0]) for i in np.nonzero(gap < 0.0))
                which = '' if single else f' #{b}'
                raise GeneralizationError(
                    f'the {name}{which} lies inside obstacle #{j} (centre '
                    f'{np.round(obs[j], 4).tolist()}, radius {radii[j]:.4g}: '
                    f'{gap[b, j] + radii[j]:.4g} from its centre): the plan cannot keep '
                    'its clearance')

    @staticmethod
    def _check_radii(obstacle_radii: ArrayLike | None, n_obs: int) -> Array:
        """Return the obstacle radii as (n_obs,) (zeros for None); raise for bad ones."""
        if obstacle_radii is None:
            return np.zeros(n_obs)
        radii = finite_array(obstacle_radii, 'obstacle_radii')
        if radii.ndim == 0:
            radii = np.full(n_obs, float(radii))
        if radii.shape != (n_obs,):
            raise GeneralizationError(f'obstacle_radii must have one radius per obstacle, shape '
                                      f'({n_obs},), got {radii.shape}')
        if np.any(radii < 0.0):
            raise GeneralizationError(f'obstacle_radii must be >= 0, got {radii.tolist()}')
        return radii

    def _plain_scale(self, i_current: Array) -> Array:
        """
        Ijspeert's per-dimension spatial scaling ``(g - x0)_i / (g_D - x0_D)_i``.

        Where ``g_D - x0_D`` is ~0 the ratio is defined only when the request has the same offset
        as the demonstration (ratio 1, e.g. the reproduction); otherwise it is an error.
        """
        offset = self.goal - self.start
        tiny = np.abs(offset) <= PLAIN_DMP_MIN_OFFSET * self.size
        same = np.abs(i_current + offset) <= PLAIN_DMP_MIN_OFFSET * self.size
        undefined = tiny & ~same
        if self.formulation == 'ijspeert' and np.any(undefined):
            b, i = (int(j[0]) for j in np.nonzero(undefined))
            raise GeneralizationError(
                f'plain DMP cannot generalize this demonstration: its start and goal coincide in '
                f'dimension {i} (|g - x0| = {abs(offset[i]):.3g} <= {PLAIN_DMP_MIN_OFFSET:g} of '
                f'its size {self.size:.3g}) but start #{b} asks for {abs(i_current[b, i]):.3g}, '
                'and '
                "Ijspeert's scaling (g - x0)/(g_D - x0_D) would divide by ~0; use method='etdmp' "
                "or formulation='hoffmann'")
        return np.where(tiny, 1.0, -i_current / np.where(tiny, 1.0, offset))

    def _forcing_table(self, tau: float, dt: float, n_out: int, substeps: int) -> tuple[
            Array, Array, Array, Array]:
        """Phase and f(s) at every sub-step midpoint and output sample, cached per timing."""
        return self.forcing.table(tau, dt, n_out, substeps)

"""
Online ET-DMP: the rollout advanced one step at a time while the goal and obstacles may move.

The method and its convergence argument: docs/design.md#online-goal. In short, with ``x0`` the
movement's start (fixed), ``g`` the goal as last given and ``g_f`` the filtered goal:

    tau dg_f/dt = alpha_goal (g - g_f)                               goal filter (Ijspeert 2013)
    R, c, A, M  = the placement of the skill between x0 and g_f       as Skill.generalize does
    tau dv/dt   = K (g_f - x) - D v + R^T (A s + M f(s)) + lambda      real situation
    tau dx/dt   = v
    rate        = 1 / (1 + alpha_err (|x_actual - x| / l)^2)          phase stopping: the whole
                                                                      system runs at this rate

Written in the real situation, the Euclidean transform acts on the forcing term only (``K`` and
``D`` are scalars, so ``R^T K (g - x') = K (g - x)``): when ``R`` changes, the state does not
jump. The code integrates each step in the virtual situation of that step's transform (the real
state mapped in with ``x' = R (x - g_f) + g_f``, ``v' = R v``) with the one integrator of
``_integrate.py``, and maps the result back; with a goal that never changes this is exactly the
offline rollout. Phase stopping scales the rate of the whole system, phase and transformation
system alike: a time warp, so a slowed or waiting plan stays on its path and resumes from where
it waits.

Obstacles with a size (``avoidance='detour'``, docs/design.md#obstacles-with-a-size): the DMP
runs without them, and the run adds the detour's displacement ``delta(theta)``, a function of
the phase time ``theta`` planned on the predicted remainder of the DMP (the same remainder
:meth:`OnlineRun.run` computes). When the goal or the obstacles change, the displacement is
planned again from the current state: the one in force is blended out (C2) as the new one
takes over, and a plan that would enter an obstacle is refused with the run left as it was.
"""

import copy
import math
from typing import NamedTuple, Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike

from ._detour import candidate_directions, keep_clear, Obstacles
from ._errors import GeneralizationError
from ._integrate import chain, discretize, MAX_SUBSTEP, numba, rollout
from ._obstacles import ObstacleGains
from ._online_gains import OnlineGains
from ._online_input import (check_goal_clear, check_goal_off_start, check_obstacle_set,
                            check_online_request, check_point, check_radii)
from ._transform import EPS
from ..geometry.arrays import Array as FloatArray

#: A float array (its shape in the docstrings).
Array = FloatArray

#: Length, in durations tau, of the forcing table that :meth:`OnlineRun.run` reads its rows
#: from (a remainder reaching past it is computed instead).
RUN_TABLE_TAUS = 4.0
#: Lowest rate phase stopping may set (a measured position absurdly far from the plan would
#: otherwise give 0 and stop the run for good).
MIN_RATE = 1e-9


class RunRows(NamedTuple):
    """
    The next N samples of an :class:`OnlineRun` stepped with no input, with the state behind each.

    Made by :meth:`OnlineRun.predict` (integrated) or :meth:`OnlineRun.replay` (from samples
    computed elsewhere); :meth:`OnlineRun.restore` puts any of them in force, without
    integrating again. ``t`` (N,): the time after each step (s); ``x``, ``v``, ``a`` (N, d): the
    DMP's position, velocity dx/dt and acceleration (without the detour's displacement:
    :meth:`OnlineRun.outputs` adds it); ``goal_f`` (N, d), ``R`` (N, d, d), ``A``, ``M``,
    ``vstart`` (N, d), ``k`` (N,): the filtered goal and the placement in force after each
    step; ``theta`` (N,): the phase time; ``n0``: the steps the run had made before the first.
    """

    t: Array
    x: Array
    v: Array
    a: Array
    goal_f: Array
    R: Array
    A: Array
    M: Array
    k: Array
    vstart: Array
    theta: Array
    n0: int


class OnlineRun:
    """
    One movement rolled out step by step (made by :meth:`Skill.online`).

    ``step(goal=None, obstacles=None, actual=None)`` advances by ``dt`` and returns
    ``(x, v, a)``: position, velocity dx/dt and acceleration d2x/dt2, each (d,), in the real
    situation. A new ``goal`` or obstacle set may be given at any step; ``actual`` is the
    measured position of the tool, for phase stopping. A bad argument raises GeneralizationError
    and leaves the run as it was. ``t``, ``phase`` (s), ``done``, ``x``, ``v``, ``a`` describe
    the current sample. Positions only: a skill's orientations are not rolled out online.

    Without stepping: :meth:`take` puts a new input in force (the next step moves towards it);
    :meth:`predict` gives the next samples as :meth:`run` would, without advancing, and
    :meth:`replay` takes them from a rollout made elsewhere (the plan the run reproduces), as
    :class:`RunRows`; :meth:`restore` puts one of those samples in force, so that a path
    already published is continued from its own samples, not integrated again;
    :meth:`outputs` gives the samples of rows as :meth:`run` returns them. :meth:`copy` makes a
    what-if run.
    """

    def __init__(self, skill, start: ArrayLike, goal: ArrayLike, obstacles: ArrayLike,
                 method: str, mode: int, independent_axis: int, dt: Optional[float],
                 tau: Optional[float], gains: Optional[ObstacleGains],
                 online: Optional[OnlineGains], fast: bool,
                 obstacle_radii: Optional[ArrayLike] = None,
                 avoidance: Optional[str] = None) -> None:
        """Start a run (use :meth:`Skill.online`: it checks the request as generalize does)."""
        online = check_online_request(online, start, goal, skill.dim)
        d = skill.dim
        r = skill._check_request(start, goal, obstacles, method, dt, tau, 0.0, gains,
                                 obstacle_radii, avoidance)
        self._skill, self._method = skill, method
        self._mode, self._axis = mode, independent_axis
        self._fast = fast
        self.online = online
        self.gains = r.gains
        self.tau, self.dt = r.tau, r.dt
        self._substeps = max(1, int(np.ceil(r.dt / (MAX_SUBSTEP * r.tau))))
        self._h = r.dt / self._substeps
        self._x0 = r.starts[0].copy()
        self._goal = r.goals[0].copy()
        self._goal_f = self._goal.copy()
        self._obstacles = r.obstacles
        self._radii = r.radii
        self.avoidance = r.avoidance
        #: The detour's displacement in force (a function of the phase time), or None.
        self._disp = None
        self._blend_length = 0.0
        self._place(self._goal)
        self._steps = {}
        self._n = 0
        self._theta = 0.0           # phase time: s = exp(-alpha theta / tau)
        self._rate = 1.0
        self._x = self._x0.copy()
        self._v = np.zeros(d)       # scaled velocity tau dx/dt of the DMP, real situation
        self._xd = np.zeros(d)
        self._a = self._advance(1.0, 0)
        if self._detours and len(self._obstacles):
            self._disp = self._plan_detour(self._goal, self._obstacles, self._radii)

    @property
    def _detours(self):
        return self.avoidance == 'detour'

    def __repr__(self):
        return (f'OnlineRun(method={self._method!r}, t={self.t:.3g}, phase={self.phase:.3g}, '
                f'done={self.done})')

    # -- state ------------------------------------------------------------------------------

    @property
    def t(self) -> float:
        """Return the time since the start in seconds (``dt`` times the number of steps)."""
        return self._n * self.dt

    @property
    def phase(self) -> float:
        """Return the phase ``s`` (1 at the start, ``exp(-alpha)`` at t = tau without stopping)."""
        return math.exp(-self._skill.alpha * self._theta / self.tau)

    @property
    def rate(self) -> float:
        """Return the rate of the last step (1, or below 1 while phase stopping slowed it)."""
        return self._rate

    @property
    def done(self) -> bool:
        """Return whether the phase has ended and the plan rests at the goal (done_tolerance)."""
        tol = self.online.done_tolerance * self._length(self._goal)
        return bool(self._theta >= self.tau * (1.0 - 1e-12)
                    and (self._disp is None or self._theta >= self._disp.end)
                    and np.linalg.norm(self._x - self._goal) <= tol
                    and np.linalg.norm(self._v) <= tol)

    @property
    def x(self) -> Array:
        """Return the position of the current sample (d,)."""
        return self._sample()[0]

    @property
    def v(self) -> Array:
        """Return the velocity dx/dt of the current sample (d,)."""
        return self._sample()[1]

    @property
    def a(self) -> Array:
        """Return the acceleration d2x/dt2 of the current sample (d,)."""
        return self._sample()[2]

    def _sample(self):
        """Return the current sample (x, v, a): the DMP's state plus the detour's displacement."""
        if self._disp is None:
            return self._x.copy(), self._xd.copy(), self._a.copy()
        delta, delta_v, delta_a = (part[0] for part in self._disp(np.array([self._theta])))
        rate = self._rate
        return self._x + delta, self._xd + rate * delta_v, self._a + rate * rate * delta_a

    @property
    def start(self) -> Array:
        """Return the movement's start ``x0`` (fixed; the transform is taken from it)."""
        return self._x0.copy()

    @property
    def goal(self) -> Array:
        """Return the goal as last given."""
        return self._goal.copy()

    @property
    def filtered_goal(self) -> Array:
        """Return the filtered goal ``g_f`` the system is attracted to now."""
        return self._goal_f.copy()

    @property
    def obstacles(self) -> Array:
        """Return the obstacle points (centres) in force, (n_obs, d)."""
        return self._obstacles.copy()

    @property
    def obstacle_radii(self) -> Array:
        """Return the obstacle radii in force, (n_obs,) (zeros for the paper's points)."""
        return self._radii.copy()

    @property
    def rotation(self) -> Array:
        """Return the Euclidean transform R in force (the identity for the plain DMP)."""
        return self._R.copy()

    @property
    def virtual_start(self) -> Array:
        """Return the virtual start ``x0' = R (x0 - g_f) + g_f`` of the transform in force."""
        return self._vstart.copy()

    # -- stepping ---------------------------------------------------------------------------

    def step(self, goal: Optional[ArrayLike] = None, obstacles: Optional[ArrayLike] = None,
             actual: Optional[ArrayLike] = None, obstacle_radii: Optional[ArrayLike] = None
             ) -> Tuple[Array, Array, Array]:
        """
        Advance by ``dt``; return ``(x, v, a)`` of the new sample.

        ``goal`` (d,): a new goal, reached through the goal filter. ``obstacles`` (n, d): the
        obstacle set from now on (replaces the previous one), with ``obstacle_radii`` (n,)
        (None: the radii in force, when the number of obstacles is unchanged). ``actual`` (d,):
        the measured position of the tool now; the farther it is from the plan's current
        sample, the slower this step runs (phase stopping). Raises GeneralizationError for a
        bad argument (NaN, wrong shape, goal at the start, obstacle on the goal, ...) and, for
        the detour, for a goal or obstacles that the plan cannot keep its clearance from; the
        run is then as it was.
        """
        measured = None if actual is None else check_point(actual, 'actual', self._skill.dim)
        self.take(goal, obstacles, obstacle_radii)     # checked: from here on the run changes
        rate = 1.0
        if measured is not None:
            with np.errstate(over='ignore'):    # an absurd measurement: rate MIN_RATE
                error = np.linalg.norm(measured - self._sample()[0]) / self._length(self._goal)
                rate = max(MIN_RATE, 1.0 / (1.0 + self.online.alpha_err * error ** 2))
        if not np.array_equal(self._goal_f, self._goal):
            keep = math.exp(-self.online.alpha_goal * self.dt / self.tau)
            goal_f = self._goal + (self._goal_f - self._goal) * keep
            if np.linalg.norm(goal_f - self._goal) <= EPS * self._skill.size:
                goal_f = self._goal.copy()
            self._goal_f = goal_f
            try:
                self._place(goal_f)
            except GeneralizationError:
                pass    # g_f passing within EPS of x0: the previous transform stays in force
        self._rate = rate
        self._a = self._advance(rate, 1)
        self._n += 1
        self._theta += rate * self.dt
        return self._sample()

    def take(self, goal: Optional[ArrayLike] = None, obstacles: Optional[ArrayLike] = None,
             obstacle_radii: Optional[ArrayLike] = None) -> None:
        """
        Put a new goal and/or obstacle set in force, as :meth:`step` takes them, without a step.

        ``goal`` (d,), ``obstacles`` (n, d) and ``obstacle_radii`` (n,) as :meth:`step` takes
        them. Raises GeneralizationError, leaving the run as it was, for what :meth:`step`
        refuses. The next step (or :meth:`run`) then moves the filtered goal towards the new
        goal. A detour is planned again here (from the current state) when either changes.
        """
        skill = self._skill
        target = self._goal if goal is None else check_point(goal, 'goal', skill.dim)
        new_goal = not np.array_equal(target, self._goal)
        if obstacles is None:
            if obstacle_radii is not None:
                raise GeneralizationError('obstacle_radii given without obstacles')
            obstacles, radii = self._obstacles, self._radii
        else:
            obstacles = check_obstacle_set(obstacles, skill.dim)
            radii = check_radii(skill, obstacles, obstacle_radii, self._radii, self._detours)
        if new_goal:
            check_goal_off_start(skill, self._x0, target, self._method, self._mode, self._axis)
        moved = obstacles is not self._obstacles and not (
            np.array_equal(obstacles, self._obstacles) and np.array_equal(radii, self._radii))
        if len(obstacles) and (new_goal or moved):
            check_goal_clear(skill, target, obstacles, radii, self._detours)
        disp = self._disp
        if self._detours and (new_goal or moved) and (len(obstacles) or disp is not None):
            disp = self._plan_detour(target, obstacles, radii)     # raises: nothing changed
        self._goal, self._obstacles, self._radii = target, obstacles, radii
        self._disp = disp

    def copy(self) -> 'OnlineRun':
        """Return an independent copy of the run (for a what-if rollout; the skill is shared)."""
        return copy.copy(self)      # every step replaces the state arrays, never edits them

    def run(self, t_max: float, fast: bool = True) -> Tuple[Array, Array, Array, Array]:
        """
        Step with no new input until the run is done or ``t >= t_max``; return the samples.

        Returns ``(t, x, v, a)``: (N,) times and (N, d) positions, velocities and accelerations
        of the samples after each step, the same as N calls of :meth:`step` (to rounding), with
        the run left where those calls leave it. The fast path computes the placements of all N
        steps in one batch (the goal filter's course is known without input) and integrates
        them in one numba loop (``_integrate.chain``): the remainder of a movement in about a
        millisecond, where N calls of :meth:`step` while the filter moves take ~0.2 ms each.
        """
        n_max = int(math.floor((t_max - self.t) / self.dt + 0.5))
        rows = self.predict(n_max) if fast and numba is not None else None
        if rows is None:
            if n_max <= 0 or self.done:
                d = self._skill.dim
                return np.zeros(0), np.zeros((0, d)), np.zeros((0, d)), np.zeros((0, d))
            return self._run_by_steps(n_max)
        n = len(rows.t)
        if n:
            self.restore(rows, n - 1)
        return (rows.t,) + self.outputs(rows)

    def outputs(self, rows: RunRows) -> Tuple[Array, Array, Array]:
        """
        Return the samples (x, v, a), each (N, d), of ``rows``: what :meth:`run` returns.

        The DMP's samples of ``rows`` plus the displacement of the detour in force.
        """
        if self._disp is None or not len(rows.t):
            return rows.x, rows.v, rows.a
        delta, delta_v, delta_a = self._disp(rows.theta)
        return rows.x + delta, rows.v + delta_v, rows.a + delta_a

    def predict(self, n_max: int) -> Optional[RunRows]:
        """
        Return the samples of :meth:`run` for at most ``n_max`` steps; leave the run as it is.

        Returns a :class:`RunRows` (possibly of no samples: ``n_max <= 0`` or done), any of which
        :meth:`restore` puts in force, or None where only :meth:`step` can step (the filtered
        goal passes by the start). The samples with the detour: :meth:`outputs`.
        """
        d = self._skill.dim
        if n_max <= 0 or self.done:
            empty = np.zeros((0, d))
            return RunRows(np.zeros(0), empty, empty, empty, empty, np.zeros((0, d, d)), empty,
                           empty, np.zeros(0), empty, np.zeros(0), self._n)
        skill = self._skill
        g = self._goal
        keep = math.exp(-self.online.alpha_goal * self.dt / self.tau)
        # The goal filter as step() runs it (to rounding), snapping to g within EPS.
        goal_f = g + (self._goal_f - g) * keep ** np.arange(1, n_max + 1)[:, None]
        snapped = np.linalg.norm(goal_f - g, axis=1) <= EPS * skill.size
        goal_f[snapped] = g
        moving = 0 if np.array_equal(self._goal_f, g) else \
            int(np.argmax(snapped)) + 1 if snapped.any() else n_max
        placements = self._placements(goal_f, moving)
        if placements is None:
            return None
        R, A, M, vstart, k = placements
        theta = self._theta + self.dt * np.arange(n_max)
        s_mid, f_mid, s_out, f_out = self._forcing_rows(n_max)
        step = self._steps.get(self.tau)
        if step is None:
            step = self._steps[self.tau] = discretize(skill.K, skill.D, self.tau, self._h)
        X, V, Acc = chain(self._x, self._xd, goal_f, A, M, R, k, s_mid, f_mid, s_out, f_out,
                          self._coupled(),
                          (self.gains.gamma, self.gains.beta, self.gains.gamma2, None),
                          skill.K, skill.D, self.tau, self._h, self._substeps, step=step)
        # Where step() would have said done: the phase ended and at rest at the goal.
        tol = self.online.done_tolerance * self._length(g)
        ended = theta + self.dt >= self.tau * (1.0 - 1e-12)
        rest = (np.linalg.norm(X - g, axis=1) <= tol) & \
            (np.linalg.norm(V * self.tau, axis=1) <= tol)
        if self._disp is not None:
            rest &= theta + self.dt >= self._disp.end
        done = np.flatnonzero(ended & rest)
        n = int(done[0]) + 1 if len(done) else n_max
        t = self.t + self.dt * np.arange(1, n + 1)
        return RunRows(t, X[:n], V[:n], Acc[:n], goal_f[:n], R[:n], A[:n], M[:n], k[:n],
                       vstart[:n], theta[:n] + self.dt, self._n)

    def _placements(self, goal_f, moving):
        """
        Return the placements (R, A, M, vstart, k) of the steps to the filtered goals ``goal_f``.

        ``goal_f`` (n, d): the filtered goal after each step; it moves in the first ``moving``
        steps and rests after them. None where the placement is undefined (g_f passes by x0:
        :meth:`step` keeps the old placement there, only it can step).
        """
        n, d = goal_f.shape
        R = np.empty((n, d, d))
        A, M, vstart, k = np.empty((n, d)), np.empty((n, d)), np.empty((n, d)), np.empty(n)
        if not moving:
            R[:], A[:], M[:], vstart[:], k[:] = self._R, self._A, self._M, self._vstart, self._k
            return R, A, M, vstart, k
        try:
            transform, vstart_m, A_m, M_m = self._skill._placement(
                np.broadcast_to(self._x0, (moving, d)), goal_f[:moving],
                self._method, self._mode, self._axis)
        except GeneralizationError:
            return None
        R[:moving], A[:moving], M[:moving] = transform.R, A_m, M_m
        R[moving:], A[moving:], M[moving:] = transform.R[-1], A_m[-1], M_m[-1]
        vstart[:moving], vstart[moving:] = vstart_m, vstart_m[-1]
        length = np.linalg.norm(self._x0 - goal_f, axis=1)
        k[:] = self.gains.k if self.gains.k is not None else \
            self.gains.k_relative / np.maximum(length, 1e-300)
        return R, A, M, vstart, k

    def replay(self, x: ArrayLike, v: ArrayLike, a: ArrayLike) -> Optional[RunRows]:
        """
        Return the rows of this run stepped with no input, from samples computed elsewhere.

        ``x``, ``v``, ``a`` (N, d): the samples after each of the next N steps, as the offline
        rollout that the run reproduces computed them (the plan it follows, with the detour's
        displacement: it is taken out); the placement in force stays. Only while the goal
        filter rests (``g_f = g``); None otherwise. :meth:`restore` puts any of them in force
        without integrating again.
        """
        if not np.array_equal(self._goal_f, self._goal):
            return None
        x, v, a = (np.asarray(c, dtype=float) for c in (x, v, a))
        n, d = x.shape
        steps = np.arange(1, n + 1)
        if self._disp is not None:      # the plan's samples carry the detour; rows do not
            delta, delta_v, delta_a = self._disp(self._theta + self.dt * steps)
            x, v, a = x - delta, v - delta_v, a - delta_a
        return RunRows(self.t + self.dt * steps, x, v, a,
                       np.broadcast_to(self._goal_f, (n, d)), np.broadcast_to(self._R, (n, d, d)),
                       np.broadcast_to(self._A, (n, d)), np.broadcast_to(self._M, (n, d)),
                       np.full(n, self._k), np.broadcast_to(self._vstart, (n, d)),
                       self._theta + self.dt * steps, self._n)

    def restore(self, rows: RunRows, i: int) -> None:
        """
        Put sample ``i`` of ``rows`` in force: the run as it is after that step.

        ``rows`` from :meth:`predict` or :meth:`replay` of this run in the state it had then
        (or of a copy of it); the detour in force is kept.
        """
        self._goal_f = rows.goal_f[i].copy()
        self._R, self._A, self._M = rows.R[i].copy(), rows.A[i].copy(), rows.M[i].copy()
        self._k = float(rows.k[i])
        self._vstart = rows.vstart[i].copy()
        self._x, self._xd, self._a = rows.x[i].copy(), rows.v[i].copy(), rows.a[i].copy()
        self._v = self._xd * self.tau
        self._rate = 1.0
        self._n = rows.n0 + i + 1
        self._theta = float(rows.theta[i])

    def _forcing_rows(self, n):
        """
        Phase and forcing at the sub-step midpoints and samples of the next ``n`` full-rate steps.

        While the phase has only run at full rate it is on the offline grid (``k dt``), and the
        rows come from the skill's cached table of RUN_TABLE_TAUS durations (built once per
        timing); after phase stopping they are computed.
        """
        skill, sub = self._skill, self._substeps
        k0 = int(round(self._theta / self.dt))
        n_table = int(math.ceil(RUN_TABLE_TAUS * self.tau / self.dt)) + 1
        if abs(self._theta - k0 * self.dt) <= 1e-9 * self.dt and k0 + n + 1 <= n_table:
            s_mid, f_mid, s_out, f_out = skill._forcing_table(self.tau, self.dt, n_table, sub)
            rows = slice(k0 * sub, (k0 + n) * sub)
            return s_mid[rows], f_mid[rows], s_out[k0 + 1:k0 + n + 1], f_out[k0 + 1:k0 + n + 1]
        theta = self._theta + self.dt * np.arange(n)
        theta_mid = (theta[:, None] + self._h * (np.arange(sub) + 0.5)).ravel()
        s_mid = np.exp(-skill.alpha * theta_mid / self.tau)
        s_out = np.exp(-skill.alpha * (theta + self.dt) / self.tau)
        term = skill.forcing.phase_term     # Hoffmann's phase term, as in the skill's table
        return term(s_mid), skill.forcing(s_mid), term(s_out), skill.forcing(s_out)

    def warm(self) -> None:
        """Build the forcing table :meth:`run` reads (~10 ms once per timing), so it is fast."""
        self._forcing_rows(1)
        if self.tau not in self._steps:
            self._steps[self.tau] = discretize(self._skill.K, self._skill.D, self.tau, self._h)

    def _run_by_steps(self, n_max):
        """:meth:`run` by calls of :meth:`step` (the reference; no numba)."""
        rows = []
        for _ in range(n_max):
            rows.append(self.step())
            if self.done:
                break
        t = self.t - self.dt * np.arange(len(rows))[::-1]
        x, v, a = (np.array([r[i] for r in rows]) for i in range(3))
        return t, x, v, a

    def _coupled(self):
        """Return the obstacles the integrator couples to (the paper's), (n, d)."""
        return self._obstacles if not self._detours else self._obstacles[:0]

    def _plan_detour(self, goal, obstacles, radii):
        """
        Plan the detour's displacement for the remainder with ``goal`` and ``obstacles``.

        The remainder of the DMP is predicted from the current state with no further input
        (:meth:`predict`, or stepped by the reference), over the phase time up to
        ``max(tau, theta + tau / 2)``; the displacement in force is carried and blended out.
        Returns the new :class:`Displacement` (or None: nothing to avoid, nothing to carry).
        Raises GeneralizationError when the clearance cannot be kept; the run is unchanged.
        """
        trial = self.copy()
        trial._goal, trial._disp = goal, None
        horizon = max(self.tau, self._theta + 0.5 * self.tau)
        n_max = max(1, int(math.ceil((horizon - self._theta) / self.dt - 1e-9)))
        rows = trial.predict(n_max) if self._fast and numba is not None else None
        if rows is not None:
            theta = np.concatenate([[self._theta], rows.theta])
            x = np.vstack([self._x[None], rows.x])
            acc = np.vstack([self._a[None], rows.a])
        else:
            x, theta, acc = [self._x.copy()], [self._theta], [self._a.copy()]
            for _ in range(n_max):
                trial.step()
                x.append(trial._x.copy())
                theta.append(trial._theta)
                acc.append(trial._a.copy())
                if trial.done:
                    break
            x, theta, acc = np.array(x), np.array(theta), np.array(acc)
        if len(x) < 2:
            return None
        obstacles_set = Obstacles(obstacles, radii)
        size = self._length(goal)
        margin = self.gains.clearance_margin * size
        directions = candidate_directions(self._skill.dim) @ self._R
        peak = float(np.max(np.linalg.norm(acc, axis=1)))
        shift, _ = keep_clear(
            theta, x, obstacles_set, margin, self.gains.ramp, directions, size,
            displacement=self._disp, t0=self._theta, blend_length=self._blend_length,
            fast=self._fast, acceleration=self.gains.detour_acceleration * peak,
            where='the new plan')
        if len(obstacles):
            self._blend_length = self.gains.ramp * float(np.max(radii + margin))
        return shift

    def _length(self, goal):
        """Size ``l`` of the movement placed between x0 and ``goal``."""
        return float(self._skill._placed_size(self._x0, goal))

    def _place(self, goal_f):
        """Put the placement of the skill between x0 and ``goal_f`` in force."""
        transform, vstart, A, M = self._skill._placement(
            self._x0[None], goal_f[None], self._method, self._mode, self._axis)
        self._R, self._vstart, self._A, self._M = transform.R[0], vstart[0], A[0], M[0]
        self._k = self.gains.decay(np.linalg.norm(self._x0 - goal_f))

    def _advance(self, rate, samples):
        """
        Integrate ``samples`` (0 or 1) steps at ``rate``; set x, v; return the acceleration.

        One call of the offline integrator, in the virtual situation of the transform in force,
        from the current state: its sample 0 is the current one, its sample 1 the next.
        """
        skill, g, R = self._skill, self._goal_f, self._R
        tau = self.tau / rate
        n_sub = self._substeps * samples
        # Phase at the sub-step midpoints, then at the current and the next sample.
        theta = np.concatenate([self._theta + rate * self._h * (np.arange(n_sub) + 0.5),
                                self._theta + rate * self.dt * np.arange(samples + 1)])
        s = np.exp(-skill.alpha * theta / self.tau)
        f = skill.forcing(s)
        s = skill.forcing.phase_term(s)     # Hoffmann's phase term, as in the skill's table
        step = self._steps.get(tau)
        if step is None:
            step = discretize(skill.K, skill.D, tau, self._h)
            if rate == 1.0:
                self._steps[tau] = step
        x_virtual = R @ (self._x - g) + g
        v_virtual = R @ self._v
        obstacles = (self._coupled() - g) @ R.T + g
        X, V, Acc = rollout(x_virtual[None], g[None], self._A[None], self._M[None], s[:n_sub],
                            f[:n_sub], s[n_sub:], f[n_sub:], obstacles[None],
                            (self.gains.gamma, self.gains.beta, self.gains.gamma2,
                             np.array([self._k])),
                            skill.K, skill.D, tau, self._h, self._substeps, R[None],
                            fast=self._fast, v0=v_virtual[None], step=step)
        self._x, self._xd = X[0, -1], V[0, -1]
        self._v = self._xd * tau
        return Acc[0, -1]

"""
Following a plan in execution: its remainder re-planned, and when a moved input is followed.

- :class:`FollowedPlan`: a plan in execution whose remainder is re-planned online from any path
  time for a moved goal or obstacle set (online ET-DMP, docs/design.md#online-goal).

The decision dmp_server makes at every perception message while a plan executes
(docs/design.md#through-ros-following-a-plan-in-execution), and that the demo's metrics replay
from a recording, without ROS:

- :func:`goal_moved`, :func:`obstacles_moved`: whether a perceived goal (3,) or obstacle set
  (m, 3) lies more than ``threshold`` (m) from another one.
- :class:`MovedInput`: the debounce. A perceived value is a candidate; any message more than
  ``threshold`` from the previous one restarts it; it is taken as moved once
  :data:`FOLLOW_CONFIRMATIONS` consecutive messages agree on it and it lies more than
  ``threshold`` from what the plan uses and from the last value the plan refused.
- :func:`merged_obstacles`: the obstacles a plan in execution follows, the ones it uses updated
  with the ones seen (matched within :data:`FOLLOW_MATCH_RADIUS`); :func:`sized_obstacles`
  gives perceived obstacle centres the radius of the nearest perceived volume.
- :class:`Following`: a plan in execution (a :class:`FollowedPlan`)
  with what it follows: the goal and obstacles to re-plan it for, the controller's estimated
  place on it, and the part of it to publish after a change.

All points are base_link metres; path times are seconds from the plan's stamp.
"""

import math
from typing import Callable, Optional, Tuple

from etdmp_ros.dmp import GeneralizationError, Skill
from etdmp_ros.geometry.arrays import Array as FloatArray
from etdmp_ros.geometry.task_plane import TaskPlane
from etdmp_ros.skills.planning import (checked_points, format_point, obstacle_clearances, Plan,
                                       PlanningError, PlanSettings, pose_orientations,
                                       SkillSpace)
import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Consecutive perception messages that must agree on a moved goal or obstacle set before a
#: plan in execution follows it: a frame rendered while the marker moved can show it in
#: between, or an obstacle hidden by the arm (about 0.1 s at the camera's 30 Hz).
FOLLOW_CONFIRMATIONS = 3
#: A perceived obstacle within this distance (m) of one the plan avoids is that one, moved; a
#: perceived volume within it of a perceived obstacle is that obstacle's volume.
FOLLOW_MATCH_RADIUS = 0.05
#: The remainder published on a change starts this far (path time, s) before the controller's
#: estimated place, so that it covers where the controller is when it takes it over.
FOLLOW_OVERLAP = 0.1
#: A plan is followed until this long (s) after its end.
FOLLOW_AFTER_END = 1.0

#: ``differ(before, now, threshold)``: whether ``now`` lies more than ``threshold`` from
#: ``before`` (True when ``before`` is None).
Differ = Callable[[Optional[FloatArray], FloatArray, float], bool]


class FollowedPlan:
    """
    A plan being executed whose goal and obstacles may still move (online ET-DMP).

    Made from the :class:`Plan` that :func:`plan_path` returned, with the same arguments. It
    keeps the skill's online rollout (:meth:`etdmp_ros.dmp.Skill.online`) in step with the
    plan: the online run reproduces the plan while nothing moves. :meth:`update` changes the
    goal or the obstacles from path time ``t_switch`` on and returns the new remainder; each
    update starts from the state the previous ones left, so the path stays continuous in
    position and velocity however often it changes (the goal filter keeps the acceleration
    bounded). ``t`` (n,) and ``positions``, ``velocities`` (n, 3) are the whole path as it
    stands (the plan's own time base); ``goal`` (3,), ``obstacles`` (m, 3), ``obstacle_radii``
    (m,) (the clearance kept from each centre, m) and ``obstacle_sizes`` (m,) (each obstacle's
    own radius, m) those in force; ``updates`` counts the updates made.

    Orientation: ``orientation`` is the plan's one tuple (mode ``tool``) or an (n, 4) array
    matching ``t``. The online rollout does not carry orientations, so a re-planned remainder
    takes the plan's orientation at the same path time, which is the same phase (the phase
    depends on time only, not on the goal or obstacles), and the plan's last orientation after
    the plan's end: the tool keeps the orientation pattern it was given (and reaches a requested
    goal orientation) even when the goal moves; it is not turned again with the moved goal.
    """

    def __init__(self, skill: Skill, plan: Plan, settings: Optional[PlanSettings] = None,
                 plane: Optional[TaskPlane] = None) -> None:
        """Start following ``plan`` (planned for ``skill`` with ``settings`` and ``plane``)."""
        settings = PlanSettings() if settings is None else settings
        self.skill, self.settings = skill, settings
        self._space = SkillSpace(skill, plane)
        space = self._space
        radii = np.zeros(len(plan.obstacles)) if plan.obstacle_radii is None else \
            plan.obstacle_radii
        try:
            self._run = skill.online(
                space.inward(plan.start), space.inward(plan.goal), space.inward(plan.obstacles),
                method=settings.method, mode=settings.mode,
                independent_axis=settings.independent_axis, dt=settings.output_period,
                tau=settings.duration or None, gains=settings.skill_gains(space.scale),
                obstacle_radii=radii / space.scale, avoidance=plan.avoidance)
        except GeneralizationError as err:
            raise PlanningError(str(err)) from None
        self.t, self.positions = plan.t.copy(), plan.positions.copy()
        self.velocities = plan.velocities.copy()
        self.goal, self.obstacles = plan.goal.copy(), plan.obstacles.copy()
        self.obstacle_radii = np.array(radii, dtype=float)
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
        self._base, self._kept = self._run, None
        traj = plan.trajectory
        if traj is not None and len(traj.t) == len(plan.t) and len(traj.t) > 1:
            self._kept = self._run.replay(traj.x[1:], traj.v[1:], traj.a[1:])

    def placed(self, points: ArrayLike) -> FloatArray:
        """Return base_link ``points`` (..., 3) as the plan uses them (on the task plane, 2D)."""
        points = np.asarray(points, dtype=float)
        return self._space.outward(self._space.inward(points.reshape(-1, 3))).reshape(
            points.shape)

    @property
    def duration(self) -> float:
        """Path time (s) of the path's last pose."""
        return float(self.t[-1])

    def index(self, t: float) -> int:
        """Return the index of the pose at path time ``t`` (the last one at or before it)."""
        return int(np.clip(np.searchsorted(self.t, t + 1e-9) - 1, 0, len(self.t) - 1))

    def orientations_at(self, t: ArrayLike) -> FloatArray:
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
        base, rows = self._base, self._kept
        if rows is not None:
            i = int(round((t - base.t) / base.dt)) - 1
            if -1 <= i < len(rows.t):
                run = base.copy()
                if i >= 0:
                    run.restore(rows, i)
                return run
        self._run.run(t)
        return self._run

    def update(self, t_switch: float, goal: Optional[ArrayLike] = None,
               obstacles: Optional[ArrayLike] = None, t_max: Optional[float] = None,
               obstacle_radii: Optional[ArrayLike] = None) -> int:
        """
        Move the goal to ``goal`` and/or the obstacles to ``obstacles`` from ``t_switch`` on.

        ``goal`` (3,) and ``obstacles`` (m, 3) are base_link points (projected onto the task
        plane for 2D skills), None for unchanged; ``obstacle_radii`` (m,) each obstacle's radius
        in metres (the tool's radius and ``obstacle_clearance`` are added, as in
        :func:`plan_path`), None for those in force (the same number of obstacles) or, for the
        paper's points, none. Return the index of the first changed pose: the path from there
        on (``t``, ``positions``, ``velocities``) is new; before it, it is as it was. The new
        path runs until the online run is done or ``t_max`` (default: the old end plus the
        skill's duration). Raises PlanningError, leaving the path as it was, for a goal out of
        reach or on the start, an obstacle on the goal, a new path that leaves the workspace
        or, for the detour, a clearance it cannot keep.
        """
        space = self._space
        goal_s, obstacles_s, radii_s = self._inputs(goal, obstacles, obstacle_radii)
        k = self.index(max(t_switch, self._run.t))
        run = self._at(self.t[k])   # in step with the path as it stands
        t_max = self.duration + self._run.tau if t_max is None else t_max
        try:
            with np.errstate(over='raise', invalid='raise', divide='raise'):
                after, kept, xs, vs = _remainder(run, goal_s, obstacles_s, radii_s, t_max)
        except (GeneralizationError, ArithmeticError) as err:
            raise PlanningError(str(err)) from None
        positions = space.outward(xs)
        outside = self.settings.workspace.violation(positions)
        if outside is not None:
            i, reason = outside
            raise PlanningError(f"the new path leaves the UR10's reach at "
                                f'{format_point(positions[i])}: {reason}')
        t_new = run.t + run.dt * np.arange(1, len(xs) + 1)
        keep = k + 1
        self.t = np.concatenate([self.t[:keep], t_new])
        self.positions = np.concatenate([self.positions[:keep], positions])
        self.velocities = np.concatenate([self.velocities[:keep], space.outward_vectors(vs)])
        if not isinstance(self.orientation, tuple):
            self.orientation = np.concatenate([self.orientation[:keep],
                                               self.orientations_at(t_new)])
        self._run = after
        self._base, self._kept = kept
        if goal_s is not None:
            self.goal = space.outward(goal_s)
        if obstacles_s is not None:
            self.obstacles = space.outward(obstacles_s)
            self.obstacle_radii = self._run.obstacle_radii * space.scale
            if obstacle_radii is not None:
                self.obstacle_sizes = np.asarray(obstacle_radii, dtype=float).reshape(-1)
        self.updates += 1
        return keep

    def _inputs(self, goal, obstacles, obstacle_radii):
        """
        Return an update's goal, obstacles and clearances in the skill's space (None: as is).

        Raises PlanningError for bad points and radii, and for a goal out of reach.
        """
        space, settings = self._space, self.settings
        goal_s = None if goal is None else space.inward(checked_points(goal, 'goal', (3,)))
        obstacles_s = None if obstacles is None else space.inward(
            checked_points(obstacles, 'obstacles', None))
        radii = None if obstacle_radii is None or obstacles_s is None else \
            obstacle_clearances(obstacle_radii, settings, len(obstacles_s))
        if goal_s is not None:
            goal_b = space.outward(goal_s)
            outside = settings.workspace.violation(goal_b)
            if outside is not None:
                raise PlanningError(f"goal {format_point(goal_b)} is out of the UR10's reach: "
                                    f'{outside[1]}')
        return goal_s, obstacles_s, None if radii is None else radii / space.scale


def _remainder(run, goal, obstacles, radii, t_max):
    """
    Return (the run after the change's step, (run, rows) to keep, x, v) of an update.

    ``run``: the online run at the switch (left as it is); ``goal``, ``obstacles``, ``radii``
    the change in the skill's space (None: as is). The step that takes the new input and the
    rest of the movement come from one call of the numba loop (what a step() and a run() give,
    to rounding); ``x``, ``v`` (N, d) the samples after each step, until done or ``t_max``.
    Raises GeneralizationError (the change is refused) or ArithmeticError.
    """
    trial = run.copy()      # what-if: the run itself changes only on success
    trial.take(goal=goal, obstacles=obstacles, obstacle_radii=radii)
    rows = trial.predict(int(math.floor((t_max - trial.t) / trial.dt + 0.5)))
    if rows is not None and len(rows.t):
        after = trial.copy()
        after.restore(rows, 0)
        xs, vs, _ = trial.outputs(rows)
        return after, (trial, rows), xs, vs
    # Only step() can (the filtered goal passes by the start).
    trial = run.copy()
    x, v, _ = trial.step(goal=goal, obstacles=obstacles, obstacle_radii=radii)
    after = trial.copy()
    _, xs, vs, _ = trial.run(t_max)
    return after, (None, None), np.vstack([x[None], xs]), np.vstack([v[None], vs])


def goal_moved(before: Optional[ArrayLike], now: ArrayLike, threshold: float) -> bool:
    """Return whether goal ``now`` is more than ``threshold`` from ``before`` (or no before)."""
    if before is None:
        return True
    gap = np.linalg.norm(np.asarray(now, dtype=float) - np.asarray(before, dtype=float))
    return bool(gap > threshold)


def obstacles_moved(used: Optional[ArrayLike], seen: ArrayLike, threshold: float) -> bool:
    """
    Return whether the obstacle set ``seen`` differs from ``used`` by more than ``threshold``.

    Sets are unordered: they differ when their sizes differ, or when some obstacle of ``used``
    has no obstacle of ``seen`` within ``threshold``. No ``used`` (None) differs from any set.
    """
    if used is None:
        return True
    seen, used = np.asarray(seen).reshape(-1, 3), np.asarray(used).reshape(-1, 3)
    if len(seen) != len(used):
        return True
    if not len(seen):
        return False
    # Each used obstacle's nearest seen one (sets are small and unordered).
    gaps = np.linalg.norm(used[:, None] - seen[None], axis=2).min(axis=1)
    return bool(gaps.max() > threshold)


class MovedInput:
    """
    The debounced decision whether a perceived input (the goal, or the obstacle set) moved.

    :meth:`see` is called with every message; ``differ`` is :func:`goal_moved` or
    :func:`obstacles_moved`. ``candidate`` is the value the last messages agree on, ``count``
    how many agree, ``refused`` the last value the plan could not take (it is not followed
    again until perception shows another one).
    """

    def __init__(self, differ: Differ, confirmations: int = FOLLOW_CONFIRMATIONS) -> None:
        """Start with no candidate; ``confirmations`` messages must agree on a move."""
        if confirmations < 1:
            raise ValueError(f'confirmations must be >= 1, got {confirmations!r}')
        self.differ, self.confirmations = differ, confirmations
        self.candidate: Optional[FloatArray] = None
        self.count = 0
        self.refused: Optional[FloatArray] = None

    def see(self, seen: FloatArray, used: Optional[ArrayLike], threshold: float) -> bool:
        """
        Note the value ``seen`` of a message; return whether to follow it now.

        True when the last ``confirmations`` messages agree on ``seen`` (each within
        ``threshold`` of the previous one) and it lies more than ``threshold`` from ``used``
        (what the plan follows now) and from the value last refused.
        """
        if self.differ(self.candidate, seen, threshold):
            self.count = 0
        self.candidate, self.count = seen, self.count + 1
        return (self.count >= self.confirmations and self.differ(used, seen, threshold)
                and self.differ(self.refused, seen, threshold))

    def refuse(self) -> None:
        """Remember the candidate as refused by the plan: it is not followed again."""
        self.refused = self.candidate

    def clear_refusal(self) -> None:
        """Forget a refusal (a plan that took no change of this input)."""
        self.refused = None


def merged_obstacles(used: ArrayLike, used_radii: ArrayLike, seen: ArrayLike,
                     seen_radii: ArrayLike, threshold: float
                     ) -> Tuple[FloatArray, FloatArray]:
    """
    Return the obstacles (m, 3) and radii (m,) a plan in execution follows: ``used`` updated.

    A seen obstacle within FOLLOW_MATCH_RADIUS of a used one is that one (moved, if by more than
    ``threshold``, and then with its seen radius); the nearest such wins, others near it are
    the same obstacle seen twice. A seen obstacle near none appeared: it is added after the used
    ones. A used obstacle that is not seen is kept where it was: the arm may be hiding it from
    the camera.
    """
    used, seen = np.asarray(used).reshape(-1, 3), np.asarray(seen).reshape(-1, 3)
    merged, radii = used.copy(), np.array(used_radii, dtype=float).reshape(-1)
    seen_radii = np.asarray(seen_radii, dtype=float).reshape(-1)
    appeared = list(range(len(seen)))
    if len(used):
        gaps = np.linalg.norm(seen[:, None] - used[None], axis=2)
        nearest = gaps.argmin(axis=1) if len(seen) else np.zeros(0, int)
        for j in range(len(used)):
            mine = np.flatnonzero((nearest == j) & (gaps[:, j] <= FOLLOW_MATCH_RADIUS))
            if len(mine):
                best = mine[np.argmin(gaps[mine, j])]
                if gaps[best, j] > threshold:
                    merged[j], radii[j] = seen[best], seen_radii[best]
        appeared = [i for i in range(len(seen)) if gaps[i].min() > FOLLOW_MATCH_RADIUS]
    return (np.vstack([merged, seen[appeared]]), np.concatenate([radii, seen_radii[appeared]]))


def sized_obstacles(seen: ArrayLike, volume_tops: Optional[ArrayLike],
                    volume_radii: Optional[ArrayLike]
                    ) -> Tuple[FloatArray, NDArray[np.bool_]]:
    """
    Return each seen obstacle's radius (m,) and whether it has one (m,) (bools).

    ``seen`` (m, 3): perceived obstacle centres; ``volume_tops`` (k, 3) and ``volume_radii``
    (k,): the perceived volumes (None: none). A seen obstacle takes the radius of the nearest
    volume within FOLLOW_MATCH_RADIUS (perception sends both for every frame); one without such
    a volume is a point (radius 0, and False).
    """
    seen = np.asarray(seen, dtype=float).reshape(-1, 3)
    radii = np.zeros(len(seen))
    if volume_tops is None or not len(seen) or not len(volume_tops):
        return radii, np.zeros(len(seen), bool)
    tops = np.asarray(volume_tops, dtype=float).reshape(-1, 3)
    gaps = np.linalg.norm(seen[:, None] - tops[None], axis=2)
    nearest = gaps.argmin(axis=1)
    sized = gaps[np.arange(len(seen)), nearest] <= FOLLOW_MATCH_RADIUS
    radii[sized] = np.asarray(volume_radii, dtype=float).reshape(-1)[nearest[sized]]
    return radii, sized


class Following:
    """
    A plan in execution that follows its goal and obstacles while they move.

    ``plan``: the :class:`FollowedPlan` (it re-plans the remainder); ``skill`` and ``stamp``
    (ns, the plan's time base) as published; ``perceived_goal``: whether the request used the
    perceived goal (only then is the goal followed); ``start``: the plan's first position;
    ``tau_c``: the controller's path time, last estimate (s); ``goal``, ``obstacles``: the
    :class:`MovedInput` decisions.
    """

    def __init__(self, plan: FollowedPlan, skill: Skill, stamp: int,
                 perceived_goal: bool) -> None:
        """Follow ``plan`` published with ``stamp``; follow its goal if ``perceived_goal``."""
        self.plan, self.skill, self.stamp = plan, skill, stamp
        self.perceived_goal = perceived_goal
        self.start = plan.positions[0].copy()
        self.tau_c = 0.0
        self.goal, self.obstacles = MovedInput(goal_moved), MovedInput(obstacles_moved)

    def ended(self, tau_now: float) -> bool:
        """Return whether path time ``tau_now`` (s) is past the end plus FOLLOW_AFTER_END."""
        return tau_now > self.plan.duration + FOLLOW_AFTER_END

    def goal_to_follow(self, goal: ArrayLike, threshold: float
                       ) -> Optional[FloatArray]:
        """
        Note a perceived goal (3,); return it if the plan is to follow it now, else None.

        The goal is compared as the plan uses it (projected onto the task plane for a 2D
        skill); a plan whose request gave its goal does not follow the perceived one.
        """
        if not self.perceived_goal:
            return None
        goal = np.asarray(goal, dtype=float)
        if self.goal.see(self.plan.placed(goal), self.plan.goal, threshold):
            return goal
        return None

    def obstacles_to_follow(self, seen: ArrayLike, seen_radii: ArrayLike, threshold: float
                            ) -> Optional[Tuple[FloatArray, FloatArray]]:
        """
        Note the perceived obstacles (m, 3) with radii (m,); return the set to follow or None.

        The set to follow: (obstacles (n, 3), radii (n,) in metres), :func:`merged_obstacles`
        of the plan's and the seen ones (placed as the plan uses them).
        """
        plan = self.plan
        merged, radii = merged_obstacles(plan.obstacles, plan.obstacle_sizes, plan.placed(seen),
                                         seen_radii, threshold)
        if self.obstacles.see(merged, plan.obstacles, threshold):
            return merged, radii
        return None

    def refused(self, goal: bool, obstacles: bool) -> None:
        """
        Remember a change the plan could not take: not tried again until perception shows another.

        ``goal``, ``obstacles``: whether the refused change moved the goal, the obstacles; an
        input the change did not move has its refusal forgotten.
        """
        for refused, watch in ((goal, self.goal), (obstacles, self.obstacles)):
            if refused:
                watch.refuse()
            else:
                watch.clear_refusal()

    def controller_path_time(self, tool: Optional[ArrayLike], tau_now: float) -> float:
        """
        Estimate the path time (s) the controller is at: where the tool is closest to the path.

        Searched between the previous estimate and ``tau_now`` (the time since the plan's
        stamp: the controller cannot be ahead of it); without a tool position (None),
        ``tau_now``.
        """
        if tool is None:
            return tau_now
        p = self.plan
        lo, hi = p.index(self.tau_c), p.index(tau_now) + 1
        if hi <= lo:
            return tau_now
        distances = np.linalg.norm(p.positions[lo:hi] - np.asarray(tool, dtype=float), axis=1)
        self.tau_c = float(p.t[lo + int(np.argmin(distances))])
        return self.tau_c

    def remainder_start(self, tau_c: float) -> int:
        """Return the index of the first pose to publish after a change (FOLLOW_OVERLAP early)."""
        return self.plan.index(max(0.0, tau_c - FOLLOW_OVERLAP))

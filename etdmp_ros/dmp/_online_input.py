"""
Checks of what is given to a running :class:`OnlineRun`: points, obstacle sets, a new goal.

Each raises GeneralizationError saying what is wrong; the run checks everything before it
changes anything, so a refused input leaves it as it was.
"""

import numpy as np

from ._errors import finite_array, GeneralizationError
from ._online_gains import OnlineGains
from ._transform import EPS


def check_online_request(online, start, goal, d):
    """
    Return the gains ``online`` (None: the defaults) of a new run, checked with its ends.

    ``start`` and ``goal`` must be one point (d,) each: an online run is one movement.
    """
    online = OnlineGains() if online is None else online
    if not isinstance(online, OnlineGains):
        raise GeneralizationError(f'online must be an OnlineGains, got {online!r}')
    try:
        online.validate()
    except ValueError as exc:
        raise GeneralizationError(str(exc)) from None
    for name, value in (('start', start), ('goal', goal)):
        if finite_array(value, name).shape != (d,):
            raise GeneralizationError(f'an online run is one movement: {name} must have '
                                      f'shape ({d},), got {np.shape(value)}')
    return online


def check_point(value, name, d):
    """Return one point (d,) given to a run, checked (finite, of the skill's dimension)."""
    arr = finite_array(value, name)
    if arr.shape != (d,):
        raise GeneralizationError(f'{name} must have shape ({d},), got {arr.shape}')
    return arr.copy()


def check_obstacle_set(value, d):
    """Return an obstacle set given to a run as (n, d), checked."""
    obs = finite_array(value, 'obstacles')
    if obs.size == 0:
        return np.zeros((0, d))
    if obs.ndim > 2 or obs.shape[-1] != d:
        raise GeneralizationError(f'obstacles must have shape (n, {d}), got {obs.shape}')
    if d not in (2, 3):
        raise GeneralizationError(f'obstacle avoidance needs 2 or 3 dimensions, skill has {d}')
    return obs.reshape(-1, d).copy()


def check_radii(skill, obstacles, obstacle_radii, in_force, detours):
    """
    Return the radii (n,) of a new obstacle set (n, d).

    ``obstacle_radii`` None keeps those ``in_force`` for the detour (the same number of
    obstacles, else an error), and gives the paper's points zeros.
    """
    if obstacle_radii is None:
        if not detours:
            return np.zeros(len(obstacles))
        if len(obstacles) != len(in_force):
            raise GeneralizationError(
                f'{len(obstacles)} obstacles given without obstacle_radii, and there were '
                f'{len(in_force)}: give their radii')
        return in_force
    return skill._check_radii(obstacle_radii, len(obstacles))


def check_goal_off_start(skill, x0, goal, method, mode, axis):
    """Refuse a new goal on the movement's start ``x0``, or where its placement is undefined."""
    gap = np.linalg.norm(x0 - goal)
    if not gap > EPS * skill.size:
        raise GeneralizationError(
            f"goal equals the movement's start (|x0 - g| = {gap:.3g}): the transform "
            'is undefined and there is no movement to make')
    # Raises where the placement is undefined (the plain DMP's division by ~0). The ET-DMP's
    # is defined wherever the goal is off the start (checked above; the demonstration's own
    # |I_D| was checked when the run was made).
    if method != 'etdmp':
        skill._placement(x0[None], goal[None], method, mode, axis)


def check_goal_clear(skill, goal, obstacles, radii, detours):
    """Refuse a goal on an obstacle (n, d) or, for the detour, inside one (radii (n,))."""
    if np.any(np.linalg.norm(obstacles - goal, axis=1) <= EPS * skill.size):
        raise GeneralizationError('an obstacle lies on the goal: the goal is unreachable')
    if detours:
        gap = np.linalg.norm(obstacles - goal, axis=1) - radii
        if np.any(gap < 0.0):
            j = int(np.argmin(gap))
            raise GeneralizationError(
                f'the goal lies inside obstacle #{j} (radius {radii[j]:.4g}, '
                f'{gap[j] + radii[j]:.4g} from its centre): the plan cannot keep its '
                'clearance')

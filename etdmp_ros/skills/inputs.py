"""
The latest inputs dmp_server plans with, and their ages: tool, goal objects, obstacles.

Each kept value is what a topic last delivered and when (``time.monotonic``); a value older than
its ``max_age`` (seconds; 0: any age) is not used, and the reason says so. Thread-safe: the
input callbacks keep values while requests read them.
"""

import threading
import time
from typing import Any, Optional, Tuple

from etdmp_ros.robot import UR10Model
from etdmp_ros.skills.following import sized_obstacles
import numpy as np
from numpy.typing import NDArray

#: Where the tool position comes from: its topic (the tool_position_source parameter's choices).
TOOL_TOPICS = {'joint_states': '/joint_states', 'tool_pose': '/etdmp/tool_pose'}
#: Where a perceived goal object comes from (the goal_object parameter's choices).
GOAL_TOPICS = {'marker': '/etdmp/goal', 'bottle': '/etdmp/bottle'}


class Latest:
    """A value received on a topic and when (time.monotonic), or nothing yet."""

    __slots__ = ('value', 'received')

    def __init__(self) -> None:
        """Start with nothing received."""
        self.value: Any = None
        self.received = 0.0         # meaningful once a value was received

    def update(self, value: Any) -> None:
        """Keep ``value``, received now."""
        self.value, self.received = value, time.monotonic()

    def fresh(self, max_age: float) -> Any:
        """Return the value if it is not older than max_age seconds (0: any age), else None."""
        if self.value is None or (max_age > 0.0 and time.monotonic() - self.received > max_age):
            return None
        return self.value

    def age(self) -> float:
        """Return the seconds since the value was received."""
        return time.monotonic() - self.received


class LatestInputs:
    """
    The latest joint state, tool pose, goal objects, obstacles and obstacle volumes.

    ``joint_states``, ``tool_pose``, ``marker``, ``bottle``, ``obstacles``, ``volumes`` are
    :class:`Latest` values; keep one with :meth:`keep`. ``model`` gives the tool position of
    joint positions (forward kinematics; used under this object's lock, it is not thread-safe).
    """

    def __init__(self, model: UR10Model) -> None:
        """Keep nothing yet; ``model``: the UR10 (its tool offset) for the tool position."""
        self.model = model
        self._lock = threading.Lock()
        self.joint_states, self.tool_pose = Latest(), Latest()
        self.marker, self.bottle = Latest(), Latest()
        self.obstacles, self.volumes = Latest(), Latest()

    def keep(self, name: str, value: Any) -> None:
        """Keep ``value`` as the latest of input ``name`` (an attribute named above)."""
        with self._lock:
            getattr(self, name).update(value)

    def joints(self, max_age: float) -> Optional[NDArray[np.float64]]:
        """Return the latest joint positions (6,) if not older than ``max_age``, else None."""
        with self._lock:
            return self.joint_states.fresh(max_age)

    def tool_position(self, source: str, max_age: float) -> NDArray[np.float64]:
        """
        Return the tool position (3,) in base_link from ``source`` (a key of TOOL_TOPICS).

        Raises ValueError saying why there is none (nothing received, or too old).
        """
        with self._lock:
            latest = self.joint_states if source == 'joint_states' else self.tool_pose
            value = latest.fresh(max_age)
            if value is not None and source == 'joint_states':
                value = self.model.tool_position(value)
        if value is None:
            state = 'none received yet' if latest.value is None else \
                f'the latest is {latest.age():.1f} s old (tool_state_max_age {max_age:g} s)'
            raise ValueError(f'the tool position is unknown ({TOOL_TOPICS[source]}: {state}); '
                             'give a start in base_link instead of an empty frame id')
        return value

    def perceived_goal(self, goal_object: str, max_age: float,
                       offset: NDArray[np.float64]) -> NDArray[np.float64]:
        """
        Return the perceived ``goal_object`` (a key of GOAL_TOPICS) plus ``offset`` (3,).

        Raises ValueError saying why there is none (nothing received, or too old).
        """
        latest = self.bottle if goal_object == 'bottle' else self.marker
        with self._lock:
            goal = latest.fresh(max_age)
            if goal is None:
                if latest.value is None:
                    raise ValueError(f'no perceived goal yet on {GOAL_TOPICS[goal_object]}; give '
                                     'a goal in base_link instead of an empty frame id')
                raise ValueError(f'the latest perceived goal is {latest.age():.1f} s old '
                                 f'(goal_max_age {max_age:g} s)')
            return goal + offset

    def obstacles_with_radii(self, max_age: float, static: NDArray[np.float64],
                             wait_for_volumes: float = 0.0
                             ) -> Tuple[NDArray[np.float64], NDArray[np.float64], bool, int]:
        """
        Return the obstacles to plan around: (points (m, 3), radii (m,), stale, unsized).

        The perceived ones, each with the radius of the nearest perceived volume
        (:func:`sized_obstacles`), then the ``static`` ones (points: radius 0). ``stale``: the
        perceived ones were left out, older than ``max_age``; ``unsized``: how many perceived
        ones have no volume (planned as points). ``wait_for_volumes``: while there are
        perceived obstacles and no volume was ever received, wait up to this many seconds for
        one (from another thread than the one that keeps them).
        """
        deadline = time.monotonic() + wait_for_volumes
        while self.volumes.value is None and self.obstacles.value is not None and \
                len(self.obstacles.value) and time.monotonic() < deadline:
            time.sleep(0.01)
        with self._lock:
            seen = self.obstacles.fresh(max_age)
            stale = seen is None and self.obstacles.value is not None and \
                len(self.obstacles.value) > 0
            volumes = self.volumes.fresh(max_age)
        if seen is None or len(seen) == 0:
            return static, np.zeros(len(static)), stale, 0
        radii, sized = sized_obstacles(seen, *(volumes or (None, None)))
        return (np.concatenate([seen, static]), np.concatenate([radii, np.zeros(len(static))]),
                stale, int(np.count_nonzero(~sized)))

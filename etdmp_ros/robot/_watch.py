"""
Watching a control loop: when its joint states count as lost, and how well it tracked a path.

ROS-free: :class:`InputWatch` decides from receipt times and stamps (ns) whether the robot's
joint states are stale, late or missing; :class:`TrackingSummary` collects the figures of one
tracked path (the controller node publishes them as its ``path_tracked`` event and logs them).
"""

import math


class TrackingSummary:
    """
    What the log line at the end of a tracked path reports (and the benchmarks read).

    The tracking error (metres, the controller's own: reference minus forward kinematics), the
    control steps against the control periods the path spanned (from the joint states' stamps),
    the joint states received and the largest wall-clock gap between two of them.
    """

    def __init__(self, period: float) -> None:
        """Start empty; ``period`` is the control period (s)."""
        self.period = period
        self.steps = 0
        self.received = 0
        self.max_gap = 0.0
        self._sum_sq = 0.0
        self._max_error = 0.0
        self._first: float | None = None
        self._last: float | None = None
        self._max_gap_at: float | None = None

    def joint_state(self, gap: float, t: float) -> None:
        """Count a joint state received while tracking (stamp ``t``), ``gap`` s after the last."""
        self.received += 1
        if gap > self.max_gap:
            self.max_gap, self._max_gap_at = gap, t

    def step(self, t: float, error: float) -> None:
        """Count a control step at stamp ``t`` (s) with tracking error ``error`` (m)."""
        self.steps += 1
        self._sum_sq += error * error
        self._max_error = max(self._max_error, error)
        self._first = t if self._first is None else self._first
        self._last = t

    @property
    def periods(self) -> int:
        """Control periods from the first to the last step, both included."""
        if self._first is None or self._last is None:
            return 0
        return round((self._last - self._first) / self.period) + 1

    def figures(self) -> dict[str, float]:
        """
        Return the figures as a dict (mm, ms, s; the event ``path_tracked``'s values).

        ``error_rms_mm``, ``error_max_mm``, ``steps``, ``periods``, ``joint_states``,
        ``largest_gap_ms`` and ``largest_gap_at_s`` (NaN when no gap was seen).
        """
        return {'error_rms_mm': math.sqrt(self._sum_sq / max(self.steps, 1)) * 1e3,
                'error_max_mm': self._max_error * 1e3, 'steps': self.steps,
                'periods': self.periods, 'joint_states': self.received,
                'largest_gap_ms': self.max_gap * 1e3,
                'largest_gap_at_s': (math.nan if self._max_gap_at is None
                                     else float(self._max_gap_at))}

    def summary(self) -> str:
        """Return the figures as one line of text."""
        f = self.figures()
        return (f'error RMS {f["error_rms_mm"]:.3f} mm, max {f["error_max_mm"]:.3f} mm; '
                f'{self.steps} control steps in {self.periods} periods '
                f'({self.received} joint states received, largest gap '
                f'{f["largest_gap_ms"]:.1f} ms'
                + (f' at t = {self._max_gap_at:.3f} s)' if self._max_gap_at is not None else ')'))


class InputWatch:
    """
    When the joint states count as lost: no new one for ``timeout`` of the robot's time.

    The robot's time is the time in which it moves. A real robot's is the wall clock (steady
    here: the system clock may jump). A simulated robot's is the simulation's /clock
    (``use_sim_time``): when the simulation stalls (its process not scheduled on a busy
    machine), its time and its joint states stop together and the arm does not move, so nothing
    is stale; the clock going on without joint states is. A simulation whose clock and joint
    states both stop for ``stall_timeout`` of wall time counts as gone. Receipt times are used,
    never the messages' stamps, which a wrong publisher can set to anything.
    """

    def __init__(self, timeout: float, stall_timeout: float) -> None:
        """Timeouts in seconds (``stall_timeout`` applies only to simulated time)."""
        self.timeout = timeout
        self.stall_timeout = stall_timeout
        self._robot: int | None = None      # robot time (ns) of the latest receipt
        self._wall: int | None = None       # steady time (ns) of the latest receipt
        self._stamp: int | None = None      # stamp (ns) of the latest joint state accepted
        # Robot time (ns) at which that stamp arrived, or would have arrived had it not come
        # late: the reference its successors' stamps are measured against (implausible()).
        self._reference: int | None = None
        self._arrived: int | None = None    # stamp (ns) of the latest plausible one to arrive
        self._simulated = False
        # (robot time ns, skew s) of the first of the joint states refused one after the other
        # with about the same skew, none taken since (implausible()).
        self._refused: tuple[int, float] | None = None

    def received(self, robot_ns: int, wall_ns: int, simulated: bool,
                 stamp_ns: int | None = None) -> None:
        """Note a joint state (stamped ``stamp_ns``) received at these robot and steady times."""
        if simulated != self._simulated:
            self._stamp = self._arrived = None
        self._refused = None
        if stamp_ns is not None:
            # A late arrival's lateness stays out of the reference: taken as its receipt time,
            # every joint state on time after it read as that much ahead of the clock, was
            # refused, and none became the reference again (after one 0.1 s stall beside a busy
            # loop, every joint state of the run was refused "+0.112 s off the robot clock").
            on_time = (None if self._stamp is None or self._reference is None
                       else self._reference + stamp_ns - self._stamp)
            self._reference = robot_ns if on_time is None else min(robot_ns, on_time)
            self._stamp = stamp_ns
        self._robot, self._wall, self._simulated = robot_ns, wall_ns, simulated

    def implausible(self, stamp_ns: int, robot_ns: int, simulated: bool,
                    wall_ns: int | None = None) -> str:
        """
        Return why a joint state stamped ``stamp_ns`` cannot be the robot's ('' if it can).

        Its stamp must have advanced from the last accepted one's as the robot's time did, to
        within ``timeout``: a stamp far in the future would end the path at once (the
        controller's time is the stamps'), one far in the past would read as a restart. On a
        starved machine this process's view of the robot's clock (its /clock messages) and the
        joint states arrive out of step, both ways, so:

        - one that advanced, but less than the clock, is late, not false: this process was not
          scheduled while the robot's clock went on (its /clock messages taken first), or the
          transport held it back; refusing it stopped the arm as stale-input ("its stamp is
          -0.104 s off the robot clock") on a machine loaded 9 times over;
        - one ahead of the clock is the clock lagging (its /clock messages still queued) when
          its stamp advanced no more than the wall clock (``wall_ns``, steady) did since the last
          one was taken, plus ``timeout``: refusing it stopped the G next to a busy core ("+0.104
          s off ... advanced 0.176 s ... while the clock advanced 0.072 s"). A stamp 100 s ahead
          still is no stamp of the robot's.

        - joint states that keep coming with the same skew for ``timeout`` of the robot's
          time, none taken meanwhile, are the robot's and the reference was wrong: the first
          joint state a starting controller took had queued while the machine was busy (its
          receipt became the reference, 0.15 s late), and every one after it read "+0.152 s
          off" until the end of the run. They are taken from then on. Forged stamps that come
          beside the robot's, or in a burst, never make such a run.

        The controller goes on from such a joint state; its missed steps re-synchronise the
        path (etdmp_ros.robot._controller).
        """
        if self._stamp is None or simulated != self._simulated:
            return ''
        assert self._reference is not None and self._wall is not None   # set with _stamp
        advance = (stamp_ns - self._stamp) * 1e-9
        skew = advance - (robot_ns - self._reference) * 1e-9
        if abs(skew) <= self.timeout or (skew < 0.0 and advance > 0.0):
            return ''
        if skew > 0.0 and wall_ns is not None and \
                advance <= (wall_ns - self._wall) * 1e-9 + self.timeout:
            return ''
        if self._refused is None or abs(skew - self._refused[1]) > self.timeout / 2:
            self._refused = (robot_ns, skew)
        elif (robot_ns - self._refused[0]) * 1e-9 >= self.timeout:
            # received() takes this one's receipt as the new reference; no gap: they came.
            self._stamp = self._arrived = None
            return ''
        return (f'its stamp is {skew:+.3f} s off the robot clock (advanced '
                f'{(stamp_ns - self._stamp) * 1e-9:.3f} s since the last accepted one while the '
                f'clock advanced {(robot_ns - self._reference) * 1e-9:.3f} s), not from the '
                'robot')

    def gap(self, stamp_ns: int, simulated: bool) -> str:
        """
        Return why the joint states before this one (stamped ``stamp_ns``) were lost, or ''.

        The robot's time advanced more than ``timeout`` between two joint states that arrived
        one after the other: the ones between never came (a network link that was down), even
        if nothing noticed meanwhile, the robot's /clock having stopped reaching this node with
        them. Joint states that only queued behind a busy process all arrive, a period apart.
        """
        previous, self._arrived = self._arrived, stamp_ns
        if previous is None or (stamp_ns - previous) * 1e-9 <= self.timeout:
            return ''
        clock = 'simulated' if simulated else 'wall-clock'
        return (f'none for {(stamp_ns - previous) * 1e-9:.3f} s of {clock} time: those '
                'between the last two never came')

    def lost(self, robot_ns: int, wall_ns: int, simulated: bool) -> str:
        """Return why the joint states count as lost at these times ('' if they do not)."""
        if self._wall is None:
            return 'never received'
        assert self._robot is not None                               # set with _wall
        if simulated != self._simulated:        # use_sim_time switched: start afresh
            self.received(robot_ns, wall_ns, simulated)
            return ''
        age = (robot_ns - self._robot) * 1e-9
        if age > self.timeout:
            clock = 'simulated' if simulated else 'wall-clock'
            return f'none for {age:.3f} s of {clock} time'
        silent = (wall_ns - self._wall) * 1e-9
        if simulated and silent > self.stall_timeout:
            return (f'none for {silent:.3f} s of wall-clock time, and the simulation clock '
                    'stopped with them (simulation_stall_timeout)')
        return ''

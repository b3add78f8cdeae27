"""
CPU per process against simulated time: what the closed loop costs the machine (Linux /proc).

:class:`CpuMonitor` samples, a few times a second, the CPU time (user + system, all threads) of
a set of processes and their descendants (ur10_sim's camera process counts as ur10_sim; a
named process counts only as itself, not as its parent's, and the monitoring process alone)
from ``/proc/<pid>/stat``, together with the wall clock and the simulated time, so that a
window of simulated time (say, while the arm moves) can be turned into

- CPU-seconds per simulated second of each process (1.0 = one core busy at real time), and
- the real-time factor (simulated seconds per wall second) over that window, and its lowest
  value over any 1 s stretch of it.

ROS-free; where ``/proc`` is missing (not Linux) :attr:`CpuMonitor.available` is False and the
window figures are None.
"""

import os
import threading
import time

_TICKS = os.sysconf('SC_CLK_TCK') if hasattr(os, 'sysconf') else 100


def child_pids(pid):
    """Return the pids of the children of process ``pid`` (all its threads'; [] if gone)."""
    children = []
    try:
        for task in os.listdir(f'/proc/{pid}/task'):
            with open(f'/proc/{pid}/task/{task}/children') as f:
                children += [int(c) for c in f.read().split()]
    except OSError:
        pass
    return children


def process_cpu_seconds(pid):
    """Return the CPU time (user + system, s) used so far by process ``pid``, or None if gone."""
    try:
        with open(f'/proc/{pid}/stat', 'rb') as f:
            text = f.read()
    except OSError:
        return None
    # Fields after the command name (which may hold spaces) start after the last ')'.
    fields = text[text.rindex(b')') + 2:].split()
    return (int(fields[11]) + int(fields[12])) / _TICKS   # utime, stime (fields 14, 15)


def descendants(pid):
    """Return the pids of every process below ``pid`` (children, their children, ...)."""
    found, todo = [], [pid]
    while todo:
        for child in child_pids(todo.pop()):
            found.append(child)
            todo.append(child)
    return found


def tree_cpu_seconds(pid):
    """Return the CPU time (s) of process ``pid`` and of its living descendants."""
    return sum(c for c in map(process_cpu_seconds, [pid, *descendants(pid)]) if c is not None)


class CpuMonitor:
    """
    Samples the CPU time of named processes with the wall clock and the simulated time.

    ``pids``: {name: pid}; ``sim_time``: a callable returning the current simulated time in s
    (None while unknown). Sampling runs in a daemon thread every ``period`` s between
    :meth:`start` and :meth:`stop`.
    """

    def __init__(self, pids, sim_time, period=0.1):
        """Prepare (not sampling yet)."""
        self.pids = dict(pids)
        self.sim_time = sim_time
        self.period = period
        self.samples = []    # (wall s, sim s, {name: cpu s})
        self._trees = {name: {pid} for name, pid in self.pids.items()}
        self._last = {}      # pid -> its latest CPU s (kept when it exits)
        self._refreshed = -1.0
        self.available = os.path.exists(f'/proc/{os.getpid()}/stat')
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name='cpu_monitor')

    def start(self):
        """Start sampling; return self."""
        if self.available:
            self._thread.start()
        return self

    def stop(self):
        """Take a last sample and stop sampling."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def _run(self):
        while True:
            self.sample()
            if self._stop.wait(self.period):
                self.sample()
                return

    def sample(self):
        """Take one sample now: each name's CPU, its descendants included (exited ones too)."""
        sim = self.sim_time()
        if sim is None:
            return
        now = time.monotonic()
        if now - self._refreshed > 1.0:     # new children appear at start-up only: look rarely
            self._refreshed = now
            roots = set(self.pids.values())   # a named process is never another's child
            for name, tree in self._trees.items():
                if self.pids[name] == os.getpid():
                    continue    # this process counts alone: what it starts beside is not its work
                todo = list(tree)
                while todo:
                    for child in child_pids(todo.pop()):
                        if child not in tree and child not in roots:
                            tree.add(child)
                            todo.append(child)
        cpu = {}
        for name, tree in self._trees.items():
            for pid in tree:
                value = process_cpu_seconds(pid)
                if value is not None:
                    self._last[pid] = value
            if self.pids[name] in self._last:
                cpu[name] = sum(self._last.get(pid, 0.0) for pid in tree)
        self.samples.append((now, float(sim), cpu))

    def window(self, start, end):
        """
        Return the figures of the simulated-time window [start, end] s, or None if unsampled.

        ``{'cpu': {name: CPU-s per simulated s}, 'total': sum of those, 'real_time_factor':
        simulated / wall s, 'min_real_time_factor_1s': lowest over 1 s stretches, 'sim_s':
        the window's simulated length, 'wall_s': its wall-clock length}``.
        """
        inside = [s for s in self.samples if start - 1e-9 <= s[1] <= end + 1e-9]
        if len(inside) < 2 or inside[-1][1] <= inside[0][1]:
            return None
        (w0, t0, c0), (w1, t1, c1) = inside[0], inside[-1]
        sim_s = t1 - t0
        cpu = {name: (c1[name] - c0[name]) / sim_s for name in c0 if name in c1}
        lowest = None
        j = 0
        for i, (wa, ta, _) in enumerate(inside):
            while j < len(inside) and inside[j][1] - ta < 1.0:
                j += 1
            if j == len(inside):
                break
            wb, tb, _ = inside[j]
            rtf = (tb - ta) / (wb - wa)
            lowest = rtf if lowest is None else min(lowest, rtf)
        return {'cpu': cpu, 'total': sum(cpu.values()), 'real_time_factor': sim_s / (w1 - w0),
                'min_real_time_factor_1s': lowest, 'sim_s': sim_s, 'wall_s': w1 - w0}

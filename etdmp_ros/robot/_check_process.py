"""
Path checks in a process of their own: :meth:`TrajectoryController.check` without the GIL.

A check solves a few hundred inverse kinematics problems (about 50 ms of Python and Pinocchio,
which holds the GIL throughout). Run in a thread of the controller's process, it holds the GIL
the control thread needs: on a loaded machine the operating system preempts the checking thread
(normal priority) while it holds the lock, and the real-time control thread waits for it until
the scheduler gives that thread the CPU again. No switch interval bounds that wait (a priority
inversion through the GIL): beside a busy-looping process and a flood of junk joint states the
simulation braked 7 times for want of commands while a path was checked.

:class:`CheckProcess` keeps one worker process (:func:`main` in a Python of its own, started
at once and building its model, so that the first path does not wait for either), which holds
its own controller for the current configuration; requests and answers are pickles on its
standard input and output. The calling thread waits for the answer without the GIL. The
worker ends when its input closes, so also when the controller is killed. It costs ~0.7 s of
CPU as the controller starts and ~220 MB of memory. A worker that died is replaced for the next
check and the check that lost it fails with :class:`CheckError` (never an empty reason, which
means valid). No ROS here.
"""

import os
import pickle
import signal
import subprocess
import sys
import threading
from typing import Any, IO

import numpy as np
from numpy.typing import ArrayLike

from ._controller import ControllerConfig, TrajectoryController
from ._trajectory import PoseTrajectory
from ._ur10 import UR10Model

_WORKER = f'import sys; from {__name__} import main; sys.exit(main())'


class CheckError(RuntimeError):
    """The check process could not check a path (it died, or could not start)."""


class _Worker:
    """The worker process and the two pipes to it."""

    def __init__(self, key: bytes) -> None:
        # -c, not -m: the package imports this module before -m would run it.
        self.process = subprocess.Popen([sys.executable, '-c', _WORKER], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE)
        assert self.process.stdin is not None and self.process.stdout is not None
        self.requests: IO[bytes] = self.process.stdin
        self.answers: IO[bytes] = self.process.stdout
        # Build the model now, not at the first path (its URDF takes ~0.7 s to load); the
        # answer is read before the first check's.
        self.unread = 1
        try:
            self._send((key, None, None, 0))
        except OSError:
            pass              # it died at once: the first check says so

    def _send(self, request: tuple[Any, ...]) -> None:
        pickle.dump(request, self.requests)
        self.requests.flush()

    def ask(self, request: tuple[Any, ...]) -> tuple[str, str]:
        """Send one request, return its answer (raises OSError, EOFError if the worker died)."""
        self._send(request)
        while self.unread:
            pickle.load(self.answers)
            self.unread -= 1
        kind, answer = pickle.load(self.answers)
        return kind, answer

    def end(self, timeout: float) -> None:
        """Close its input (it exits); kill it if it has not within ``timeout`` s."""
        try:
            self.requests.close()
        except OSError:
            pass              # it died: its pipe is broken
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.answers.close()


class CheckProcess:
    """
    :meth:`TrajectoryController.check` in a worker process; :meth:`check` is thread-safe.

    ``tool_offset`` and the ``config`` object are read at each check (the controller node
    changes its config's fields in place when a parameter is set).
    """

    def __init__(self, tool_offset: ArrayLike, config: ControllerConfig) -> None:
        """Start the worker process (it imports Pinocchio meanwhile)."""
        self.tool_offset = np.array(tool_offset, dtype=float)
        self.config = config
        self._lock = threading.Lock()
        self._closed = False
        self._worker = _Worker(self._key())

    def _key(self) -> bytes:
        return pickle.dumps((tuple(self.tool_offset), self.config))

    @property
    def pid(self) -> int:
        """Return the worker's process id."""
        return self._worker.process.pid

    def check(self, path: PoseTrajectory, q: ArrayLike, max_samples: int = 200) -> str:
        """Return why ``path`` cannot be executed from ``q``, '' if it can (as the controller)."""
        request = (self._key(), path, np.asarray(q, dtype=float), max_samples)
        with self._lock:
            if self._closed:
                raise CheckError('the check process is closed')
            worker = self._worker
            try:
                kind, answer = worker.ask(request)
            except (OSError, EOFError, pickle.UnpicklingError) as exc:
                worker.process.kill()
                worker.end(0.0)
                self._worker = _Worker(self._key())       # for the next check
                raise CheckError(f'the check process died (exit code '
                                 f'{worker.process.returncode}: {type(exc).__name__})') from None
        if kind != 'ok':
            raise CheckError(f'the check failed in the check process: {answer}')
        return answer

    def close(self) -> None:
        """Stop the worker: its input closes, it exits (killed if it has not within 2 s)."""
        with self._lock:
            self._closed = True
            self._worker.end(2.0)


def _serve(requests: IO[bytes], answers: IO[bytes]) -> int:
    """Answer checks until the input closes."""
    controllers: dict[bytes, TrajectoryController] = {}
    while True:
        try:
            key, path, q, max_samples = pickle.load(requests)
        except EOFError:
            return 0
        try:
            controller = controllers.get(key)
            if controller is None:
                tool_offset, config = pickle.loads(key)
                controllers.clear()       # one configuration at a time (a parameter change)
                controller = controllers[key] = TrajectoryController(
                    UR10Model(tool_offset), config, fast=False)     # checks use no kernels
            answer = ('ok', '' if path is None else controller.check(path, q, max_samples))
        except Exception as exc:   # noqa: B902 - sent back: the controller says the path failed
            answer = ('error', f'{type(exc).__name__}: {exc}')
        pickle.dump(answer, answers)
        answers.flush()


def main() -> int:
    """Run the worker: normal scheduling, no Ctrl-C of its own (the controller stops it)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(os, 'sched_setscheduler') and os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    answers = os.fdopen(os.dup(sys.stdout.fileno()), 'wb')
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())     # a stray print must not corrupt them
    return _serve(sys.stdin.buffer, answers)

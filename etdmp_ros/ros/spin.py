"""
Run nodes until Ctrl-C or SIGTERM, shutting down in order: one implementation for every node.

rclpy's own signal handler shuts the context down at once, so a callback or a thread still at
work then fails to publish (a traceback on Ctrl-C) and the controller could not send its final
zero velocity. Raising KeyboardInterrupt from a handler instead can land inside rclpy's C++
bindings and come out as a RuntimeError. So the handler here only sets a flag, and the executor
spins in short slices that check it; the caller then stops its nodes while the context is alive.

Executor. rclpy's EventsExecutor (``rclpy.experimental``, in Jazzy since rclpy 7.1.4) when it is
there: it dispatches each message from the middleware's event callbacks in C++, where the
SingleThreadedExecutor rebuilds and scans a wait set in Python for every wake-up. Measured on
this machine kind (test/benchmarks/bench_system.py, letter G, medians of 3): with every other
change of the budget in place, the closed loop takes 0.87 cores with it and 1.24 with the
SingleThreadedExecutor; a 125 Hz JointState subscription alone 0.03 against 0.07 cores. It does
not support guard conditions (no node here uses one). ``ETDMP_EXECUTOR=single`` selects the
SingleThreadedExecutor (e.g. to rule the executor out when debugging). rclpy's
MultiThreadedExecutor is never used: next to the simulation's 125 Hz topics it keeps a core busy
(rclpy issues #1223, #1452).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import gc
import os
import signal
import threading
from types import FrameType
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions

EventsExecutor: Any
try:
    from rclpy.experimental import EventsExecutor
except ImportError:   # rclpy before 7.1.4
    EventsExecutor = None

#: Longest time (s) between a signal and the end of spinning.
SLICE = 0.05
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: Environment variable choosing the executor: ``events`` (the default where available) or
#: ``single``.
EXECUTOR_VARIABLE = 'ETDMP_EXECUTOR'
#: Environment variables naming a Fast DDS XML profile file (Fast DDS 2.x, 3.x).
DDS_PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')


def make_executor(context: Context | None = None) -> Executor:
    """Return the executor every node program and tool of this package spins with (above)."""
    choice = os.environ.get(EXECUTOR_VARIABLE, 'events')
    if choice not in ('events', 'single'):
        raise ValueError(f'{EXECUTOR_VARIABLE} must be events or single, got {choice!r}')
    if choice == 'events' and EventsExecutor is not None:
        return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


def use_dds_profile() -> None:
    """
    Have Fast DDS load the package's config/fastdds.xml, unless a profile file is set already.

    Call before the process's first rclpy context; a no-op for another RMW implementation.
    The profile gives the shared-memory transport segments big enough for camera frames (the
    file says why and what it measured).
    """
    if not os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp').startswith('rmw_fastrtps'):
        return
    if any(os.environ.get(name) for name in DDS_PROFILE_VARIABLES):
        return
    from etdmp_ros.ros.paths import config_path
    try:
        os.environ[DDS_PROFILE_VARIABLES[0]] = str(config_path('fastdds.xml'))
    except FileNotFoundError:   # a bare copy of the modules: Fast DDS's defaults
        pass


def init(args: list[str] | None = None) -> None:
    """Initialise rclpy (with the package's DDS profile) without its signal handlers."""
    use_dds_profile()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)


def spin_until_signal(nodes: Sequence[Node], stop: threading.Event | None = None) -> None:
    """
    Spin ``nodes`` on one executor (:func:`make_executor`) until SIGINT or SIGTERM.

    Also returns when rclpy shuts down, or at once if ``stop`` (a threading.Event) is already
    set. On return, further SIGINT/SIGTERM are ignored, so a second Ctrl-C cannot interrupt the
    caller's clean-up (stopping the simulation, sending zero velocity, destroying the nodes).
    """
    event = threading.Event() if stop is None else stop

    def request_stop(signum: int, frame: FrameType | None) -> None:
        event.set()

    for signum in SIGNALS:
        signal.signal(signum, request_stop)
    executor = make_executor()
    try:
        for node in nodes:
            executor.add_node(node)
        while not event.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=SLICE)
    finally:
        for signum in SIGNALS:
            signal.signal(signum, signal.SIG_IGN)
        for node in nodes:
            executor.remove_node(node)


def freeze_heap() -> None:
    """
    Collect garbage once, then exempt every object alive now from Python's cycle collector.

    A node's heap after start-up (rclpy, numpy, Pinocchio, numba, MuJoCo, OpenCV, the learned
    skills) holds 80 000-130 000 objects that live as long as the process, and each full
    collection traversed all of them: 17 ms (perception) to 50 ms (dmp_server, controller) on
    this machine kind, up to six control periods (``test/benchmarks/bench_system.py
    --gc-pauses``). Frozen (gc.freeze), they are never traversed again (a full collection then
    takes well under 0.1 ms); objects made later are collected as usual. A full collection runs
    only when many objects have survived the younger generations, which is why the demo's
    figures seldom show one.
    """
    gc.collect()
    gc.freeze()


#: Seconds of messages a publisher at the control rate keeps for its reliable readers.
HISTORY_SECONDS = 1.0


def rate_qos(rate: float) -> QoSProfile:
    """
    Return the QoS of a reliable publisher at ``rate`` Hz: a history of :data:`HISTORY_SECONDS`.

    A reliable writer whose history is full of samples that some reader has not acknowledged
    yet waits in ``publish()`` for that reader, up to the DDS default max_blocking_time of
    0.1 s (Fast DDS, StatefulWriter::try_remove_change). With rclpy's usual depth of 10, one
    reader starved of CPU for 80 ms at 125 Hz (the demo's recorder, dmp_server, next to busy
    processes) blocked the simulation's /joint_states for 100 ms and tripped the controller's
    0.1 s watchdog. A second of history leaves a slow reader that much time; the samples are
    a few hundred bytes.
    """
    return QoSProfile(depth=max(10, int(round(rate * HISTORY_SECONDS))))


def set_realtime_priority(priority: int) -> str:
    """
    Put the calling thread under SCHED_FIFO at ``priority`` (1-99); 0 changes nothing.

    Only this thread: the one that spins the executor, as ros2_control raises only its update
    loop. The middleware's threads (Fast DDS receives in threads of its own) keep normal
    scheduling; threads this one starts later inherit the policy (the EventsExecutor's timer
    thread; :func:`normal_scheduling` lets a worker give it up). Needs CAP_SYS_NICE or an
    rtprio limit (``ulimit -r``, /etc/security/limits.conf) of at least ``priority``. Returns
    '' on success, else why not (and changes nothing). The kernel keeps 5 % of each second for
    other tasks (``sched_rt_runtime_us``), so a runaway thread cannot lock the machine up.
    """
    if priority == 0:
        return ''
    if not hasattr(os, 'sched_setscheduler'):
        return 'this platform has no SCHED_FIFO'
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return f'SCHED_FIFO priority {priority} refused ({exc.strerror})'
    return ''


def normal_scheduling() -> None:
    """Return the calling thread to normal scheduling (SCHED_OTHER), e.g. a worker thread."""
    if hasattr(os, 'sched_getscheduler') and os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def run(make_nodes: Callable[[list[Node]], None], name: str, args: list[str] | None = None,
        startup_errors: tuple[type[Exception], ...] = ()) -> int:
    """
    Run a node program: init, create the nodes, spin until a signal, stop them in order.

    ``make_nodes(nodes)`` creates the nodes and appends each to ``nodes`` as soon as it exists
    (so a failure half-way still cleans up the others). On exit, every node that has them gets
    ``send_zeros()`` (the controller: zero velocity while the context is alive) and ``stop()``
    (the simulation's thread), in reverse order, then is destroyed. A ValueError or
    ParameterException (or one of ``startup_errors``) while creating the nodes is a bad
    configuration: logged as FATAL without a traceback, exit code 1. Returns the exit code.
    """
    from rclpy.exceptions import ParameterException
    bad_configuration: tuple[type[Exception], ...] = (ValueError, ParameterException,
                                                      *startup_errors)
    init(args)
    nodes: list[Node] = []
    code = 0
    # A signal during start-up is remembered, not raised: a KeyboardInterrupt raised inside a
    # library callback (numba compiling the controller's kernels calls back from C) is printed
    # and dropped there, and the program would go on running. Spinning then ends at once.
    stop = threading.Event()
    for signum in SIGNALS:
        signal.signal(signum, lambda signum, frame: stop.set())
    try:
        make_nodes(nodes)
        freeze_heap()
        spin_until_signal(nodes, stop)
    except KeyboardInterrupt:   # Ctrl-C before our handler was installed (during start-up)
        pass
    except bad_configuration as exc:
        rclpy.logging.get_logger(name).fatal(f'cannot start: {exc}')
        code = 1
    finally:
        for signum in SIGNALS:
            signal.signal(signum, signal.SIG_IGN)
        for node in reversed(nodes):
            for hook in ('send_zeros', 'stop'):
                if hasattr(node, hook):
                    getattr(node, hook)()
            code = code or int(bool(getattr(node, 'failed', False)))
            node.destroy_node()
        rclpy.try_shutdown()
    return code

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

from collections.abc import Callable, Iterator, Mapping, Sequence
import contextlib
import faulthandler
import gc
import os
from pathlib import Path
import signal
import tempfile
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


#: Set beside them to the same file when the file is this package's choice, so that a process
#: started from this one (the camera of ur10_sim) chooses again for itself.
DDS_PROFILE_MARK = 'ETDMP_DDS_PROFILE'
#: The package's Fast DDS profiles in config/ by (shared memory, localhost-only discovery).
DDS_PROFILES = {(True, False): 'fastdds.xml', (False, False): 'fastdds_udp.xml',
                (True, True): 'fastdds_localhost.xml',
                (False, True): 'fastdds_udp_localhost.xml'}
DISCOVERY_RANGE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
#: SCHED_FIFO priority of the Fast DDS UDP reception threads of a real-time node (ur10_sim, the
#: controller): under its real-time thread (thread_priority 50 and 60), above every normal one.
RECEPTION_PRIORITY = 49
_PROFILES_NS = 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'


def _localhost_only(environ: Mapping[str, str]) -> bool:
    """Return whether rcl will use localhost-only discovery without static peers."""
    if environ.get('ROS_LOCALHOST_ONLY') == '1':
        return True     # rcl then ignores ROS_STATIC_PEERS
    return (environ.get(DISCOVERY_RANGE) == 'LOCALHOST'
            and not environ.get('ROS_STATIC_PEERS', '').strip(';'))


def dds_profile(shared_memory: bool = True, environ: Mapping[str, str] | None = None,
                realtime: bool = False) -> Path | None:
    """
    Return the package's Fast DDS profile file for a process (a Path), None to keep another.

    ``shared_memory``: the process receives or sends camera images (perception, the camera,
    teach, tools recording them); the others (ur10_sim, controller, dmp_server) talk UDP only,
    so that no send of theirs can wait for another process (docs/reliability.md). None when
    FASTRTPS_DEFAULT_PROFILES_FILE (or FASTDDS_...) names a file that is not the package's
    choice, when the RMW is not Fast DDS, or when the package has no config/ folder.
    ``realtime``: a node with a real-time thread; where this process may use SCHED_FIFO, the
    profile with real-time reception threads (:func:`realtime_profile`).
    """
    environ = os.environ if environ is None else environ
    if not environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp').startswith('rmw_fastrtps'):
        return None
    mark = environ.get(DDS_PROFILE_MARK)
    if any(environ.get(name) and environ.get(name) != mark for name in DDS_PROFILE_VARIABLES):
        return None
    from etdmp_ros.ros.paths import config_path
    try:
        path = config_path(DDS_PROFILES[bool(shared_memory), _localhost_only(environ)])
    except FileNotFoundError:   # a bare copy of the modules: Fast DDS's defaults
        return None
    return realtime_profile(path) if realtime and may_use_realtime() else path


def may_use_realtime(priority: int = RECEPTION_PRIORITY) -> bool:
    """Return whether this process may put a thread under SCHED_FIFO at ``priority``."""
    result: list[str] = []
    # In a short-lived thread: set_realtime_priority changes the calling thread only.
    thread = threading.Thread(target=lambda: result.append(set_realtime_priority(priority)),
                              name='fifo_probe')
    thread.start()
    thread.join()
    return result == ['']


def realtime_profile(path: Path) -> Path:
    """
    Return ``path``'s profile with its UDP reception threads under SCHED_FIFO, written once.

    A real-time thread that takes a message waits for the reader's lock, which the reception
    thread holds while it stores one; with the reception thread under normal scheduling, a
    busy machine can keep it off the CPU while holding that lock, and the real-time thread
    waits with it (a priority inversion): under a flood of 13 000 junk joint states a second
    the controller missed 70 ms of control steps and the simulation's watchdog braked (2 runs
    of 5); with its reception threads at :data:`RECEPTION_PRIORITY`, 250 of 250 steps (10 of
    10). Written from the package's file, so there is one description of the transports, into
    a folder of this user's own in the system's temporary folder; ``path`` itself where that
    folder is not this user's or cannot be written.
    """
    from xml.etree import ElementTree
    ElementTree.register_namespace('', _PROFILES_NS)
    tree = ElementTree.parse(path)
    ns = f'{{{_PROFILES_NS}}}'
    for descriptor in tree.getroot().iter(f'{ns}transport_descriptor'):
        if descriptor.findtext(f'{ns}type') == 'UDPv4':
            threads = ElementTree.SubElement(descriptor, f'{ns}default_reception_threads')
            ElementTree.SubElement(threads, f'{ns}scheduling_policy').text = str(os.SCHED_FIFO)
            ElementTree.SubElement(threads, f'{ns}priority').text = str(RECEPTION_PRIORITY)
    folder = Path(tempfile.gettempdir()) / f'etdmp_ros-{os.getuid()}'
    target = folder / f'{path.stem}_realtime.xml'
    text = ElementTree.tostring(tree.getroot(), encoding='unicode')
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        if folder.is_symlink() or folder.stat().st_uid != os.getuid():
            return path
        if not target.is_file() or target.read_text(encoding='utf-8') != text:
            scratch = folder / f'.{target.name}.{os.getpid()}'
            scratch.write_text(text, encoding='utf-8')
            os.replace(scratch, target)      # whole, also with another node writing it too
    except OSError:
        return path
    return target


def use_dds_profile(shared_memory: bool = True, realtime: bool = False) -> Path | None:
    """
    Have Fast DDS load the package's profile (:func:`dds_profile`); return its path or None.

    Call before the process's first rclpy context; a no-op for another RMW implementation or
    when the user names a profile file. The profiles give the shared-memory transport segments
    big enough for camera frames, or leave shared memory out (the files say why).
    """
    path = dds_profile(shared_memory, realtime=realtime)
    if path is not None:
        for name in DDS_PROFILE_VARIABLES:
            os.environ.pop(name, None)
        os.environ[DDS_PROFILE_VARIABLES[0]] = os.environ[DDS_PROFILE_MARK] = str(path)
    return path


@contextlib.contextmanager
def dds_settings(shared_memory: bool = True, realtime: bool = False) -> Iterator[list[str]]:
    """
    Prepare the middleware for an rclpy.init inside: the DDS profile, /dev/shm cleaned.

    Removes the shared-memory files of processes that died without cleaning up
    (:func:`etdmp_ros.ros.fastdds_files.clean`) and loads the package's profile
    (:func:`use_dds_profile`). Under localhost-only discovery rmw_fastrtps would add a
    shared-memory transport of its own to the profile's, so the profile carries the localhost
    discovery itself (config/fastdds*_localhost.xml) and rcl sees SYSTEM_DEFAULT inside this
    block; the environment is as before after it. Yields the names of the files removed.
    """
    removed: list[str] = []
    if os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp').startswith('rmw_fastrtps'):
        from etdmp_ros.ros import fastdds_files
        removed = fastdds_files.clean()
    path = use_dds_profile(shared_memory, realtime)
    translate = path is not None and '_localhost' in path.stem
    saved = {name: os.environ.get(name) for name in (DISCOVERY_RANGE, 'ROS_LOCALHOST_ONLY')}
    if translate:
        os.environ[DISCOVERY_RANGE] = 'SYSTEM_DEFAULT'
        os.environ.pop('ROS_LOCALHOST_ONLY', None)
    try:
        yield removed
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def cleaned_message(removed: Sequence[str]) -> str:
    """Return the log line about the files :func:`dds_settings` removed or locked ('' if none)."""
    from etdmp_ros.ros import fastdds_files
    kept = fastdds_files.quarantined()
    lines = []
    if removed:
        lines.append(f'removed {len(removed)} Fast DDS shared-memory files that processes '
                     'killed earlier had left in /dev/shm (docs/reliability.md)')
    if kept:
        lines.append(f'locked the shared-memory ports of killed readers that live writers still '
                     f'use ({", ".join(kept)}): no reader takes their numbers again')
    return '; '.join(lines)


def init(args: list[str] | None = None, shared_memory: bool = True, realtime: bool = False
         ) -> list[str]:
    """
    Initialise rclpy (with the package's DDS profile) without its signal handlers.

    Returns the names of the stale shared-memory files removed first (:func:`dds_settings`).
    """
    with dds_settings(shared_memory, realtime) as removed:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    return removed


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
    loop. The middleware's threads are not changed here (Fast DDS's UDP reception threads get
    theirs from the profile, :func:`realtime_profile`); threads this one starts later inherit
    the policy (the EventsExecutor's timer thread; :func:`normal_scheduling` lets a worker give
    it up). Needs CAP_SYS_NICE or an rtprio limit (``ulimit -r``, /etc/security/limits.conf)
    of at least ``priority``. Returns '' on success, else why not (and changes nothing). The
    kernel keeps 5 % of each second for other tasks (``sched_rt_runtime_us``), so a runaway
    thread cannot lock the machine up.
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


def _start(name: str, args: list[str] | None, shared_memory: bool | None) -> None:
    """Prepare the process of node ``name`` as :func:`run` says, up to rclpy.init."""
    from etdmp_ros.ros import system
    try:
        spec = system.node(name)
    except KeyError:
        spec = None
    if shared_memory is None:
        shared_memory = True if spec is None else spec.shared_memory
    # A node with a real-time thread (ur10_sim, the controller) gets real-time reception.
    realtime = spec is not None and any(p.name == 'thread_priority'
                                        for p in spec.all_parameters)
    # A node that does not stop when told: its launcher asks for the stacks before the kill.
    from etdmp_ros.ros.processes import STACKS_SIGNAL
    faulthandler.register(STACKS_SIGNAL, all_threads=True)
    message = cleaned_message(init(args, shared_memory, realtime))
    if message:
        rclpy.logging.get_logger(name).info(message)


def run(make_nodes: Callable[[list[Node]], None], name: str, args: list[str] | None = None,
        startup_errors: tuple[type[Exception], ...] = (), shared_memory: bool | None = None
        ) -> int:
    """
    Run a node program: init, create the nodes, spin until a signal, stop them in order.

    ``make_nodes(nodes)`` creates the nodes and appends each to ``nodes`` as soon as it exists
    (so a failure half-way still cleans up the others). On exit, every node that has them gets
    ``send_zeros()`` (the controller: zero velocity while the context is alive) and ``stop()``
    (the simulation's thread), in reverse order, then is destroyed. A ValueError or
    ParameterException (or one of ``startup_errors``) while creating the nodes is a bad
    configuration: logged as FATAL without a traceback, exit code 1. Returns the exit code.
    ``shared_memory``: see :func:`dds_profile`; None: as the system description says of the
    node called ``name`` (:attr:`etdmp_ros.ros.system.NodeSpec.shared_memory`; True for others).
    """
    from rclpy.exceptions import ParameterException
    bad_configuration: tuple[type[Exception], ...] = (ValueError, ParameterException,
                                                      *startup_errors)
    _start(name, args, shared_memory)
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

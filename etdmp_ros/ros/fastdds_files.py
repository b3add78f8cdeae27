"""
Fast DDS's shared-memory files in /dev/shm: which are whose, and removing those of dead processes.

A process using Fast DDS's shared-memory transport keeps its files there while it runs and
removes them when it shuts down cleanly; killed (SIGKILL, a crash, a power cut of the process),
it leaves them. The files and how Fast DDS 2.14 (ROS 2 Jazzy) tells a live owner from a dead
one:

- ``fastrtps_<16 hex>``: a participant's segment, the buffers it writes; its creator holds an
  exclusive ``flock`` on ``fastrtps_<16 hex>_el`` for its whole life.
- ``fastrtps_port<N>``: a port, the queue readers listen on; its reader holds ``..._el``
  (one reader) or a shared lock on ``..._sl`` (several). ``sem.fastrtps_port<N>_mutex`` is the
  POSIX semaphore Fast DDS uses as the port's mutex between processes, taken while a process
  opens, checks or closes the port.
- ``fast_datasharing_*``: data-sharing pools (no lock files; rmw_fastrtps does not use data
  sharing for this package's topics, and :func:`clean` leaves them alone).

:func:`clean` removes what belongs to dead processes, deciding as ``fastdds shm clean`` does
(a segment or port whose lock file nobody holds; but a killed reader's port that a live writer
still maps is locked for this process's life instead, so that no new reader takes its number
while the writer goes on sending into that file), and beyond it: a port with no lock file at all
that no live process maps, i.e. without a reader (its reader exited cleanly while a killed
writer's reference kept the file; the next reader of that number would reuse it with its stale
health-check state), taken under the port's mutex as Fast DDS opens ports (while a live writer
maps it, it is kept: the writer goes on sending into that file, and the next reader must find
it there); and a port semaphore that is taken while no
process has it mapped (its holder died holding it: every process opening that port would wait
2 s for it). Why such files froze the robot, and what the nodes do about it:
docs/reliability.md.

:func:`lock_owners` and :func:`mappers` say which processes hold or map which files (the test
suite's check that nothing it started leaves a file behind). Linux only; elsewhere there are
no such files and everything here returns empty. No ROS here.
"""

import contextlib
import ctypes
import ctypes.util
import errno
import fcntl
import os
from pathlib import Path
import re
import time

SHM_DIR = Path('/dev/shm')
#: Files younger than this (s) are never removed: a process may be between creating one and
#: locking or mapping it.
GRACE = 1.0

_SEGMENT = re.compile(r'fastrtps_[0-9a-z]{16}')
_PORT = re.compile(r'fastrtps_port(\d+)')
_MUTEX = re.compile(r'sem\.fastrtps_port(\d+)_mutex')
_LOCK_SUFFIXES = ('_el', '_sl')
_DATASHARING = 'fast_datasharing_'


def kind(name):
    """
    Return what the /dev/shm file ``name`` is to Fast DDS, or None if it is not Fast DDS's.

    One of ``segment``, ``port``, ``lock`` (a segment's or port's ``_el``/``_sl``), ``mutex``
    (a port's semaphore), ``datasharing``.
    """
    if _SEGMENT.fullmatch(name):
        return 'segment'
    if _PORT.fullmatch(name):
        return 'port'
    if name.endswith(_LOCK_SUFFIXES) and (_SEGMENT.fullmatch(name[:-3])
                                          or _PORT.fullmatch(name[:-3])):
        return 'lock'
    if _MUTEX.fullmatch(name):
        return 'mutex'
    if name.startswith(_DATASHARING):
        return 'datasharing'
    return None


def listing(directory=SHM_DIR):
    """Return ``{name: os.stat_result}`` of the Fast DDS files in ``directory``."""
    files = {}
    try:
        names = os.listdir(directory)
    except OSError:
        return files
    for name in names:
        if kind(name) is None:
            continue
        try:
            files[name] = os.stat(directory / name)
        except FileNotFoundError:
            pass
    return files


def lock_held(path):
    """
    Return whether some process holds a ``flock`` on ``path`` (False if it does not exist).

    Probes as Fast DDS does: an exclusive non-blocking lock, released at once.
    """
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            return True
        raise
    finally:
        os.close(fd)   # closing releases the probe's lock
    return False


def _pids():
    return [int(p) for p in os.listdir('/proc') if p.isdigit()]


def mappers(directory=SHM_DIR, pids=None):
    """
    Return ``{name: {pid, ...}}``: which processes map which files of ``directory``.

    ``pids``: only these processes (default: all). A process whose memory map cannot be read
    (another user's, or one that is not dumpable) counts as mapping nothing.
    """
    prefix = f'{directory}/'
    found = {}
    for pid in _pids() if pids is None else pids:
        try:
            with open(f'/proc/{pid}/maps') as maps:
                for line in maps:
                    at = line.find(prefix)
                    if at >= 0:
                        name = line[at + len(prefix):].rstrip('\n')
                        name = name.removesuffix(' (deleted)')
                        found.setdefault(name, set()).add(pid)
        except (FileNotFoundError, PermissionError, ProcessLookupError):
            continue        # ended meanwhile, or not ours to read
    return found


def lock_owners(directory=SHM_DIR):
    """Return ``{inode: {pid, ...}}`` of the flock locks held on files of ``directory``."""
    try:
        device = os.stat(directory).st_dev
        with open('/proc/locks') as f:
            lines = f.read().splitlines()
    except OSError:
        return {}
    major, minor = os.major(device), os.minor(device)
    owners = {}
    for line in lines:
        fields = line.split()
        if '->' in fields or len(fields) < 6 or fields[1] != 'FLOCK':
            continue
        try:
            pid = int(fields[4])
            dev_major, dev_minor, inode = fields[5].split(':')
            if (int(dev_major, 16), int(dev_minor, 16)) != (major, minor):
                continue
            owners.setdefault(int(inode), set()).add(pid)
        except ValueError:
            continue
    return owners


class _Semaphores:
    """POSIX named semaphores through libc: Fast DDS's port mutexes (boost's named_mutex)."""

    def __init__(self):
        libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6', use_errno=True)
        self._open = libc.sem_open
        self._open.restype = ctypes.c_void_p
        self._open.argtypes = [ctypes.c_char_p, ctypes.c_int]
        self._getvalue = libc.sem_getvalue
        self._getvalue.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)]
        self._trywait = libc.sem_trywait
        self._trywait.argtypes = [ctypes.c_void_p]
        self._post = libc.sem_post
        self._post.argtypes = [ctypes.c_void_p]
        self._close = libc.sem_close
        self._close.argtypes = [ctypes.c_void_p]

    def _handle(self, name):
        sem = self._open(b'/' + name.encode(), 0)
        return None if not sem or sem == ctypes.c_void_p(-1).value else sem

    def taken(self, name):
        """Return whether the semaphore ``sem.<name>`` is at 0 (its mutex held), None if gone."""
        sem = self._handle(name)
        if sem is None:
            return None
        try:
            value = ctypes.c_int()
            if self._getvalue(sem, ctypes.byref(value)) != 0:
                return None
            return value.value <= 0
        finally:
            self._close(sem)

    @contextlib.contextmanager
    def holding(self, name):
        """
        Take the mutex ``sem.<name>`` without waiting, as Fast DDS takes it to open a port.

        Yields True if taken (released on exit), False if another process holds it, None if
        there is no such semaphore.
        """
        sem = self._handle(name)
        if sem is None:
            yield None
            return
        try:
            if self._trywait(sem) != 0:
                yield False
                return
            try:
                yield True
            finally:
                self._post(sem)
        finally:
            self._close(sem)


def _quarantine(lock):
    """Hold ``lock`` (a port's ``_el``) for this process's life: no reader takes its number."""
    if lock.name in _QUARANTINED:
        return
    try:
        fd = os.open(lock, os.O_RDWR)
    except FileNotFoundError:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)          # a new reader took it first: it is alive again
        return
    _QUARANTINED[lock.name] = fd


def quarantined():
    """Return the names of the port locks this process holds for killed readers (:func:`clean`)."""
    return sorted(_QUARANTINED)


def release():
    """Let go of the ports :func:`clean` locked (their files: the next cleaning's)."""
    while _QUARANTINED:
        os.close(_QUARANTINED.popitem()[1])


def _remove(directory, names, removed):
    for name in names:
        try:
            os.unlink(directory / name)
            removed.append(name)
        except FileNotFoundError:
            pass


def stale(directory=SHM_DIR, now=None):
    """
    Return ``[(names, reason)]``: the Fast DDS files in ``directory`` whose processes are gone.

    Only this user's files older than :data:`GRACE`; see the module's docstring for the rules.
    """
    now = time.time() if now is None else now
    files = {n: s for n, s in listing(directory).items()
             if s.st_uid == os.getuid() and now - s.st_mtime > GRACE}
    groups = []
    maps = None

    def unmapped(name):
        nonlocal maps
        if maps is None:
            maps = mappers(directory)
        return name not in maps

    taken = set()
    for name in files:
        k = kind(name)
        if k == 'segment' or (k == 'lock' and _SEGMENT.fullmatch(name[:-3])):
            segment = name if k == 'segment' else name[:-3]
            if segment in taken:
                continue
            lock = f'{segment}_el'
            if (directory / lock).exists():
                if not lock_held(directory / lock):
                    groups.append(([segment, lock], 'segment lock not held'))
                    taken.add(segment)
            elif k == 'segment' and unmapped(segment):
                groups.append(([segment], 'segment without lock, not mapped'))
                taken.add(segment)
        elif k in ('port', 'lock', 'mutex'):
            port_name = name[:-3] if k == 'lock' else name
            number = (_MUTEX.fullmatch(name) or _PORT.fullmatch(port_name)).group(1)
            if number in taken:
                continue
            taken.add(number)
            group = _stale_port(directory, number, files, unmapped)
            if group:
                groups.append(group)
    return groups


def _stale_port(directory, number, files, unmapped):
    """Return ``(names, reason)`` if port ``number``'s files are a dead process's, else None."""
    port = f'fastrtps_port{number}'
    locks = [f'{port}{s}' for s in _LOCK_SUFFIXES if (directory / f'{port}{s}').exists()]
    mutex = f'sem.{port}_mutex'
    every = [port, *[f'{port}{s}' for s in _LOCK_SUFFIXES], mutex]
    if any(lock_held(directory / lock) for lock in locks):
        # A live reader: only its semaphore can be stale (taken, and its holder gone).
        if mutex in files and _semaphores().taken(mutex[4:]) and unmapped(mutex):
            return [mutex], 'port mutex taken by a dead process'
        return None
    if locks:
        present = (directory / port).exists()
        if f'{port}_el' in locks and present and not unmapped(port):
            # Its reader was killed and a live writer still sends into this file. Removed, the
            # next reader of that number would make a new file that the writer never opens:
            # it goes on sending into this one (Fast DDS notices a dead reader only if it
            # died waiting, not while it handled a message). Locked, no reader takes this
            # number again and the writer opens the new reader's port afresh (clean). The
            # file's age does not matter: a writer that finds the port broken makes it anew.
            return [f'{port}_el'], QUARANTINE
        if present and port not in files:
            return None         # made a moment ago: its maker may not have mapped it yet
        return every, 'port lock not held'
    if port in files:
        # No reader at all (readers lock for life): a reader that exited cleanly while a
        # killed writer's reference kept the file. Removed under the port's mutex (clean).
        if not unmapped(port):
            # A live writer still has it open and would go on sending into the removed file
            # (Fast DDS keeps a port open once it sent to it): the next reader must reuse it.
            return None
        if mutex in files and _semaphores().taken(mutex[4:]) and unmapped(mutex):
            return every, 'port without reader, its mutex taken by a dead process'
        return every, 'port without reader'
    if mutex in files and not (directory / port).exists() and unmapped(mutex):
        return [mutex], 'port mutex without port'
    return None


_SEMAPHORES: list['_Semaphores'] = []
#: The reason :func:`stale` gives a killed reader's port that a live process still maps.
QUARANTINE = 'port of a killed reader, a live writer maps it'
#: ``{lock file name: descriptor}`` of the ports this process keeps locked (:func:`clean`).
_QUARANTINED: dict[str, int] = {}


def _semaphores():
    if not _SEMAPHORES:
        _SEMAPHORES.append(_Semaphores())
    return _SEMAPHORES[0]


def clean(directory=SHM_DIR):
    """
    Remove the Fast DDS files of dead processes from ``directory``; return the names removed.

    Safe to run while other Fast DDS programs run: held lock files, files younger than
    :data:`GRACE` seconds and a reader-less port that some process is opening (its mutex
    taken) are kept. Never raises for a file another process removes first.
    """
    if not directory.is_dir():
        return []
    removed = []
    for names, reason in stale(directory):
        if reason == QUARANTINE:
            _quarantine(directory / names[0])
            continue
        if reason == 'port without reader':
            # Fast DDS opens a port holding its mutex: holding it here, no process can be
            # between finding this file and locking it as its reader.
            mutex = names[-1]
            with _semaphores().holding(mutex[4:]) as held:
                if held is False or any(lock_held(directory / n) for n in names[1:3]):
                    continue
                _remove(directory, names, removed)
            continue
        _remove(directory, names, removed)
    return removed

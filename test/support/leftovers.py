"""
What the test suite starts must not outlive it: processes, and Fast DDS files in /dev/shm.

:class:`Leftovers` (conftest: from ``pytest_configure`` to ``pytest_sessionfinish``) makes the
pytest process the child subreaper of everything it starts, so that a process whose parent died
(``ros2 launch``'s nodes, a ``ros2 daemon``) stays its descendant, and marks the environment
(``ETDMP_TEST_SESSION``) for processes started with a copy of it. A thread notes, every
:data:`POLL` seconds, the /dev/shm files that the suite's processes hold (flock, /proc/locks) or
map (/proc/<pid>/maps), by name and inode. At the end, a process of the suite still alive, or
such a file still there (same inode) and used by no live process, is a leftover: the run fails
naming them, and they are killed and removed. Other sessions on the machine make and leave
such files too: only files the suite's own processes were seen using count.
"""

import ctypes
import os
from pathlib import Path
import signal
import threading
import time
import uuid

from etdmp_ros.ros import fastdds_files

#: Seconds between two looks at which files the suite's processes use.
POLL = 0.5
SESSION_VARIABLE = 'ETDMP_TEST_SESSION'
_PR_SET_CHILD_SUBREAPER = 36


def descendants(root):
    """Return the pids of the live (not zombie) processes below ``root``."""
    found, todo = set(), [root]
    while todo:
        pid = todo.pop()
        try:
            tasks = os.listdir(f'/proc/{pid}/task')
        except OSError:
            continue
        for task in tasks:
            try:    # /proc/<pid>/task/<tid>/children: the children each thread started
                children = Path(f'/proc/{pid}/task/{task}/children').read_text().split()
            except OSError:
                continue
            for child in map(int, children):
                if child not in found:
                    found.add(child)
                    todo.append(child)
    return {pid for pid in found if _state(pid) not in ('Z', None)}


def _state(pid):
    try:
        stat = Path(f'/proc/{pid}/stat').read_text()
    except OSError:
        return None
    return stat[stat.rindex(')') + 2:].split()[0]


def marked(token):
    """Return the pids of live processes whose environment carries the session's ``token``."""
    needle = f'{SESSION_VARIABLE}={token}'.encode()
    pids = set()
    for entry in os.listdir('/proc'):
        if entry.isdigit() and int(entry) != os.getpid():
            try:
                if needle in Path(f'/proc/{entry}/environ').read_bytes().split(b'\0'):
                    pids.add(int(entry))
            except OSError:
                continue
    return {pid for pid in pids if _state(pid) not in ('Z', None)}


def _describe(pid):
    try:
        return Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ').decode()[:200]
    except OSError:
        return '?'


class Leftovers:
    """Watch what the suite starts; :meth:`finish` returns what it left behind."""

    def __init__(self):
        """Become the subreaper, mark the environment, start noting the files in use."""
        self.root = os.getpid()
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
        except (OSError, AttributeError):
            pass     # not Linux: orphans escape the tree, the environment mark still finds them
        self.token = os.environ.setdefault(SESSION_VARIABLE, uuid.uuid4().hex)
        self.ours = {}          # (name, inode) -> a description of who used it
        self.test = None        # the test running (conftest), named in the descriptions
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True, name='leftovers')
        self._thread.start()

    def _watch(self):
        while not self._stop.wait(POLL):
            self.note()

    def note(self):
        """Note the /dev/shm files the suite's processes hold or map now."""
        pids = descendants(self.root)
        if not pids:
            return
        files = fastdds_files.listing()
        by_inode = {stat.st_ino: name for name, stat in files.items()}
        for inode, holders in fastdds_files.lock_owners().items():
            if inode in by_inode and holders & pids and (by_inode[inode], inode) not in self.ours:
                self.ours[by_inode[inode], inode] = self._who('locked', holders)
        for name, users in fastdds_files.mappers(pids=pids).items():
            if name in files and (name, files[name].st_ino) not in self.ours:
                self.ours[name, files[name].st_ino] = self._who('mapped', users)

    def _who(self, how, pids):
        """Describe the processes using a file, and when (so that a leftover can be traced)."""
        names = ', '.join(f'{pid} {_describe(pid)[:80]}' for pid in sorted(pids))
        return f'{how} by {names}; seen first during {self.test}'

    def finish(self):
        """
        Stop watching; kill the suite's processes still alive, remove its files still there.

        Returns the lines describing them ([] if nothing was left behind).
        """
        self._stop.set()
        self._thread.join(timeout=5)
        fastdds_files.release()      # the ports this process locked for killed readers
        self.note()
        problems = []
        alive = descendants(self.root) | marked(self.token)
        for pid in sorted(alive):
            problems.append(f'process {pid} still running: {_describe(pid)}')
        for pid in alive:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + 5.0
        while alive and time.monotonic() < deadline:
            for pid in list(alive):
                try:
                    if os.waitpid(pid, os.WNOHANG)[0] == pid:
                        alive.discard(pid)
                except ChildProcessError:
                    if not Path(f'/proc/{pid}').exists():
                        alive.discard(pid)
            time.sleep(0.05)
        files = fastdds_files.listing()
        held = fastdds_files.lock_owners()
        maps = fastdds_files.mappers()
        for (name, inode), who in sorted(self.ours.items()):
            if name not in files or files[name].st_ino != inode:
                continue
            if held.get(inode) or maps.get(name) or _live_port_mutex(name, files, held, maps):
                continue          # in use again: another process took it over
            problems.append(f'/dev/shm/{name} left behind (it was {who})')
            try:
                os.unlink(fastdds_files.SHM_DIR / name)
            except FileNotFoundError:
                pass
        return problems


def _live_port_mutex(name, files, held, maps):
    """
    Return whether ``name`` is the semaphore of a port some process uses now.

    Fast DDS maps a port's semaphore only while it opens or closes the port, and removes it
    only with the port: a port of a killed process that a later participant (of any domain or
    session: the numbers are the machine's) took over keeps the same semaphore file, unmapped,
    for that participant's life. It is not a leftover then (and must not be removed).
    """
    if fastdds_files.kind(name) != 'mutex':
        return False
    port = name.removeprefix('sem.').removesuffix('_mutex')
    if maps.get(port):
        return True
    return any(held.get(files[lock].st_ino) for lock in (f'{port}_el', f'{port}_sl')
               if lock in files)

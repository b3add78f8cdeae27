"""
Waiting in the node and system tests: on the condition itself, with a deadline.

A fixed ``time.sleep`` before an assertion is either too short on a loaded machine (the test
fails for nothing) or too long everywhere else (the suite is slow). :func:`wait_for` returns as
soon as what the test waits for has happened and fails naming it when it has not. A sleep that
remains in a test is the subject of the test (a silence that must trigger a watchdog, a window
in which nothing may arrive, a pace) and says so in a comment.
"""

import time


def _exit_code(process):
    """Return the exit code of a ``subprocess.Popen`` or a node process, None while it runs."""
    poll = getattr(process, 'poll', None)
    return poll() if callable(poll) else process.returncode


def _tail(process, chars=3000):
    """Return the end of a process's log, '' when it has none."""
    log = getattr(process, 'log', None)
    return log()[-chars:] if callable(log) else ''


def wait_for(predicate, timeout, what, processes=(), period=0.02, details=None):
    """
    Poll ``predicate()`` until it returns a true value; return that value.

    Fail (AssertionError) naming ``what`` once ``timeout`` s have passed, or as soon as one of
    ``processes`` has exited: a ``subprocess.Popen``, a node process (``returncode``, ``log()``;
    the end of its log is in the message) or a set of them (``check_alive()``, which raises
    itself). ``details()``, if given, adds what the test saw (e.g. the last statuses) to the
    message. ``period``: seconds between polls (longer for a predicate that runs a command).
    """
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        for process in processes:
            if callable(getattr(process, 'check_alive', None)):
                process.check_alive()
                continue
            code = _exit_code(process)
            if code is not None:
                raise AssertionError(f'waiting for {what}: a process exited with code {code}:\n'
                                     f'{_tail(process)}')
        if time.monotonic() > deadline:
            seen = f'; {details()}' if details is not None else ''
            logs = ''.join(f'\n{_tail(p)}' for p in processes)
            raise AssertionError(f'timed out after {timeout:g} s waiting for {what}{seen}{logs}')
        time.sleep(period)

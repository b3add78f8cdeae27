"""The scheduling of a process's threads, read from /proc (the real-time nodes' tests)."""

import os


def scheduling(pid):
    """Return ``{tid: (name, policy, priority)}`` of the live threads of process ``pid``."""
    found = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm') as comm:
                name = comm.read().strip()
            found[int(tid)] = (name, os.sched_getscheduler(int(tid)),
                               os.sched_getparam(int(tid)).sched_priority)
        except (FileNotFoundError, ProcessLookupError):
            pass        # ended meanwhile
    return found


def middleware(policies):
    """Return ``(reception, other)``: the sets of (policy, priority) of Fast DDS's threads."""
    reception = {p[1:] for p in policies.values() if p[0].startswith('dds.udp.')}
    other = {p[1:] for p in policies.values()
             if p[0].startswith('dds.') and not p[0].startswith('dds.udp.')}
    return reception, other

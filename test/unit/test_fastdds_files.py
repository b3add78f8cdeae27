"""
Which Fast DDS shared-memory files belong to dead processes (etdmp_ros.ros.fastdds_files).

In a folder of this test's own: files laid out as Fast DDS 2.14 lays them out in /dev/shm,
their lock files held (flock) by a live helper process or by nobody, their age set with utime.
"""

import fcntl
import mmap
import os
import subprocess
import sys
import time

from etdmp_ros.ros import fastdds_files
from etdmp_ros.ros.fastdds_files import clean, kind, lock_owners, mappers, stale
import pytest

#: Port numbers no Fast DDS process uses (ports are UDP-port-like numbers below 65536): their
#: semaphore names cannot meet a real port's in /dev/shm.
PORT = 3_999_999_901
OTHER_PORT = 3_999_999_903


def make(folder, *names, age=60.0):
    """Create ``names`` in ``folder``, ``age`` seconds old."""
    then = time.time() - age
    for name in names:
        path = folder / name
        path.write_bytes(b'\0' * 64)
        os.utime(path, (then, then))


@pytest.fixture
def holder(tmp_path):
    """Start a process that holds an flock on the files given to it; yield start(names)."""
    processes = []

    def start(*names, shared=False):
        mode = 'LOCK_SH' if shared else 'LOCK_EX'
        code = ('import fcntl, sys, time\n'
                'fds = [open(p) for p in sys.argv[1:]]\n'
                f'[fcntl.flock(f, fcntl.{mode}) for f in fds]\n'
                'print("locked", flush=True)\n'
                'time.sleep(60)\n')
        process = subprocess.Popen([sys.executable, '-c', code,
                                    *[str(tmp_path / n) for n in names]],
                                   stdout=subprocess.PIPE, text=True)
        assert process.stdout.readline().strip() == 'locked'
        processes.append(process)
        return process
    yield start
    for process in processes:
        process.kill()
        process.wait()


def test_kinds_of_files():
    assert kind('fastrtps_0123456789abcdef') == 'segment'
    assert kind('fastrtps_0123456789abcdef_el') == 'lock'
    assert kind('fastrtps_port7411') == 'port'
    assert kind('fastrtps_port7411_el') == kind('fastrtps_port7411_sl') == 'lock'
    assert kind('sem.fastrtps_port7411_mutex') == 'mutex'
    assert kind('fast_datasharing_01.0f.aa_0.0.1.3') == 'datasharing'
    for other in ('lttng-ust-wait-6', 'fastrtps_port', 'fastrtps_0123', 'sem.other',
                  'fastrtps_0123456789abcdef_xx', 'fastrtps_port7411_el.bak'):
        assert kind(other) is None, other


def test_a_dead_participants_segment_is_stale_a_live_ones_is_not(tmp_path, holder):
    dead, live = 'fastrtps_00000000000000d1', 'fastrtps_00000000000000a1'
    make(tmp_path, dead, f'{dead}_el', live, f'{live}_el', 'lttng-ust-wait-6')
    holder(f'{live}_el')
    assert stale(tmp_path) == [([dead, f'{dead}_el'], 'segment lock not held')]
    assert sorted(clean(tmp_path)) == [dead, f'{dead}_el']
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [live, f'{live}_el', 'lttng-ust-wait-6'])


def test_young_files_are_kept(tmp_path):
    # A process may be between creating its files and locking them.
    name = 'fastrtps_00000000000000b1'
    make(tmp_path, name, f'{name}_el', age=0.0)
    assert stale(tmp_path) == []
    make(tmp_path, name, f'{name}_el', age=fastdds_files.GRACE + 1.0)
    assert len(stale(tmp_path)) == 1


def test_ports_of_dead_readers_and_without_readers_are_stale(tmp_path, holder):
    port, other = f'fastrtps_port{PORT}', f'fastrtps_port{OTHER_PORT}'
    live, shared = 'fastrtps_port3999999905', 'fastrtps_port3999999907'
    make(tmp_path, port, f'{port}_el', f'sem.{port}_mutex',       # its reader was killed
         other, f'sem.{other}_mutex',                             # no reader at all
         live, f'{live}_el', shared, f'{shared}_sl')
    holder(f'{live}_el')
    holder(f'{shared}_sl', shared=True)
    groups = {tuple(names): why for names, why in stale(tmp_path)}
    assert groups == {
        (port, f'{port}_el', f'{port}_sl', f'sem.{port}_mutex'): 'port lock not held',
        (other, f'{other}_el', f'{other}_sl', f'sem.{other}_mutex'): 'port without reader'}
    assert sorted(clean(tmp_path)) == sorted([port, f'{port}_el', f'sem.{port}_mutex', other,
                                              f'sem.{other}_mutex'])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [live, f'{live}_el', shared, f'{shared}_sl'])


def test_a_port_without_reader_that_a_live_writer_maps_is_kept(tmp_path):
    # Its reader exited cleanly; the writer keeps the port open and sends into that file: the
    # next reader of that number must find it there (removed, the writer sent into the
    # removed file and the new reader saw nothing).
    port = f'fastrtps_port{PORT}'
    make(tmp_path, port, f'sem.{port}_mutex')
    with open(tmp_path / port, 'r+b') as f:
        view = mmap.mmap(f.fileno(), 64)
        try:
            assert stale(tmp_path) == []
        finally:
            view.close()
    assert stale(tmp_path) == [([port, f'{port}_el', f'{port}_sl', f'sem.{port}_mutex'],
                                'port without reader')]


def test_a_killed_readers_port_that_a_live_writer_maps_is_locked_not_removed(tmp_path):
    # Removed, the restarted reader took the same number in a new file, and the camera went on
    # sending into the old one: perception blind for 90 s. Locked, the new reader takes
    # another number, which the writer opens afresh.
    port = f'fastrtps_port{PORT}'
    make(tmp_path, port, f'{port}_el', f'sem.{port}_mutex')
    writer = subprocess.Popen(
        [sys.executable, '-c', 'import mmap, sys\n'
         'f = open(sys.argv[1], "r+b"); m = mmap.mmap(f.fileno(), 64)\n'
         'print("mapped", flush=True); sys.stdin.read()', str(tmp_path / port)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline().strip() == 'mapped'
        assert stale(tmp_path) == [([f'{port}_el'], fastdds_files.QUARANTINE)]
        assert clean(tmp_path) == []
        assert fastdds_files.quarantined() == [f'{port}_el']
        assert fastdds_files.lock_held(tmp_path / f'{port}_el')     # as Fast DDS probes it
        assert stale(tmp_path) == []                 # held: a live reader's, to everyone
        assert clean(tmp_path) == [] and fastdds_files.quarantined() == [f'{port}_el']
    finally:
        writer.communicate('')
        fastdds_files.release()
    assert fastdds_files.quarantined() == []
    # The writer gone, this process's lock released: a killed reader's port, removed.
    assert sorted(clean(tmp_path)) == sorted([port, f'{port}_el', f'sem.{port}_mutex'])


def test_a_killed_readers_port_made_anew_by_its_writer_is_locked_too(tmp_path):
    # A writer that finds a killed reader's port broken makes the port file anew (Fast DDS's
    # regenerate_port): the file is young, its lock file old. Taken as a dead reader's port
    # ('port lock not held'), the file the writer maps was removed with the lock.
    port = f'fastrtps_port{PORT}'
    make(tmp_path, f'{port}_el', f'sem.{port}_mutex')
    make(tmp_path, port, age=0.0)
    with open(tmp_path / port, 'r+b') as f:
        view = mmap.mmap(f.fileno(), 64)
        try:
            assert stale(tmp_path) == [([f'{port}_el'], fastdds_files.QUARANTINE)]
        finally:
            view.close()
    # Not mapped by anyone and young: its maker may be about to map it; kept this time.
    assert stale(tmp_path) == []
    make(tmp_path, port, age=fastdds_files.GRACE + 1.0)
    assert stale(tmp_path) == [([port, f'{port}_el', f'{port}_sl', f'sem.{port}_mutex'],
                                'port lock not held')]


def test_a_left_over_lock_and_mutex_alone_are_stale(tmp_path):
    make(tmp_path, 'fastrtps_00000000000000c1_el', f'sem.fastrtps_port{PORT}_mutex')
    assert sorted(clean(tmp_path)) == ['fastrtps_00000000000000c1_el',
                                       f'sem.fastrtps_port{PORT}_mutex']


def test_lock_owners_and_mappers_name_the_processes(tmp_path):
    lock, segment = tmp_path / 'fastrtps_00000000000000e1_el', tmp_path / 'fastrtps_x'
    lock.write_bytes(b'')
    segment.write_bytes(b'\0' * mmap.PAGESIZE)
    with open(lock) as held, open(segment, 'r+b') as f:
        fcntl.flock(held, fcntl.LOCK_EX)
        view = mmap.mmap(f.fileno(), mmap.PAGESIZE)
        try:
            assert lock_owners(tmp_path).get(lock.stat().st_ino) == {os.getpid()}
            assert mappers(tmp_path).get('fastrtps_x') == {os.getpid()}
            assert mappers(tmp_path, pids=[os.getppid()]).get('fastrtps_x') is None
        finally:
            view.close()
    assert lock.stat().st_ino not in lock_owners(tmp_path)


# ----------------------------------------------------------------- which profile a process gets

def _profile_name(monkeypatch, shared_memory, realtime=False, **env):
    from etdmp_ros.ros.spin import dds_profile
    for name in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_LOCALHOST_ONLY', 'ROS_STATIC_PEERS',
                 'FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                 'ETDMP_DDS_PROFILE', 'RMW_IMPLEMENTATION'):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    path = dds_profile(shared_memory, realtime=realtime)
    return None if path is None else path.name


def test_the_control_loop_gets_udp_the_image_processes_shared_memory(monkeypatch):
    assert _profile_name(monkeypatch, False) == 'fastdds_udp.xml'
    assert _profile_name(monkeypatch, True) == 'fastdds.xml'
    local = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    assert _profile_name(monkeypatch, False, **local) == 'fastdds_udp_localhost.xml'
    assert _profile_name(monkeypatch, True, **local) == 'fastdds_localhost.xml'
    assert _profile_name(monkeypatch, False, ROS_LOCALHOST_ONLY='1') == 'fastdds_udp_localhost.xml'
    # Static peers cannot be written into a fixed file: rmw_fastrtps's LOCALHOST then applies.
    assert _profile_name(monkeypatch, False, ROS_STATIC_PEERS='10.0.0.2', **local) == \
        'fastdds_udp.xml'
    # A profile the user names is theirs; the package's own choice (marked) is chosen again.
    assert _profile_name(monkeypatch, False, FASTRTPS_DEFAULT_PROFILES_FILE='/x.xml') is None
    assert _profile_name(monkeypatch, True, FASTRTPS_DEFAULT_PROFILES_FILE='/a/fastdds_udp.xml',
                         ETDMP_DDS_PROFILE='/a/fastdds_udp.xml') == 'fastdds.xml'
    assert _profile_name(monkeypatch, True, RMW_IMPLEMENTATION='rmw_cyclonedds_cpp') is None


def test_localhost_discovery_is_handed_to_the_profile_only_during_init(monkeypatch):
    from etdmp_ros.ros import spin as _spin
    monkeypatch.setattr(fastdds_files, 'clean', lambda: ['fastrtps_x'])
    _profile_name(monkeypatch, False, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    with _spin.dds_settings(shared_memory=False) as removed:
        assert removed == ['fastrtps_x']
        assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SYSTEM_DEFAULT'
        assert os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'].endswith(
            'fastdds_udp_localhost.xml')
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'


def test_the_localhost_profiles_are_the_others_with_localhost_discovery():
    """Each *_localhost.xml is its base file plus rmw_fastrtps's LOCALHOST settings."""
    import xml.etree.ElementTree as ElementTree
    from etdmp_ros.ros.paths import config_path
    ns = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'

    def parts(name):
        root = ElementTree.parse(config_path(name)).getroot()
        transports = {d.find(f'{ns}transport_id').text: {c.tag: c.text for c in d}
                      for d in root.iter(f'{ns}transport_descriptor')}
        rtps = root.find(f'{ns}participant/{ns}rtps')
        used = [t.text for t in rtps.find(f'{ns}userTransports')]
        return transports, used, rtps.find(f'{ns}builtin'), rtps
    for base in ('fastdds.xml', 'fastdds_udp.xml'):
        transports, used, builtin, _ = parts(base)
        local, local_used, local_builtin, rtps = parts(base.replace('.xml', '_localhost.xml'))
        assert builtin is None and local_used == used
        assert local['etdmp_udpv4'].pop(f'{ns}maxInitialPeersRange') == '32'
        assert local == transports
        assert [e.tag for e in local_builtin] == [f'{ns}metatrafficUnicastLocatorList',
                                                  f'{ns}initialPeersList']
        peers = [a.text for a in local_builtin.iter(f'{ns}address')]
        assert peers == ['127.0.0.1']
        assert rtps.find(f'{ns}useBuiltinTransports').text == 'false'
    assert 'etdmp_shm' not in parts('fastdds_udp.xml')[0]


def test_real_time_nodes_get_real_time_reception_where_permitted(monkeypatch, tmp_path):
    from xml.etree import ElementTree
    from etdmp_ros.ros import spin
    monkeypatch.setenv('TMPDIR', str(tmp_path))
    monkeypatch.setattr(spin.tempfile, 'tempdir', None)
    monkeypatch.setattr(spin, 'may_use_realtime', lambda: False)
    assert _profile_name(monkeypatch, False, realtime=True) == 'fastdds_udp.xml'
    monkeypatch.setattr(spin, 'may_use_realtime', lambda: True)
    local = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    assert _profile_name(monkeypatch, False, realtime=True, **local) == \
        'fastdds_udp_localhost_realtime.xml'
    # The package's file, with SCHED_FIFO reception threads on its UDP transport, nothing else.
    from etdmp_ros.ros.paths import config_path
    base = config_path('fastdds_udp_localhost.xml')
    made = spin.realtime_profile(base)
    assert made.parent.parent == tmp_path
    ns = '{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}'
    tree = ElementTree.parse(made).getroot()
    threads = tree.find(f'{ns}transport_descriptors/{ns}transport_descriptor/'
                        f'{ns}default_reception_threads')
    assert threads.findtext(f'{ns}scheduling_policy') == '1'
    assert int(threads.findtext(f'{ns}priority')) == spin.RECEPTION_PRIORITY
    for descriptor in tree.iter(f'{ns}transport_descriptor'):
        descriptor.remove(descriptor.find(f'{ns}default_reception_threads'))

    def canonical(root):
        return [(e.tag, (e.text or '').strip()) for e in root.iter()]
    assert canonical(tree) == canonical(ElementTree.parse(base).getroot())
    assert spin.realtime_profile(base) == made      # the same file, written once
    # Under the control loop's real-time threads (their thread_priority defaults).
    from etdmp_ros.ros import system
    for name in ('controller', 'ur10_sim'):
        assert system.node(name).parameter('thread_priority').default > spin.RECEPTION_PRIORITY

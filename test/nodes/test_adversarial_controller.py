"""
Attacks on the controller through its topics, against the installed nodes.

``ur10_sim`` (camera off) and ``controller`` run from the colcon install as in
test_controller_node (its :class:`Rig`). While the arm writes the letter G, each row of
:data:`ATTACKS` does what an adversarial user with ``ros2 topic pub`` or a small rclpy script
would: joint states stamped 100 s ahead or 5 s back, a flood of joint states for other joints
from another process, a Path of 10^5 poses, a path at the length limit. For every row:

- the letter still ends on its last pose (0.5 mm) with the status ``idle``, no stale-input, no
  early end, every command within the velocity and acceleration limits;
- the controller says why it ignored the input (a WARN or ERROR line naming it);
- the control loop kept its rate: the simulation never went ``watchdog_timeout`` (0.06 s)
  without a command;
- the controller is alive and its memory grows by less than :data:`RSS_GROWTH_LIMIT`; the
  next row is the next good request.
"""

import os
import subprocess
import sys
import time

from etdmp_ros.robot import JOINT_NAMES
from etdmp_ros.ros.conversions import joint_state_msg, ns_to_stamp, serialize_path
import numpy as np
import pytest
from support.controller_plans import g_plan
from support.flood import FLOOD, FLOOD_PRIORITY
from test_controller_node import Rig

#: How much the controller's resident memory may grow over the attacks (bytes), from what it
#: uses once started (360 MB with numba's cache, 450 MB when numba compiled in the process:
#: a fresh clone). Measured: +3 to +33 MB; a 10^5-pose path is 8 MB of bytes.
RSS_GROWTH_LIMIT = 64e6
#: Joint states per second of the flood: the rate that stopped every letter before.
FLOOD_RATE = 13000
#: The least the flood must reach to count as one: 50 junk joint states per robot's one (at 125
#: Hz). At FLOOD_PRIORITY it reached 12 700-13 000/s here, idle and beside a busy loop; without
#: the permission it runs at normal priority and a busy machine can starve it (4 340/s once).
#: What the test asserts of the letter does not depend on this floor.
FLOOD_MIN_RATE = 6250
#: The shipped max_path_poses (config/controller.yaml).
MAX_PATH_POSES = 20000


@pytest.fixture(scope='module')
def rig(colcon_install, tmp_path_factory):
    r = Rig(colcon_install, tmp_path_factory.mktemp('adversarial_controller'), 125.0)
    yield r
    assert r.close() == 0, r.logs()


def _latest_stamp(rig):
    """Return the stamp of the joint state received last (not the largest: forged ones)."""
    with rig.client.lock:
        return max(rig.client.joints.items(), key=lambda item: item[1][1])[0]


def _newest_received_q(rig):
    """Return the joints of the joint state received last (forged ones have odd stamps)."""
    with rig.client.lock:
        return max(rig.client.joints.values(), key=lambda v: v[1])[0].copy()


def _forged_joint_states(rig, offset_ns):
    """Publish 3 joint states of the right joints at the right pose, stamped ``offset_ns`` off."""
    yield
    q = _newest_received_q(rig)
    stamp = max(_latest_stamp(rig) + offset_ns, 1000)
    for k in range(3):
        rig.client.joint_pub.publish(joint_state_msg(q, np.zeros(6), names=JOINT_NAMES,
                                                     stamp=ns_to_stamp(stamp + k * 8_000_000)))
        time.sleep(0.01)        # the subject: one a control period or so, as a robot's would
    return 'joint state ignored: its stamp is'


# Each attack is a generator: what it does before the letter is sent, then (after its yield)
# while the letter is being written; it returns what the controller must log.

def future_stamps(rig):
    """Three joint states stamped 100 s ahead (they would end the path at once)."""
    return (yield from _forged_joint_states(rig, 100_000_000_000))


def past_stamps(rig):
    """Three joint states stamped 5 s back (they would read as a restart: path dropped)."""
    return (yield from _forged_joint_states(rig, -5_000_000_000))


def joint_state_flood(rig):
    """Another process floods /joint_states with other joints (13 kHz) through the letter."""
    seconds = 5.0
    flood = subprocess.Popen([sys.executable, '-c', FLOOD, str(seconds), str(FLOOD_RATE),
                              str(FLOOD_PRIORITY)],
                             text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             env=dict(os.environ))
    try:
        assert flood.stdout.readline().strip() == 'flooding', flood.stderr.read()
        yield
        out, err = flood.communicate(timeout=60)
    finally:
        flood.kill()
    assert flood.returncode == 0, err
    rate = float(out.split()[-1])
    print(f'joint state flood: {rate:.0f}/s for {seconds:g} s (asked {FLOOD_RATE}/s)')
    assert rate >= FLOOD_MIN_RATE, f'the flood reached only {rate:.0f} joint states/s'
    return "joint state lacks joints ['shoulder_pan_joint'"


def oversized_path(rig):
    """Send a Path of 10^5 poses (8 MB) while the letter is written: refused unread."""
    yield
    seen = len(rig.controller.log())
    rig.client.path_pub.publish(rig.oversized)
    said = f'path ignored: the path has 100000 poses, more than max_path_poses ({MAX_PATH_POSES})'
    rig.client.wait_for(lambda: said in rig.controller.log()[seen:], 10.0,
                        'the refusal of the oversized path', rig.processes)
    return said


def path_at_the_limit(rig):
    """Send the letter again as 20000 poses, replacing the one being written (accepted)."""
    yield
    rig.client.path_pub.publish(rig.at_limit)
    # Stamped like the letter being written, it continues it: taken over at its path time.
    return f'path continued: {MAX_PATH_POSES} poses'


ATTACKS = (future_stamps, past_stamps, joint_state_flood, oversized_path, path_at_the_limit)


def _rss(pid):
    with open(f'/proc/{pid}/status') as f:
        for line in f:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) * 1024
    raise AssertionError(f'no VmRSS for {pid}')


@pytest.fixture(scope='module')
def letter(rig):
    path = g_plan()[0]
    t = np.linspace(0.0, path.duration, MAX_PATH_POSES)
    # All-zero orientations: the tool keeps its own (identity would turn it over).
    rig.at_limit = serialize_path(np.array([path.pose(s)[0] for s in t]), t,
                                  orientation=(0.0, 0.0, 0.0, 0.0))
    t = np.linspace(0.0, 1000.0, 100000)
    rig.oversized = serialize_path(np.tile(path.positions[:1], (len(t), 1)), t,
                                   orientation=(0.0, 0.0, 0.0, 0.0))
    rig.rss_before = _rss(rig.controller.pid)
    return path


@pytest.mark.parametrize('attack', ATTACKS, ids=[a.__name__ for a in ATTACKS])
def test_an_attack_while_writing_leaves_the_letter_whole(rig, letter, attack):
    c = rig.client
    controller, sim = rig.controller, rig.processes[0]
    log_start, sim_log_start = len(controller.log()), len(sim.log())
    with c.lock:
        start, n_status = time.monotonic(), len(c.status)
    steps = attack(rig)
    next(steps)
    c.publish_path(letter)
    c.wait_for(lambda: c.state() == 'tracking', 30.0, 'tracking', rig.processes)
    time.sleep(0.5)             # the subject: the attack while the letter is being written
    try:
        next(steps)
    except StopIteration as end:
        said = end.value
    c.wait_for(lambda: c.state() == 'idle', 40.0, 'the end of the letter', rig.processes)
    joints, _, commands, _ = rig.records(start)
    with c.lock:
        status = [s for _, s in c.status[n_status:]]
    log = controller.log()[log_start:]
    assert said in log, log[-3000:]
    assert not any(s.startswith(('stale-input', 'unreachable', 'halted')) for s in status), \
        status
    assert status[-1] == 'idle' and 'holding' in status, status
    np.testing.assert_allclose(rig.ur10.frame_pose(_newest_received_q(rig))[0],
                               letter.positions[-1], atol=0.5e-3)
    rig.assert_commands_within_limits(commands, joints)
    assert 'no velocity command' not in sim.log()[sim_log_start:], \
        f'{sim.log()[sim_log_start:]}\ncontroller:\n{log[-3000:]}'
    assert controller.returncode is None
    rss = _rss(controller.pid)
    print(f'{attack.__name__}: controller RSS {rss / 1e6:.0f} MB '
          f'({(rss - rig.rss_before) / 1e6:+.0f} MB)')
    assert rss - rig.rss_before < RSS_GROWTH_LIMIT

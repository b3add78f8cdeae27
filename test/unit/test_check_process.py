"""Path checks in a worker process: the controller's answers, without the caller's CPU."""

import os
import signal
import subprocess
import sys
import textwrap
import time

from etdmp_ros.robot import (CheckError, CheckProcess, ControllerConfig, PoseTrajectory,
                             TrajectoryController, UR10Model)
import numpy as np
import pytest
from support.controller_plans import g_plan, Q_INITIAL, TOOL_OFFSET


@pytest.fixture(scope='module')
def checker():
    process = CheckProcess(TOOL_OFFSET, ControllerConfig())
    yield process
    process.close()


def test_the_process_answers_as_the_controller_and_follows_its_config(checker):
    path = g_plan()[0]
    far = PoseTrajectory(path.t, path.positions + [1.5, 0.0, 0.0], path.rotations)
    own = TrajectoryController(UR10Model(TOOL_OFFSET), checker.config)
    assert checker.check(path, Q_INITIAL) == own.check(path, Q_INITIAL) == ''
    reason = checker.check(far, Q_INITIAL)
    assert 'out of reach' in reason and reason == own.check(far, Q_INITIAL)
    # A parameter set changes the config object in place: the next check uses it.
    default = ControllerConfig()
    checker.config.condition_slowdown, checker.config.condition_halt = 2.5, 5.0
    try:
        reason = checker.check(path, Q_INITIAL)
        assert 'singular configuration (Jacobian condition number 6 >= 5)' in reason, reason
        assert reason == TrajectoryController(UR10Model(TOOL_OFFSET),
                                              checker.config).check(path, Q_INITIAL)
    finally:
        checker.config.condition_slowdown = default.condition_slowdown
        checker.config.condition_halt = default.condition_halt
    assert checker.check(path, Q_INITIAL) == ''


def test_a_check_costs_the_caller_almost_no_cpu(checker):
    path = g_plan()[0]
    checker.check(path, Q_INITIAL)               # warm (imports, the model)
    own = TrajectoryController(UR10Model(TOOL_OFFSET))
    costs = {}
    for name, check in (('in process', own.check), ('worker', checker.check)):
        wall, cpu = time.perf_counter(), time.thread_time()
        for _ in range(3):
            check(path, Q_INITIAL)
        costs[name] = (time.thread_time() - cpu, time.perf_counter() - wall)
    print({k: f'{c * 1e3:.1f} ms CPU in {w * 1e3:.1f} ms' for k, (c, w) in costs.items()})
    assert costs['in process'][0] > 0.05       # 3 checks: the work is this thread's CPU
    assert costs['worker'][0] < 0.1 * costs['in process'][0]


def test_a_dead_worker_fails_that_check_and_is_replaced(checker):
    path = g_plan()[0]
    first = checker.pid
    os.kill(first, signal.SIGKILL)
    time.sleep(0.2)
    with pytest.raises(CheckError, match='died'):
        checker.check(path, Q_INITIAL)
    assert checker.check(path, Q_INITIAL) == '' and checker.pid != first


def test_the_worker_ends_with_a_killed_parent(tmp_path):
    script = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(os.path.join(os.path.dirname(__file__), '..'))!r})
        from etdmp_ros.robot import CheckProcess, ControllerConfig
        from support.controller_plans import g_plan, Q_INITIAL, TOOL_OFFSET
        c = CheckProcess(TOOL_OFFSET, ControllerConfig())
        assert c.check(g_plan()[0], Q_INITIAL) == ''
        print(c.pid, flush=True)
        time.sleep(60)
    """)
    parent = subprocess.Popen([sys.executable, '-c', script], stdout=subprocess.PIPE, text=True)
    try:
        worker = int(parent.stdout.readline())
    finally:
        parent.kill()
        parent.wait()
    deadline = time.monotonic() + 5.0
    while os.path.exists(f'/proc/{worker}') and time.monotonic() < deadline:
        with open(f'/proc/{worker}/stat') as f:
            if f.read().split(')')[-1].split()[0] == 'Z':
                break           # exited; its zombie waits for init to reap it
        time.sleep(0.05)
    assert time.monotonic() < deadline, 'the worker outlived its killed parent by 5 s'


def test_a_closed_checker_refuses():
    process = CheckProcess(TOOL_OFFSET, ControllerConfig())
    process.close()
    with pytest.raises(CheckError, match='closed'):
        process.check(g_plan()[0], np.array(Q_INITIAL))

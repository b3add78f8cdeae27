"""
Benchmark of dmp_server's /generalize round trip against the floor of rclpy itself.

    .venv/bin/python test/benchmarks/bench_dmp_server.py [--install PREFIX] [--calls 200]

Starts, in one run and one isolated DDS domain:

- the installed ``dmp_server`` (a colcon install: ``--install PREFIX``, or one built now into a
  temporary folder), configured for a 5 s plan at 100 Hz (501 poses; with 2 obstacles tau is
  5 / 1.5 s so that the obstacle margin gives the same 501 poses);
- the floor: a bare rclpy GetPlan server returning a precomputed 501-pose plan, once with
  ``rclpy.spin`` (single-threaded) and once with the MultiThreadedExecutor and a reentrant group
  that dmp_server uses (this isolates the executor's cost).

One client process calls them in interleaved rounds (so background load hits every case alike)
and reports p50/p90/p99 over ``--calls`` calls each. Then 4 client processes call dmp_server
together at 20 requests/s in total for ``--sustain`` seconds; every answer must be a non-empty
plan. Finally the request's pieces are timed in-process to say where the time goes: rollout
(planning), building the response Path, serializing it for /etdmp/path, and what rclpy and DDS
cost (serializing the response, deserializing it in the client: measured the same way).

Targets: p50 <= 1.5x the floor and <= 25 ms; sustained 20 req/s from 4 clients with
no failure.
"""

import argparse
import json
import os
from pathlib import Path as FsPath
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = FsPath(__file__).resolve().parents[2]
COLCON = FsPath(sys.executable).with_name('colcon')
POSES = 501
DURATION = 5.0
PERIOD = 0.01
START = (0.80, 0.20, 0.0)
GOAL = (0.74, 0.15, 0.0)


def _obstacles_on_path():
    """Two obstacle points on G's obstacle-free path (at 30 % and 60 %), 8 cm up (cylinders)."""
    from etdmp_ros.dmp import builtin_demo, learn
    from etdmp_ros.skills.planning import plan_path, PlanSettings
    from etdmp_ros.geometry.task_plane import TaskPlane
    plane = TaskPlane.create([0.75, 0.15, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02)
    free = plan_path(learn(builtin_demo('G')), START, GOAL, (), PlanSettings(), plane)
    n = len(free.positions)
    return free.positions[[int(0.3 * n), int(0.6 * n)]] + [0.0, 0.0, 0.08]


def _percentiles(samples_ms):
    p50, p90, p99 = np.percentile(samples_ms, [50, 90, 99])
    return {'p50': float(p50), 'p90': float(p90), 'p99': float(p99), 'n': len(samples_ms)}


def _median_ms(fn, repeat=200):
    for _ in range(10):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3)


# -- child process modes ---------------------------------------------------------------------


def floor_server(executor_kind):
    """Serve /floor_<kind>: GetPlan answered with one precomputed 501-pose plan."""
    import rclpy
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
    from nav_msgs.srv import GetPlan
    from etdmp_ros.ros.conversions import path_from_numpy

    rclpy.init()
    node = rclpy.create_node(f'floor_{executor_kind}')
    rng = np.random.default_rng(0)
    plan = path_from_numpy(rng.uniform(0.5, 1.0, (POSES, 3)), np.arange(POSES) * PERIOD,
                           stamp=time.time_ns(), orientation=(-0.7071, 0.7071, 0.0, 0.0))

    def answer(request, response):
        response.plan = plan
        return response
    group = ReentrantCallbackGroup() if executor_kind == 'multi' else None
    node.create_service(GetPlan, f'/floor_{executor_kind}', answer, callback_group=group)
    try:
        if executor_kind == 'multi':
            executor = MultiThreadedExecutor(num_threads=4)
            executor.add_node(node)
            executor.spin()
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


class _Caller:
    """An rclpy client of several GetPlan services, in this process."""

    def __init__(self, services, name):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from nav_msgs.srv import GetPlan
        self.rclpy = rclpy
        rclpy.init()
        self.node = rclpy.create_node(name)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.clients = {s: self.node.create_client(GetPlan, s) for s in services}
        self.request = GetPlan.Request()
        for pose, point in ((self.request.start, START), (self.request.goal, GOAL)):
            pose.header.frame_id = 'base_link'
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = point

    def wait(self, timeout=60.0):
        for service, client in self.clients.items():
            if not client.wait_for_service(timeout_sec=timeout):
                raise RuntimeError(f'{service} did not come up')

    def call(self, service, timeout=5.0):
        """Return (round-trip seconds, number of poses) or (seconds, -1) on timeout."""
        t0 = time.perf_counter()
        future = self.clients[service].call_async(self.request)
        self.executor.spin_until_future_complete(future, timeout_sec=timeout)
        elapsed = time.perf_counter() - t0
        if not future.done():
            future.cancel()
            return elapsed, -1
        return elapsed, len(future.result().plan.poses)

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.shutdown()


def sustained_worker(rate, seconds, worker):
    """Call /generalize at ``rate`` Hz for ``seconds``; print a JSON summary on stdout."""
    caller = _Caller(['/generalize'], f'bench_worker_{worker}')
    caller.wait()
    latencies, failures = [], 0
    t_start = time.perf_counter() + 0.5
    count = int(rate * seconds)
    for k in range(count):
        delay = t_start + k / rate - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        elapsed, poses = caller.call('/generalize')
        latencies.append(elapsed * 1e3)
        failures += poses != POSES
    wall = time.perf_counter() - t_start
    caller.close()
    print(json.dumps({'latencies_ms': latencies, 'failures': failures, 'calls': count,
                      'wall_s': wall}))


# -- the benchmark ---------------------------------------------------------------------------


def _build_install(tmp):
    """Build the repository with colcon into tmp (as test/conftest.py does); return the prefix."""
    env = dict(os.environ, COLCON_HOME=str(tmp / 'colcon_home'))
    subprocess.run([str(COLCON), '--log-base', str(tmp / 'log'), 'build', '--paths', str(REPO),
                    '--merge-install', '--build-base', str(tmp / 'build'),
                    '--install-base', str(tmp / 'install')],
                   cwd=tmp, env=env, check=True, capture_output=True, timeout=600)
    return tmp / 'install'


def _sourced(install, command):
    return ['sh', '-c', f'. "{install}/local_setup.sh" && exec {command}']


def _stop(process):
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _set_parameters(caller, **values):
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    if not hasattr(caller, 'parameters'):
        caller.parameters = caller.node.create_client(SetParameters,
                                                      '/dmp_server/set_parameters')
        caller.parameters.wait_for_service(timeout_sec=30.0)
    future = caller.parameters.call_async(SetParameters.Request(parameters=[
        Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]))
    caller.executor.spin_until_future_complete(future, timeout_sec=10.0)
    assert all(r.successful for r in future.result().results), future.result()


def _publish_obstacles(caller, points):
    from geometry_msgs.msg import PoseArray
    from etdmp_ros.ros.conversions import pose_array_from_numpy
    if not hasattr(caller, 'obstacles'):
        caller.obstacles = caller.node.create_publisher(PoseArray, '/etdmp/obstacles', 10)
    publisher = caller.obstacles
    deadline = time.monotonic() + 30.0
    while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
        caller.executor.spin_once(timeout_sec=0.05)
    publisher.publish(pose_array_from_numpy(np.array(points)))
    caller.executor.spin_once(timeout_sec=0.05)
    time.sleep(0.1)


def _breakdown():
    """Time the parts of one request in this process (no DDS), medians in ms."""
    from etdmp_ros import limits
    from etdmp_ros.dmp import builtin_demo, learn
    from etdmp_ros.skills.planning import plan_path, PlanSettings
    from etdmp_ros.ros.conversions import path_from_numpy, serialize_path
    from etdmp_ros.geometry.task_plane import TaskPlane
    from nav_msgs.msg import Path
    from rclpy.serialization import deserialize_message, serialize_message

    plane = TaskPlane.create([0.75, 0.15, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.02)
    skill = learn(builtin_demo('G'))
    rows = {}
    for n_obs, tau in ((0, DURATION), (2, DURATION / 1.5)):
        settings = PlanSettings(duration=tau, output_period=PERIOD)
        obstacles = _obstacles_on_path()[:n_obs]
        rows[f'plan_path (rollout + checks), {n_obs} obstacles'] = _median_ms(
            lambda: plan_path(skill, START, GOAL, obstacles, settings, plane))
    plan = plan_path(skill, START, GOAL, (), PlanSettings(duration=DURATION), plane)
    rows[f'timing check (IK at {limits.TIMING_CHECK_SAMPLES} poses, check_timing)'] = _median_ms(
        lambda: _timing_check(plan))
    args = (plan.positions, plan.t, time.time_ns(), 'base_link', plan.orientation)
    rows['response Path (path_from_numpy)'] = _median_ms(lambda: path_from_numpy(*args))
    message = path_from_numpy(*args)
    # dmp_server publishes /etdmp/path as the Path's bytes written with numpy.
    rows['/etdmp/path: the Path serialized at publish'] = _median_ms(
        lambda: serialize_path(*args))
    rows['rclpy: serialize the response (in send_response)'] = _median_ms(
        lambda: serialize_message(message))
    data = serialize_message(message)
    rows['rclpy: deserialize it in the client'] = _median_ms(
        lambda: deserialize_message(data, Path), 50)
    return rows


def _timing_check(plan):
    """Run dmp_server's joint timing check on ``plan`` as the node does (initial joints)."""
    from etdmp_ros import limits
    from etdmp_ros.ros import system
    from etdmp_ros.robot import DEFAULT_ACCELERATION_LIMITS, UR10Model
    from etdmp_ros.geometry import quaternion as quat
    from etdmp_ros.robot._timing import timing_violation
    global _TIMING_MODEL
    if _TIMING_MODEL is None:
        _TIMING_MODEL = UR10Model(tool_offset=system.scene_defaults()['tool_offset'])
    q0 = system.scene_defaults()['initial_joint_positions']
    return timing_violation(_TIMING_MODEL, plan.positions,
                            quat.to_matrix(quat.normalized(plan.orientation)), plan.t, q0,
                            _TIMING_MODEL.velocity_limits, DEFAULT_ACCELERATION_LIMITS,
                            limits.TIMING_CHECK_SAMPLES)


_TIMING_MODEL = None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--install', type=FsPath, help='an existing colcon install prefix')
    parser.add_argument('--calls', type=int, default=200, help='timed calls per case')
    parser.add_argument('--sustain', type=float, default=10.0, help='seconds at 20 req/s')
    parser.add_argument('--json', type=FsPath, help='also write the figures here')
    parser.add_argument('--check-timing', choices=('true', 'false'), default='true',
                        help="dmp_server's check_timing (the joint timing check of each plan)")
    parser.add_argument('--floor-server', choices=('single', 'multi'), help=argparse.SUPPRESS)
    parser.add_argument('--worker', type=int, help=argparse.SUPPRESS)
    from _results import add_option   # test/benchmarks/_results.py
    add_option(parser)
    args = parser.parse_args()
    args.load = os.getloadavg()[0]
    if args.floor_server:
        return floor_server(args.floor_server)
    if args.worker is not None:
        return sustained_worker(5.0, args.sustain, args.worker)

    os.environ.update(ROS_DOMAIN_ID=str(202 + os.getpid() % 30),
                      ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                      RMW_IMPLEMENTATION='rmw_fastrtps_cpp', RCUTILS_COLORIZED_OUTPUT='0')
    os.environ.pop('ROS_LOCALHOST_ONLY', None)
    with tempfile.TemporaryDirectory(prefix='bench_dmp_server_') as tmp_name:
        tmp = FsPath(tmp_name)
        install = args.install
        if install is None:
            print('building a colcon install of the repository ...', flush=True)
            install = _build_install(tmp)
        share = install / 'share' / 'etdmp_ros' / 'config'
        overrides = tmp / 'bench.yaml'
        overrides.write_text(
            'dmp_server:\n  ros__parameters:\n'
            f'    duration: {DURATION}\n    output_period: {PERIOD}\n'
            f'    obstacle_max_age: 0.0\n    skills_dir: {tmp / "skills"}\n'
            f'    check_timing: {args.check_timing}\n')
        env = dict(os.environ, ROS_HOME=str(tmp / 'ros_home'))
        log = open(tmp / 'dmp_server.log', 'w')
        processes = [subprocess.Popen(_sourced(
            install, f'{install}/lib/etdmp_ros/dmp_server --ros-args --params-file '
            f'{share}/scene.yaml --params-file {share}/dmp_server.yaml '
            f'--params-file {overrides}'), env=env, stdout=log, stderr=subprocess.STDOUT)]
        for kind in ('single', 'multi'):
            processes.append(subprocess.Popen(
                [sys.executable, __file__, '--floor-server', kind], env=env))
        try:
            return _run(args, tmp, env)
        finally:
            for process in processes:
                _stop(process)
            log.close()


def _run(args, tmp, env):
    services = ['/floor_single', '/floor_multi', '/generalize']
    caller = _Caller(services, 'bench_client')
    caller.wait()
    # Without obstacles, then with 2 (tau 5/1.5 s so the plan keeps 501 poses).
    cases = {'floor: bare rclpy server (rclpy.spin)': '/floor_single',
             'floor: same, MultiThreadedExecutor': '/floor_multi',
             'dmp_server, 0 obstacles': '/generalize',
             'dmp_server, 2 obstacles': '/generalize'}
    samples = {case: [] for case in cases}
    on_path = _obstacles_on_path()
    rounds, per_round = 10, max(1, args.calls // 10)
    for case, service in cases.items():          # warm-up, and check the sizes
        if case.endswith('2 obstacles'):
            continue
        sizes = {caller.call(service)[1] for _ in range(20)}
        assert sizes == {POSES}, (case, sizes)
    for _ in range(rounds):
        for case, service in cases.items():
            obstacles = case.endswith('2 obstacles')
            if service == '/generalize':
                _publish_obstacles(caller, on_path if obstacles else np.zeros((0, 3)))
                _set_parameters(caller, duration=DURATION / 1.5 if obstacles else DURATION)
                caller.call(service)
            for _ in range(per_round):
                elapsed, poses = caller.call(service)
                assert poses == POSES, (case, poses)
                samples[case].append(elapsed * 1e3)
    _publish_obstacles(caller, np.zeros((0, 3)))
    _set_parameters(caller, duration=DURATION)
    caller.close()

    results = {case: _percentiles(s) for case, s in samples.items()}
    floor = results['floor: bare rclpy server (rclpy.spin)']['p50']
    from _results import command, printed, publish
    with printed() as tables:
        print(f'\n/generalize round trip, {POSES}-pose plan ({DURATION:g} s at '
              f'{1 / PERIOD:g} Hz), {results[next(iter(cases))]["n"]} calls per case, '
              'interleaved:\n')
        print('| case | p50 (ms) | p90 (ms) | p99 (ms) | p50 / floor |')
        print('|---|---|---|---|---|')
        for case, r in results.items():
            print(f'| {case} | {r["p50"]:.2f} | {r["p90"]:.2f} | {r["p99"]:.2f} | '
                  f'{r["p50"] / floor:.2f} |')
        verdicts = {case: (r['p50'] <= 1.5 * floor and r['p50'] <= 25.0)
                    for case, r in results.items() if case.startswith('dmp_server')}
        for case, ok in verdicts.items():
            print(f'target p50 <= 1.5x floor and <= 25 ms, {case}: {"met" if ok else "MISSED"}')

        print(f'\nsustained: 4 client processes x 5 req/s for {args.sustain:g} s ...', flush=True)
        workers = [subprocess.Popen([sys.executable, __file__, '--worker', str(k), '--sustain',
                                     str(args.sustain)], env=env, stdout=subprocess.PIPE,
                                    text=True)
                   for k in range(4)]
        reports = [json.loads(w.communicate(timeout=args.sustain + 120)[0]) for w in workers]
        calls = sum(r['calls'] for r in reports)
        failures = sum(r['failures'] for r in reports)
        rate = calls / max(r['wall_s'] for r in reports)
        sustained = _percentiles([x for r in reports for x in r['latencies_ms']])
        print(f'{calls} calls, {rate:.1f} req/s achieved, {failures} failures; latency p50 '
              f'{sustained["p50"]:.2f} ms, p90 {sustained["p90"]:.2f} ms, p99 '
              f'{sustained["p99"]:.2f} ms -> {"met" if failures == 0 else "MISSED"}')

        breakdown = _breakdown()
        print('\nwhere the time goes (same functions timed in-process, medians):\n')
        print('| part | ms |')
        print('|---|---|')
        for part, ms in breakdown.items():
            print(f'| {part} | {ms:.3f} |')
        ours = (breakdown['plan_path (rollout + checks), 0 obstacles'] +
                breakdown['response Path (path_from_numpy)'] +
                breakdown['/etdmp/path: the Path serialized at publish'])
        transport = (breakdown['rclpy: serialize the response (in send_response)'] +
                     breakdown['rclpy: deserialize it in the client'])
        print(f"\ndmp_server's own work per request (0 obstacles: plan + response + publish): "
              f'{ours:.2f} ms. In the floor, rclpy alone converts the 501-pose response twice '
              f'({transport:.2f} ms: serialize in the server, deserialize in the client); the '
              'rest '
              'of a round trip is DDS and the executors (MultiThreadedExecutor vs rclpy.spin: '
              f'{results["floor: same, MultiThreadedExecutor"]["p50"] - floor:+.2f} ms at p50 in '
              'this run).')
    if not args.no_docs:
        publish('dmp_server', tables.getvalue().strip(), command('dmp_server'), load=args.load)
    if args.json:
        args.json.write_text(json.dumps({'round_trip': results, 'sustained': {
            **sustained, 'calls': calls, 'failures': failures, 'rate': rate},
            'breakdown_ms': breakdown}, indent=2))
    return 0 if all(verdicts.values()) and failures == 0 else 1


if __name__ == '__main__':
    sys.exit(main())

"""
Controller benchmark: cost per control cycle, loop timing through ROS, and pin-pink side by side.

A script, not a pytest test. It runs in the benchmark environment ``.venv-bench/`` (which has
``pin-pink`` and its QP solvers, test/benchmarks/requirements-bench.txt)::

    make .venv-bench/.installed          # once
    .venv-bench/bin/python test/benchmarks/bench_controller.py [--quick] [--no-ros] [--no-fast]
        [--json P]

Three parts, one workload: the ET-DMP plan of letter G on the task plane of config/scene.yaml
(0.2 m tall, its nominal 2 s, pen pointing down), the 6D pose of the UR10 tool tip.

1. **Compute per cycle** of ``TrajectoryController.step`` (reference sampling, forward
   kinematics + Jacobian, damped least squares with every limit, state machine) and of its IK
   core alone (``DifferentialIK.kinematics`` + ``solve``), over whole closed-loop runs on a
   kinematic plant at 125 Hz; p50 and p99 of ``time.perf_counter_ns``. Both ways, side by
   side: with the numba kernels (the default) and with the numpy code only
   (``TrajectoryController(..., fast=False)``; ``--no-fast`` times only that one).
2. **pin-pink** (Pinocchio-based QP differential IK) on the same task and plant: per step a
   ``Configuration`` (forward kinematics, Jacobians), a ``FrameTask`` on ``tool_tip`` whose target
   is the reference one period ahead (gain 1: feed-forward plus deadbeat feedback, the best pink
   can do without a feed-forward input), ``solve_ik`` with the model's position, velocity and
   acceleration limits (``ConfigurationLimit``, ``VelocityLimit``, ``AccelerationLimit``, the same
   values as ours) and the ``daqp`` or ``quadprog`` solver. Both start on the path's first pose (no
   approach) and are fed the same reference; tracking error RMS and max over the path, for a
   plant that applies commands at once and one that applies them one period late.
3. **Loop timing through ROS** at 125 and 500 Hz: ``ur10_sim`` (camera off) and ``controller``
   as processes (``python -m``), the G published on /etdmp/path; from this process: period
   between successive commands (p50, p99, max), latency from a joint state to the command that
   answers it, and the tracking error (reference vs forward kinematics of /joint_states).

Targets (issue): p99 compute <= 0.2 ms; at least 3x cheaper than pink per step with equal or
better tracking. The machine has 2 cores shared with other work: figures vary with load, the
p99 column most.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import signal
import subprocess
import sys
import tempfile
import threading
import time

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / 'test'))

from _results import add_option, command, printed, publish  # noqa: E402
from etdmp_ros.geometry import quaternion as quat  # noqa: E402
from etdmp_ros.robot import ControllerConfig, TrajectoryController, UR10Model  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
from support.controller_plans import g_plan, Q_INITIAL, run_kinematic, TOOL_OFFSET  # noqa: E402

RATE = 125.0


def percentiles(samples_ns):
    """Return (p50, p99) in microseconds."""
    a = np.asarray(samples_ns, dtype=float) / 1e3
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


def start_configuration(ur10, path):
    """Return joints putting the tool on the path's first pose (Newton from the scene's start)."""
    q, error = ur10.solve_pose(path.positions[0], path.rotations[0], Q_INITIAL)
    assert np.linalg.norm(error) < 1e-6
    return q


def bench_ours(ur10, path, q0, delay, repeats, fast=None):
    """
    Return timings (ns) of whole steps and of the IK core, and the tracking errors (m).

    ``fast``: the controller's numba kernels (True), its numpy code (False), its default (None).
    """
    steps, core, errors = [], [], None
    for r in range(repeats):
        # The plant's delay is known here: start the delay estimate on it.
        controller = TrajectoryController(ur10, ControllerConfig(
            rate=RATE, actuation_delay=delay / RATE), fast=fast)
        ik = controller.ik
        original_step = controller._step
        original_kin, original_solve = ik.kinematics, ik.solve
        spent = [0]

        def timed_kinematics(q, _f=original_kin):
            t0 = time.perf_counter_ns()
            out = _f(q)
            spent[0] += time.perf_counter_ns() - t0
            return out

        def timed_solve(*a, _f=original_solve):
            t0 = time.perf_counter_ns()
            out = _f(*a)
            spent[0] += time.perf_counter_ns() - t0
            return out

        def timed_step(q, t, age, _f=original_step):
            spent[0] = 0
            t0 = time.perf_counter_ns()
            out = _f(q, t, age)
            steps.append(time.perf_counter_ns() - t0)
            core.append(spent[0])
            return out

        if r > 0:       # the first run only measures tracking, untimed by wrappers
            controller._step = timed_step
            ik.kinematics, ik.solve = timed_kinematics, timed_solve
        controller.follow(path)
        log, _ = run_kinematic(controller, q0, path.duration + 2.0, delay_periods=delay)
        if r == 0:
            errors = log.errors('tracking')
    return steps, core, errors


def bench_pink(ur10, path, q0, delay, solver, repeats):
    """Return step timings (ns) and tracking errors (m) of pin-pink on the same task."""
    import pink
    from pink.limits import AccelerationLimit, ConfigurationLimit, VelocityLimit
    from pink.tasks import FrameTask
    model = ur10.model.copy() if hasattr(ur10.model, 'copy') else pin.Model(ur10.model)
    model.velocityLimit = TrajectoryController(ur10).ik.velocity_limits.copy()
    data = model.createData()
    limits = [ConfigurationLimit(model), VelocityLimit(model),
              AccelerationLimit(model, np.asarray(ControllerConfig().acceleration_limits))]
    T = 1.0 / RATE
    times, errors = [], []
    for r in range(repeats):
        task = FrameTask('tool_tip', position_cost=1.0, orientation_cost=1.0, gain=1.0)
        q = q0.copy()
        queue = [np.zeros(6)] * delay
        limits[2].set_last_integration(np.zeros(6), T) if hasattr(
            limits[2], 'set_last_integration') else None
        n = int(round(path.duration / T))
        errs = []
        for k in range(n + 1):
            t = k * T
            t0 = time.perf_counter_ns()
            configuration = pink.Configuration(model, data, q, copy_data=False)
            p_ref, r_ref = path.pose(t + T * (1 + delay))
            task.set_target(pin.SE3(r_ref, p_ref))
            v = pink.solve_ik(configuration, [task], T, solver=solver, limits=limits,
                              safety_break=False)
            elapsed = time.perf_counter_ns() - t0
            if r > 0:
                times.append(elapsed)
            p_now = ur10.frame_pose(q)[0]
            errs.append(np.linalg.norm(p_now - path.pose(t)[0]))
            if hasattr(limits[2], 'set_last_integration'):
                limits[2].set_last_integration(v, T)
            queue.append(v)
            q = q + queue.pop(0) * T
        if r == 0:
            errors = np.array(errs)
    return times, errors


# -- ROS loop timing ----------------------------------------------------------------------------

class _Recorder:
    """rclpy in this process, spinning in a thread: records commands, joints, references."""

    def __init__(self, domain):
        import rclpy
        from etdmp_ros.ros.conversions import stamp_to_ns
        from geometry_msgs.msg import PoseStamped
        from nav_msgs.msg import Path as PathMsg
        from rclpy.qos import DurabilityPolicy, QoSProfile
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray, String
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('bench_controller', context=self.context)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.path_pub = self.node.create_publisher(PathMsg, '/etdmp/path', latched)
        self.lock = threading.Lock()
        self.joints, self.commands, self.refs, self.status = {}, [], {}, []

        def on_joints(m):
            with self.lock:
                self.joints[stamp_to_ns(m.header.stamp)] = (np.array(m.position),
                                                            time.perf_counter())

        def on_command(m):
            with self.lock:
                self.commands.append((time.perf_counter(), np.array(m.data)))

        def on_ref(m):
            p = m.pose.position
            with self.lock:
                self.refs[stamp_to_ns(m.header.stamp)] = np.array([p.x, p.y, p.z])

        def on_status(m):
            with self.lock:
                self.status.append(m.data)

        self.node.create_subscription(JointState, '/joint_states', on_joints, 100)
        self.node.create_subscription(Float64MultiArray, '/forward_velocity_controller/commands',
                                      on_command, 100)
        self.node.create_subscription(PoseStamped, '/etdmp/controller/reference', on_ref, 100)
        self.node.create_subscription(String, '/etdmp/controller/status', on_status, latched)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:   # noqa: B902 - context shut down while waiting
                break

    def state(self):
        with self.lock:
            return self.status[-1].split(':')[0] if self.status else None

    def wait(self, predicate, timeout):
        end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > end:
                raise TimeoutError(f'status {self.status[-3:]}')
            time.sleep(0.01)

    def close(self):
        self.rclpy.shutdown(context=self.context)
        self.thread.join(timeout=5)


def bench_ros(rate, ur10, path, duration_margin=3.0):
    """Run sim + controller at ``rate``; return loop timing and tracking figures."""
    from etdmp_ros.ros.conversions import serialize_path
    domain = 90 + os.getpid() % 10
    tmp = Path(tempfile.mkdtemp(prefix='bench_controller_'))
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               RMW_IMPLEMENTATION='rmw_fastrtps_cpp', MUJOCO_GL='egl', PYTHONUNBUFFERED='1')
    env.pop('ROS_LOCALHOST_ONLY', None)
    processes = []
    for node, params in (('ur10_sim', {'camera_rate': 0.0, 'control_rate': rate}),
                         ('controller', {'control_rate': rate})):
        overrides = tmp / f'{node}.yaml'
        overrides.write_text(json.dumps({node: {'ros__parameters': params}}))
        config = REPO / 'config'
        command = [sys.executable, '-m', f'etdmp_ros.nodes.{node}', '--ros-args',
                   '--params-file', str(config / 'scene.yaml'), '--params-file',
                   str(config / f'{node}.yaml'), '--params-file', str(overrides)]
        log = open(tmp / f'{node}.log', 'w')
        processes.append((subprocess.Popen(command, env=env, stdout=log,
                                           stderr=subprocess.STDOUT), log))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    recorder = _Recorder(domain)
    try:
        recorder.wait(lambda: recorder.state() == 'idle', 60.0)
        # The controller publishes its reference only to a reader it has matched: wait until
        # this side sees its publisher, then let discovery finish on its side too.
        recorder.wait(lambda: recorder.node.count_publishers('/etdmp/controller/reference') > 0,
                      30.0)
        time.sleep(1.0)
        start = time.perf_counter()
        recorder.path_pub.publish(serialize_path(path.positions, path.t, stamp=0,
                                                 orientation=quat.from_matrix(
                                                     path.rotations[0])))
        recorder.wait(lambda: 'tracking' in recorder.status, 30.0)
        recorder.wait(lambda: recorder.state() == 'idle', 30.0)
        with recorder.lock:
            joints = {k: v for k, v in recorder.joints.items() if v[1] >= start}
            commands = [(w, v) for w, v in recorder.commands if w >= start]
            refs = dict(recorder.refs)
    finally:
        recorder.close()
        for process, log in processes:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
            log.close()
    period = 1.0 / rate
    receipts = np.array([w for w, _ in commands])
    intervals = np.diff(receipts)
    jitter = np.abs(intervals - period)
    js_receipts = np.array(sorted(v[1] for v in joints.values()))
    idx = np.searchsorted(receipts, js_receipts)
    ok = idx < len(receipts)
    latency = receipts[idx[ok]] - js_receipts[ok]
    stamps = sorted(set(refs) & set(joints))
    if not stamps:
        raise TimeoutError('no reference received while tracking')
    ref = np.array([refs[s] for s in stamps])
    tool = np.array([ur10.frame_pose(joints[s][0])[0] for s in stamps])
    # Tracking phase: reference samples moving along the path (not the approach/hold).
    t = np.array(stamps) * 1e-9
    from support.controller_plans import path_time_offset
    tau = t - path_time_offset(path, t, ref)
    tracking = (tau > 0) & (tau < path.duration)
    errors = np.linalg.norm(tool - ref, axis=1)[tracking]
    return {
        'rate': rate,
        'period_p50_ms': float(np.percentile(intervals, 50) * 1e3),
        'period_p99_ms': float(np.percentile(intervals, 99) * 1e3),
        'period_max_ms': float(intervals.max() * 1e3),
        'jitter_p50_ms': float(np.percentile(jitter, 50) * 1e3),
        'jitter_p99_ms': float(np.percentile(jitter, 99) * 1e3),
        'latency_p50_ms': float(np.percentile(latency, 50) * 1e3),
        'latency_p99_ms': float(np.percentile(latency, 99) * 1e3),
        'rms_mm': float(np.sqrt(np.mean(errors ** 2)) * 1e3),
        'max_mm': float(errors.max() * 1e3),
        'samples': int(tracking.sum()),
    }


def main(argv=None):
    """Run the benchmark and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--quick', action='store_true', help='fewer repetitions (noisier)')
    parser.add_argument('--no-ros', action='store_true', help='skip the ROS loop timing')
    parser.add_argument('--json', type=Path, help='also write the figures to this file')
    parser.add_argument('--no-fast', action='store_true',
                        help="time only the controller's numpy path (default: numba and numpy)")
    add_option(parser)
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    repeats = 3 if args.quick else 8

    ur10 = UR10Model(tool_offset=TOOL_OFFSET)
    path = g_plan()[0]
    q0 = start_configuration(ur10, path)
    results = {'machine': f'{platform.processor() or platform.machine()}, {os.cpu_count()} cores',
               'python': platform.python_version()}

    print(f'# Controller benchmark ({results["machine"]}, Python {results["python"]})\n')
    print('Task: ET-DMP letter G, 0.2 m, 2 s, 6D tool-tip pose, kinematic plant at 125 Hz.\n')
    rows = []
    for delay in (0, 1):
        for fast in ((False,) if args.no_fast else (True, False)):
            steps, core, errors = bench_ours(ur10, path, q0, delay, repeats, fast)
            ours = {'step': percentiles(steps), 'core': percentiles(core),
                    'rms_mm': float(np.sqrt(np.mean(errors ** 2)) * 1e3),
                    'max_mm': float(errors.max() * 1e3)}
            kind = 'numba' if fast else 'numpy'
            rows.append((f'etdmp_ros TrajectoryController.step ({kind})', delay, ours['step'],
                         ours))
            rows.append((f'etdmp_ros IK core (FK + Jacobian + solve, {kind})', delay,
                         ours['core'], None))
            results[f'ours_{kind}_delay{delay}'] = ours
        try:
            import pink  # noqa: F401
        except ImportError:
            print('pin-pink is not installed here: run in .venv-bench (make .venv-bench/'
                  '.installed)\n')
            continue
        for solver in ('daqp', 'quadprog'):
            times, perr = bench_pink(ur10, path, q0, delay, solver, max(2, repeats // 2))
            theirs = {'step': percentiles(times),
                      'rms_mm': float(np.sqrt(np.mean(perr ** 2)) * 1e3),
                      'max_mm': float(perr.max() * 1e3)}
            rows.append((f'pin-pink solve_ik ({solver})', delay, theirs['step'], theirs))
            results[f'pink_{solver}_delay{delay}'] = theirs

    with printed() as tables:
        print('| per control step | plant delay | p50 (us) | p99 (us) | tracking RMS (mm) | '
              'max (mm) |')
        print('|---|---|---|---|---|---|')
        for name, delay, (p50, p99), track in rows:
            t = (f'{track["rms_mm"]:.4f} | {track["max_mm"]:.4f}' if track else ' | ')
            print(f'| {name} | {delay} period | {p50:.1f} | {p99:.1f} | {t} |')
        for kind in ('numba', 'numpy'):
            ours = results.get(f'ours_{kind}_delay1')
            if ours is None:
                continue
            print(f'\n{kind}: target p99 compute <= 200 us: step {ours["step"][1]:.0f} us, '
                  f'IK core {ours["core"][1]:.0f} us.')
            for solver in ('daqp', 'quadprog'):
                key = f'pink_{solver}_delay1'
                if key in results:
                    ratio = results[key]['step'][0] / ours['step'][0]
                    core = results[key]['step'][0] / ours['core'][0]
                    print(f'pink ({solver}) / ours ({kind}) per step (p50): {ratio:.1f}x for the '
                          f'whole step, {core:.1f}x for the IK core (target >= 3x); tracking RMS '
                          f'{results[key]["rms_mm"]:.3f} vs {ours["rms_mm"]:.4f} mm (plant one '
                          'period late).')

        if not args.no_ros:
            print('\n| through ROS (ur10_sim + controller) | command period p50 / p99 / max '
                  '(ms) | jitter p50 / p99 (ms) | joint state -> command p50 / p99 (ms) | '
                  'tracking RMS / max (mm) |')
            print('|---|---|---|---|---|')
            for rate in (125.0, 500.0):
                try:
                    r = bench_ros(rate, ur10, path)
                except (TimeoutError, OSError) as exc:
                    print(f'| {rate:g} Hz | failed: {exc} | | | |')
                    continue
                results[f'ros_{rate:g}'] = r
                print(f'| {rate:g} Hz | {r["period_p50_ms"]:.2f} / {r["period_p99_ms"]:.2f} / '
                      f'{r["period_max_ms"]:.1f} | {r["jitter_p50_ms"]:.2f} / '
                      f'{r["jitter_p99_ms"]:.2f} | {r["latency_p50_ms"]:.2f} / '
                      f'{r["latency_p99_ms"]:.2f} | {r["rms_mm"]:.3f} / {r["max_mm"]:.3f} |')
    if not args.no_docs:
        task = ('Task: ET-DMP letter G, 0.2 m, 2 s, 6D tool-tip pose, kinematic plant at 125 Hz; '
                f'{repeats} runs per row ({max(2, repeats // 2)} for pink).')
        publish('controller', f'{task}\n\n{tables.getvalue().strip()}',
                command('controller', argv), load=load)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

"""
The closed-loop demo (``make demo``): see, plan, write, measure.

``python -m etdmp_ros.demo [--skill G|P|R|W|wipe|stir] [--method etdmp|dmp] [--out out/demo]
[--move-goal]`` starts the four nodes as separate processes, exactly as ``ros2 run`` starts them
(:mod:`etdmp_ros.ros.processes`; ``ur10_sim``, ``perception``, ``dmp_server``, ``controller``;
parameters: config/scene.yaml, then the node's own file, then a small overrides file), on a DDS
domain of its own with localhost-only discovery, dmp_server and the controller on simulated time
(``use_sim_time``: plans are stamped with the ROS clock, joint states judged stale on the
simulation's time; the others stamp with their inputs' stamps). Then it

1. waits until the camera has shown the goal marker and the obstacles to ``perception``;
2. asks ``/generalize`` for the plain-DMP baseline without executing it (``dmp_server``
   parameters ``method: dmp``, ``execute: false``, set through its SetParameters service), then
   for the real plan (``method: etdmp``, ``execute: true``), both with empty frame ids: from the
   tool's current position to the perceived goal (stir: to an explicit goal in the bottle);
3. records (:mod:`etdmp_ros.demo.recording`) every topic of the system, as ``ros2 bag record``
   would, until the controller is idle again; it follows the controller's status and keeps
   the camera frames for the pictures;
4. stops the nodes with SIGINT (Ctrl-C), writes the recording, ``demo.mcap`` (rosbag2 MCAP,
   camera images as CompressedImage; ``metadata.yaml`` beside it), measures from it
   (:mod:`etdmp_ros.demo.metrics`, which defines the numbers; the nodes' own figures come
   from their events in it) and writes ``plot.png``, ``camera_start.png``,
   ``camera_middle.png``, ``camera_end.png``, ``animation.gif`` (:mod:`etdmp_ros.demo.pictures`),
   ``metrics.json`` and ``recording.npz`` to the output folder, node logs to ``<out>/logs/``;
5. fails (exit code 1, after writing all of it) when the simulation saw the arm or the tool
   touch an obstacle, the bottle or the table (``metrics.json``'s ``contacts``, the
   simulation's ground truth), as it does when the controller stopped the motion.

With ``--move-goal`` (``make demo MOVE_GOAL=1``) the demo moves the goal marker
(:data:`etdmp_ros.demo.scenario.MOVE_GOAL_BY`, 4 cm) at
:data:`~etdmp_ros.demo.scenario.MOVE_GOAL_AT` of the letter's duration after tracking began, as
``ros2 param set /ur10_sim goal_position`` would; dmp_server follows it (online ET-DMP) and the
metrics measure the run against the moved marker and the plan as executed
(:mod:`etdmp_ros.demo.metrics`). For stir it moves the bottle instead
(:data:`~etdmp_ros.demo.scenario.MOVE_BOTTLE_BY`, 2 cm, at
:data:`~etdmp_ros.demo.scenario.MOVE_BOTTLE_AT`, as ``ros2 param set /ur10_sim bottle.position``
would), and the stir request targets the perceived bottle (dmp_server's ``goal_object:
bottle``), which dmp_server then follows.

The goal, obstacles and start of each skill: :mod:`etdmp_ros.demo.scenario`.
"""

from dataclasses import dataclass, field
import json
import os
from pathlib import Path
import sys
import time

from etdmp_ros.demo.cpu_monitor import CpuMonitor
from etdmp_ros.demo.metrics import compute_metrics, MeasurementError, Run, system_figures
from etdmp_ros.demo.pictures import plot_run, write_pictures
from etdmp_ros.demo.recording import (read_streams, Recorder, RecorderError, save_recording,
                                      write_bag)
from etdmp_ros.demo.scenario import Scenario, ScenarioError
from etdmp_ros.dmp import METHOD_LABELS
from etdmp_ros.geometry.camera import CameraIntrinsics
from etdmp_ros.ros.processes import module_argv, NodeExited, SystemProcesses
import numpy as np

STARTUP_TIMEOUT = 150.0
STATUS_FAILURES = ('unreachable', 'halted-singularity', 'halted-joint-limit', 'stale-input')
#: Errors of the parts that end the demo (reported as a DemoError with their message).
PART_ERRORS = (NodeExited, RecorderError, ScenarioError, MeasurementError)
#: The recording of the whole run in the output folder (with rosbag2's metadata.yaml beside it).
BAG_NAME = 'demo.mcap'


class DemoError(RuntimeError):
    """The demo could not run to the end; the message says why (and where the logs are)."""


@dataclass
class Options:
    """How to run the demo (the command line's options)."""

    skill: str = 'G'
    method: str = 'etdmp'
    out: Path = Path('out/demo')
    animation: bool = True
    #: False: no camera images are recorded and no pictures drawn (only plot.png).
    pictures: bool = True
    layout: str = 'skill'
    timeout: float = 60.0
    #: Folder of the parameter files (None: the package's config folder).
    config_dir: Path = None
    #: ``command(node, param_files)`` -> argv (etdmp_ros.ros.processes: module_argv,
    #: installed_command(install)).
    command: object = module_argv
    quiet: bool = False
    #: Extra node parameters, {node: {name: value}}, after the scene's (e.g. control_rate).
    parameters: dict = field(default_factory=dict)
    #: Move the goal marker by MOVE_GOAL_BY at MOVE_GOAL_AT of the movement (online ET-DMP).
    move_goal: bool = False
    #: A taught stir (.mcap of /joint_states) instead of the built-in one (scenario.Scenario).
    demo_file: Path = None
    #: ``before_plans(recorder, nodes, scenario, progress)``: called once the system is up,
    #: before the demo's plans (e.g. a fault during an earlier motion: test/two_hosts.py);
    #: what it returns is ``metrics['before_plans']``.
    before_plans: object = None


@dataclass
class _Live:
    """What the demo saw while the system ran (filled in by the steps of :func:`_drive`)."""

    n_status: int = 0
    goal_truth: np.ndarray = None
    goal_seen: np.ndarray = None
    goal_stamp_lag: float = None
    obstacles_truth: np.ndarray = None
    obstacles_seen: np.ndarray = None
    other_plan: tuple = None
    call_ns: int = None
    stamp: int = None
    plan: tuple = None
    start: np.ndarray = None
    goal: np.ndarray = None
    end_ns: int = None
    failure: str = None
    #: (sim ns, marker before, marker after) of the goal move (``--move-goal``).
    goal_move: tuple = None
    #: What :attr:`Options.before_plans` returned.
    before_plans: object = None


class _Progress:

    def __init__(self, quiet):
        self.quiet = quiet
        self.start = time.monotonic()

    def __call__(self, text):
        if not self.quiet:
            print(f'[{time.monotonic() - self.start:6.1f} s] {text}', flush=True)


def _wait_until(predicate, timeout, what, nodes, seen=None):
    """Wait for ``predicate``; on timeout raise DemoError with ``seen()`` (what there is)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        nodes.check_alive()
        if time.monotonic() > deadline:
            found = f': {seen()}' if seen is not None else ''
            raise DemoError(f'timed out after {timeout:g} s waiting for {what}{found}')
        time.sleep(0.05)


def _log_end(nodes, node, lines=8):
    """Return the last ``lines`` lines of ``node``'s log, indented, for an error message."""
    return '\n    '.join(['', *nodes.log(node).splitlines()[-lines:]])


def _perceived(recorder, nodes):
    """Say what perception has published so far, and how its log ends."""
    goal = ('not seen' if recorder.goal_seen is None
            else f'at {np.round(recorder.goal_seen, 3).tolist()}')
    obstacles = ('none published' if recorder.obstacles_seen is None else
                 f'{len(recorder.obstacles_seen)} at '
                 f'{np.round(recorder.obstacles_seen, 3).tolist()}')
    return (f"goal {goal}; obstacles {obstacles}; the end of perception's log:"
            + _log_end(nodes, 'perception'))


def _generalize(recorder, goal, attempts=20):
    """
    Call /generalize; return (stamp, t, positions, quaternions, reason if refused).

    Right after start-up dmp_server may not have heard the tool or the goal yet (its
    subscriptions match after its service is offered): such a refusal is retried.
    """
    for _ in range(attempts):
        seen = len(recorder.events_of('dmp_server', 'plan_refused'))
        stamp, t, positions, quaternions = recorder.call_generalize(goal)
        if len(positions):
            return stamp, t, positions, quaternions, ''
        refused = recorder.wait_for_event('dmp_server', 'plan_refused', seen, timeout=1.0)
        reason = refused.values['reason'] if refused is not None else 'no plan_refused event'
        if refused is not None and ' yet' not in reason:
            break
        time.sleep(0.2)
    return stamp, t, positions, quaternions, reason


# ------------------------------------------------------------------------ the steps of a run


def _wait_for_the_system(recorder, nodes, scenario, live, progress):
    """Wait for the simulation, for perception to see the scene and for the planner."""
    expected = scenario.obstacle_count
    _wait_until(lambda: len(recorder.tip) > 0 and recorder.goal_truth is not None
                and recorder.obstacles_truth is not None, STARTUP_TIMEOUT,
                'the simulation (/ur10_sim/ground_truth/*)', nodes)
    progress('simulation running; waiting for the camera to show the goal and obstacles')
    _wait_until(lambda: recorder.goal_seen is not None
                and recorder.obstacles_seen is not None
                and len(recorder.obstacles_seen) == expected, STARTUP_TIMEOUT,
                f'perception to see the goal and {expected} obstacles', nodes,
                lambda: _perceived(recorder, nodes))
    progress(f'perceived goal {np.round(recorder.goal_seen, 3).tolist()}, obstacles '
             f'{np.round(recorder.obstacles_seen, 3).tolist()}')
    _wait_until(lambda: recorder.generalize.service_is_ready()
                and any(t.split(':')[0] == 'idle' for _, t in recorder.state()),
                STARTUP_TIMEOUT, 'dmp_server (/generalize) and the controller (idle)', nodes)
    recorder.keep_frames_after = recorder.sim_ns - int(0.5e9)
    live.goal_truth, live.goal_seen = recorder.goal_truth, recorder.goal_seen
    # perception stamps its output with the image's (simulated) stamp.
    live.goal_stamp_lag = (recorder.sim_ns - recorder.goal_seen_stamp) * 1e-9
    live.obstacles_truth, live.obstacles_seen = recorder.obstacles_truth, recorder.obstacles_seen


def _plan_for_comparison(recorder, nodes, scenario, other, live, progress):
    """Plan with the other method first, not executed, from the same start to the same goal."""
    recorder.set_server_parameters(method=other, execute=False)
    _, o_t, o_x, _, reason = _generalize(recorder, scenario.request_goal)
    if len(o_x):
        progress(f'{METHOD_LABELS[other]} plan (not executed): {len(o_x)} poses over '
                 f'{o_t[-1]:.2f} s')
        live.other_plan = (other, o_t, o_x)
    else:
        progress(f'{METHOD_LABELS[other]} plan refused: {reason}')
        live.other_plan = (other, None, reason)


def _plan_and_execute(recorder, nodes, scenario, method, live, progress):
    """Ask for the plan that the controller executes."""
    recorder.set_server_parameters(method=method, execute=True)
    live.n_status = len(recorder.state())
    live.start = recorder.latest_tip()
    live.call_ns = recorder.sim_ns
    recorder.request_snapshot('start', live.call_ns)
    live.stamp, p_t, p_x, p_q, reason = _generalize(recorder, scenario.request_goal)
    if not len(p_x):
        raise DemoError(f'/generalize returned no plan: {reason}')
    # The plan starts where dmp_server saw the tool (projected onto the task plane for 2D
    # skills) and ends at the goal it was given (the perceived one, projected).
    live.plan = (p_t, p_x, p_q)
    live.start = p_x[0]
    live.goal = p_x[-1] if scenario.explicit_goal is None else scenario.explicit_goal
    progress(f'{METHOD_LABELS[method]} plan: {len(p_x)} poses over {p_t[-1]:.2f} s,'
             f' published on /etdmp/path; the controller executes it')


def _move_goal(recorder, move, live, progress, scenario):
    """
    Move the goal marker in the simulation, as ``ros2 param set /ur10_sim goal_position``.

    Stir: the bottle (``bottle.position``); the move is then recorded as the goal's, the
    bottle's mouth plus the skill's goal offset, before and after.
    """
    if scenario.perceived_bottle:
        mouth = np.asarray(recorder.bottle_truth, dtype=float)
        moved = mouth + move
        recorder.set_parameters('ur10_sim', **{'bottle.position': moved[:2].tolist()})
        before, after = mouth + scenario.goal_offset, moved + scenario.goal_offset
        what = 'bottle'
    else:
        before = np.asarray(recorder.goal_truth, dtype=float)
        after = before + move
        recorder.set_parameters('ur10_sim', goal_position=after.tolist())
        what = 'goal marker'
    live.goal_move = (recorder.sim_ns, before, after)
    progress(f'{what} moved by {np.linalg.norm(after - before) * 1e3:.0f} mm; the goal is now '
             f'{np.round(after, 3).tolist()}')


def _follow_the_controller(recorder, nodes, live, timeout, progress, move=None, tau=None,
                           scenario=None):
    """
    Report the controller's status until it is idle after the plan, or has failed.

    ``move`` (3,): move the goal marker (stir: the bottle) by this at ``scenario.move_at`` of
    the movement's duration ``tau`` (s; the plan's without its obstacle margin) after tracking
    began (``--move-goal``).
    """
    duration = live.plan[0][-1]
    tau = duration if tau is None else tau
    deadline = time.monotonic() + duration + timeout
    seen = 0
    move_at = None
    while live.end_ns is None:
        nodes.check_alive()
        if move_at is not None and live.goal_move is None and recorder.sim_ns >= move_at:
            _move_goal(recorder, move, live, progress, scenario)
            deadline += duration
        news = recorder.state(live.n_status)
        for ns, text in news[seen:]:
            word = text.split(':')[0]
            progress(f'controller: {text} (t = {(ns - live.call_ns) * 1e-9:.2f} s simulated)')
            if word == 'tracking' and move_at is None:
                recorder.request_snapshot('middle', ns + int(duration * 0.5e9))
                if move is not None:
                    move_at = ns + int(scenario.move_at * tau * 1e9)
            if word in STATUS_FAILURES:
                live.failure, live.end_ns = text, ns
            elif word == 'idle' and any(t.split(':')[0] in ('holding', 'tracking')
                                        for _, t in news):
                live.end_ns = ns
        seen = len(news)
        if time.monotonic() > deadline:
            raise DemoError('timed out waiting for the controller to finish; status '
                            f'{[t for _, t in news]}')
        time.sleep(0.02)


def _last_frame(recorder, live):
    if not recorder.images:
        return
    recorder.request_snapshot('end', live.end_ns + int(0.2e9))
    deadline = time.monotonic() + 5.0
    while 'end' not in recorder.snapshots and time.monotonic() < deadline:
        time.sleep(0.05)
    if recorder.snapshot('end') is None:
        raise DemoError('no camera frame arrived after the end of the motion')


def _drive(options, scenario, recorder, nodes, live, progress):
    """Run the demo's steps against the running system, filling in ``live``."""
    other = 'dmp' if options.method == 'etdmp' else 'etdmp'
    move = scenario.goal_move if options.move_goal else None   # ScenarioError if it cannot
    _wait_for_the_system(recorder, nodes, scenario, live, progress)
    if options.before_plans is not None:
        live.before_plans = options.before_plans(recorder, nodes, scenario, progress)
    _plan_for_comparison(recorder, nodes, scenario, other, live, progress)
    _plan_and_execute(recorder, nodes, scenario, options.method, live, progress)
    tau = float(scenario.server['duration']) or float(scenario.demo.duration)
    _follow_the_controller(recorder, nodes, live, options.timeout, progress, move, tau,
                           scenario)
    _last_frame(recorder, live)


# ------------------------------------------------------------------------------- measuring


def _measure(scenario, options, live, rec, status, out):
    """
    Return (run, metrics, extra) of the recording.

    A controller failure before anything could be measured is reported as that failure.
    """
    run = Run(scenario, options.method, np.asarray(live.start), np.asarray(live.goal),
              live.plan, live.other_plan, rec, status, live.call_ns, live.stamp, live.end_ns,
              live.goal_truth, live.goal_seen, live.obstacles_truth, live.obstacles_seen,
              goal_move=live.goal_move)
    try:
        metrics, extra = compute_metrics(run)
    except MeasurementError as err:
        if live.failure:   # stopped before it tracked anything worth measuring: say why
            raise DemoError(f'the controller stopped: {live.failure} (nothing measured: {err}; '
                            f'logs in {out / "logs"})') from None
        raise
    return run, metrics, extra


def _add_system_figures(metrics, live, codes, monitor, rec):
    metrics['node_exit_codes'] = codes
    metrics['perceived_goal_stamp_age_s'] = live.goal_stamp_lag
    metrics['controller_failure'] = live.failure
    if live.before_plans is not None:
        metrics['before_plans'] = live.before_plans
    metrics['system'] = system_figures(monitor, rec, live.call_ns, live.end_ns)
    # The controller's own tracking error (reference minus its forward kinematics), from the
    # event it publishes at the end of the path.
    metrics['controller_reported_tracking_max_mm'] = (
        metrics['system'].get('controller', {}).get('tracking_max_mm'))


def _write_bag(path, recorder):
    """Write the recording (rosbag2 MCAP); return its figures for metrics.json."""
    started = time.monotonic()
    counts = write_bag(path, recorder)
    return {'file': path.name, 'bytes': path.stat().st_size,
            'write_s': time.monotonic() - started, 'message_counts': counts,
            'not_recorded': dict(recorder.unrecorded)}


def _keep_recording_of_failed_run(path, recorder, progress):
    """Write what was recorded of a run that did not finish (what happened is in it)."""
    try:
        write_bag(path, recorder)
        progress(f'the run did not finish; what was recorded is in {path}')
    except Exception as err:    # noqa: B902 - the run's own error is the one to report
        progress(f'the run did not finish, and its recording could not be written: {err}')


def _write_outputs(out, run, metrics, extra, recorder, rec, options):
    """Write the plot, the pictures, the recording; return the paths written (not metrics.json)."""
    intrinsics = recorder.camera_info or CameraIntrinsics.from_fovy(640, 480, 42.5)
    written = [out / 'plot.png']
    plot_run(written[0], run, metrics, extra)
    if options.pictures:
        snapshots = {name: recorder.snapshot(name) for name in ('start', 'middle', 'end')}
        written += write_pictures(out, run, rec, snapshots, recorder.frames, intrinsics,
                                  options.animation, t0=extra['t0'])
    save_recording(out / 'recording.npz', rec, run.plan, run.other, extra['t0'],
                   extra['executed'] if run.goal_move is not None else None)
    return written


def run_demo(options, env):
    """
    Run the demo once; return (metrics, written files).

    ``env``: the environment of the node processes (see
    :func:`etdmp_ros.ros.processes.isolated_environment`); this process must already be on the same
    DDS domain settings (its ``os.environ``). Raises DemoError saying why it could not finish.
    """
    try:
        return _run_demo(options, env)
    except PART_ERRORS as err:
        raise DemoError(str(err)) from err


def _run_demo(options, env):
    progress = _Progress(options.quiet)
    wall = time.monotonic()
    out = Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    scenario = Scenario(options.config_dir, options.skill, options.layout, options.parameters,
                        options.demo_file,
                        perceived_bottle=options.move_goal and options.skill == 'stir')
    progress(f'starting ur10_sim, perception, dmp_server and controller (ROS_DOMAIN_ID '
             f'{env["ROS_DOMAIN_ID"]}, localhost only; logs in {out / "logs"})')
    recorder = Recorder(env['ROS_DOMAIN_ID'], animation=options.animation and options.pictures,
                        images=options.pictures)
    nodes = SystemProcesses(scenario.param_files, out / 'logs', env, options.command)
    monitor = CpuMonitor({**{n: p.pid for n, p in nodes.processes.items()},
                          'demo': os.getpid()},
                         lambda: recorder.sim_ns * 1e-9 if recorder.sim_ns else None).start()
    live = _Live()
    finished = False
    try:
        _drive(options, scenario, recorder, nodes, live, progress)
        finished = True
    finally:
        monitor.stop()
        codes = nodes.stop(interrupted=sys.exc_info()[0] is KeyboardInterrupt)
        recorder.close()
        if not finished:
            _keep_recording_of_failed_run(out / BAG_NAME, recorder, progress)
    progress(f'nodes stopped (exit codes {codes}); writing {out / BAG_NAME}, measuring from it')
    bag_figures = _write_bag(out / BAG_NAME, recorder)
    rec = read_streams(out / BAG_NAME)
    status = rec['status'][live.n_status:]
    run, metrics, extra = _measure(scenario, options, live, rec, status, out)
    _add_system_figures(metrics, live, codes, monitor, rec)
    metrics['recording'] = bag_figures
    written = _write_outputs(out, run, metrics, extra, recorder, rec, options)
    metrics['wall_time_s'] = time.monotonic() - wall
    (out / 'metrics.json').write_text(json.dumps(metrics, indent=2) + '\n')
    written += [out / 'metrics.json', out / 'recording.npz', out / BAG_NAME,
                out / 'metadata.yaml']
    if live.failure:
        raise DemoError(f'the controller stopped: {live.failure} (files written to {out})')
    return metrics, written

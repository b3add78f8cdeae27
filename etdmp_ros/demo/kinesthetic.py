"""
Kinesthetic teaching, simulated: lead the arm through a movement and record ``/joint_states``.

``python -m etdmp_ros.demo.kinesthetic [--script FILE] [--out out/kinesthetic]`` (``make
kinesthetic``) does with the simulated UR10 what a person does with a real one in freedrive
while ``ros2 bag record /joint_states`` runs:

1. starts ``ur10_sim`` alone (as ``ros2 run`` would, camera off), the stirrer above the bottle
   where the demo's stir starts (:mod:`etdmp_ros.demo.scenario`);
2. once this process receives its joint states, sets its ``teach_script`` parameter (as ``ros2
   param set /ur10_sim teach_script <file>`` would): the teaching mode leads the tool along the
   script (:class:`etdmp_ros.robot.GuidedMotion`, a hand in freedrive) until ``~/teaching``
   says ``done``;
3. writes what it received, every topic as the demo's recorder keeps them
   (:class:`etdmp_ros.demo.recording.Recorder`, ``ros2 bag record -a``: ``/joint_states``, the
   simulation's true tool tip, ...), to ``<out>/<name>.mcap`` (rosbag2 MCAP, ``metadata.yaml``
   beside it).

The script defaults to :func:`hand_stir`, a stir made here as a hand would make it, written to
``<out>/<name>_script.csv``: not the built-in stir, and learning never sees it, only the joint
states. Learn from the recording with dmp_server's ``demo_files`` (the skill is named after the
file, ``stir_by_hand``), or repeat it from another quadrant with
``make demo SKILL=stir DEMO_FILE=<out>/stir_by_hand.mcap``.
"""

import argparse
import math
import os
from pathlib import Path
import sys
import time

from etdmp_ros.demo.recording import Recorder, RecorderError, write_bag
from etdmp_ros.demo.scenario import Scenario, stir_start, stir_start_joints
from etdmp_ros.dmp import Demonstration, load_demo, save_demo
from etdmp_ros.ros.processes import (DISCOVERY_VARIABLES, isolated_environment, module_argv,
                                     NodeProcess)
import numpy as np
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

NAME = 'stir_by_hand'
JOINT_STATES = '/joint_states'
TOOL_TIP = '/ur10_sim/ground_truth/tool_tip'
TEACHING = '/ur10_sim/teaching'
#: Rest before and after the hand's movement in the default script (s): a person takes hold of
#: the arm, moves it, lets go; the recording is trimmed to the motion when it is learned.
REST = 0.5
STARTUP_TIMEOUT = 60.0


class KinestheticError(RuntimeError):
    """The recording could not be made (the simulation exited, the script was refused)."""


def _smoothstep(a, b, s):
    x = np.clip((s - a) / (b - a), 0.0, 1.0)
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))      # C2, flat at both ends


def hand_stir(start, mouth, duration=6.0, rate=100.0, turns=3.0):
    """
    Return (t, positions (n, 3)) of a stir a hand makes from ``start`` into the bottle.

    ``mouth``: the bottle mouth's centre (base_link). Over the mouth, down into the bottle while
    circling (a radius of 2.2 cm that breathes by 15 %, ``turns`` turns, quicker in the middle),
    and on the axis near the bottom at the end; at rest for :data:`REST` s before and after.
    Every part is C2, so the hand's speed and acceleration start and end at zero.
    """
    start, mouth = np.asarray(start, float), np.asarray(mouth, float)
    rel = start - mouth
    u = np.linspace(0.0, 1.0, int(round(duration * rate)) + 1)    # each part starts, ends flat
    phi0 = math.atan2(rel[1], rel[0])
    r0 = math.hypot(rel[0], rel[1])
    radius = 0.022 * (1.0 + 0.15 * np.sin(5.0 * np.pi * u))
    radius = r0 + (radius - r0) * _smoothstep(0.0, 0.3, u)          # over the mouth first
    radius *= 1.0 - _smoothstep(0.8, 1.0, u)                        # onto the axis at the end
    z = rel[2] + (-0.13 - rel[2]) * _smoothstep(0.05, 1.0, u) ** 0.7
    phi = phi0 + 2.0 * np.pi * turns * _smoothstep(0.05, 0.95, u)
    moving = mouth + np.column_stack([radius * np.cos(phi), radius * np.sin(phi), z])
    n_rest = int(round(REST * rate))
    positions = np.vstack([np.repeat(moving[:1], n_rest, 0), moving,
                           np.repeat(moving[-1:], n_rest, 0)])
    return np.arange(len(positions)) / rate, positions


def _messages(recorder, topic):
    """Return the messages ``recorder`` received on ``topic`` so far, [(receipt ns, CDR)]."""
    with recorder.lock:
        stream = recorder.streams.get(topic)
        return list(stream.messages) if stream is not None else []


def _teaching(recorder):
    """Return the latest state ur10_sim's teaching mode published, or ''."""
    received = _messages(recorder, TEACHING)
    return deserialize_message(received[-1][1], String).data if received else ''


def record(out, env, script=None, name=None, config_dir=None, command=module_argv,
           progress=print):
    """
    Record a kinesthetic demonstration in the simulation; return (bag path, message counts).

    ``script``: a file of tool tip positions (3 columns, metres, with times) or None for
    :func:`hand_stir`; ``env``: the node's environment (:func:`isolated_environment`), this
    process on the same domain settings. Raises KinestheticError.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    scenario = Scenario(config_dir, 'stir')
    # The hand takes hold of the stirrer upright (the tool pointing down), as the nodes start it
    # for a position-only skill, not tilted as the built-in stir starts.
    scenario.overrides['ur10_sim']['initial_joint_positions'] = stir_start_joints(
        scenario, scenario.tool_rotation).tolist()
    if script is None:
        name = name or NAME
        t, positions = hand_stir(stir_start(scenario), scenario.bottle_mouth)
        script = (out / f'{name}_script.csv').resolve()
        save_demo(script, Demonstration(name, positions, t))
    else:
        script = Path(script).resolve()
        name = name or script.stem
        load_demo(script)      # a file that cannot be read fails here, with its reason
    scenario.overrides['ur10_sim']['camera_rate'] = 0.0
    logs = out / 'logs'
    logs.mkdir(exist_ok=True)
    recorder = Recorder(env['ROS_DOMAIN_ID'], animation=False)   # as ros2 bag record -a
    sim = NodeProcess(command('ur10_sim', scenario.param_files('ur10_sim', logs)),
                      logs / 'ur10_sim.log', env)
    try:
        progress(f'ur10_sim started (ROS_DOMAIN_ID {env["ROS_DOMAIN_ID"]}); waiting for its '
                 'joint states')
        _wait(lambda: len(_messages(recorder, JOINT_STATES)) > 10, STARTUP_TIMEOUT, sim,
              'no joint states')
        try:
            recorder.set_parameters('ur10_sim', teach_script=str(script))
        except RecorderError as err:
            raise KinestheticError(f'the script was not taken: {err}') from None
        progress(f'teaching mode: {script} leads the arm; recording {JOINT_STATES}')
        duration = float(load_demo(script).duration)
        _wait(lambda: _teaching(recorder).startswith('done'), 3 * duration + STARTUP_TIMEOUT,
              sim, f'the script did not finish (teaching: {_teaching(recorder)!r})')
        time.sleep(0.2)
    finally:
        code = sim.stop()
        recorder.close()
    path = out / f'{name}.mcap'
    counts = write_bag(path, recorder)
    progress(f'ur10_sim stopped (exit code {code}); wrote {path}: {counts[JOINT_STATES]} joint '
             'states')
    return path, counts


def _wait(condition, timeout, process, what):
    deadline = time.monotonic() + timeout
    while not condition():
        if process.returncode is not None:
            tail = '\n'.join(process.log().splitlines()[-10:])
            raise KinestheticError(f'ur10_sim exited with code {process.returncode}:\n{tail}')
        if time.monotonic() > deadline:
            raise KinestheticError(f'{what} after {timeout:.0f} s')
        time.sleep(0.05)


def main(argv=None):
    """Record a kinesthetic demonstration from the command line; return the exit code."""
    parser = argparse.ArgumentParser(
        prog='python -m etdmp_ros.demo.kinesthetic',
        description="Kinesthetic teaching in the simulation: ur10_sim's teaching mode leads "
                    'the arm along a script as a hand in freedrive would; /joint_states is '
                    'recorded to a rosbag2 .mcap that dmp_server learns a skill from.')
    parser.add_argument('--script', type=Path, default=None, metavar='FILE',
                        help='tool tip positions (.csv/.npy/.npz, 3 columns in metres, with '
                             'times) as offsets from the start; default: a stir by hand')
    parser.add_argument('--out', type=Path, default=Path('out/kinesthetic'),
                        help='output folder (default out/kinesthetic)')
    parser.add_argument('--name', default=None, help="the recording's (and skill's) name "
                        f"(default: {NAME}, or the script's file stem)")
    args = parser.parse_args(argv)
    env = isolated_environment()
    os.environ.update(env)
    for variable in DISCOVERY_VARIABLES:
        os.environ.pop(variable, None)
    try:
        path, _ = record(args.out, env, args.script, args.name)
    except (KinestheticError, ValueError, OSError) as err:
        print(f'kinesthetic recording failed: {err}', file=sys.stderr)
        return 1
    print(f'learn it: make demo SKILL=stir DEMO_FILE={path}  (or dmp_server demo_files: '
          f'["{path}"])')
    return 0


if __name__ == '__main__':
    sys.exit(main())

"""
The demo's command line: ``python -m etdmp_ros.demo`` (``make demo``); its printed summary.

The options are :class:`etdmp_ros.demo.run.Options`; the run itself is
:func:`etdmp_ros.demo.run.run_demo`.
"""

import argparse
import os
from pathlib import Path
import sys

from etdmp_ros.demo.metrics import format_nrmse
from etdmp_ros.demo.run import DemoError, Options, run_demo
from etdmp_ros.demo.scenario import SKILLS
from etdmp_ros.dmp import METHOD_LABELS, METHODS
from etdmp_ros.ros.processes import DISCOVERY_VARIABLES, isolated_environment


def _contact_failure(metrics):
    """Return why the run's contacts fail it (there were some, or they were not recorded)."""
    if metrics['contacts'] is None:
        return ('no contact ground truth was recorded (/ur10_sim/ground_truth/contacts): '
                'whether the arm touched anything is unknown')
    return (f'the arm touched the workcell in {metrics["contacts"]} ticks: '
            f'{", ".join(metrics["contact_pairs"])} (up to '
            f'{metrics["contact_max_depth_mm"]:.1f} mm deep)')


def _ms(value, scale=1.0):
    return 'n/a' if value is None else f'{value * scale:.0f} ms'


def _move_summary(m):
    """Return the summary's lines about a goal that moved (``--move-goal``)."""
    follow = m.get('goal_follow', {})
    if m['switch_path_time_s'] is None:
        return [f'  {m["moved_object"]} moved by {m["goal_moved_by_mm"]:.0f} mm at path time '
                f'{follow.get("goal_moved_at_path_time_s", float("nan")):.2f} s: the plan was '
                'NOT re-planned (goal error above is to the moved marker)']
    ratio = m['switch_speed_ratio_min']
    return [
        f'  {m["moved_object"]} moved by {m["goal_moved_by_mm"]:.0f} mm at path time '
        f'{follow["goal_moved_at_path_time_s"]:.2f} s; re-planned online from '
        f'{m["switch_path_time_s"]:.2f} s ({m["plan_updates"]} update(s)); first plan nRMSE '
        f'{format_nrmse(m["nrmse_original_plan"])}; tool speed after the switch >= '
        + ('n/a' if ratio is None else f'{100 * ratio:.0f} %') + " of the plan's",
        f'  following: {m["moved_object"]} moved -> first command on the new path '
        f'{_ms(follow["goal_change_to_first_command_s"], 1e3)} simulated (perception '
        f'{_ms(follow["perception_latency_s"], 1e3)}, confirmation '
        f'{_ms(follow["confirmation_wait_ms"])}); dmp_server {_ms(follow["dmp_server_ms"])}, '
        f'goal seen by dmp_server -> first command {_ms(follow["end_to_end_ms"])}',
    ]


def summary(metrics, written):
    """Return the short summary printed at the end."""
    m = metrics
    method = METHOD_LABELS[m['method']]
    other = 'dmp' if m['method'] == 'etdmp' else 'etdmp'
    value = m['nrmse_dmp_baseline'] if other == 'dmp' else m.get('nrmse_etdmp_plan')
    lines = [
        f'{m["skill"]} with {method}: the pen started in quadrant {m["start_quadrant"]} of the '
        f'goal (demonstration: {m["demo_quadrant"]}; start direction turned by '
        f'{m["start_turn_deg"]:+.0f} deg), goal: {m["goal_source"]}',
        f'  nRMSE vs the demonstration: {method} plan {format_nrmse(m["nrmse_plan"])}, '
        f'executed pen trace {format_nrmse(m["nrmse_trace"])}; {METHOD_LABELS[other]} plan '
        '(not executed) ' + ('refused' if value is None else format_nrmse(value)),
        f'  tracking error RMS {m["tracking_rms_mm"]:.3f} mm, max {m["tracking_max_mm"]:.3f} mm;'
        f' goal error {m["goal_error_mm"]:.2f} mm; min obstacle clearance '
        f'{m["min_clearance_mm"]:.1f} mm',
        f'  commands: {m["commands_nonzero"]} moving; up to '
        f'{100 * m["max_joint_velocity_ratio"]:.0f} % of the velocity and '
        f'{100 * m["max_joint_acceleration_ratio"]:.0f} % of the acceleration limits',
        '  contacts (simulation): ' + ('none: no link nor the tool touched an obstacle, the '
                                       'bottle or the table' if m.get('contacts') == 0 else
                                       _contact_failure(m)),
        f'  motion {m["duration_s"]:.2f} s simulated (approach {m["approach_duration_s"]:.2f} s,'
        f' plan {m["plan_duration_s"]:.2f} s); demo took {m["wall_time_s"]:.0f} s',
    ]
    if 'orientation_tracking_rms_deg' in m:
        lines.append(
            f'  orientation: the tool turns by up to {m["orientation_plan_turn_deg"]:.0f} deg; '
            f'tracking error RMS {m["orientation_tracking_rms_deg"]:.3f} deg, max '
            f'{m["orientation_tracking_max_deg"]:.3f} deg'
            + (f'; plan vs the demonstration turned by the transform: max '
               f'{m["orientation_plan_vs_demo_turned_max_deg"]:.2f} deg'
               if 'orientation_plan_vs_demo_turned_max_deg' in m else ''))
    if 'goal_moved_by_mm' in m:
        lines += _move_summary(m)
    system = m.get('system', {})
    if 'cpu_cores' in system and 'moving_commands_per_s' in system:
        cpu = ', '.join(f'{name} {value:.2f}' for name, value in system['cpu_cores'].items())
        lines.append(f'  while moving: {system["moving_commands_per_s"]:.0f} commands/s, '
                     f'real-time factor {system["real_time_factor"]:.3f}, CPU '
                     f'{system["cpu_cores_total"]:.2f} cores ({cpu})')
    recording = m.get('recording')
    if recording:
        counts = recording['message_counts']
        lines.append(f'  recording: {recording["file"]}, {recording["bytes"] / 1e6:.1f} MB, '
                     f'{len(counts)} topics, {sum(counts.values())} messages (written in '
                     f'{recording["write_s"]:.1f} s): a rosbag2 MCAP for Foxglove or '
                     '`ros2 bag play` of its folder')
    lines.append('files: ' + ', '.join(str(p) for p in written))
    return '\n'.join(lines)


def parse_args(argv=None):
    """Return the parsed command line."""
    parser = argparse.ArgumentParser(
        prog='python -m etdmp_ros.demo',
        description='Closed-loop demo: the four nodes as processes, the simulated UR10 writes '
                    'the skill generalized to the goal the camera sees, around the obstacles.')
    parser.add_argument('--skill', default='G', choices=SKILLS,
                        help='built-in skill (default G; stir is the 3D one)')
    parser.add_argument('--method', default='etdmp', choices=METHODS,
                        help='method executed (the other one is planned for comparison)')
    parser.add_argument('--out', default='out/demo', type=Path, help='output folder')
    parser.add_argument('--no-animation', dest='animation', action='store_false',
                        help='skip animation.gif (the camera PNGs are still written)')
    parser.add_argument('--no-pictures', dest='pictures', action='store_false',
                        help='record no camera images and draw no camera pictures (plot.png '
                             'only)')
    parser.add_argument('--layout', default='skill', choices=('skill', 'scene'),
                        help="goal and obstacles: the skill's own layout (default) or "
                             "config/scene.yaml's as they are (G's layout)")
    parser.add_argument('--timeout', default=60.0, type=float,
                        help='s allowed beyond the plan duration for the execution')
    parser.add_argument('--move-goal', action='store_true',
                        help='move the goal marker (ur10_sim goal_position; stir: the bottle, '
                             'bottle.position) while the robot moves: dmp_server follows it '
                             'with the online ET-DMP')
    parser.add_argument('--demo-file', default=None, type=Path, metavar='FILE',
                        help='with --skill stir: a stir taught by moving the arm (rosbag2 .mcap '
                             'of /joint_states, python -m etdmp_ros.demo.kinesthetic), repeated '
                             'from another quadrant instead of the built-in stir')
    parser.add_argument('--duration', default=None, type=float, metavar='SECONDS',
                        help="the movement's tau (dmp_server's duration; default: the "
                             "skill's, 4 s for letters, 5 s for wiping and stirring; 0: the "
                             "demonstration's own)")
    parser.add_argument('--domain-id', default=None, type=int,
                        help='ROS_DOMAIN_ID of the demo (default: derived from the process id)')
    return parser.parse_args(argv)


def main(argv=None):
    """Run the demo from the command line; return the exit code."""
    args = parse_args(argv)
    env = isolated_environment(args.domain_id)
    os.environ.update(env)
    for name in DISCOVERY_VARIABLES:
        os.environ.pop(name, None)
    options = Options(skill=args.skill, method=args.method, out=args.out,
                      animation=args.animation, pictures=args.pictures, layout=args.layout,
                      timeout=args.timeout, move_goal=args.move_goal, demo_file=args.demo_file,
                      parameters=({} if args.duration is None else
                                  {'dmp_server': {'duration': args.duration}}))
    try:
        metrics, written = run_demo(options, env)
    except DemoError as err:
        print(f'demo failed: {err}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130
    print(summary(metrics, written), flush=True)
    if metrics['contacts'] != 0:        # measured and written, but the run failed
        print(f'demo failed: {_contact_failure(metrics)}', file=sys.stderr)
        return 1
    return 0

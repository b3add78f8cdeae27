"""
Obstacles with a size, ROS side: radii measured, contacts seen, the arm checked.

A script, not a pytest test. From the repository root::

    MUJOCO_GL=egl .venv/bin/python test/benchmarks/bench_obstacle_volumes.py [--quick] \
        [--json PATH] [--no-docs]

or ``make bench-obstacle_volumes BENCH_ARGS="..."``.

In this process, no ROS:

1. Radius measurement (perception's :class:`Detector`, the shipped parameters) on 640x480
   frames rendered by :class:`UR10Sim`: obstacles of random radii (10-80 mm) placed at random
   fully in view (the arm turned away), and obstacles of 25 and 40 mm partly hidden by the arm
   at its start pose (15-90 % of them visible). Errors of the measured radius and of the
   top-face centre against the simulation's ground truth (median, p90, max), how many radii
   were measured (the others: the rim seen spans less than half the circle, obstacle.radius
   reported), and the detection's time per frame against the same detector told the radius
   (``radius_range`` None: what perception did before), interleaved.
2. Contacts (:meth:`UR10Sim.detect_contacts`): the cost of one control tick (4 physics steps
   of 2 ms, then the collision pass) with and without the pass, interleaved, in three scenes:
   the shipped one at the start pose (nothing near the arm), the stirrer in the bottle (its
   wall's 24 boxes around the tool), and the pen pressed on an obstacle (a contact found).
3. The arm check (:mod:`etdmp_ros.robot._arm_check`): building the spheres once, and per plan,
   for the demo's G, W and stir (their layouts, dmp_server's settings), the IK along the plan
   (:func:`plan_joints`, 32 poses: shared with the timing check) and the check itself.

Medians of wall-clock times (``time.perf_counter``) on a 2-core machine shared with other work.
Unless ``--no-docs``, each part's table goes into its node's page (``_results.publish``): the
radii into docs/perception.md (block ``obstacle-radii``), the contacts into docs/ur10_sim.md
(``obstacle-contacts``), the arm check into docs/dmp_server.md (``obstacle-arm-check``).
"""

import argparse
import json
import math
import os
from pathlib import Path
import sys
import time

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / 'test'))
sys.path.insert(0, str(REPO / 'test' / 'unit'))
sys.path.insert(0, str(REPO / 'test' / 'benchmarks'))
os.environ.setdefault('MUJOCO_GL', 'egl')

from _results import add_option, command, publish  # noqa: E402
from etdmp_ros.demo.scenario import Scenario  # noqa: E402
from etdmp_ros.dmp import builtin_demo, learn  # noqa: E402
from etdmp_ros.geometry import quaternion as quat  # noqa: E402
from etdmp_ros.perception import Detector, detector_from_parameters  # noqa: E402
from etdmp_ros.robot import SceneConfig, UR10Model  # noqa: E402
from etdmp_ros.robot._arm_check import arm_obstacle_violation, ArmGeometry  # noqa: E402
from etdmp_ros.robot._timing import plan_joints  # noqa: E402
from etdmp_ros.ros import system  # noqa: E402
from etdmp_ros.ros.config_files import read_node_parameters  # noqa: E402
from etdmp_ros.sim import UR10Sim  # noqa: E402
from etdmp_ros.skills.planning import plan_path  # noqa: E402
import numpy as np  # noqa: E402
from test_vision import boxes_apart, image_box, place, visible_fraction  # noqa: E402

ARM_AWAY = (math.pi, -1.2, 1.9, -2.27, -1.57, 0.0)
AREA_X, AREA_Y = (0.30, 1.25), (-0.45, 0.50)


def _stats(values, scale=1e3):
    values = np.asarray(values, dtype=float) * scale
    return {'median': float(np.median(values)), 'p90': float(np.percentile(values, 90)),
            'max': float(values.max()), 'n': int(len(values))}


def _known_radius(detector):
    """Return the same detector with the obstacles' radius known (not measured)."""
    from dataclasses import replace
    return Detector(detector.goal, replace(detector.obstacle, radius_range=None),
                    detector.camera_pose, detector.table, detector.settings, detector.bottle)


def bench_radii(scenes, repeats):
    """Radius and centre errors, and the time per frame with radii measured or known."""
    detector = detector_from_parameters(read_node_parameters('perception'))
    known = _known_radius(detector)
    rng = np.random.default_rng(11)
    radius_errors, centre_errors, frames = [], [], []
    with UR10Sim(system.scene_config()) as sim:
        made = tries = 0
        while made < scenes:
            tries += 1
            radii = rng.uniform(0.01, 0.08, rng.integers(1, 4))
            tops = np.array([[rng.uniform(*AREA_X), rng.uniform(*AREA_Y), 0.08] for _ in radii])
            if not boxes_apart([image_box(sim, t, r, 0.08) for t, r in zip(tops, radii)]) or \
                    min(np.linalg.norm(t[:2] - sim.scene.bottle_position) for t in tops) < 0.15:
                continue
            sim.set_obstacle_radii(radii)
            rgb, depth = place(sim, (2.0, 2.0, -1.0), tops, ARM_AWAY)
            if any(visible_fraction(sim, depth, t, r, 0.08) < 1.0 for t, r in zip(tops, radii)):
                continue
            made += 1
            found = detector.detect(rgb, depth, sim.intrinsics)
            for det in found.obstacles:
                i = int(np.argmin(np.linalg.norm(tops - det.position, axis=1)))
                radius_errors.append(abs(det.radius - radii[i]) if det.radius_measured
                                     else np.nan)
                centre_errors.append(np.linalg.norm(det.position - tops[i]))
            frames.append((rgb, depth))
        # Partly hidden by the arm at its start pose.
        hidden_errors, unmeasured = [], 0
        q = sim.scene.initial_joint_positions
        for radius in (0.025, 0.04):
            sim.set_obstacle_radii([radius])
            for x in np.arange(0.30, 0.62, 0.02):
                for y in np.arange(-0.05, 0.40, 0.02):
                    top = np.array([x, y, 0.08])
                    rgb, depth = place(sim, (2.0, 2.0, -1.0), [top], q)
                    if not 0.15 <= visible_fraction(sim, depth, top, radius, 0.08) <= 0.9:
                        continue
                    for det in detector.detect(rgb, depth, sim.intrinsics).obstacles:
                        if det.radius_measured:
                            hidden_errors.append(abs(det.radius - radius))
                        else:
                            unmeasured += 1
        sim.set_obstacle_radii([])
        intrinsics = sim.intrinsics
    times = {'measured': [], 'known': []}
    for _ in range(repeats):
        for rgb, depth in frames:
            for name, which in (('measured', detector), ('known', known)):
                start = time.perf_counter()
                which.detect(rgb, depth, intrinsics)
                times[name].append(time.perf_counter() - start)
    radius_errors = np.array(radius_errors)
    return {'in_view': {'radius_mm': _stats(radius_errors[np.isfinite(radius_errors)]),
                        'radii_not_measured': int(np.sum(~np.isfinite(radius_errors))),
                        'centre_mm': _stats(centre_errors)},
            'behind_the_arm': {'radius_mm': _stats(hidden_errors),
                               'radii_not_measured': unmeasured},
            'detect_ms': {name: _stats(t) for name, t in times.items()}}


def _tick(sim, ticks):
    """Return the wall-clock time of each of ``ticks`` control ticks (4 steps + contacts)."""
    out = []
    for _ in range(ticks):
        start = time.perf_counter()
        sim.step(4)
        out.append(time.perf_counter() - start)
    return out


def bench_contacts(ticks, rounds):
    """Time a control tick with and without the contact pass, in three scenes."""
    figures = {}
    scene = system.scene_config()
    with UR10Sim(scene) as on, UR10Sim(scene, detect_contacts=False) as off:
        stir = Scenario(None, 'stir')
        stir_q = np.array(stir.overrides['ur10_sim']['initial_joint_positions'])
        model = on.ur10
        mouth = on.bottle_mouth
        # The stirrer upright, 10 cm down in the bottle, 2 cm off its axis: inside the wall's
        # boxes, touching none.
        upright = model.frame_pose(scene.initial_joint_positions)[1]
        in_bottle, _ = model.solve_pose(mouth + [0.02, 0.0, -0.1], upright, stir_q)
        tip = on.tool_tip_position
        cases = {'start pose, nothing near': (scene.initial_joint_positions, None),
                 'stirrer in the bottle': (in_bottle, None),
                 'pen pressed on an obstacle': (scene.initial_joint_positions,
                                                [tip[0] + 0.02, tip[1], tip[2] + 0.01])}
        for name, (q, obstacle) in cases.items():
            times = {'with': [], 'without': []}
            found = ()
            for _ in range(rounds):
                for key, sim in (('with', on), ('without', off)):
                    sim.reset(q)
                    if obstacle is not None:
                        sim.set_obstacles([obstacle])
                    times[key] += _tick(sim, ticks)
                    found = on.contacts if sim is on else found
            with_us, without_us = (np.median(times[k]) * 1e6 for k in ('with', 'without'))
            figures[name] = {'tick_with_us': float(with_us), 'tick_without_us': float(without_us),
                             'contact_pass_us': float(with_us - without_us),
                             'contacts': sorted({f'{c.part}/{c.item}' for c in found})}
        passes = []
        on.reset()
        for _ in range(ticks * rounds):
            start = time.perf_counter()
            on.detect_contacts()
            passes.append(time.perf_counter() - start)
        figures['detect_contacts alone, start pose'] = {'us': float(np.median(passes) * 1e6)}
    return figures


def bench_arm_check(rounds):
    """Time building the spheres; per demo plan, the IK along it and the arm check."""
    scene = system.scene_defaults()
    model = UR10Model(tool_offset=scene['tool_offset'])
    start = time.perf_counter()
    arm = ArmGeometry(model)
    figures = {'build_ms': (time.perf_counter() - start) * 1e3, 'spheres': int(len(arm.radii))}
    from etdmp_ros.nodes.dmp_server import Settings
    for name in ('G', 'W', 'stir'):
        layout = Scenario(None, name)
        values = system.defaults('dmp_server')
        values.update(layout.server)
        values.update(layout.overrides['dmp_server'])
        values.pop('use_sim_time', None)
        settings = Settings.from_values(values)
        world = dict(layout.scene)
        world.update(layout.overrides['ur10_sim'])
        cfg = SceneConfig.from_parameters(world)
        q0 = np.array(world['initial_joint_positions'])
        start_point = model.tool_position(q0)
        goal = layout.explicit_goal if layout.explicit_goal is not None else cfg.goal_position
        radii = np.full(len(cfg.obstacle_positions), cfg.obstacle_radius)
        plan = plan_path(learn(builtin_demo(name)), start_point, goal, cfg.obstacle_positions,
                         settings.plan, settings.plane, obstacle_radii=radii)
        rotations = quat.to_matrix(quat.normalized(plan.orientations))
        ik, check = [], []
        for _ in range(rounds):
            t0 = time.perf_counter()
            idx, joints, _ = plan_joints(model, plan.positions, rotations, plan.t, q0, 32)
            t1 = time.perf_counter()
            touch = arm_obstacle_violation(arm, joints, plan.t[idx], cfg.obstacle_positions,
                                           radii, settings.arm_clearance)
            t2 = time.perf_counter()
            ik.append(t1 - t0)
            check.append(t2 - t1)
        figures[name] = {'poses': int(len(plan.t)), 'ik_ms': float(np.median(ik) * 1e3),
                         'arm_check_ms': float(np.median(check) * 1e3),
                         'refused': None if touch is None else touch.part}
    return figures


def radii_table(r):
    """Return the table of the radii measured against the ground truth; the detection's cost."""
    e, c = r['in_view']['radius_mm'], r['in_view']['centre_mm']
    h, d = r['behind_the_arm'], r['detect_ms']
    return '\n'.join([
        '| case | obstacles | radius error median / p90 / max (mm) | centre error median / max '
        '(mm) |', '|---|---|---|---|',
        f'| fully in view, radii 10-80 mm | {e["n"]} measured, '
        f'{r["in_view"]["radii_not_measured"]} not | {e["median"]:.2f} / {e["p90"]:.2f} / '
        f'{e["max"]:.2f} | {c["median"]:.2f} / {c["max"]:.2f} |',
        f'| partly behind the arm, 25 and 40 mm, 15-90 % visible | {h["radius_mm"]["n"]} '
        f'measured, {h["radii_not_measured"]} not (obstacle.radius reported) | '
        f'{h["radius_mm"]["median"]:.2f} / {h["radius_mm"]["p90"]:.2f} / '
        f'{h["radius_mm"]["max"]:.2f} | |',
        '',
        f'Detection per frame (medians of {d["measured"]["n"]} frames each, interleaved):\n'
        f'{d["measured"]["median"]:.2f} ms with the radii measured, '
        f'{d["known"]["median"]:.2f} ms with the radius known.'])


def contacts_table(contacts):
    """Return the table of a control tick's cost with and without the contact pass."""
    lines = ['| scene | tick without the pass (us) | with it (us) | the pass (us) | contacts '
             'found |', '|---|---|---|---|---|']
    alone = ''
    for name, c in contacts.items():
        if 'us' in c:
            alone = f'{name.replace("detect_contacts", "`detect_contacts()`")}: {c["us"]:.1f} us.'
            continue
        lines.append(f'| {name} | {c["tick_without_us"]:.0f} | {c["tick_with_us"]:.0f} | '
                     f'{c["contact_pass_us"]:.1f} | {", ".join(c["contacts"]) or "none"} |')
    return '\n'.join(lines) + (f'\n\n{alone}' if alone else '')


def arm_check_table(a):
    """Return the table of the arm check's cost per demo plan."""
    lines = ['| plan | poses | IK at 32 poses (ms) | arm check (ms) | refused |',
             '|---|---|---|---|---|']
    for name in ('G', 'W', 'stir'):
        f = a[name]
        lines.append(f'| {name} | {f["poses"]} | {f["ik_ms"]:.2f} | {f["arm_check_ms"]:.2f} | '
                     f'{f["refused"] or "no"} |')
    built = f'The {a["spheres"]} spheres are built once, in {a["build_ms"]:.0f} ms.'
    return '\n'.join(lines) + f'\n\n{built}'


def main(argv=None):
    """Run the three parts; print the tables (and write them as JSON with ``--json``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--quick', action='store_true', help='fewer scenes and rounds')
    parser.add_argument('--json', type=Path, help='also write the figures here')
    add_option(parser)
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    scenes, repeats, rounds = (6, 2, 3) if args.quick else (30, 5, 15)
    figures = {'radii': bench_radii(scenes, repeats), 'contacts': bench_contacts(250, rounds),
               'arm_check': bench_arm_check(rounds), 'load': os.getloadavg()}
    tables = {'radii': radii_table(figures['radii']),
              'contacts': contacts_table(figures['contacts']),
              'arm check': arm_check_table(figures['arm_check'])}
    for name, table in tables.items():
        print(f'{name}:\n\n{table}\n')
    print('load average (1, 5, 15 min) at the end: '
          + ', '.join(f'{v:.1f}' for v in figures['load']))
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    if not args.no_docs:
        run = command('obstacle_volumes', argv)
        publish('obstacle-radii', tables['radii'], run, page='docs/perception.md', load=load)
        publish('obstacle-contacts', tables['contacts'], run, page='docs/ur10_sim.md',
                load=load)
        publish('obstacle-arm-check', tables['arm check'], run, page='docs/dmp_server.md',
                load=load)
    return 0


if __name__ == '__main__':
    sys.exit(main())

#!/usr/bin/env python3
"""
Draw the goal-jump comparison of docs/design.md#online-goal: ``docs/img/online_goal.png``.

For the built-in G, W and stir, the goal jumps at 40 % of the movement (``goal_jump_case``) and
is handled three ways (``compare_goal_jump``): (a) the online ET-DMP, (b) a fresh ET-DMP from
the position at the switch, at rest, (c) the plain DMP's goal change. Top row: the paths, with
the demonstration placed at the new goal (wide pale line); middle: the speed |dx/dt|; bottom:
the acceleration the samples imply, |v_(k+1) - v_k| / dt. Usage::

    .venv/bin/python tools/plot_online_goal.py [--out docs/img/online_goal.png]
"""

import argparse
from pathlib import Path

from etdmp_ros.apps.plotting import _equal_2d, _equal_3d, _figure, _save, _start_goal, DEMO_STYLE
from etdmp_ros.dmp import builtin_demo, compare_goal_jump, goal_jump_case, GOAL_JUMP_WAYS, learn
import numpy as np

REPO = Path(__file__).resolve().parents[1]
SKILLS = ('G', 'W', 'stir')
SWITCH = 0.4
STYLE = {'online': {'color': 'tab:green', 'linestyle': '-', 'linewidth': 2.0},
         'replan': {'color': 'tab:orange', 'linestyle': '-.', 'linewidth': 1.6},
         'dmp': {'color': 'tab:blue', 'linestyle': '--', 'linewidth': 1.6}}


def plot_online_goal(path, cases):
    """
    Plot ``cases``: ``[(name, start, goal, new_goal, results, reference), ...]``.

    ``results`` and ``reference`` are what :func:`compare_goal_jump` returns. Returns the path.
    """
    fig = _figure(figsize=(4.6 * len(cases), 11.0), layout='constrained')
    for col, (name, start, goal, new_goal, results, reference) in enumerate(cases):
        three_d = len(start) == 3
        ax = fig.add_subplot(3, len(cases), col + 1, projection='3d' if three_d else None)
        ax.plot(*reference.x.T, label='demo placed at the new goal', **DEMO_STYLE)
        for way, result in results.items():
            ax.plot(*result.x.T, label=GOAL_JUMP_WAYS[way], **STYLE[way])
        k = int(round(SWITCH * (len(reference.t) - 1)))
        switch_point = results['online'].x[k]
        if three_d:
            ax.scatter(*start, marker='*', s=140, color='k', label='start')
            for point, face in ((goal, '0.7'), (new_goal, 'none')):
                ax.scatter(*point, marker='o', s=110, facecolors=face, edgecolors='k')
            ax.scatter(*switch_point, marker='x', s=80, color='tab:red', label='switch')
            ax.set_xlabel('x')
            ax.set_ylabel('y')
            ax.set_zlabel('z')
            _equal_3d(ax, [reference.x] + [r.x for r in results.values()])
        else:
            _start_goal(ax, start, new_goal, label=(col == 0))
            ax.plot(*goal, marker='o', markersize=10, markerfacecolor='0.7',
                    markeredgecolor='k', linestyle='none',
                    label='first goal' if col == 0 else None)
            ax.plot(*switch_point, marker='x', markersize=9, markeredgewidth=2,
                    color='tab:red', linestyle='none', label='switch' if col == 0 else None)
            _equal_2d(ax)
        ax.set_title(f'{name}: goal jumps at {SWITCH:.0%}')
        if col == 0:
            ax.legend(loc='upper left', fontsize=8)
        speed = fig.add_subplot(3, len(cases), len(cases) + col + 1)
        accel = fig.add_subplot(3, len(cases), 2 * len(cases) + col + 1)
        for way, result in results.items():
            dt = result.t[1] - result.t[0]
            speed.plot(result.t, np.linalg.norm(result.v, axis=1), label=GOAL_JUMP_WAYS[way],
                       **STYLE[way])
            implied = np.linalg.norm(np.diff(result.v, axis=0), axis=1) / dt
            accel.plot(result.t[1:], implied, **STYLE[way])
        for ax in (speed, accel):
            ax.axvline(reference.t[k], color='tab:red', linewidth=0.8, alpha=0.6)
            ax.grid(True, alpha=0.3)
            ax.set_xlabel('t (s)')
        top = max(np.linalg.norm(np.diff(r.v, axis=0), axis=1).max() / (r.t[1] - r.t[0])
                  for way, r in results.items() if way != 'replan')
        accel.set_ylim(0.0, 1.3 * top)     # (b)'s impulse goes off the scale: it is |v| / dt
        speed.set_ylabel('speed |dx/dt|')
        accel.set_ylabel('acceleration |dv/dt| (from samples)')
        if col == 0:
            speed.legend(fontsize=8)
    return _save(fig, path)


def main(argv=None):
    """Run the comparison for G, W and stir and write the figure."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--out', default=str(REPO / 'docs' / 'img' / 'online_goal.png'))
    args = parser.parse_args(argv)
    cases = []
    for name in SKILLS:
        skill = learn(builtin_demo(name))
        start, goal, new_goal = goal_jump_case(skill)
        results, reference = compare_goal_jump(skill, start, goal, new_goal, switch=SWITCH)
        cases.append((name, start, goal, new_goal, results, reference))
    print(plot_online_goal(args.out, cases))


if __name__ == '__main__':
    main()

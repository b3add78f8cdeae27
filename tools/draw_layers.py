"""
Draw the package's layers (docs/img/layers.png) from `.importlinter` (``make docs``).

The contract that test/unit/test_architecture.py checks: one row a layer, top to bottom, each
folder with its modules' line count.
"""

import configparser
from pathlib import Path
import sys

import matplotlib
matplotlib.use('Agg')
from matplotlib.patches import FancyBboxPatch  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
WHAT = {
    'demo': 'make demo, make teach, make kinesthetic:\nrun, record, measure, draw',
    'apps': 'the offline command line etdmp:\ngeneralize, reproduce, plot',
    'nodes': 'thin rclpy nodes: ur10_sim, perception,\ndmp_server, controller, bringup, teach',
    'ros': 'system description, parameters, spin,\nconversions, processes',
    'skills': 'skill library, recordings,\nplanning and following, teaching',
    'sim': 'MuJoCo workcell and camera',
    'perception': 'OpenCV detection, deprojection',
    'robot': 'UR10 model, IK, trajectories, controller, workcell',
    'dmp': 'the ET-DMP core: learn, generalize, online, orientation, obstacles',
    'geometry': 'quaternions, camera model, task plane',
    'limits': 'bounds on what comes from outside',
}


def layers(path):
    config = configparser.ConfigParser()
    config.read(path)
    section = next(s for s in config.sections() if s.startswith('importlinter:contract'))
    return [[name.strip() for name in row.split('|')]
            for row in config[section]['layers'].strip().splitlines()]


def lines_of(name):
    package = REPO / 'etdmp_ros'
    paths = [package / f'{name}.py'] if (package / f'{name}.py').exists() else \
        sorted((package / name).rglob('*.py'))
    return sum(len(p.read_text(encoding='utf-8').splitlines()) for p in paths)


def main(out):
    rows = layers(REPO / '.importlinter')
    fig, ax = plt.subplots(figsize=(9, 0.9 * len(rows) + 0.6))
    ax.set_xlim(0, 10)
    ax.set_ylim(-0.4, len(rows))
    ax.axis('off')
    for r, row in enumerate(rows):
        y = len(rows) - 1 - r
        width = 9.6 / len(row)
        for c, name in enumerate(row):
            x = 0.2 + c * width
            ax.add_patch(FancyBboxPatch((x + 0.05, y + 0.12), width - 0.1, 0.7,
                                        boxstyle='round,pad=0.02', fc='#dde8f3', ec='#4a6b8a'))
            ax.text(x + 0.2, y + 0.62, f'{name}/' if name != 'limits' else 'limits.py',
                    fontsize=11, weight='bold', va='center')
            ax.text(x + width - 0.2, y + 0.62, f'{lines_of(name)} lines', fontsize=8,
                    ha='right', va='center', color='#555555')
            ax.text(x + 0.2, y + 0.33, WHAT.get(name, ''), fontsize=7.5, va='center')
    ax.annotate('', xy=(9.85, 0.1), xytext=(9.85, len(rows) - 0.2),
                arrowprops={'arrowstyle': '->', 'color': '#4a6b8a'})
    ax.set_title('etdmp_ros/: each folder one layer; imports point down (.importlinter)',
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f'wrote {out}')


if __name__ == '__main__':
    main(sys.argv[1] if len(sys.argv) > 1 else REPO / 'docs' / 'img' / 'layers.png')

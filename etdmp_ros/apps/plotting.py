"""
Figures of the ``etdmp`` command line: demo vs. DMP vs. ET-DMP, like the paper's figures.

matplotlib is an optional dependency: it is imported only when a figure is drawn, and its absence
raises :class:`PlottingUnavailable` with a message saying what to install. Figures are built on
:class:`matplotlib.figure.Figure` directly (no pyplot), so nothing depends on a display or on a
global backend, and plotting from several threads or tests cannot interfere.

Conventions in every figure: start = star, goal = ring, obstacle = '+'; ET-DMP solid, DMP dashed,
the demonstration a wide pale line *translated* so that its last sample is the requested goal (no
rotation or scaling, so the reader sees the demonstrated shape as recorded).
"""

from pathlib import Path

from etdmp_ros.dmp import METHOD_LABELS, METHODS
from etdmp_ros.geometry.task_plane import QUADRANTS
import numpy as np

DPI = 110
METHOD_STYLE = {'etdmp': {'color': 'tab:green', 'linestyle': '-'},
                'dmp': {'color': 'tab:blue', 'linestyle': '--'}}
DEMO_STYLE = {'color': '0.55', 'linewidth': 4.0, 'alpha': 0.45, 'solid_capstyle': 'round'}
#: A plan that was replaced while it executed (a goal that moved): light and dashed.
REPLACED_STYLE = {'linewidth': 1.8, 'linestyle': (0, (4, 2)), 'alpha': 0.55}


class PlottingUnavailable(RuntimeError):
    """matplotlib is not installed, so no figure can be drawn."""


def _figure(**kwargs):
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise PlottingUnavailable(
            'plotting needs matplotlib, which is not installed: pip install matplotlib '
            '(or run without the plot options / with --no-plots)') from None
    return Figure(**kwargs)


def require_matplotlib():
    """Raise :class:`PlottingUnavailable` now if matplotlib is missing (fail before long runs)."""
    _figure()


def _save(fig, path):
    path = Path(path)
    fig.savefig(path, dpi=DPI, bbox_inches='tight')
    return path


def _start_goal(ax, start, goal, color='k', label=True):
    ax.plot(*np.asarray(start)[:2], marker='*', markersize=13, color=color,
            markeredgecolor='k', markeredgewidth=0.6, linestyle='none',
            label='start' if label else None, zorder=5)
    ax.plot(*np.asarray(goal)[:2], marker='o', markersize=12, markerfacecolor='none',
            markeredgecolor='k', markeredgewidth=1.8, linestyle='none',
            label='goal' if label else None, zorder=5)


def _obstacles(ax, obstacles, label=True, three_d=False):
    obstacles = np.asarray(obstacles, dtype=float).reshape(-1, 3 if three_d else 2)
    if len(obstacles):
        ax.plot(*obstacles.T, marker='+', markersize=14, markeredgewidth=2.5, color='tab:red',
                linestyle='none', label='obstacle' if label else None, zorder=6)


def _equal_2d(ax):
    ax.set_aspect('equal', adjustable='datalim')
    ax.grid(True, alpha=0.3)
    ax.set_xlabel('x')
    ax.set_ylabel('y')


def _equal_3d(ax, arrays):
    # mplot3d has no equal aspect for data; a cube around all points gives undistorted shapes.
    pts = np.concatenate([np.reshape(a, (-1, 3)) for a in arrays])
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    half = 0.5 * max(float(np.ptp(pts, axis=0).max()), 1e-12)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))


def plot_generalization(path, *, demo, start, goal, paths, obstacles=(), title='',
                        selected=None):
    """
    Plot one request: the demo translated to the goal, and one path per method.

    ``paths`` maps a method name ("etdmp", "dmp") to its positions (n, d), d = 2 or 3, or None if
    that method failed. ``selected`` is drawn thicker. Returns the written path.
    """
    dim = np.asarray(demo).shape[1]
    three_d = dim == 3
    fig = _figure(figsize=(8.4, 6.0) if not three_d else (9.0, 6.5))
    ax = fig.add_subplot(projection='3d') if three_d else fig.add_subplot()
    demo_at_goal = np.asarray(demo) - np.asarray(demo)[-1] + np.asarray(goal)
    ax.plot(*demo_at_goal.T, label='demo (translated to goal)', **DEMO_STYLE)
    for method in METHODS:
        x = paths.get(method)
        if x is None:
            continue
        width = 2.4 if method == selected else 1.6
        ax.plot(*np.asarray(x).T, linewidth=width, label=METHOD_LABELS[method],
                **METHOD_STYLE[method])
    if three_d:
        ax.scatter(*np.asarray(start), marker='*', s=160, color='k', label='start')
        ax.scatter(*np.asarray(goal), marker='o', s=120, facecolors='none', edgecolors='k',
                   linewidths=1.8, label='goal')
        _obstacles(ax, obstacles, three_d=True)
        ax.set_xlabel('x')
        ax.set_ylabel('y')
        ax.set_zlabel('z')
        _equal_3d(ax, [demo_at_goal, np.reshape(start, (1, 3)), np.reshape(goal, (1, 3))]
                  + [np.asarray(x) for x in paths.values() if x is not None])
    else:
        _start_goal(ax, start, goal)
        _obstacles(ax, obstacles)
        _equal_2d(ax)
    ax.set_title(title)
    # Outside the axes: inside, it hides parts of the paths whatever corner it picks.
    ax.legend(loc='upper left', bbox_to_anchor=(1.02, 1.0), fontsize=9)
    return _save(fig, path)


def plot_demos(path, demos):
    """Plot built-in demonstrations ``[(name, positions (T, d)), ...]`` side by side."""
    n = len(demos)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig = _figure(figsize=(4.0 * cols, 3.8 * rows), layout='constrained')
    for i, (name, x) in enumerate(demos):
        x = np.asarray(x, dtype=float)
        three_d = x.shape[1] == 3
        ax = fig.add_subplot(rows, cols, i + 1, projection='3d' if three_d else None)
        ax.plot(*x.T, color='tab:purple', linewidth=1.6)
        if three_d:
            ax.scatter(*x[0], marker='*', s=120, color='k')
            ax.scatter(*x[-1], marker='o', s=90, facecolors='none', edgecolors='k')
            ax.set_xlabel('x')
            ax.set_ylabel('y')
            ax.set_zlabel('z')
            _equal_3d(ax, [x])
        else:
            _start_goal(ax, x[0], x[-1], label=(i == 0))
            _equal_2d(ax)
        ax.set_title(f'{name} ({x.shape[1]}D, {len(x)} samples)')
    if demos:
        fig.legend(loc='outside lower center', ncols=2, fontsize=9)
    return _save(fig, path)


# --------------------------------------------------------------------------------------------
# Reproduction figures (paper Figs. 5, 7-8, 13)


def plot_fig5(path, rep):
    """
    Fig. 5: per letter, rows ET-DMP and DMP, one column per relative quadrant of the start.

    Each panel holds the starts of one quadrant (colour = start index within the letter) so the
    rotated letters do not hide each other; DMP panels keep their full extent, however far the
    plain DMP strays, because that is the effect being shown.
    """
    from matplotlib.lines import Line2D
    quadrants = [q for q in QUADRANTS
                 if any(s.quadrant == q for letter in rep.letters for s in letter.starts)]
    n_letters, n_cols = len(rep.letters), len(quadrants)
    fig = _figure(figsize=(3.1 * n_cols + 0.4, 5.6 * n_letters + 0.6), layout='constrained')
    subfigs = np.atleast_1d(fig.subfigures(n_letters, 1, hspace=0.02))
    colors = ('tab:blue', 'tab:orange', 'tab:purple', 'tab:brown', 'tab:pink', 'tab:olive',
              'tab:cyan', 'tab:red', 'tab:green')
    for sub, letter in zip(subfigs, rep.letters):
        axes = sub.subplots(2, n_cols, squeeze=False)
        for col, q in enumerate(quadrants):
            starts = [s for s in letter.starts if s.quadrant == q]
            for row, method in enumerate(METHODS):
                ax = axes[row, col]
                ax.plot(*letter.demo_at_goal.T, **DEMO_STYLE)
                for s in starts:
                    color = colors[s.index % len(colors)]
                    r = s.results[method]
                    if r.ok:
                        ax.plot(*r.trajectory.x.T, color=color, linewidth=1.5,
                                **({} if method == 'etdmp' else {'linestyle': '--'}))
                    ax.plot(*s.start, marker='*', markersize=13, color=color,
                            markeredgecolor='k', markeredgewidth=0.6, linestyle='none',
                            zorder=5)
                ax.plot(*letter.goal, marker='o', markersize=11, markerfacecolor='none',
                        markeredgecolor='k', markeredgewidth=1.8, linestyle='none', zorder=6)
                failed = sum(not s.results[method].ok for s in starts)
                own = " = demo's" if q == letter.demo_quadrant else ''
                head = f'{METHOD_LABELS[method]}, start in {q}{own}'
                if not starts:
                    head += ' (no start)'
                elif failed:
                    head += f' ({failed} failed)'
                ax.set_title(head, fontsize=9.5)
                _equal_2d(ax)
        sub.suptitle(f'letter {letter.name}: demo starts in quadrant {letter.demo_quadrant} '
                     'of its goal', fontsize=11.5, fontweight='bold')
    handles = [Line2D([], [], label='demo (translated to goal)', **DEMO_STYLE),
               Line2D([], [], color='0.3', label='ET-DMP'),
               Line2D([], [], color='0.3', linestyle='--', label='DMP'),
               Line2D([], [], marker='*', markersize=12, color='0.5', markeredgecolor='k',
                      linestyle='none', label='start (colour = its path)'),
               Line2D([], [], marker='o', markersize=11, markerfacecolor='none',
                      markeredgecolor='k', markeredgewidth=1.8, linestyle='none', label='goal')]
    fig.legend(handles=handles, loc='outside lower center', ncols=5, fontsize=9.5)
    fig.suptitle('Generalization of DMP and ET-DMP from starts in every relative quadrant '
                 '(quadrant of start - goal)', fontsize=13)
    return _save(fig, path)


def plot_fig13(path, rep):
    """Fig. 13: per letter and quadrant, mean nRMSE of ET-DMP vs DMP (bars: min-max spread)."""
    n = len(rep.letters)
    fig = _figure(figsize=(3.6 * n + 0.8, 6.6), layout='constrained')
    axes = fig.subplots(2, n, squeeze=False, sharey='row')
    width = 0.38
    for col, letter in enumerate(rep.letters):
        for row, variant in enumerate(('conventional', 'paper')):
            ax = axes[row, col]
            for k, method in enumerate(METHODS):
                means, lo, hi = [], [], []
                for q in QUADRANTS:
                    vals = [s.results[method].nrmse[variant] for s in letter.starts
                            if s.quadrant == q and s.results[method].ok]
                    m = float(np.mean(vals)) if vals else np.nan
                    means.append(m)
                    lo.append(m - min(vals) if vals else 0.0)
                    hi.append(max(vals) - m if vals else 0.0)
                xs = np.arange(len(QUADRANTS)) + (k - 0.5) * width
                ax.bar(xs, means, width, yerr=[lo, hi], capsize=3,
                       color=METHOD_STYLE[method]['color'], alpha=0.85,
                       label=METHOD_LABELS[method] if (row, col) == (0, 0) else None,
                       error_kw={'elinewidth': 1.0})
            labels = [f'{q}\n(demo)' if q == letter.demo_quadrant else q for q in QUADRANTS]
            counts = [sum(s.quadrant == q for s in letter.starts) for q in QUADRANTS]
            labels = [f'{lab}\nn={c}' for lab, c in zip(labels, counts)]
            ax.set_xticks(np.arange(len(QUADRANTS)), labels, fontsize=8)
            ax.set_yscale('log')
            ax.grid(True, axis='y', which='major', alpha=0.35)
            if row == 0:
                ax.set_title(f'letter {letter.name}')
            if col == 0:
                ax.set_ylabel(f'nRMSE ({variant})')
            if row == 1:
                ax.set_xlabel('relative quadrant of start')
    fig.suptitle('Imitation error (nRMSE vs the demo) by start quadrant: mean over starts, '
                 'error bars = min-max\ntop: conventional RMSE, bottom: paper Eq. 16 as printed',
                 fontsize=11)
    fig.legend(loc='outside lower center', ncols=2, fontsize=9)
    return _save(fig, path)


def plot_obstacles(path, rep):
    """Figs. 7-8: per letter, ET-DMP with one and with two obstacles on its free path."""
    letters = [letter for letter in rep.letters if letter.obstacle_runs]
    n = max(len(letters), 1)
    rows = max((len(letter.obstacle_runs) for letter in letters), default=1)
    fig = _figure(figsize=(3.9 * n + 0.6, 4.1 * rows + 0.6), layout='constrained')
    axes = fig.subplots(rows, n, squeeze=False)
    for col, letter in enumerate(letters):
        for row, run in enumerate(letter.obstacle_runs):
            ax = axes[row, col]
            ax.plot(*run.without_obstacles.trajectory.x.T, color='tab:green', linestyle=':',
                    linewidth=1.6)
            if run.with_obstacles.ok:
                ax.plot(*run.with_obstacles.trajectory.x.T, color='tab:green', linewidth=1.8)
                note = f'clearance {run.with_obstacles.min_clearance:.2f}'
            else:
                note = 'failed'
            _start_goal(ax, run.start, letter.goal, color='tab:green', label=False)
            _obstacles(ax, run.obstacles, label=False)
            k = len(run.obstacles)
            ax.set_title(f'{letter.name}, start {run.start_index}, {k} obstacle'
                         f"{'s' if k > 1 else ''}: {note}", fontsize=10)
            _equal_2d(ax)
    for ax in axes.flat[len(letters) * rows:]:
        ax.set_visible(False)
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color='tab:green', label='ET-DMP with obstacles'),
               Line2D([], [], color='tab:green', linestyle=':', label='ET-DMP without obstacles'),
               Line2D([], [], marker='+', markersize=12, markeredgewidth=2.5, color='tab:red',
                      linestyle='none', label='obstacle'),
               Line2D([], [], marker='*', markersize=12, color='tab:green', markeredgecolor='k',
                      linestyle='none', label='start'),
               Line2D([], [], marker='o', markersize=11, markerfacecolor='none',
                      markeredgecolor='k', markeredgewidth=1.8, linestyle='none', label='goal')]
    fig.legend(handles=handles, loc='outside lower center', ncols=3, fontsize=9)
    fig.suptitle('ET-DMP obstacle avoidance: obstacles placed on the obstacle-free path')
    return _save(fig, path)


def write_reproduction_figures(rep, out_dir):
    """Write the three reproduction figures into ``out_dir``; return their paths."""
    out_dir = Path(out_dir)
    return [plot_fig5(out_dir / 'fig5_generalization.png', rep),
            plot_fig13(out_dir / 'fig13_nrmse.png', rep),
            plot_obstacles(out_dir / 'fig7_8_obstacles.png', rep)]

"""
Pictures of a closed-loop run: the plot of plans and trace, the camera frames with ink, the GIF.

:func:`plot_run` draws the top view (2D skills) or the top and side views (stir) of a
:class:`etdmp_ros.demo.metrics.Run` with its metrics; when the goal marker moved during the
run, the plan as first planned (dashed), the plan as executed (re-planned online), the marker
before (grey ring) and after, and the switch between the plans. For a skill with orientations it
draws the tool at intervals along the plan: the stirrer's shaft (stir, both views: the tilt) or the
sponge's long side (wipe, top view: the turn), planned (coloured) and true (black, forward
kinematics of the simulated joints at the same path time). :func:`write_pictures` writes the
camera's frames (PNG) and the animation (GIF) with the pen's trace drawn in as ink
(:func:`draw_ink`; the simulation leaves none) and, for a skill with orientations, the tool's
tilt or turn in a corner (:class:`ToolInset`). matplotlib, OpenCV and Pillow are imported when
a picture is made.
"""

from etdmp_ros.apps.plotting import DEMO_STYLE, METHOD_STYLE, REPLACED_STYLE
from etdmp_ros.demo.metrics import format_nrmse, obstacle_radii
from etdmp_ros.dmp import learn, METHOD_LABELS
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.geometry.camera import CameraPose
from etdmp_ros.robot import PEN_TIP_RADIUS, UR10Model
from etdmp_ros.skills.planning import place_demo
import numpy as np

#: RGB of the pen's ink drawn into the camera frames.
INK_COLOR = (25, 35, 150)
PLAN_LABELS = {'etdmp': 'ET-DMP plan', 'dmp': 'DMP plan'}
#: Tools drawn along the plan of a skill with orientations, and the drawn lengths (m) of the
#: stirrer's shaft (from the tip along -tool z) and the sponge's long side (tool y, centred).
TOOLS_DRAWN, SHAFT_LENGTH, SPONGE_LENGTH = 11, 0.06, 0.03


# ------------------------------------------------------------------------------------ plot


def _curves(run, metrics, extra):
    """Return (curves drawn first, executed curves drawn last): (points, style, label)."""
    scene = run.scene
    moved = run.goal_move is not None
    goal = np.asarray(metrics['executed_plan_end']) if moved else run.goal
    placed = place_demo(learn(scene.demo), run.start, goal,
                        scene.plane if scene.planar else None, scene.server.get('mode', 1),
                        scene.server.get('independent_axis', 2))
    curves = [(placed, DEMO_STYLE, 'demonstration, turned and scaled into place'
               + (' (at the moved goal)' if moved else ''))]
    executed = [(extra['executed'][1], dict(METHOD_STYLE[run.method], linewidth=3.5, alpha=0.5),
                 f'{PLAN_LABELS[run.method]} ' + ('re-planned online (executed)' if moved
                                                  else '(executed)')
                 + f', nRMSE {format_nrmse(metrics["nrmse_plan"])}'),
                (extra['trace'], {'color': 'k', 'linewidth': 0.9},
                 f'pen tip, true (MuJoCo), nRMSE {format_nrmse(metrics["nrmse_trace"])}')]
    if getattr(scene, 'demo_file', None) is not None:       # a stir taught by moving the arm
        curves.append((scene.demo.positions + scene.bottle_mouth,
                       {'color': '0.3', 'linewidth': 1.2, 'linestyle': (0, (1, 1.5))},
                       'taught: the tool path recorded by hand (joint states)'))
    if moved:
        curves.append((run.plan[1], dict(METHOD_STYLE[run.method], **REPLACED_STYLE),
                       f'{PLAN_LABELS[run.method]} as first planned (goal before the move), '
                       f'nRMSE {format_nrmse(metrics["nrmse_original_plan"])}'))
    return curves, executed


def _focus(run, curves):
    """Return the points the view must show (curves, obstacles or the bottle) and the pad."""
    scene = run.scene
    focus = [np.reshape(c[0], (-1, 3)) for c in curves]
    if scene.planar:
        focus.append(np.asarray(run.obstacles_truth, dtype=float).reshape(-1, 3))
    else:
        r_b = float(scene.scene['bottle.radius'])
        for mouth, _ in _bottle_mouths(run):
            focus.append(mouth + [[r_b, r_b, 0.0], [-r_b, -r_b, -mouth[2]]])
    pad = 0.02 + (float(scene.scene['obstacle.radius']) if scene.planar else 0.0)
    return np.concatenate(focus), pad


def _other_curve(run, metrics, low, high):
    """Return the curve of the plan not executed, or None if it was refused."""
    other_method, other_t, other_x = run.other
    if other_t is None:
        return None
    value = (metrics['nrmse_dmp_baseline'] if other_method == 'dmp'
             else metrics.get(f'nrmse_{other_method}_plan'))
    out_of_view = np.any((other_x[:, :2] < low[:2]) | (other_x[:, :2] > high[:2]))
    return (other_x, dict(METHOD_STYLE[other_method], linewidth=1.6),
            f'{PLAN_LABELS[other_method]} (not executed), nRMSE {format_nrmse(value)}'
            + (', leaves the view' if out_of_view else ''))


def _figure(scene, views, low, high, legend_rows=4):
    """Return a figure sized to the data, so that equal axes leave no empty band."""
    from matplotlib.figure import Figure

    plane = scene.plane
    width = (high - low) @ plane.y_axis
    heights = [abs((high - low) @ plane.x_axis)] + ([high[2] - low[2]] if not scene.planar
                                                    else [])
    panel = 6.0 if scene.planar else 5.0
    return Figure(figsize=(panel * len(views) + 0.8,
                           min(max(panel * max(heights) / abs(width), 3.0), 9.0) + 1.4
                           + 0.2 * legend_rows),
                  layout='constrained')


def _projection(plane, view):
    """Return the map of base_link points to a view's (horizontal, vertical) coordinates."""
    def xy(points):
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if view == 'top':
            return points @ plane.y_axis, points @ plane.x_axis
        return points @ plane.y_axis, points[:, 2]
    return xy


def _bottle_mouths(run):
    """Return [(mouth, moved)]: where the bottle stood, before and after a move (stir)."""
    scene = run.scene
    if run.goal_move is None or not getattr(scene, 'perceived_bottle', False):
        return [(scene.bottle_mouth, False)]
    return [(np.asarray(run.goal_move[1], float) - scene.goal_offset, False),
            (np.asarray(run.goal_move[2], float) - scene.goal_offset, True)]


def _draw_bottle(ax, run, view, xy):
    from matplotlib.patches import Circle, Rectangle

    scene = run.scene
    r_b = float(scene.scene['bottle.radius'])
    places = _bottle_mouths(run)
    for mouth, moved in places:
        (h,), (v,) = xy(mouth)
        style = ({'edgecolor': 'tab:blue', 'linewidth': 1.5,
                  'label': 'bottle (after the move)' if moved else 'bottle'}
                 if moved or len(places) == 1 else
                 {'edgecolor': '0.6', 'linewidth': 1.0, 'linestyle': '--',
                  'label': 'bottle before the move'})
        if view == 'top':
            ax.add_patch(Circle((h, v), r_b, fill=False, **style))
        else:
            ax.add_patch(Rectangle((h - r_b, 0.0), 2 * r_b, mouth[2], fill=False, **style))
    if view != 'top':
        ax.axhline(0.0, color='0.6', linewidth=1.0)


def _draw_obstacles(ax, run, view, xy, low, high):
    from matplotlib.patches import Circle, Rectangle

    obstacles = np.asarray(run.obstacles_truth, dtype=float).reshape(-1, 3)
    radii = obstacle_radii(run)
    near = np.all((obstacles[:, :2] > low[:2] - radii[:, None])
                  & (obstacles[:, :2] < high[:2] + radii[:, None]), axis=1)
    for j, (o, radius) in enumerate(zip(obstacles[near], radii[near])):
        (h,), (v,) = xy(o)
        kind = {'color': 'tab:red', 'alpha': 0.45, 'label': 'obstacle' if j == 0 else None}
        if view == 'top':
            ax.add_patch(Circle((h, v), radius, **kind))
            # Where the pen tip's centre would touch the cylinder.
            ax.add_patch(Circle((h, v), radius + PEN_TIP_RADIUS, fill=False,
                                edgecolor='tab:red', linestyle=':', linewidth=0.8))
        else:
            ax.add_patch(Rectangle((h - radius, 0.0), 2 * radius, o[2], **kind))


def _draw_markers(ax, run, metrics, extra, xy):
    planar = run.scene.planar
    moved = run.goal_move is not None
    ax.plot(*xy(run.start), marker='*', markersize=14, color='gold', markeredgecolor='k',
            linestyle='none', label='start (tool)', zorder=6)
    if moved:
        _draw_goal_move(ax, run, metrics, extra, xy)
    ax.plot(*xy(extra['goal']), marker='o', markersize=12, markerfacecolor='none',
            markeredgecolor='k', markeredgewidth=1.8, linestyle='none',
            label=('goal (true marker, after the move)' if moved else 'goal (true marker)')
            if planar else ('goal (in the moved bottle)' if moved else 'goal (requested)'),
            zorder=6)
    if planar:
        seen = metrics.get('perceived_goal_final') if moved else None
        ax.plot(*xy(run.goal if seen is None else seen), marker='x', markersize=8,
                color='tab:green', linestyle='none', label='goal as perceived', zorder=7)


def _draw_goal_move(ax, run, metrics, extra, xy):
    """Draw the goal before the move (grey ring), the move, and the switch of plans."""
    plane, what = run.scene.plane, metrics.get('moved_object', 'goal marker')
    before = np.asarray(run.goal_move[1], dtype=float)
    if run.scene.planar:
        before = plane.from_plane(plane.to_plane(before))
    (h0,), (v0,) = xy(before)
    (h1,), (v1,) = xy(extra['goal'])
    ax.plot(h0, v0, marker='o', markersize=12, markerfacecolor='none', markeredgecolor='0.5',
            markeredgewidth=1.5, linestyle='none', zorder=6,
            label=(f'goal marker before the move ({metrics["goal_moved_by_mm"]:.0f} mm)'
                   if what == 'goal marker' else
                   f'goal before the {what} moved ({metrics["goal_moved_by_mm"]:.0f} mm)'))
    ax.annotate('', xy=(h1, v1), xytext=(h0, v0), zorder=6,
                arrowprops={'arrowstyle': '->', 'color': '0.4', 'linewidth': 1.2,
                            'shrinkA': 7, 'shrinkB': 7})
    if metrics.get('switch_point') is None:
        return
    (h,), (v,) = xy(metrics['switch_point'])
    moved_at = metrics['goal_follow']['goal_moved_at_path_time_s']
    ax.plot(h, v, marker='D', markersize=7, color='tab:orange', markeredgecolor='k',
            linestyle='none', zorder=8,
            label=f'switch: {what.split()[-1]} moved at {moved_at:.2f} s, re-planned from '
                  f'{metrics["switch_path_time_s"]:.2f} s (path time)')
    ratio = metrics.get('switch_speed_ratio_min')
    if ratio is not None:
        ax.annotate(f"switch: tool speed\n>= {ratio:.0%} of the plan's", (h, v), fontsize=8,
                    xytext=(10, -4), textcoords='offset points', zorder=8)


def tool_segments(run, extra, count=TOOLS_DRAWN):
    """
    Return (planned, true) tool segments (k, 2, 3) along the plan, or None without orientations.

    Stirrer (3D skill): from the tip SHAFT_LENGTH along -tool z; sponge (2D): SPONGE_LENGTH
    along tool y, centred on the tip. True: forward kinematics of the recorded joint state
    nearest the same path time (after the tracking start ``extra['t0']``); None if none.
    """
    plan_t, plan_x, plan_q = run.plan
    if run.scene.demo.orientations is None or plan_q is None or not len(plan_q):
        return None
    tau = float(extra['tau'])
    idx = np.unique(np.linspace(0, np.searchsorted(plan_t, tau + 1e-9) - 1,
                                count).round().astype(int))

    def segments(points, rotations):
        if run.scene.planar:
            half = 0.5 * SPONGE_LENGTH * rotations[:, :, 1]
            return np.stack([points - half, points + half], axis=1)
        return np.stack([points, points - SHAFT_LENGTH * rotations[:, :, 2]], axis=1)

    planned = segments(np.asarray(plan_x)[idx],
                       quat.to_matrix(quat.normalized(np.asarray(plan_q)[idx])))
    joints = run.rec.get('joints')
    if joints is None or not len(joints):
        return planned, None
    model = UR10Model(tool_offset=run.scene.scene['tool_offset'])
    at = (extra['t0'] + np.asarray(plan_t)[idx]) * 1e9
    k = np.clip(np.searchsorted(joints[:, 0], at), 0, len(joints) - 1)
    poses = [model.frame_pose(q)[:2] for q in joints[k, 1:]]
    return planned, segments(np.array([p for p, _ in poses]), np.array([r for _, r in poses]))


def _draw_tools(ax, run, view, xy, tools):
    if tools is None or (run.scene.planar and view != 'top'):
        return
    what = 'sponge (long side)' if run.scene.planar else 'stirrer shaft'
    for segments, style, label in (
            (tools[0], {'color': 'tab:purple', 'linewidth': 2.4, 'alpha': 0.8},
             f'{what}, planned orientation'),
            (tools[1], {'color': 'k', 'linewidth': 0.9},
             f'{what}, true (MuJoCo joints)')):
        if segments is None:
            continue
        for j, segment in enumerate(segments):
            ax.plot(*xy(segment), label=label if j == 0 else None, zorder=5, **style)


def _frame_axes(ax, plane, view, name, xy, focus, pad):
    h, v = xy(focus)
    ax.set_xlim(h.min() - pad, h.max() + pad)
    ax.set_ylim(v.min() - pad, v.max() + pad)
    ax.set_aspect('equal', adjustable='box')
    ax.grid(True, alpha=0.3)
    standard = np.allclose(plane.x_axis, [1, 0, 0]) and np.allclose(plane.y_axis, [0, 1, 0])
    ax.set_xlabel('y (m)' if standard else 'along task_plane.y_axis (m)')
    if view == 'top':
        ax.set_ylabel('x (m)' if standard else 'along task_plane.x_axis (m)')
        ax.invert_yaxis()
    else:
        ax.set_ylabel('z (m)')
    ax.set_title(name, fontsize=10)


def _legend_and_title(fig, run, metrics):
    handles = {}
    for ax in fig.axes:
        for handle, text in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(text, handle)
    fig.legend(handles.values(), handles.keys(), loc='outside lower center', ncol=2,
               fontsize=8, frameon=False)
    moved = run.goal_move is not None
    fig.suptitle(
        f'{run.scene.skill}: {METHOD_LABELS[run.method]} executed by the simulated UR10'
        + (f', the {metrics.get("moved_object", "goal marker")} moved by '
           f'{metrics["goal_moved_by_mm"]:.0f} mm while it '
           + ('wrote' if run.scene.planar else 'stirred') if moved else '') + '\n'
        f'start direction {metrics["start_turn_deg"]:+.0f} deg from the demonstration\'s '
        f'(quadrant {metrics["start_quadrant"]} of the goal; demonstration: '
        f'{metrics["demo_quadrant"]})\ntracking error RMS {metrics["tracking_rms_mm"]:.2f} mm, '
        f'goal error {metrics["goal_error_mm"]:.1f} mm'
        + ((' (to the moved marker)' if run.scene.planar else ' (in the moved bottle)')
           if moved else '')
        + f', min obstacle clearance {metrics["min_clearance_mm"]:.1f} mm'
        + (f'\norientation tracking error RMS {metrics["orientation_tracking_rms_deg"]:.3f} '
           f'deg, max {metrics["orientation_tracking_max_deg"]:.3f} deg (the tool turns by up '
           f'to {metrics["orientation_plan_turn_deg"]:.0f} deg)'
           if 'orientation_tracking_rms_deg' in metrics else ''), fontsize=10)


def plot_run(path, run, metrics, extra):
    """Draw the top view (2D skills) or top and side views (stir) of a run into ``path``."""
    scene = run.scene
    curves, executed = _curves(run, metrics, extra)
    # The view shows what was executed (a wild baseline may leave it).
    focus, pad = _focus(run, curves + executed)
    low, high = focus.min(axis=0) - pad, focus.max(axis=0) + pad
    other = _other_curve(run, metrics, low, high)
    curves += ([other] if other is not None else []) + executed
    views = [('top', 'top view (robot base at the top)')]
    if not scene.planar:
        views.append(('side', 'side view (as the camera sees it)'))
    tools = tool_segments(run, extra)
    # The legend's rows below the view: a moved goal adds three entries, tools one.
    fig = _figure(scene, views, low, high,
                  legend_rows=(6 if run.goal_move is not None else 4) + (tools is not None))
    for i, (view, name) in enumerate(views):
        ax = fig.add_subplot(1, len(views), i + 1)
        xy = _projection(scene.plane, view)
        if not scene.planar:
            _draw_bottle(ax, run, view, xy)
        _draw_obstacles(ax, run, view, xy, low, high)
        for points, style, text in curves:
            ax.plot(*xy(points), label=text, **style)
        _draw_tools(ax, run, view, xy, tools)
        _draw_markers(ax, run, metrics, extra, xy)
        _frame_axes(ax, scene.plane, view, name, xy, focus, pad)
    _legend_and_title(fig, run, metrics)
    fig.savefig(path, dpi=110, bbox_inches='tight')


# ---------------------------------------------------------------------------- camera frames


def draw_ink(frame, depth_mm, points, camera, intrinsics, scale, thickness=1):
    """
    Draw the pen-tip trace ``points`` (n, 3, base_link) onto ``frame`` (in place) as ink.

    The simulation leaves no ink: the trace is projected with the camera model (``scale``: the
    frame's size relative to the camera's) and drawn where the camera sees it, i.e. where the
    point is not farther than the depth image (plus 5 mm) or the depth has no data.
    """
    import cv2

    if len(points) < 2:
        return
    in_camera = camera.from_base(points)
    uv = intrinsics.project(in_camera) * scale
    pixels = np.round(uv).astype(np.int64)
    h, w = frame.shape[:2]
    inside = (pixels[:, 0] >= 0) & (pixels[:, 0] < w) & (pixels[:, 1] >= 0) & (pixels[:, 1] < h)
    visible = inside.copy()
    if depth_mm is not None:
        seen = depth_mm[pixels[inside, 1], pixels[inside, 0]].astype(float)
        visible[inside] = (seen == 0) | (in_camera[inside, 2] * 1000.0 <= seen + 5.0)
    # Runs of consecutive visible points become polylines (sub-pixel precision: shift 2).
    edges = np.flatnonzero(np.diff(np.r_[0, visible.astype(int), 0]))
    runs = [np.round(uv[a:b] * 4).astype(np.int32).reshape(-1, 1, 2)
            for a, b in zip(edges[::2], edges[1::2]) if b - a >= 2]
    if runs:
        cv2.polylines(frame, runs, False, INK_COLOR, thickness, cv2.LINE_AA, shift=2)


def _caption(frame, text, scale):
    import cv2

    cv2.putText(frame, text, (int(8 * scale), int(20 * scale)), cv2.FONT_HERSHEY_SIMPLEX,
                0.45 * scale, (0, 0, 0), 1 if scale < 1.5 else 2, cv2.LINE_AA)


class ToolInset:
    """
    The tool's orientation drawn into a corner of the camera frames (a skill with orientations).

    The camera sees the stirrer inside the bottle or the sponge from afar; the inset shows
    what turns: the stirrer's shaft (tool -z) in the side view (base_link y, z) with its tilt
    from vertical, or the sponge's long side (tool y) in the top view with its turn from the
    start; true (black, forward kinematics of the recorded joints at the frame's stamp) and
    planned (purple, the plan at the same path time once tracking started, ``t0``).
    """

    def __init__(self, run, rec, t0=None):
        """Prepare from a run, its recorded streams and the tracking start (simulated s)."""
        self.planar = run.scene.planar
        self.joints = rec.get('joints')
        self.model = UR10Model(tool_offset=run.scene.scene['tool_offset'])
        plan_t, _, plan_q = run.plan
        self.plan_t = np.asarray(plan_t)
        self.plan_rot = quat.to_matrix(quat.normalized(np.asarray(plan_q)))
        self.t0 = t0
        self.start_rot = self.plan_rot[0]

    @classmethod
    def of(cls, run, rec, t0=None):
        """Return an inset for a run of a skill with orientations, else None."""
        q = run.plan[2]
        if run.scene.demo.orientations is None or q is None or not len(q) or \
                rec.get('joints') is None or not len(rec['joints']):
            return None
        return cls(run, rec, t0)

    def _direction(self, rot):
        """Return the drawn direction (2,) in the inset's (right, up) and the angle (deg)."""
        if self.planar:
            long_side = rot[:, 1]
            start = self.start_rot[:, 1]
            turn = np.degrees(np.arctan2(start[0] * long_side[1] - start[1] * long_side[0],
                                         start[:2] @ long_side[:2]))
            return np.array([long_side[1], -long_side[0]]), turn
        shaft = -rot[:, 2]
        tilt = np.degrees(np.arccos(np.clip(shaft[2], -1.0, 1.0)))
        return np.array([shaft[1], shaft[2]]), tilt

    def draw(self, frame, stamp, scale):
        """Draw the inset into ``frame`` (in place) for the simulated time ``stamp`` (ns)."""
        import cv2

        k = min(int(np.searchsorted(self.joints[:, 0], stamp)), len(self.joints) - 1)
        rot = self.model.frame_pose(self.joints[k, 1:])[1]
        size = int(round(110 * scale))
        h = frame.shape[0]
        x0, y0 = int(6 * scale), h - size - int(6 * scale)
        cv2.rectangle(frame, (x0, y0), (x0 + size, y0 + size), (255, 255, 255), -1)
        cv2.rectangle(frame, (x0, y0), (x0 + size, y0 + size), (0, 0, 0), 1)
        centre = np.array([x0 + size / 2, y0 + (size / 2 if self.planar else size * 0.8)])
        length = size * (0.42 if self.planar else 0.6)

        def line(direction, colour, width):
            d = np.array([direction[0], -direction[1]]) * length
            a = centre - d if self.planar else centre
            b = centre + d
            cv2.line(frame, tuple(int(round(c)) for c in a), tuple(int(round(c)) for c in b),
                     colour, width, cv2.LINE_AA)

        reference = np.array([0.0, 1.0]) if not self.planar else \
            self._direction(self.start_rot)[0]
        line(reference, (170, 170, 170), 1)
        if self.t0 is not None and stamp * 1e-9 >= self.t0:
            i = min(int(np.searchsorted(self.plan_t, stamp * 1e-9 - self.t0)),
                    len(self.plan_t) - 1)
            line(self._direction(self.plan_rot[i])[0], (160, 80, 190),
                 max(3, int(round(4 * scale))))
        direction, angle = self._direction(rot)
        line(direction, (0, 0, 0), max(1, int(round(1.5 * scale))))
        text = f'turn {angle:+.0f} deg' if self.planar else f'tilt {angle:.0f} deg'
        title = 'sponge, top' if self.planar else 'stirrer, side'
        for j, line_text in enumerate((title, text)):
            cv2.putText(frame, line_text, (x0 + int(4 * scale), y0 + int((13 + 13 * j) * scale)),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.36 * scale, (0, 0, 0), 1, cv2.LINE_AA)


def write_pictures(out, run, rec, snapshots, frames, intrinsics, animation=True, t0=None):
    """
    Write the camera frames (PNG) and the animation (GIF), the pen's trace drawn in as ink.

    Returns the paths written. Frames are captioned with the simulated time since the
    ``/generalize`` call and the controller's status (and "goal moved" once the goal marker,
    which the frames show where the simulation has it, has moved). A skill with orientations
    gets the tool's orientation in a corner (:class:`ToolInset`; ``t0``: the tracking start,
    simulated s, for the planned one).
    """
    from PIL import Image as PilImage

    camera = CameraPose(tuple(run.scene.scene['camera.position']),
                        tuple(run.scene.scene['camera.orientation']))
    tip = rec['tip'][rec['tip'][:, 0] >= run.call_ns]
    inset = ToolInset.of(run, rec, t0)

    def render(stamp, rgb, depth, scale):
        frame = rgb.copy()
        draw_ink(frame, depth, tip[tip[:, 0] <= stamp, 1:], camera, intrinsics, scale,
                 thickness=1 if scale < 1 else 2)
        if inset is not None:
            inset.draw(frame, stamp, max(scale, 0.75))
        state = [text.split(':')[0] for ns, text in run.status if ns <= stamp]
        moved = run.goal_move is not None and stamp >= run.goal_move[0]
        _caption(frame, f't = {(stamp - run.call_ns) * 1e-9:+.2f} s  '
                        f'{state[-1] if state else "perceiving, planning"}'
                        + ('  (goal moved)' if moved else ''), scale * 2)
        return frame

    written = []
    for name in ('start', 'middle', 'end'):
        if snapshots.get(name) is not None:
            stamp, rgb, depth = snapshots[name]
            path = out / f'camera_{name}.png'
            PilImage.fromarray(render(stamp, rgb, depth, 1.0)).save(path)
            written.append(path)
    if not (animation and frames):
        return written
    stamps = sorted(frames)
    images = [PilImage.fromarray(render(s, *frames[s], 0.5)) for s in stamps]
    # Real-time playback: each frame lasts until the next one's stamp.
    durations = [int(round(d * 1e-6)) for d in np.diff(stamps)] + [1500]
    path = out / 'animation.gif'
    images[0].save(path, save_all=True, append_images=images[1:], duration=durations, loop=0,
                   optimize=True)
    written.append(path)
    return written

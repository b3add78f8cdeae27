"""
The tool's orientation against the plan, the reference and the demonstration turned.

Definition: ``orientation_tracking`` (:mod:`._definitions`).
"""

from etdmp_ros.dmp import euclidean_transform
from etdmp_ros.geometry import quaternion as quat
from etdmp_ros.robot import UR10Model
import numpy as np


def _geodesic(t, q, at):
    """Return the orientations (len(at), 4) at times ``at`` of quaternions ``q`` at ``t``."""
    q = quat.continuous(np.asarray(q, dtype=float))
    at = np.clip(at, t[0], t[-1])
    i = np.clip(np.searchsorted(t, at, 'right') - 1, 0, len(t) - 2)
    s = ((at - t[i]) / (t[i + 1] - t[i]))[:, None]
    step = quat.log_map(quat.multiply(q[i + 1], quat.conjugate(q[i])))
    return quat.multiply(quat.exp_map(s * step), q[i])


def _angles_deg(p, q):
    return np.degrees(quat.angle_between(np.asarray(p), np.asarray(q)))


def demo_turned(scene, start, goal, plan_t, tau):
    """
    Return the demonstration's orientations at the plan's phase turned by ET-DMP's rotation.

    ``plan_t`` (n,) path times; ``tau`` the plan's duration without margin. Base_link (n, 4);
    None for a position-only demonstration, orientation_mode tool, or a transform that mirrors.
    """
    demo = scene.demo
    if demo.orientations is None or scene.server.get('orientation_mode') == 'tool':
        return None     # the plan keeps the tool's orientation: nothing turned to compare with
    if scene.planar:
        plane = scene.plane
        s, g = plane.to_plane(np.asarray(start)), plane.to_plane(np.asarray(goal))
    else:
        s, g = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    mode = 1 if scene.planar else scene.server.get('mode', 1)
    transform = euclidean_transform(demo.positions[0] - demo.positions[-1], s - g, mode,
                                    scene.server.get('independent_axis', 2))
    turn = np.eye(3)
    r_t = np.asarray(transform.R, dtype=float).T
    turn[:len(r_t), :len(r_t)] = r_t
    if np.linalg.det(turn) < 0.0:
        return None
    q_demo = _geodesic(demo.t, demo.orientations,
                       np.asarray(plan_t) * demo.duration / tau)
    turned = quat.multiply(quat.from_matrix(turn), q_demo)
    return plane.orientation_from_plane(turned) if scene.planar else turned


def orientation_figures(run, tr):
    """Return the orientation tracking figures of a run (``orientation_tracking``), or {}."""
    plan_t, plan_x, plan_q = run.plan
    joints = run.rec.get('joints')
    if run.scene.demo.orientations is None or plan_q is None or joints is None or \
            not len(joints):
        return {}
    plan_t, plan_q = np.asarray(plan_t), np.asarray(plan_q)
    stamps = joints[:, 0]
    span = stamps * 1e-9 - tr.t0
    inside = (span >= 0.0) & (span <= plan_t[-1])
    if not inside.any():
        return {}
    model = UR10Model(tool_offset=run.scene.scene['tool_offset'])
    poses = [model.frame_pose(q) for q in joints[inside, 1:]]
    true_q = quat.from_matrix(np.array([rot for _, rot in poses]))
    vs_plan = _angles_deg(true_q, _geodesic(plan_t, plan_q, span[inside]))
    figures = {'orientation_tracking_rms_deg': float(np.sqrt(np.mean(vs_plan ** 2))),
               'orientation_tracking_max_deg': float(vs_plan.max()),
               'orientation_samples': int(inside.sum()),
               'orientation_plan_turn_deg': float(_angles_deg(plan_q[0], plan_q).max())}
    ref = run.rec['reference'][:, 0].astype(np.int64)
    ref_q = run.rec.get('reference_q')
    order = {int(k): i for i, k in enumerate(ref)}
    pairs = [(j, order[int(k)]) for j, k in enumerate(stamps[inside]) if int(k) in order]
    if pairs and ref_q is not None:
        a, b = np.array(pairs).T
        vs_ref = _angles_deg(true_q[a], ref_q[b])
        figures.update({'orientation_tracking_vs_reference_rms_deg':
                        float(np.sqrt(np.mean(vs_ref ** 2))),
                        'orientation_tracking_vs_reference_max_deg': float(vs_ref.max())})
    tip = {int(k): x for k, x in zip(run.rec['tip'][:, 0], run.rec['tip'][:, 1:])}
    gaps = [np.linalg.norm(p - tip[int(k)]) for (p, _), k in zip(poses, stamps[inside])
            if int(k) in tip]
    if gaps:
        figures['orientation_fk_vs_tip_max_mm'] = float(np.max(gaps) * 1e3)
    turned = demo_turned(run.scene, plan_x[0], plan_x[-1], plan_t, tr.tau) \
        if run.goal_move is None and run.method == 'etdmp' else None
    if turned is not None:
        keep = plan_t <= tr.tau + 1e-9
        figures['orientation_plan_vs_demo_turned_max_deg'] = float(
            _angles_deg(plan_q[keep], turned[keep]).max())
    return figures

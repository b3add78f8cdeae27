"""
The arm check (etdmp_ros.robot._arm_check, no ROS): spheres around the UR10 against obstacles.

The spheres must enclose what the simulation collides (MuJoCo: the convex hulls of the same
URDF's collision meshes, the pen's cylinders): every hull vertex lies in a sphere of its link,
and no sphere's distance to an obstacle cylinder exceeds MuJoCo's own distance between the
link's hull and that cylinder (mj_geomDistance), so a contact the simulation would count is
never missed. Along a plan, an obstacle where the wrist sweeps is found, named by link.
"""

from etdmp_ros.robot import UR10Model
from etdmp_ros.robot._arm_check import (arm_obstacle_violation, ArmGeometry,
                                        checked_configurations, cylinder_gaps, densified, LINKS)
from etdmp_ros.robot._timing import plan_joints
from etdmp_ros.ros.system import scene_config
from etdmp_ros.sim import UR10Sim
import numpy as np
import pinocchio as pin
import pytest
from support.controller_plans import letter_plan, Q_INITIAL, TOOL_OFFSET


@pytest.fixture(scope='module')
def ur10():
    return UR10Model(tool_offset=TOOL_OFFSET)


@pytest.fixture(scope='module')
def arm(ur10):
    return ArmGeometry(ur10)


@pytest.fixture(scope='module')
def sim():
    with UR10Sim(scene_config()) as s:
        yield s


def random_joints(count, seed):
    """Return joint positions (count, 6) about the scene's start pose."""
    return Q_INITIAL + np.random.default_rng(seed).normal(0.0, 0.6, (count, 6))


def test_the_chain_is_pinocchios(ur10, arm):
    q = random_joints(20, 1)
    frames = arm.joint_frames(q)
    data = ur10.model.createData()
    for qi, f in zip(q, frames):
        pin.forwardKinematics(ur10.model, data, qi)
        for j in range(6):
            np.testing.assert_allclose(f[j], data.oMi[j + 1].homogeneous, atol=1e-12)


def test_the_spheres_enclose_every_link_and_the_tool_as_the_simulation_collides_them(sim, arm):
    assert set(arm.parts) == set(LINKS)
    assert set(arm.tool_parts) == {'tool', 'tool_tip'}
    m, d = sim.model, sim.data
    for q in random_joints(10, 2):
        sim.set_joint_positions(q)
        centres = arm.centres(q)[0]
        for g in range(m.ngeom):
            link = m.body(m.geom_bodyid[g]).name
            if link not in LINKS or m.geom_dataid[g] < 0:
                continue
            mesh = m.geom_dataid[g]
            # The hull's vertices are the mesh's (MuJoCo collides a mesh by its convex hull).
            start, count = m.mesh_vertadr[mesh], m.mesh_vertnum[mesh]
            points = m.mesh_vert[start:start + count] @ d.geom_xmat[g].reshape(3, 3).T + \
                d.geom_xpos[g]
            mine = arm.parts == link
            outside = (np.linalg.norm(points[:, None] - centres[mine][None], axis=2)
                       - arm.radii[mine]).min(axis=1)
            assert outside.max() < 1e-9, (link, outside.max())
        # The pen: points on its cylinders' surfaces, in the tool's spheres.
        tip, rotation = sim.site_pose(sim.tool_tip_site)
        tool = arm.tool_centres(tip, rotation)[0]
        for name, radius, (a, b) in (('pen', 0.009, (0.0, 0.14)),
                                     ('pen_tip', 0.003, (0.14, 0.16))):
            along = np.linspace(a, b, 41)
            angle = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
            local = np.stack([np.outer(np.ones_like(along), radius * np.cos(angle)).ravel(),
                              np.outer(np.ones_like(along), radius * np.sin(angle)).ravel(),
                              np.repeat(along - 0.16, len(angle))], axis=1)
            points = local @ rotation.T + tip
            outside = (np.linalg.norm(points[:, None] - tool[None], axis=2)
                       - arm.tool_radii).min(axis=1)
            assert outside.max() < 1e-9, (name, outside.max())


def test_no_gap_exceeds_the_simulations_distance_between_a_link_and_an_obstacle(sim, arm):
    # Against MuJoCo's own distance between each link's hull and an obstacle cylinder
    # (mj_geomDistance): the spheres' gap is never larger (never misses a contact), and
    # typically a few centimetres smaller (the spheres' over-cover). The simulation's
    # cylinders float here (random tops): the checked ones are shifted to stand on z = 0 too.
    import mujoco
    m, d = sim.model, sim.data
    rng = np.random.default_rng(3)
    over = []
    obstacle = m.geom('obstacle_0').id
    for q in random_joints(12, 4):
        sim.set_joint_positions(q)
        centres = arm.centres(q)
        for _ in range(6):
            radius = rng.uniform(0.01, 0.08)
            link_points = centres[0][rng.integers(len(arm.radii))]
            top = link_points + [*rng.normal(0.0, 0.08, 2), rng.uniform(-0.05, 0.15)]
            top[2] = max(top[2], 0.02)
            sim.set_obstacles([top], [radius])
            # The simulation's obstacle is obstacle.height tall: so is the checked cylinder.
            bottom = top[2] - sim.scene.obstacle_height
            shifted = centres.copy()
            shifted[..., 2] -= bottom
            gaps = cylinder_gaps(shifted, arm.radii, [top - [0.0, 0.0, bottom]],
                                 [radius])[0, :, 0]
            for g in range(m.ngeom):
                link = m.body(m.geom_bodyid[g]).name
                if link not in LINKS or m.geom_dataid[g] < 0:
                    continue
                truth = mujoco.mj_geomDistance(m, d, g, obstacle, 10.0, None)
                mine = gaps[arm.parts == link].min()
                # (Overlapping, the two measure depth differently: only the sign counts.)
                assert mine <= max(truth, 0.0) + 1e-6, (link, mine, truth)
                if truth < 0.1:
                    over.append(truth - mine)
    sim.set_obstacles(sim.scene.obstacle_positions, [])
    print(f'spheres vs the hulls near an obstacle: median {np.median(over) * 1e3:.1f} mm, '
          f'max {np.max(over) * 1e3:.1f} mm closer ({len(over)} pairs)')
    assert len(over) > 50


def test_cylinder_gaps_of_spheres_around_a_cylinder():
    centres = np.array([[[0.5, 0.0, 0.04],      # beside it, 0.1 m from the axis
                         [0.4, 0.0, 0.20],      # above its top (0.08) by 0.12
                         [0.5, 0.0, 0.18],      # off the rim: 0.05 out, 0.1 up
                         [0.4, 0.02, 0.05]]])   # inside
    gaps = cylinder_gaps(centres, np.full(4, 0.01), [[0.4, 0.0, 0.08]], [0.05])[0, :, 0]
    np.testing.assert_allclose(gaps, [0.04, 0.11, np.hypot(0.05, 0.1) - 0.01, -0.01])
    # A point obstacle (radius 0): a vertical segment from the table to it.
    assert cylinder_gaps(centres[:, :1], [0.01], [[0.5, 0.0, 0.3]], [0.0])[0, 0, 0] == \
        pytest.approx(-0.01)


def test_checked_configurations_move_no_sphere_more_than_the_step(arm):
    joints = random_joints(8, 5)
    solved = arm.centres(joints)
    moved = np.linalg.norm(np.diff(solved, axis=0), axis=2).max(axis=1)
    rows, when = densified(joints, np.arange(8.0), moved, 0.02)
    assert np.all(np.diff(when) > 0) and when[0] == 0.0 and when[-1] == 7.0
    assert len(rows) == 1 + np.sum(np.maximum(1, np.ceil(moved / 0.02)))
    np.testing.assert_allclose(rows[np.searchsorted(when, np.arange(8.0))], joints)
    rows, when, centres = checked_configurations(arm, joints, np.arange(8.0), 0.02)
    np.testing.assert_allclose(centres, arm.centres(rows))
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=2).max(axis=1)
    assert steps.max() <= 0.02, steps.max()


def test_an_obstacle_where_the_wrist_sweeps_is_found_and_named(ur10, arm):
    # The letter W on the task plane, IK along it as dmp_server solves it. A tall obstacle
    # (top 0.4 m up, radius 3 cm) where the first wrist passes half-way: the pen (16 cm long)
    # writes 0.1 m beside it, untouched, but the wrist meets it.
    path, t, positions = letter_plan('W', dt=0.01)
    idx, joints, violation = plan_joints(ur10, positions, path.rotations, t, Q_INITIAL, 32)
    assert violation is None
    free = arm_obstacle_violation(arm, joints, t[idx], np.zeros((0, 3)), [], 0.005)
    assert free is None
    half = len(idx) // 2
    wrist = arm.joint_frames(joints[half])[0, 3, :3, 3]        # wrist_1_joint's origin
    tip = positions[idx[half]]
    assert np.linalg.norm(wrist[:2] - tip[:2]) > 0.1            # the pen is far from it
    tall = np.array([[*wrist[:2], 0.4]])
    touch = arm_obstacle_violation(arm, joints, t[idx], tall, [0.03], 0.005)
    assert touch is not None and touch.part in ('forearm_link', 'wrist_1_link',
                                                'wrist_2_link'), touch
    assert touch.obstacle == 0 and touch.gap < 0.005 and touch.t <= t[idx[half]] + 1e-9
    print(f'wrist sweep: {touch}')
    # The same obstacle 8 cm tall (the scene's) stays below the wrist: no violation; nor
    # does a tall one 0.3 m away.
    assert arm_obstacle_violation(arm, joints, t[idx], [[*wrist[:2], 0.08]], [0.03],
                                  0.005) is None
    assert arm_obstacle_violation(arm, joints, t[idx], [[wrist[0] + 0.3, wrist[1] - 0.3, 0.4]],
                                  [0.03], 0.005) is None
    # The tool, when asked (every pose of the plan): a cylinder the pen passes through.
    on_path = np.array([[*positions[150, :2], 0.08]])
    pen = arm_obstacle_violation(arm, joints, t[idx], on_path, [0.01], 0.0,
                                 tool_poses=(t, positions, path.rotations))
    assert pen is not None and pen.part in ('tool', 'tool_tip') and pen.gap < 0
    assert arm_obstacle_violation(arm, joints, t[idx], on_path, [0.01], 0.0) is None

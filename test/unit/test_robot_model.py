"""The UR10 model: limits, tool frame, Jacobian."""

from etdmp_ros.robot import JOINT_NAMES, UR10Model
import numpy as np
import pytest


@pytest.fixture(scope='module')
def ur10():
    return UR10Model(tool_offset=(0.0, 0.0, 0.15))


def test_joints_and_limits(ur10):
    assert tuple(ur10.model.names[1:]) == JOINT_NAMES
    # Stricter of URDF (2.16, 2.16, 3.15, 3.2, 3.2, 3.2 rad/s) and official UR10 (120/180 deg/s).
    np.testing.assert_allclose(ur10.velocity_limits, np.radians([120, 120, 180, 180, 180, 180]))
    assert ur10.lower[2] == pytest.approx(-np.pi) and ur10.upper[2] == pytest.approx(np.pi)


def test_tool_tip_is_offset_along_the_flange_axis(ur10):
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, 6)
        p_flange, r_flange = ur10.frame_pose(q, ur10.flange_frame_id)
        p_tip, r_tip = ur10.frame_pose(q)
        np.testing.assert_allclose(p_tip, p_flange + r_flange @ [0.0, 0.0, 0.15], atol=1e-12)
        np.testing.assert_allclose(r_tip, r_flange, atol=1e-12)


def test_reach_at_zero_configuration(ur10):
    # All joints at zero: the arm lies stretched along -x of base_link (upper arm 0.612 m,
    # forearm 0.5723 m), so the flange is about 1.18 m out plus the wrist offsets.
    p, _ = ur10.frame_pose(np.zeros(6), ur10.flange_frame_id)
    assert 1.15 < np.hypot(p[0], p[1]) < 1.45


def test_jacobian_matches_finite_differences(ur10):
    rng = np.random.default_rng(1)
    q = rng.uniform(-2.0, 2.0, 6)
    jac = ur10.tool_jacobian(q)
    eps = 1e-7
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = eps
        p1, r1 = ur10.frame_pose(q + dq)
        p0, r0 = ur10.frame_pose(q - dq)
        np.testing.assert_allclose(jac[:3, j], (p1 - p0) / (2 * eps), atol=1e-6)
        skew = (r1 - r0) @ ur10.frame_pose(q)[1].T / (2 * eps)
        np.testing.assert_allclose(jac[3:, j], [skew[2, 1], skew[0, 2], skew[1, 0]], atol=1e-6)


def test_kinematics_is_frame_pose_and_jacobian_in_one_call(ur10):
    q = np.random.default_rng(2).uniform(-2.0, 2.0, 6)
    p, rot, jac = ur10.kinematics(q)
    p_ref, rot_ref = ur10.frame_pose(q)
    np.testing.assert_allclose(p, p_ref, atol=1e-15)
    np.testing.assert_allclose(rot, rot_ref, atol=1e-15)
    np.testing.assert_allclose(jac, ur10.tool_jacobian(q), atol=1e-15)


def test_solve_pose_reaches_a_reachable_pose_and_reports_the_error(ur10):
    rng = np.random.default_rng(3)
    q_goal = rng.uniform(-1.5, 1.5, 6)
    position, rotation = ur10.frame_pose(q_goal)
    q0 = q_goal + rng.uniform(-0.2, 0.2, 6)
    start = q0.copy()
    q, error = ur10.solve_pose(position, rotation, q0, iterations=200, tolerance=1e-9)
    np.testing.assert_array_equal(q0, start)            # the start is not modified
    assert error.shape == (6,) and np.linalg.norm(error) < 1e-9
    p, rot = ur10.frame_pose(q)
    np.testing.assert_allclose(p, position, atol=1e-9)
    np.testing.assert_allclose(rot, rotation, atol=1e-9)
    # Out of reach (3 m away): the error at the returned joints is what is left.
    far = np.array([3.0, 0.0, 0.5])
    q, error = ur10.solve_pose(far, rotation, q0)
    np.testing.assert_allclose(error[:3], far - ur10.frame_pose(q)[0], atol=1e-12)
    assert np.linalg.norm(error[:3]) > 1.0

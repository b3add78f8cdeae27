"""
The three pieces under every skill, tested directly.

The Euclidean transform, the forcing term and the numpy reference rollout (the oracle the numba
rollout is checked against elsewhere).

Each is compared with what it must be by construction: rotations that turn I_C onto I_D with the
signed angle (the paper's Eq. 10 corrected), normalised kernels that vanish with the phase, and
the closed-form motion of a critically damped spring.
"""

import math

from etdmp_ros.dmp import euclidean_transform, GeneralizationError
from etdmp_ros.dmp._forcing_term import ForcingTerm, gate, GATE_WIDTH, phase
from etdmp_ros.dmp._integrate import rollout_reference
import numpy as np
import pytest


def _rotation_2d(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _assert_rotation(R):
    assert np.allclose(R @ R.T, np.eye(len(R)), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


# ------------------------------------------------------------------------- Euclidean transform
@pytest.mark.parametrize('degrees', [30.0, 120.0, 179.0, -30.0, -120.0, -179.0])
def test_2d_rotation_uses_the_signed_angle(degrees):
    i_demo = np.array([2.0, 1.0])
    i_current = 0.5 * _rotation_2d(math.radians(degrees)) @ i_demo
    t = euclidean_transform(i_demo, i_current)
    _assert_rotation(t.R)
    # R turns I_C back by exactly the angle it was turned by (arccos would lose the sign).
    assert np.allclose(t.R, _rotation_2d(-math.radians(degrees)), atol=1e-12)
    assert np.allclose(t.scale, 0.5)


def test_1d_is_a_reflection_about_the_goal():
    assert euclidean_transform([2.0], [-3.0]).R.item() == -1.0
    assert euclidean_transform([-2.0], [-3.0]).R.item() == 1.0
    assert euclidean_transform([2.0], [-3.0]).scale.item() == pytest.approx(1.5)


def test_3d_mode_1_is_the_rodrigues_rotation_about_ic_cross_id():
    i_demo = np.array([0.3, -0.2, 0.5])
    i_current = np.array([-0.1, 0.4, 0.2])
    t = euclidean_transform(i_demo, i_current)
    _assert_rotation(t.R)
    u_c, u_d = (v / np.linalg.norm(v) for v in (i_current, i_demo))
    assert np.allclose(t.R @ u_c, u_d, atol=1e-12)
    axis = np.cross(i_current, i_demo)
    assert np.allclose(t.R @ axis, axis, atol=1e-12)        # the axis is fixed
    assert np.allclose(t.scale, np.linalg.norm(i_current) / np.linalg.norm(i_demo))


def test_3d_anti_parallel_is_a_half_turn_about_a_defined_axis():
    i_demo = np.array([1.0, 0.2, 0.0])
    t = euclidean_transform(i_demo, -2.0 * i_demo)
    _assert_rotation(t.R)
    assert np.allclose(t.R @ -i_demo, i_demo, atol=1e-12)
    # A half turn (symmetric, its own inverse) about I_D x z, z being the coordinate axis least
    # aligned with I_D: the axis is fixed.
    assert np.allclose(t.R, t.R.T, atol=1e-12) and np.allclose(t.R @ t.R, np.eye(3), atol=1e-12)
    axis = np.cross(i_demo, [0.0, 0.0, 1.0])
    assert np.allclose(t.R @ axis, axis, atol=1e-12)


def test_3d_mode_2_splits_into_a_1d_and_a_2d_rule():
    i_demo = np.array([0.3, 0.4, -0.2])
    i_current = np.array([-0.4, 0.3, 0.6])          # the same plane part, turned by +90 degrees
    t = euclidean_transform(i_demo, i_current, mode=2, independent_axis=2)
    assert t.R[2, 2] == -1.0 and np.allclose(t.R[2, :2], 0.0) and np.allclose(t.R[:2, 2], 0.0)
    assert np.allclose(t.R[:2, :2], _rotation_2d(-math.pi / 2), atol=1e-12)
    assert np.allclose(t.scale, [1.0, 1.0, 3.0])    # per block: |I_C| / |I_D|


def test_virtual_and_real_situations_map_into_each_other():
    rng = np.random.default_rng(3)
    goal = np.array([0.7, -0.1, 0.3])
    t = euclidean_transform(rng.normal(size=3), rng.normal(size=3))
    points = rng.normal(size=(20, 3))
    virtual = t.to_virtual(points, goal)
    assert np.allclose(t.from_virtual(virtual, goal), points, atol=1e-12)
    assert np.allclose(virtual - goal, (points - goal) @ t.R.T, atol=1e-12)   # Eq. 12
    assert np.allclose(t.vectors_from_virtual(virtual - goal), points - goal, atol=1e-12)
    assert np.allclose(np.linalg.norm(virtual - goal, axis=1),
                       np.linalg.norm(points - goal, axis=1))       # distances are kept


def test_undefined_transforms_are_refused():
    with pytest.raises(GeneralizationError, match='start equals goal'):
        euclidean_transform([1.0, 0.0], [0.0, 0.0])
    with pytest.raises(GeneralizationError, match='starts at its goal'):
        euclidean_transform([0.0, 0.0], [1.0, 0.0])
    with pytest.raises(GeneralizationError, match='mode'):
        euclidean_transform([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], mode=3)


# ------------------------------------------------------------------------------ forcing term
def test_kernels_are_normalised_and_spaced_evenly_in_time():
    forcing = ForcingTerm(30, alpha=4.0)
    times = -np.log(forcing.centres) / forcing.alpha
    assert np.allclose(times, np.linspace(0.0, 1.0, 30))
    s = phase(np.linspace(0.0, 1.0, 101), 1.0, 4.0)
    # s G(s) psi_i / sum_j psi_j summed over the kernels is the gated phase s G(s).
    assert np.allclose(forcing.design_matrix(s).sum(axis=1), s * gate(s, 4.0), rtol=1e-12)


def test_the_gate_ends_the_forcing_at_tau_smoothly():
    # docs/design.md#coming-to-rest: G = 1 until (1 - GATE_WIDTH) tau, 0 from tau on, C2.
    alpha = 4.0
    t = np.linspace(0.0, 3.0, 30001)
    g = gate(phase(t, 1.0, alpha), alpha)
    assert np.all(g[t <= 1.0 - GATE_WIDTH] == 1.0)
    assert np.all(g[t >= 1.0] == 0.0)
    assert np.all(np.diff(g) <= 1e-12)
    h = t[1] - t[0]
    # The smootherstep's slopes: at most 15/8 / GATE_WIDTH per tau, 0 at both ends.
    slope = np.diff(g) / h
    assert np.max(np.abs(slope)) <= 1.875 / GATE_WIDTH * 1.001
    assert abs(slope[np.searchsorted(t, 1.0 - GATE_WIDTH)]) < 1e-2
    assert abs(slope[np.searchsorted(t, 1.0) - 1]) < 1e-2
    forcing = ForcingTerm(30, alpha)
    forcing.weights = np.random.default_rng(0).normal(size=(30, 2)) * 1e4
    assert np.all(forcing(phase(t[t >= 1.0], 1.0, alpha)) == 0.0)


def test_forcing_vanishes_with_the_phase_and_fits_a_smooth_target():
    forcing = ForcingTerm(50, alpha=4.0)
    t = np.linspace(0.0, 1.0, 400)
    s = phase(t, 1.0, 4.0)
    target = np.stack([100.0 * np.sin(2 * math.pi * t), 50.0 * t * (1 - t)], axis=1)
    forcing.fit(s, target)
    rms = np.sqrt(np.mean((forcing(s) - target) ** 2))
    assert rms < 0.5                                # of amplitudes 100 and 12.5
    # The factor s (docs/design.md, corrections to the paper): far past the end of the
    # movement f is ~0.
    late = forcing(phase(np.array([3.0, 6.0]), 1.0, 4.0))
    assert np.all(np.abs(late) < 1e-3 * np.abs(target).max())


def test_too_few_kernels_are_refused():
    with pytest.raises(ValueError, match='n_basis'):
        ForcingTerm(1, alpha=4.0)


# ----------------------------------------------------------------------- reference rollout
def _rollout(x0, goal, forcing=0.0, R=None, obstacles=None, K=156.25, D=25.0, tau=1.0, n=201,
             substeps=4):
    x0, goal = np.atleast_2d(x0).astype(float), np.atleast_2d(goal).astype(float)
    B, d = x0.shape
    dt = 1.5 * tau / (n - 1)
    h = dt / substeps
    n_sub = (n - 1) * substeps
    s_mid = phase((np.arange(n_sub) + 0.5) * h, tau, 4.0)
    s_out = phase(np.arange(n) * dt, tau, 4.0)
    f_mid, f_out = np.full((n_sub, d), forcing), np.full((n, d), forcing)
    obstacles = np.zeros((B, 0, d)) if obstacles is None else obstacles
    R = np.broadcast_to(np.eye(d), (B, d, d)) if R is None else R
    gains = (250.0, 20.0 / math.pi, 300.0, np.full(B, 10.0))
    X, V, A = rollout_reference(x0, goal, np.zeros((B, d)), np.ones((B, d)), s_mid, f_mid,
                                s_out, f_out, obstacles, gains, K, D, tau, h, substeps, R)
    return np.arange(n) * dt, X, V, A


def test_without_forcing_it_is_the_critically_damped_spring():
    K, tau = 156.25, 0.8
    x0, goal = np.array([[0.4, -0.2]]), np.array([[0.1, 0.3]])
    t, X, V, A = _rollout(x0, goal, K=K, D=2 * math.sqrt(K), tau=tau)
    w = math.sqrt(K) / tau
    exact = goal + (x0 - goal) * ((1 + w * t) * np.exp(-w * t))[:, None]
    exact_v = (x0 - goal) * (-w * w * t * np.exp(-w * t))[:, None]
    assert np.abs(X[0] - exact).max() < 1e-12     # exact discretisation, not an approximation
    assert np.abs(V[0] - exact_v).max() < 1e-10
    # The acceleration is that of the equation of motion at every sample.
    assert np.allclose(A[0], (K * (goal - X[0]) - 2 * math.sqrt(K) * tau * V[0]) / tau ** 2)


def test_a_constant_forcing_shifts_the_rest_point_by_f_over_k():
    _, X, _, _ = _rollout([[0.0]], [[1.0]], forcing=31.25, n=801)
    assert X[0, -1, 0] == pytest.approx(1.0 + 31.25 / 156.25, abs=1e-6)


def test_the_output_is_mapped_back_with_r_transposed():
    R = _rotation_2d(0.7)[None]
    x0, goal = np.array([[0.5, 0.0]]), np.array([[0.2, 0.1]])
    _, X, V, _ = _rollout(x0, goal, R=R)
    _, X_virtual, V_virtual, _ = _rollout(x0, goal)
    assert np.allclose(X[0], (X_virtual[0] - goal) @ R[0] + goal, atol=1e-14)
    assert np.allclose(V[0], V_virtual[0] @ R[0], atol=1e-14)


def test_obstacles_turn_the_path_without_stopping_it_at_the_goal():
    x0, goal = np.array([[0.0, 0.0]]), np.array([[1.0, 0.0]])
    obstacle = np.array([[[0.5, 0.01]]])            # almost on the straight line
    _, X, _, _ = _rollout(x0, goal, obstacles=obstacle, n=601)
    _, straight, _, _ = _rollout(x0, goal, n=601)
    assert np.abs(straight[0, :, 1]).max() < 1e-12
    clearance = np.linalg.norm(X[0] - obstacle[0, 0], axis=1).min()
    assert clearance > 0.05                           # it went round
    assert np.linalg.norm(X[0, -1] - goal[0]) < 1e-3  # and still arrives (Eq. 28-29)


def test_plane_rotation_fast_path_equals_the_numpy_formula():
    from etdmp_ros.dmp._transform import plane_rotation, plane_rotation_numpy
    rng = np.random.default_rng(7)
    for d in (2, 3):
        for _ in range(50):
            demo = rng.normal(size=d)
            rows = rng.normal(size=(40, d))
            rows[0], rows[1], rows[2] = 0.0, -2.0 * demo, 3.0 * demo    # zero, anti-, parallel
            fast = plane_rotation(demo, rows)
            np.testing.assert_allclose(fast, plane_rotation_numpy(demo, rows), atol=1e-12)
            turned = np.einsum('bij,bj->bi', fast[1:], rows[1:])
            np.testing.assert_allclose(turned / np.linalg.norm(turned, axis=1)[:, None],
                                       np.tile(demo / np.linalg.norm(demo), (39, 1)), atol=1e-12)
        np.testing.assert_array_equal(plane_rotation(np.zeros(d), rows),
                                      np.tile(np.eye(d), (40, 1, 1)))

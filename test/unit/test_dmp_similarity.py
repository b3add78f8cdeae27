"""nRMSE (paper Eq. 15-16; docs/design.md#similarity-measure) and clearance."""

from etdmp_ros.dmp import clearance, nrmse, similarity
import numpy as np
import pytest


def curve(n=200):
    t = np.linspace(0.0, 1.0, n)
    return np.c_[np.cos(4 * t) * (1 - t), np.sin(3 * t) + t]


def test_identical_paths_have_zero_error():
    y = curve()
    assert similarity(y, y) == (0.0, 0.0)


def test_invariant_to_rotation_scale_translation_and_sampling():
    y = curve()
    angle = 2.3
    q = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    moved = 3.7 * (y - y[-1]) @ q.T + np.array([5.0, -2.0])
    assert nrmse(moved, y) < 1e-12
    assert nrmse(moved, y, variant='paper') < 1e-12
    dense = np.c_[np.interp(np.linspace(0, 1, 1000), np.linspace(0, 1, 200), y[:, 0]),
                  np.interp(np.linspace(0, 1, 1000), np.linspace(0, 1, 200), y[:, 1])]
    assert nrmse(dense, y) < 1e-3


def test_values_match_the_formula():
    y = curve()
    other = y.copy()
    other[:, 1] += 0.1 * np.sin(np.linspace(0, 6, 200))
    other[-1] = y[-1]
    other[0] = y[0]             # same start direction: no rotation involved
    a = y - y[-1]
    b = other - other[-1]
    a /= np.abs(a).max()
    b /= np.abs(b).max()
    m = np.mean((b - a) ** 2, axis=0)
    sim = similarity(other, y)
    assert sim.conventional == pytest.approx(np.sqrt(m.sum()))
    assert sim.paper == pytest.approx(np.sqrt((m ** 2).sum()))
    assert 0.0 < sim.paper < sim.conventional


def test_3d_and_1d():
    rng = np.random.default_rng(0)
    y = np.cumsum(rng.normal(size=(100, 3)), axis=0)
    # Only the start direction is aligned (Eq. 10 / Rodrigues): a rotation about an axis
    # perpendicular to it is undone, a twist about the start direction itself is not.
    i_d = y[0] - y[-1]
    k = np.cross(i_d, rng.normal(size=3))
    k /= np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    q = np.eye(3) + np.sin(1.1) * kx + (1 - np.cos(1.1)) * kx @ kx
    assert nrmse((y - y[-1]) @ q.T * 2.0, y) < 1e-12
    e = i_d / np.linalg.norm(i_d)
    ex = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
    twist = np.eye(3) + np.sin(1.1) * ex + (1 - np.cos(1.1)) * ex @ ex
    assert nrmse((y - y[-1]) @ twist.T, y) > 0.01
    z = np.sin(np.linspace(0, 3, 50))
    assert nrmse(-(z - z[-1]), z) < 1e-12     # a reflection is the 1D "rotation"


def test_bad_input():
    with pytest.raises(ValueError, match='variant'):
        nrmse(curve(), curve(), variant='other')
    with pytest.raises(ValueError, match='same d'):
        nrmse(curve(), np.zeros((10, 3)))
    with pytest.raises(ValueError, match='NaN'):
        nrmse(np.full((10, 2), np.nan), curve())


def test_clearance():
    path = np.c_[np.linspace(0, 1, 11), np.zeros(11)]
    assert clearance(path, [[0.5, 0.3], [2.0, 0.0]]) == pytest.approx(0.3)
    assert clearance(path, np.zeros((0, 2))) == np.inf

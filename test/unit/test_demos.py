"""Demonstrations: the built-in set, file round trips, and clear errors for bad files (no ROS)."""

import pickle

from etdmp_ros.dmp import (builtin_demo, builtin_demo_names, Demonstration, DemonstrationError,
                           load_demo, save_demo)
from etdmp_ros.dmp._demos import MIN_SAMPLES
import numpy as np
import pytest

LETTERS = ('G', 'P', 'R', 'W')
# name: (dim, samples, duration [s])
BUILTINS = {'G': (2, 200, 2.0), 'P': (2, 200, 2.0), 'R': (2, 200, 2.0), 'W': (2, 200, 2.0),
            'wipe': (2, 400, 4.0), 'stir': (3, 500, 5.0)}


def _kinematics(demo):
    v = np.gradient(demo.positions, demo.t, axis=0)
    a = np.gradient(v, demo.t, axis=0)
    return np.linalg.norm(v, axis=1), a


def _write(path, text):
    path.write_text(text, encoding='utf-8')
    return path


def _csv(rows, header='t,x,y'):
    return header + '\n' + ''.join(','.join(str(v) for v in row) + '\n' for row in rows)


def _good_rows(n=12):
    return [(k * 0.1, float(k), float(k * k)) for k in range(n)]


# ----------------------------------------------------------------------------- built-in demos

def test_builtin_names():
    assert sorted(builtin_demo_names()) == sorted(BUILTINS)


@pytest.mark.parametrize('name', sorted(BUILTINS))
def test_builtin_shape_and_timing(name):
    dim, samples, duration = BUILTINS[name]
    demo = builtin_demo(name)
    assert demo.name == name
    assert demo.positions.shape == (samples, dim)
    assert demo.positions.dtype == np.float64
    assert demo.dim == dim
    assert demo.t[0] == 0.0
    assert demo.duration == pytest.approx(duration, abs=1e-8)
    np.testing.assert_allclose(np.diff(demo.t), duration / (samples - 1), rtol=1e-6)
    assert np.all(np.isfinite(demo.positions))


@pytest.mark.parametrize('name', sorted(BUILTINS))
def test_builtin_starts_and_ends_at_rest(name):
    demo = builtin_demo(name)
    speed, accel = _kinematics(demo)
    peak = speed.max()
    assert peak > 0
    assert speed[0] < 0.02 * peak, f'{name}: start speed {speed[0]} vs peak {peak}'
    assert speed[-1] < 0.02 * peak, f'{name}: end speed {speed[-1]} vs peak {peak}'
    peak_accel = np.linalg.norm(accel, axis=1).max()
    assert np.linalg.norm(accel[0]) < 0.02 * peak_accel
    assert np.linalg.norm(accel[-1]) < 0.02 * peak_accel


@pytest.mark.parametrize('name', sorted(BUILTINS))
def test_builtin_is_smooth(name):
    # A jump in the finite-difference acceleration close to its peak would mean a kink or noise
    # in the curve (the corners of letters are tight but still rounded over several samples).
    _, accel = _kinematics(builtin_demo(name))
    peak = np.linalg.norm(accel, axis=1).max()
    assert np.linalg.norm(np.diff(accel, axis=0), axis=1).max() < 0.75 * peak


@pytest.mark.parametrize('name', sorted(BUILTINS))
def test_builtin_start_and_goal_apart_in_every_dimension(name):
    # The plain DMP scales the forcing term by (goal - start) per dimension.
    demo = builtin_demo(name)
    size = np.ptp(demo.positions, axis=0).max()
    separation = np.abs(demo.goal - demo.start)
    assert np.all(separation >= 0.2 * size), f'{name}: {separation} vs size {size}'


@pytest.mark.parametrize('name', LETTERS)
def test_letters_are_ten_units_tall(name):
    extent = np.ptp(builtin_demo(name).positions, axis=0)
    assert 9.9 <= extent[1] <= 10.05
    assert 5.0 <= extent[0] <= 10.0


def test_wipe_covers_board_area_and_ends_in_its_centre():
    x = builtin_demo('wipe').positions
    lo, hi = x.min(axis=0), x.max(axis=0)
    np.testing.assert_allclose(hi - lo, [10.0, 6.0], atol=0.3)
    np.testing.assert_allclose(x[0], lo + [0.0, hi[1] - lo[1]], atol=0.05)  # top-left corner
    np.testing.assert_allclose(x[-1], (lo + hi) / 2, atol=0.3)
    # Back and forth: the x velocity changes sign at several turnarounds.
    vx = np.diff(x[:, 0])
    reversals = np.count_nonzero(np.diff(np.sign(vx[np.abs(vx) > 1e-3])) != 0)
    assert reversals >= 5


def test_stir_spirals_down_the_bottle():
    demo = builtin_demo('stir')
    x = demo.positions
    np.testing.assert_allclose(demo.start, [0.08 * np.sqrt(0.5), 0.08 * np.sqrt(0.5), 0.12],
                               atol=1e-6)
    np.testing.assert_allclose(demo.goal[:2], [0.0, 0.0], atol=1e-6)
    assert -0.16 < demo.goal[2] < -0.1
    inside = x[:, 2] < 0.0
    radius = np.hypot(x[:, 0], x[:, 1])
    assert radius[inside].max() == pytest.approx(0.025, abs=0.002)
    angle = np.unwrap(np.arctan2(x[inside, 1], x[inside, 0]))
    assert 3.0 <= np.ptp(angle) / (2 * np.pi) <= 4.0
    assert np.all(np.diff(x[inside, 2]) <= 1e-9), 'the spoon only goes down inside the bottle'


def test_builtin_is_shared_and_read_only():
    demo = builtin_demo('G')
    assert builtin_demo('G') is demo
    with pytest.raises(ValueError):
        demo.positions[0, 0] = 1.0


def test_unknown_builtin_lists_available_names():
    with pytest.raises(DemonstrationError) as err:
        builtin_demo('Q')
    message = str(err.value)
    assert "'Q'" in message
    for name in BUILTINS:
        assert name in message


# ----------------------------------------------------------------------------- Demonstration

def test_demonstration_properties_and_defaults():
    positions = np.c_[np.arange(11.0), np.arange(11.0) ** 2]
    demo = Demonstration('d', positions)
    np.testing.assert_allclose(demo.t, np.linspace(0, 1, 11))
    assert (demo.dim, demo.n_samples, demo.duration) == (2, 11, 1.0)
    np.testing.assert_array_equal(demo.start, [0, 0])
    np.testing.assert_array_equal(demo.goal, [10, 100])
    positions[0, 0] = 99.0
    assert demo.positions[0, 0] == 0.0, 'the demonstration keeps its own copy'
    assert 'samples=11' in repr(demo)


def test_demonstration_one_dimensional_positions():
    demo = Demonstration('line', np.linspace(0, 1, MIN_SAMPLES), t=np.arange(MIN_SAMPLES))
    assert demo.positions.shape == (MIN_SAMPLES, 1)
    assert demo.duration == MIN_SAMPLES - 1


@pytest.mark.parametrize('positions, t, expected', [
    (np.zeros((MIN_SAMPLES - 1, 2)), None, f'at least {MIN_SAMPLES}'),
    (np.zeros((2, 50)), None, 'transpose'),
    (np.zeros((12, 2, 2)), None, 'shape'),
    (np.zeros((12, 0)), None, 'no coordinates'),
    (np.zeros((12, 2)), np.arange(11.0), 'shape (12,)'),
    (np.where(np.eye(12, 2) > 0, np.nan, 0.0), None, 'positions[0, 0] is nan'),
    (np.full((12, 2), np.inf), None, 'finite'),
    (np.zeros((12, 2)), np.r_[np.arange(6.0), 5.0, np.arange(7.0, 12.0)], 't[6]'),
    (np.zeros((12, 2)), np.r_[np.arange(11.0), np.nan], 't[11]'),
    (np.array([['a', 'b']] * 12), None, 'real numbers'),
    (np.zeros((12, 2), dtype=complex), None, 'real numbers'),
])
def test_demonstration_rejects_bad_arrays(positions, t, expected):
    with pytest.raises(DemonstrationError) as err:
        Demonstration('bad', positions, t)
    assert expected in str(err.value)
    assert "'bad'" in str(err.value)


def test_demonstration_rejects_empty_name():
    with pytest.raises(DemonstrationError, match='name'):
        Demonstration('', np.zeros((12, 2)))


# ----------------------------------------------------------------------------- round trips

@pytest.mark.parametrize('dim', [1, 2, 3, 5])
@pytest.mark.parametrize('suffix', ['.csv', '.npz'])
def test_round_trip_keeps_everything(tmp_path, dim, suffix):
    rng = np.random.default_rng(dim)
    t = np.cumsum(rng.uniform(0.001, 0.1, 37)) + 1.7e9  # non-uniform, ROS-stamp-like
    demo = Demonstration('orig', rng.normal(scale=3.0, size=(37, dim)) / 7.0, t)
    path = tmp_path / f'my demo{suffix}'
    save_demo(path, demo)
    back = load_demo(path)
    assert back.name == 'my demo'
    np.testing.assert_array_equal(back.positions, demo.positions)
    np.testing.assert_array_equal(back.t, demo.t)


def test_round_trip_npy_keeps_positions_and_assumes_one_second(tmp_path):
    demo = builtin_demo('stir')
    save_demo(tmp_path / 'stir.npy', demo)
    back = load_demo(tmp_path / 'stir.npy', name='again')
    assert back.name == 'again'
    np.testing.assert_array_equal(back.positions, demo.positions)
    np.testing.assert_allclose(back.t, np.linspace(0.0, 1.0, 500))


def test_csv_header_names(tmp_path):
    stir = builtin_demo('stir')
    save_demo(tmp_path / 'a.csv', Demonstration('a', stir.positions, stir.t))
    assert (tmp_path / 'a.csv').read_text().splitlines()[0] == 't,x,y,z'
    # The built-in stir carries orientations (docs/orientation.md): four more columns.
    save_demo(tmp_path / 'o.csv', stir)
    assert (tmp_path / 'o.csv').read_text().splitlines()[0] == 't,x,y,z,qx,qy,qz,qw'
    save_demo(tmp_path / 'b.csv', Demonstration('b', np.zeros((12, 4)) + np.arange(12)[:, None]))
    assert (tmp_path / 'b.csv').read_text().splitlines()[0] == 't,x0,x1,x2,x3'


def test_csv_precision(tmp_path):
    save_demo(tmp_path / 'p.csv', builtin_demo('G'), precision=2)
    assert (tmp_path / 'p.csv').read_text().splitlines()[1] == '0,3.04,3.08'


@pytest.mark.parametrize('time_name', ['t', 'time', 'Stamp'])
def test_csv_time_column_names_and_order(tmp_path, time_name):
    rows = [(float(k), float(-k), k * 0.5) for k in range(12)]
    demo = load_demo(_write(tmp_path / 'd.csv', _csv(rows, f'a,b,{time_name}')))
    np.testing.assert_array_equal(demo.t, np.arange(12) * 0.5)
    np.testing.assert_array_equal(demo.positions, np.c_[np.arange(12.0), -np.arange(12.0)])


def test_csv_without_time_is_uniform_over_one_second(tmp_path):
    text = 'x,y\n' + ''.join(f'{k},{2 * k}\n' for k in range(20)) + '\n\n'
    demo = load_demo(_write(tmp_path / 'letter.csv', text))
    assert demo.name == 'letter'
    np.testing.assert_allclose(demo.t, np.linspace(0, 1, 20))
    assert demo.duration == 1.0


def test_csv_tolerates_spaces_and_byte_order_mark(tmp_path):
    text = '\ufeff t , x \n' + ''.join(f' {k} , {k * k} \n' for k in range(12))
    demo = load_demo(_write(tmp_path / 'bom.csv', text))
    assert demo.goal[0] == 121.0


def test_pbdlib_style_file_loads(tmp_path):
    # Same layout as the reference letters: header x,y, 200 rows, no time.
    xy = np.c_[np.linspace(0, 1, 200), np.linspace(2, 3, 200)]
    text = 'x,y\n' + ''.join(f'{a:.6f},{b:.6f}\n' for a, b in xy)
    demo = load_demo(_write(tmp_path / 'G_00.csv', text))
    assert demo.positions.shape == (200, 2) and demo.duration == 1.0


def test_save_rejects_unknown_suffix_and_non_demonstrations(tmp_path):
    with pytest.raises(DemonstrationError, match='unknown demonstration file type'):
        save_demo(tmp_path / 'd.txt', builtin_demo('G'))
    with pytest.raises(TypeError):
        save_demo(tmp_path / 'd.csv', np.zeros((12, 2)))


# ----------------------------------------------------------------------------- bad files

BAD_CSV = {
    'empty': ('', ['empty file']),
    'blank_lines_only': ('\n \n\n', ['empty file']),
    'no_header': (''.join(f'{k},{k}\n' for k in range(12)), ['no header row', 'line 1']),
    'header_only': ('t,x,y\n', ['0 data rows', f'at least {MIN_SAMPLES}']),
    'too_few': (_csv(_good_rows(MIN_SAMPLES - 1)), [f'{MIN_SAMPLES - 1} data rows']),
    'non_numeric': (_csv(_good_rows()[:5] + [(0.5, 'abc', 1.0)] + _good_rows()[6:]),
                    ['line 7', "column 'x'", "'abc' is not a number"]),
    'empty_cell': (_csv(_good_rows()[:3] + [(0.3, 1.0, '')] + _good_rows()[4:]),
                   ['line 5', "column 'y'", 'empty']),
    'ragged_short': (_csv(_good_rows()[:8] + [(0.8, 1.0)] + _good_rows()[9:]),
                     ['line 10', '2 cells', '3 columns']),
    'ragged_long': (_csv(_good_rows()[:2] + [(0.2, 1.0, 2.0, 3.0)] + _good_rows()[3:]),
                    ['line 4', '4 cells']),
    'nan': (_csv(_good_rows()[:9] + [(0.9, 'nan', 1.0)] + _good_rows()[10:]),
            ['line 11', "column 'x'", 'nan', 'finite']),
    'inf': (_csv(_good_rows()[:4] + [(0.4, 1.0, '-inf')] + _good_rows()[5:]),
            ['line 6', "column 'y'", 'inf', 'finite']),
    'time_not_increasing': (_csv(_good_rows()[:6] + [(0.5, 6.0, 36.0)] + _good_rows()[7:]),
                            ['line 8', "column 't'", 'strictly increasing']),
    'time_nan': (_csv(_good_rows()[:6] + [('nan', 6.0, 36.0)] + _good_rows()[7:]),
                 ['line 8', "column 't'", 'finite']),
    'two_time_columns': (_csv([(k, k, k) for k in range(12)], 't,time,x'),
                         ['more than one time column']),
    'only_time': (_csv([(k,) for k in range(12)], 't'), ['no position column']),
    'duplicate_column': (_csv(_good_rows(), 't,x,x'), ['repeats', 'x']),
    'unnamed_column': (_csv(_good_rows(), 't,,y'), ['column 2 has no name']),
}


@pytest.mark.parametrize('case', sorted(BAD_CSV))
def test_bad_csv_is_refused_with_a_helpful_message(tmp_path, case):
    text, expected = BAD_CSV[case]
    path = _write(tmp_path / f'{case}.csv', text)
    with pytest.raises(DemonstrationError) as err:
        load_demo(path)
    message = str(err.value)
    assert str(path) in message
    for part in expected:
        assert part in message, f'{part!r} not in {message!r}'


def test_missing_file(tmp_path):
    with pytest.raises(DemonstrationError, match='no such file'):
        load_demo(tmp_path / 'nothing.csv')


def test_directory_is_not_a_demo(tmp_path):
    (tmp_path / 'dir.csv').mkdir()
    with pytest.raises(DemonstrationError, match='not a regular file'):
        load_demo(tmp_path / 'dir.csv')


def test_unknown_extension(tmp_path):
    path = _write(tmp_path / 'demo.txt', _csv(_good_rows()))
    with pytest.raises(DemonstrationError) as err:
        load_demo(path)
    assert "'.txt'" in str(err.value) and '.csv' in str(err.value)


def test_non_utf8_csv(tmp_path):
    path = tmp_path / 'latin.csv'
    path.write_bytes(b't,x\xe9\n' + b''.join(b'%d,%d\n' % (k, k) for k in range(12)))
    with pytest.raises(DemonstrationError, match='UTF-8'):
        load_demo(path)


class _Boobytrap:
    """Unpickling this creates a marker file: proof that a loader executed pickle code."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), 'w'))


def test_pickled_object_npy_is_refused_and_never_unpickled(tmp_path):
    marker = tmp_path / 'unpickled'
    path = tmp_path / 'evil.npy'
    array = np.empty((12, 2), dtype=object)
    array[:] = 0.0
    array[0, 0] = _Boobytrap(marker)
    np.save(path, array, allow_pickle=True)
    with pytest.raises(DemonstrationError) as err:
        load_demo(path)
    assert 'pickle' in str(err.value) and str(path) in str(err.value)
    assert not marker.exists()


def test_raw_pickle_named_npy_is_refused(tmp_path):
    marker = tmp_path / 'unpickled'
    path = tmp_path / 'evil.npy'
    path.write_bytes(pickle.dumps(_Boobytrap(marker)))
    with pytest.raises(DemonstrationError) as err:
        load_demo(path)
    assert 'pickle' in str(err.value)
    assert not marker.exists()


def test_pickled_object_npz_is_refused(tmp_path):
    marker = tmp_path / 'unpickled'
    path = tmp_path / 'evil.npz'
    array = np.empty((12, 2), dtype=object)
    array[:] = 0.0
    array[0, 0] = _Boobytrap(marker)
    np.savez(path, positions=array)
    with pytest.raises(DemonstrationError, match='pickle'):
        load_demo(path)
    assert not marker.exists()


@pytest.mark.parametrize('make, expected', [
    (lambda p: p.write_bytes(b''), 'empty file'),
    (lambda p: p.write_bytes(b'\x93NUMPY\x01'), 'not a valid .npy'),
    (lambda p: p.write_bytes(b'not numpy at all'), 'neither a .npy array nor an .npz'),
    (lambda p: np.save(p, np.zeros((12, 2, 2))), 'shape'),
    (lambda p: np.save(p, np.array([['a', 'b']] * 12)), 'real numbers'),
    (lambda p: np.save(p, np.zeros((2, 200))), 'transpose'),
    (lambda p: np.save(p, np.r_[np.zeros(11), np.nan]), 'positions[11, 0] is nan'),
])
def test_bad_npy(tmp_path, make, expected):
    path = tmp_path / 'bad.npy'
    make(path)
    with pytest.raises(DemonstrationError) as err:
        load_demo(path)
    assert expected in str(err.value) and str(path) in str(err.value)


def test_npz_without_positions(tmp_path):
    path = tmp_path / 'keys.npz'
    np.savez(path, x=np.zeros((12, 2)), t=np.arange(12.0))
    with pytest.raises(DemonstrationError) as err:
        load_demo(path)
    assert '"positions"' in str(err.value) and 't, x' in str(err.value)


def test_npz_with_bad_time(tmp_path):
    path = tmp_path / 'time.npz'
    np.savez(path, positions=np.zeros((12, 2)), t=np.r_[np.arange(11.0), 3.0])
    with pytest.raises(DemonstrationError, match=r't\[11\].*strictly increasing'):
        load_demo(path)


def test_npz_named_npy_and_vice_versa(tmp_path):
    npz_as_npy = tmp_path / 'a.npy'
    with open(npz_as_npy, 'wb') as f:
        np.savez(f, positions=np.zeros((12, 2)))
    with pytest.raises(DemonstrationError, match='not a single .npy'):
        load_demo(npz_as_npy)
    npy_as_npz = tmp_path / 'b.npz'
    with open(npy_as_npz, 'wb') as f:
        np.save(f, np.zeros((12, 2)))
    with pytest.raises(DemonstrationError, match='not an .npz'):
        load_demo(npy_as_npz)

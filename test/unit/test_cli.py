"""
The ``etdmp`` command line: generalize, reproduce (paper Figs. 5, 7-8, 13), demos, bad input.

No ROS. Commands run in-process through ``main(argv)`` (fast); one case runs the real console
entry point through ``python -m etdmp_ros.apps.cli`` to check exit code and stderr of a real
process.
"""

import json
import math
import os
from pathlib import Path
import subprocess
import sys

from etdmp_ros.apps.cli import main
from etdmp_ros.apps.reproduce import quadrant
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
LETTERS = REPO.parent / 'shared' / 'data' / 'pbdlib_2Dletters'
needs_letters = pytest.mark.skipif(
    not (LETTERS / 'table2.json').is_file(),
    reason=f'reference data {LETTERS} is absent (external, never copied into the repo)')


def _has_matplotlib():
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


needs_matplotlib = pytest.mark.skipif(not _has_matplotlib(),
                                      reason='matplotlib (optional extra) is not installed')


def _finite_numbers(obj):
    """Yield every number in a decoded JSON document."""
    if isinstance(obj, dict):
        for value in obj.values():
            yield from _finite_numbers(value)
    elif isinstance(obj, list):
        for value in obj:
            yield from _finite_numbers(value)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        yield obj


# --------------------------------------------------------------------------------------------
# reproduce on the paper's data


@pytest.fixture(scope='module')
def paper_metrics(tmp_path_factory):
    if not (LETTERS / 'table2.json').is_file():
        pytest.skip(f'reference data {LETTERS} is absent')
    out = tmp_path_factory.mktemp('reproduce')
    rc = main(['reproduce', '--letters-dir', str(LETTERS), '--table',
               str(LETTERS / 'table2.json'), '--out', str(out), '--no-plots'])
    assert rc == 0
    assert not list(out.glob('*.png')), '--no-plots must not draw'
    return json.loads((out / 'metrics.json').read_text())


@needs_letters
def test_reproduce_paper_covers_every_letter_and_start(paper_metrics):
    table = json.loads((LETTERS / 'table2.json').read_text())
    assert set(paper_metrics['letters']) == set(table['letters'])
    for name, spec in table['letters'].items():
        letter = paper_metrics['letters'][name]
        assert [s['start'] for s in letter['starts']] == spec['starts']
        for s in letter['starts']:
            for method in ('etdmp', 'dmp'):
                assert set(s['nrmse'][method]) == {'paper', 'conventional'}
                assert math.isfinite(s['final_distance_to_goal'][method])
        assert len(letter['obstacle_runs']) == 2
    assert all(math.isfinite(v) for v in _finite_numbers(paper_metrics))
    p = paper_metrics['parameters']
    assert (p['K'], p['D'], p['tau'], p['n_basis']) == (156.25, 25.0, 1.0, 100)


@needs_letters
def test_reproduce_paper_etdmp_beats_dmp_outside_demo_quadrant(paper_metrics):
    outside = 0
    for name, letter in paper_metrics['letters'].items():
        for s in letter['starts']:
            assert s['quadrant'] == quadrant(np.subtract(s['start'], letter['goal']))
            if s['quadrant'] == letter['demo_quadrant']:
                continue
            outside += 1
            for variant in ('conventional', 'paper'):
                assert s['nrmse']['etdmp'][variant] < s['nrmse']['dmp'][variant], (name, s)
    summary = paper_metrics['summary']
    assert summary['starts_outside_demo_quadrant'] == outside > 0
    assert summary['etdmp_better_outside_demo_quadrant'] == outside


@needs_letters
def test_reproduce_paper_reports_demo_quadrants_and_table_mismatch(paper_metrics):
    # Demo 00 of each letter, quadrant of (demo start - demo goal).
    demo_q = {n: letter['demo_quadrant'] for n, letter in paper_metrics['letters'].items()}
    assert demo_q == {'G': 'I', 'P': 'III', 'R': 'II', 'W': 'II'}
    # Table 2 files P's start (5.00, -3.15) under quadrant I; relative to P's goal it is in IV.
    mism = paper_metrics['summary']['quadrant_mismatches']
    assert [(m['letter'], m['index'], m['table_quadrant'], m['quadrant']) for m in mism] == [
        ('P', 1, 'I', 'IV')]


@needs_letters
def test_reproduce_paper_obstacle_runs_avoid_and_converge(paper_metrics):
    for name, letter in paper_metrics['letters'].items():
        counts = [len(run['obstacles']) for run in letter['obstacle_runs']]
        assert counts == [1, 2]
        for run in letter['obstacle_runs']:
            # The obstacles sit on the free path; avoidance must move the path off them.
            clear = run['min_clearance']
            assert clear['with_obstacles'] > clear['without_obstacles'], (name, run)
            assert run['final_distance_to_goal']['with_obstacles'] < 0.1, (name, run)


# --------------------------------------------------------------------------------------------
# reproduce on a synthetic letters directory (other names, 3 starts, no quadrant_order)


def _min_jerk(n):
    p = np.linspace(0.0, 1.0, n)
    return 10 * p**3 - 15 * p**4 + 6 * p**5


def _write_letters(folder):
    u = _min_jerk(150)
    theta = 1.6 * np.pi * u
    radius = 4.0 - 2.5 * u
    curl = np.stack([radius * np.cos(theta) + 1.0, radius * np.sin(theta) + 2.0], axis=1)
    corners = np.array([[0.0, 6.0], [5.0, 6.0], [0.5, 0.5], [6.0, 0.0]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(corners, axis=0), axis=1))])
    zig = np.stack([np.interp(_min_jerk(180) * arc[-1], arc, corners[:, k]) for k in (0, 1)],
                   axis=1)
    for name, path in (('curl', curl), ('zig', zig)):
        np.savetxt(folder / f'{name}_00.csv', path, delimiter=',', header='x,y', comments='')
    table = {
        'units': 'cm',
        'dmp_parameters': {'K': 156.25, 'D': 25.0, 'tau': 1.5, 'n_basis': 60},
        'letters': {
            'curl': {'goal': [1.0, 1.0], 'starts': [[5.0, 2.0], [-3.0, 4.0], [2.0, -6.0]]},
            'zig': {'goal': [10.0, 10.0], 'starts': [[4.0, 16.0], [13.0, 18.0], [3.0, 2.0]]},
        },
    }
    (folder / 'table.json').write_text(json.dumps(table))
    return table


def test_reproduce_synthetic_letters_without_quadrant_order(tmp_path, capsys):
    letters = tmp_path / 'letters'
    letters.mkdir()
    table = _write_letters(letters)
    out = tmp_path / 'out'
    rc = main(['reproduce', '--letters-dir', str(letters), '--table',
               str(letters / 'table.json'), '--out', str(out), '--no-plots'])
    assert rc == 0
    stdout = capsys.readouterr().out
    assert 'curl' in stdout and 'zig' in stdout and str(out / 'metrics.json') in stdout
    metrics = json.loads((out / 'metrics.json').read_text())
    assert all(math.isfinite(v) for v in _finite_numbers(metrics))
    assert metrics['parameters']['tau'] == 1.5
    assert metrics['letters']['curl']['demo_quadrant'] == quadrant(
        np.array([1, -1]) @ np.loadtxt(letters / 'curl_00.csv', delimiter=',',
                                       skiprows=1)[[0, -1]])
    assert metrics['letters']['zig']['demo_quadrant'] == 'II'
    for name, spec in table['letters'].items():
        starts = metrics['letters'][name]['starts']
        assert len(starts) == 3
        assert [s['quadrant'] for s in starts] == [
            quadrant(np.subtract(s, spec['goal'])) for s in spec['starts']]
        assert all('table_quadrant' not in s for s in starts)
        et = [s['nrmse']['etdmp']['conventional'] for s in starts]
        # ET-DMP output is the demo's reproduction rotated and scaled about the goal, so its
        # similarity to the demo does not depend on the start.
        assert max(et) < 0.05 and max(et) - min(et) < 1e-3
        for s in starts:
            assert s['final_distance_to_goal']['etdmp'] < 0.05
    assert metrics['summary']['quadrant_mismatches'] == []


@needs_matplotlib
def test_reproduce_with_plots_writes_figures(tmp_path):
    letters = tmp_path / 'letters'
    letters.mkdir()
    _write_letters(letters)
    out = tmp_path / 'figs'
    rc = main(['reproduce', '--letters-dir', str(letters), '--table',
               str(letters / 'table.json'), '--out', str(out)])
    assert rc == 0
    for name in ('fig5_generalization.png', 'fig13_nrmse.png', 'fig7_8_obstacles.png'):
        png = out / name
        assert png.is_file() and png.stat().st_size > 10_000, name
        assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_reproduce_no_plots_does_not_need_matplotlib(tmp_path, monkeypatch):
    # A None entry in sys.modules makes 'import matplotlib' raise ImportError.
    for mod in [m for m in sys.modules if m == 'matplotlib' or m.startswith('matplotlib.')]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, 'matplotlib', None)
    letters = tmp_path / 'letters'
    letters.mkdir()
    _write_letters(letters)
    args = ['reproduce', '--letters-dir', str(letters), '--table', str(letters / 'table.json')]
    assert main(args + ['--out', str(tmp_path / 'a'), '--no-plots']) == 0
    assert (tmp_path / 'a' / 'metrics.json').is_file()
    # With plots it must refuse up front, with a clear message and no partial output.
    assert main(args + ['--out', str(tmp_path / 'b')]) == 1
    assert not (tmp_path / 'b').exists()


# --------------------------------------------------------------------------------------------
# generalize and demos


def test_generalize_json_reaches_goal(tmp_path, capsys):
    out = tmp_path / 'g.json'
    goal = [1.0, 0.5]
    rc = main(['generalize', '--skill', 'G', '--start', '-4', '3', '--goal', *map(str, goal),
               '--obstacle', '-2', '-3', '--json', str(out)])
    assert rc == 0
    stdout = capsys.readouterr().out
    assert 'ET-DMP' in stdout and 'DMP' in stdout
    doc = json.loads(out.read_text())
    assert doc['method'] == 'etdmp' and doc['goal'] == goal
    x, v, a, t = (np.array(doc[k]) for k in ('x', 'v', 'a', 't'))
    assert x.shape == v.shape == a.shape == (len(t), 2)
    assert all(math.isfinite(n) for n in _finite_numbers(doc))
    size = math.dist([-4, 3], goal)
    assert np.linalg.norm(x[-1] - goal) < 0.01 * size
    assert np.allclose(x[0], [-4, 3])
    for method in ('etdmp', 'dmp'):
        m = doc['metrics'][method]
        assert m['min_clearance'] > 0 and set(m['nrmse']) == {'paper', 'conventional'}


def test_generalize_from_demo_file_and_dmp_method(tmp_path):
    demo = tmp_path / 'arc.csv'
    # Minimum-jerk timing: the demo starts and ends at rest, as a recorded movement does.
    s = _min_jerk(120)
    np.savetxt(demo, np.stack([np.cos(np.pi * s), np.sin(np.pi * s) + 0.3 * s], axis=1),
               delimiter=',', header='x,y', comments='')
    out = tmp_path / 'arc.json'
    rc = main(['generalize', '--demo', str(demo), '--start', '2', '-1', '--goal', '0', '0',
               '--method', 'dmp', '--formulation', 'hoffmann', '--margin', '0.5',
               '--json', str(out)])
    assert rc == 0
    doc = json.loads(out.read_text())
    assert doc['method'] == 'dmp' and doc['formulation'] == 'hoffmann'
    assert np.linalg.norm(np.array(doc['x'][-1])) < 0.02


@needs_matplotlib
def test_generalize_and_demos_plots(tmp_path, capsys):
    png = tmp_path / 'stir.png'
    assert main(['generalize', '--skill', 'stir', '--start', '0.3', '0.2', '0.1', '--goal', '0',
                 '0', '0', '--mode', '2', '--plot', str(png)]) == 0
    assert png.stat().st_size > 10_000
    demos_png = tmp_path / 'demos.png'
    assert main(['demos', '--plot', str(demos_png)]) == 0
    assert demos_png.stat().st_size > 10_000
    listing = capsys.readouterr().out
    assert 'stir' in listing and 'wipe' in listing


def test_demos_lists_builtin_demos(capsys):
    from etdmp_ros.dmp import builtin_demo_names
    assert main(['demos', '--list']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:2] == ['name', 'dim']
    assert [line.split()[0] for line in lines[1:]] == builtin_demo_names()


def test_help_exits_zero(capsys):
    assert main(['--help']) == 0
    assert 'generalize' in capsys.readouterr().out


# --------------------------------------------------------------------------------------------
# bad input: exit 2, one line on stderr, no traceback


def _bad_table(folder, mutate):
    _write_letters(folder)
    table = json.loads((folder / 'table.json').read_text())
    mutate(table)
    (folder / 'table.json').write_text(json.dumps(table))
    return ['reproduce', '--letters-dir', str(folder), '--table', str(folder / 'table.json'),
            '--out', str(folder / 'out'), '--no-plots']


BAD_GENERALIZE = {
    'unknown skill': (['--skill', 'Nope', '--start', '1', '2', '--goal', '0', '0'],
                      'unknown skill'),
    'too many coordinates': (['--skill', 'G', '--start', '1', '2', '3', '--goal', '0', '0'],
                             '2 coordinates'),
    'too few coordinates': (['--skill', 'stir', '--start', '1', '2', '--goal', '0', '0', '0'],
                            '3 coordinates'),
    'start equals goal': (['--skill', 'G', '--start', '1', '2', '--goal', '1', '2'], 'equals'),
    'not a number': (['--skill', 'G', '--start', '1', 'x', '--goal', '0', '0'], 'invalid float'),
    'nan start': (['--skill', 'G', '--start', 'nan', '2', '--goal', '0', '0'], 'finite'),
    'obstacle on goal': (['--skill', 'G', '--start', '1', '2', '--goal', '0', '0', '--obstacle',
                          '0', '0'], 'goal'),
    'missing demo file': (['--demo', '/nonexistent/demo.csv', '--start', '1', '2', '--goal', '0',
                           '0'], 'no such file'),
    'bad dt': (['--skill', 'G', '--start', '1', '2', '--goal', '0', '0', '--dt', '0'], '--dt'),
    'json folder missing': (['--skill', 'G', '--start', '1', '2', '--goal', '0', '0', '--json',
                             '/nonexistent/x.json'], 'does not exist'),
}


def _assert_one_line_error(rc, err, expected):
    assert rc == 2
    assert 'Traceback' not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('etdmp: error:'), err
    assert expected in lines[0], err


@pytest.mark.parametrize('case', sorted(BAD_GENERALIZE))
def test_generalize_bad_input(case, capsys):
    argv, expected = BAD_GENERALIZE[case]
    rc = main(['generalize', *argv])
    _assert_one_line_error(rc, capsys.readouterr().err, expected)


def test_generalize_malformed_demo_file(tmp_path, capsys):
    bad = tmp_path / 'bad.csv'
    bad.write_text('x,y\n1,2\nfoo,bar\n')
    rc = main(['generalize', '--demo', str(bad), '--start', '1', '2', '--goal', '0', '0'])
    _assert_one_line_error(rc, capsys.readouterr().err, str(bad))


BAD_TABLES = {
    'no dmp_parameters': (lambda t: t.pop('dmp_parameters'), 'dmp_parameters'),
    'negative tau': (lambda t: t['dmp_parameters'].update(tau=-1), 'positive'),
    'quadrant_order length': (lambda t: t.update(quadrant_order=['I', 'II']), 'quadrant_order'),
    'start on goal': (lambda t: t['letters']['zig']['starts'].append([10.0, 10.0]), 'coincide'),
    'missing letter file': (lambda t: t['letters'].update(nope=t['letters']['zig']), 'nope_00'),
    '3D start': (lambda t: t['letters']['zig']['starts'].append([1, 2, 3]), '2 finite numbers'),
}


@pytest.mark.parametrize('case', sorted(BAD_TABLES))
def test_reproduce_bad_table(case, tmp_path, capsys):
    mutate, expected = BAD_TABLES[case]
    rc = main(_bad_table(tmp_path, mutate))
    _assert_one_line_error(rc, capsys.readouterr().err, expected)
    assert not (tmp_path / 'out' / 'metrics.json').exists()


def test_reproduce_missing_dir_and_bad_json(tmp_path, capsys):
    rc = main(['reproduce', '--letters-dir', str(tmp_path / 'none'), '--out', str(tmp_path)])
    _assert_one_line_error(rc, capsys.readouterr().err, 'not a directory')
    (tmp_path / 'table2.json').write_text('{not json')
    rc = main(['reproduce', '--letters-dir', str(tmp_path), '--out', str(tmp_path / 'o')])
    _assert_one_line_error(rc, capsys.readouterr().err, 'not valid JSON')


def test_console_entry_point_subprocess(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO)] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]))
    bad = subprocess.run(
        [sys.executable, '-m', 'etdmp_ros.apps.cli', 'generalize', '--skill', 'G', '--start', '1',
         '2', '3', '--goal', '0', '0'], capture_output=True, text=True, env=env, cwd=tmp_path,
        timeout=60)
    _assert_one_line_error(bad.returncode, bad.stderr, '2 coordinates')
    good = subprocess.run(
        [sys.executable, '-m', 'etdmp_ros.apps.cli', 'generalize', '--skill', 'W', '--start', '5',
         '-5', '--goal', '0', '0', '--json', 'w.json'], capture_output=True, text=True, env=env,
        cwd=tmp_path, timeout=60)
    assert good.returncode == 0, good.stderr
    assert json.loads((tmp_path / 'w.json').read_text())['skill'] == 'W'

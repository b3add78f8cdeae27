"""
The type check: mypy over the folders ``mypy.ini`` lists, and a proof that it can fail.

mypy keeps what it learned in ``.mypy_cache/`` at the repository root, so only the first run
after a change reads everything again.
"""

from pathlib import Path
import re
import subprocess
import sys
import textwrap

import pytest

REPO = Path(__file__).resolve().parents[2]

#: Calls that break the public API's types, each with the error code mypy must report.
WRONG = textwrap.dedent("""\
    from etdmp_ros.dmp import learn
    from etdmp_ros.geometry import quaternion
    from etdmp_ros.robot import ControllerConfig

    skill = learn([[0.0, 0.0], [1.0, 2.0], [3.0, 3.0]])
    plan = skill.generalize([1.0, 0.0], [0.0, 0.0], method=2)
    first = plan.q[0]
    angle: float = quaternion.angle_between([0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 0.0])
    config = ControllerConfig(rate='125 Hz')
    """)
#: Line of WRONG -> error code: a method is named by a string; a position-only skill's plan has
#: no orientations (q may be None); angle_between returns an array of angles; a rate is a number
#: (Hz).
EXPECTED = {6: 'arg-type', 7: 'index', 8: 'assignment', 9: 'arg-type'}


def _mypy(*args):
    return subprocess.run([sys.executable, '-m', 'mypy', '--config-file',
                           str(REPO / 'mypy.ini'), *args], cwd=REPO, capture_output=True,
                          text=True, timeout=600)


@pytest.mark.linter
def test_package_type_checks():
    result = _mypy()
    assert result.returncode == 0, result.stdout[-5000:] + result.stderr[-2000:]
    assert result.stdout.startswith('Success: no issues found'), result.stdout


@pytest.mark.linter
def test_wrong_calls_are_found(tmp_path):
    wrong = tmp_path / 'wrong_calls.py'
    wrong.write_text(WRONG, encoding='utf-8')
    result = _mypy(str(wrong))
    assert result.returncode == 1, result.stdout + result.stderr
    found = {int(line): code for line, code in
             re.findall(r'wrong_calls\.py:(\d+): error: .*\[([a-z-]+)\]$', result.stdout,
                        flags=re.MULTILINE)}
    assert found == EXPECTED, result.stdout

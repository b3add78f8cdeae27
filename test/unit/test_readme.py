"""The README's library example runs as written (so the README stays current)."""

from pathlib import Path
import re

README = Path(__file__).resolve().parents[2] / 'README.md'


def test_readme_python_example_runs():
    blocks = re.findall(r'```python\n(.*?)```', README.read_text(), re.S)
    assert blocks, 'README.md has no python example'
    namespace = {}
    exec(compile(blocks[0], str(README), 'exec'), namespace)   # noqa: S102 - our own README
    assert namespace['batch'].x.shape[0] == 256
    assert namespace['traj'].x.shape[1] == 2

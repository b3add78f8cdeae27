"""
Every module of the package stays readable: at most 600 lines, no function over 60.

A file or a function past these is a sign that it holds more than one thing; split it by
meaning (docs/design.md, "Layout").
"""

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / 'etdmp_ros'
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 60


def _too_long(text):
    """Return the functions of a module's source over MAX_FUNCTION_LINES, described."""
    return [f'{node.name} ({node.end_lineno - node.lineno + 1} lines, line {node.lineno})'
            for node in ast.walk(ast.parse(text))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]


@pytest.mark.parametrize('path', sorted(PACKAGE.rglob('*.py')),
                         ids=lambda p: str(p.relative_to(REPO)))
def test_modules_and_functions_stay_small(path):
    text = path.read_text(encoding='utf-8')
    lines = len(text.splitlines())
    assert lines <= MAX_FILE_LINES, f'{path.name}: {lines} lines, over {MAX_FILE_LINES}'
    assert not _too_long(text), f'{path.name}: functions over {MAX_FUNCTION_LINES} lines'


def test_the_check_finds_a_long_function():
    body = '\n'.join(f'    x{i} = {i}' for i in range(MAX_FUNCTION_LINES))
    assert _too_long(f'def f():\n{body}\n') == [f'f ({MAX_FUNCTION_LINES + 1} lines, line 1)']
    assert _too_long('def g():\n    return 1\n') == []

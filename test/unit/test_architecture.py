"""
The package's structure: its folders are its layers, imports point down, no cycle.

The layers are declared once, in ``.importlinter`` (``lint-imports`` checks them, as this test
does); docs/design.md#layout draws them.
"""

from pathlib import Path
import subprocess
import sys

import grimp

REPO = Path(__file__).resolve().parents[2]


def test_imports_only_point_down_the_layers():
    lint = Path(sys.executable).with_name('lint-imports')
    result = subprocess.run([str(lint), '--no-cache', '--config', str(REPO / '.importlinter')],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert 'KEPT' in result.stdout and 'BROKEN' not in result.stdout


def _cycles(graph):
    """Return the strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.find_modules_directly_imported_by(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    return found


def test_no_two_modules_import_each_other():
    graph = grimp.build_graph('etdmp_ros', cache_dir=None)
    assert len(graph.modules) > 50
    assert _cycles(graph) == []


def test_the_cycle_check_finds_a_cycle():
    graph = grimp.ImportGraph()
    for module in ('a', 'a.b', 'a.c'):
        graph.add_module(module)
    graph.add_import(importer='a.b', imported='a.c')
    graph.add_import(importer='a.c', imported='a.b')
    assert _cycles(graph) == [['a.b', 'a.c']]

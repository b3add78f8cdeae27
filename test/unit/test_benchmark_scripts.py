"""
Every benchmark script imports with the package as it is today.

The benchmarks run outside `make test` (minutes each), so a name moved in the package would
break one unseen until someone runs it (`bench_sim.py` imported topic names from a node after
they had moved to ``etdmp_ros.ros.topics``). Their peer libraries (movement-primitives, pydmps,
pin-pink) are imported inside functions, so every script imports in the project's venv.
"""

import os
from pathlib import Path
import subprocess
import sys

BENCHMARKS = Path(__file__).resolve().parents[1] / 'benchmarks'
SCRIPTS = sorted(p.stem for p in BENCHMARKS.glob('bench_*.py'))

_IMPORT_ALL = """
import importlib, sys, traceback
failed = []
for name in sys.argv[1:]:
    try:
        importlib.import_module(name)
    except Exception:
        failed.append(name + ': ' + traceback.format_exc(limit=-1).strip().splitlines()[-1])
print('\\n'.join(failed))
sys.exit(1 if failed else 0)
"""


def test_every_benchmark_script_imports():
    assert len(SCRIPTS) >= 10, SCRIPTS
    # One process for all: each script is a module of test/benchmarks, beside its _results.
    result = subprocess.run(
        [sys.executable, '-c', _IMPORT_ALL, *SCRIPTS], cwd=BENCHMARKS, capture_output=True,
        text=True, timeout=300,
        env={**os.environ, 'MUJOCO_GL': os.environ.get('MUJOCO_GL', 'egl'),
             'PYTHONPATH': f'{BENCHMARKS}{os.pathsep}{BENCHMARKS.parent}'})
    assert result.returncode == 0, result.stdout + result.stderr[-2000:]

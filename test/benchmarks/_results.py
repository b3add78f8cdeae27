"""
Benchmark results into the docs (a helper of the benchmark scripts, not a benchmark).

A benchmark writes its table as ``make config`` writes the parameter tables, so re-running it
updates the page.

A result block stands between ``<!-- results: NAME -->`` and ``<!-- end of results: NAME -->``
in a page of ``docs/`` (or the README); :func:`publish` replaces what is between them with the
table and a line saying how, when and on what it was measured.
"""

from datetime import date
import os
from pathlib import Path
import platform
import subprocess

from etdmp_ros.config_files import replace_block

REPO = Path(__file__).resolve().parents[2]


def _cpu_model():
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _version():
    from xml.etree import ElementTree
    version = ElementTree.parse(REPO / 'package.xml').getroot().findtext('version')
    try:
        sha = subprocess.run(['git', 'describe', '--always', '--dirty'], cwd=REPO,
                             capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        sha = ''
    return f'etdmp_ros {version}' + (f' ({sha})' if sha else '')


def provenance(command, load=None):
    """Return the line under a table: the command, the date, the machine, the load, the code."""
    load = os.getloadavg()[0] if load is None else load
    return (f'Written by `{command}` on {date.today().isoformat()}: {_cpu_model()}, '
            f'{os.cpu_count()} cores, load {load:.1f} at the start; {_version()}.')


def publish(name, table, command, page='docs/benchmarks.md', load=None):
    """Write ``table`` (markdown) and its provenance into the ``name`` block of ``page``."""
    path = REPO / page
    begin, end = f'<!-- results: {name} -->', f'<!-- end of results: {name} -->'
    text = replace_block(path.read_text(encoding='utf-8'), begin, end,
                         f'{table.rstrip()}\n\n{provenance(command, load)}', page)
    path.write_text(text, encoding='utf-8')
    print(f'{page}: results "{name}" written')

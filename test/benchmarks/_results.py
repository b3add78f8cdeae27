"""
Benchmark results into the docs (a helper of the benchmark scripts, not a benchmark).

A benchmark writes its table as ``make config`` writes the parameter tables, so re-running it
updates the page.

A result block stands between ``<!-- results: NAME -->`` and ``<!-- end of results: NAME -->``
in a page of ``docs/`` (or the README); :func:`publish` replaces what is between them with the
table and a line saying how, when and on what it was measured. A script publishes unless
given ``--no-docs`` (:func:`add_option`); test/unit/test_docs.py checks that every block has a
``publish`` call of a script here and every call a block in its page.
"""

from contextlib import contextmanager
from datetime import date
from functools import lru_cache
import io
import os
from pathlib import Path
import platform
import shlex
import subprocess
import sys

from etdmp_ros.ros.config_files import replace_block

REPO = Path(__file__).resolve().parents[2]


def _cpu_model():
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


@lru_cache(maxsize=None)
def _version():
    # Once per run: the pages a run writes would make the tree "dirty" for its next block.
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


def add_option(parser):
    """Add ``--no-docs`` (only print, leave the pages as they are) to a script's parser."""
    parser.add_argument('--no-docs', action='store_true',
                        help='only print the tables; do not write them into the docs')


def command(target, argv=None):
    """
    Return the command that ran this script: ``make bench-TARGET`` with its arguments.

    ``argv``: the script's arguments (default ``sys.argv[1:]``); ``--no-docs`` is left out.
    """
    args = [a for a in (sys.argv[1:] if argv is None else argv) if a != '--no-docs']
    return f'make bench-{target}' + (f' BENCH_ARGS="{shlex.join(args)}"' if args else '')


class _Tee(io.TextIOBase):
    """Write to a stream and keep a copy."""

    def __init__(self, stream):
        self.stream, self.kept = stream, io.StringIO()

    def write(self, text):
        self.stream.write(text)
        self.kept.write(text)
        return len(text)

    def flush(self):
        self.stream.flush()


@contextmanager
def printed():
    """
    Print as usual and keep what is printed inside the block: ``kept.getvalue()`` after it.

    A script's printed tables are what it publishes: ``with printed() as kept: print(...)``.
    """
    tee = _Tee(sys.stdout)
    sys.stdout = tee
    try:
        yield tee.kept
    finally:
        sys.stdout = tee.stream

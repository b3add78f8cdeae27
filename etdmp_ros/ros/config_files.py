"""
ROS 2 parameter files: read them, and write ``config/*.yaml`` and the docs' tables.

Parameter files have the ROS 2 layout (``<node or /**>: ros__parameters: {...}``); nested keys
become dotted parameter names (``camera.position``), exactly as ``--params-file`` declares them.

``config/*.yaml`` and the parameter tables of ``docs/<node>.md`` are written from the system
description (:mod:`etdmp_ros.ros.system`), the table of ``docs/limits.md`` from
:mod:`etdmp_ros.limits` (each constant's ``#:`` comment)::

    python -m etdmp_ros.ros.config_files            # (make config) rewrite them
    python -m etdmp_ros.ros.config_files --check    # exit 1 naming the files that are out of date
"""

from __future__ import annotations

import argparse
import ast
from collections.abc import Iterable, Mapping, Sequence
import json
import keyword
import os
from pathlib import Path
import sys
import textwrap
from typing import Any

from etdmp_ros import limits
from etdmp_ros.ros import system
from etdmp_ros.ros.specs import NodeSpec, Parameter
import yaml

WIDTH = 99
TABLE_BEGIN = '<!-- parameters: written by `make config` from etdmp_ros/ros/system.py -->'
TABLE_END = '<!-- end of parameters -->'
LIMITS_BEGIN = '<!-- limits: written by `make config` from etdmp_ros/limits.py -->'
LIMITS_END = '<!-- end of limits -->'
SERVICES_BEGIN = '<!-- services: written by `make config` from etdmp_ros/ros/system.py -->'
SERVICES_END = '<!-- end of services -->'


def read_parameter_file(path: str | os.PathLike[str], node_name: str | None = None
                        ) -> dict[str, Any]:
    """
    Return the parameters of a ROS 2 parameter file as a flat dict ``{'a.b': value}``.

    Sections ``/**`` and, if given, ``node_name`` / ``/node_name`` are merged in that order (a
    node's own section wins), as rcl does for ``--params-file``.
    """
    with open(path, encoding='utf-8') as f:
        doc = yaml.safe_load(f) or {}
    sections = ['/**']
    if node_name:
        sections += [node_name, '/' + node_name]
    flat: dict[str, Any] = {}
    for section in sections:
        params = (doc.get(section) or {}).get('ros__parameters') or {}
        flat.update(_flatten(params))
    return flat


def _flatten(tree: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            flat.update(_flatten(value, name + '.'))
        else:
            flat[name] = value
    return flat


def read_node_parameters(name: str, config_dir: str | os.PathLike[str] | None = None
                         ) -> dict[str, Any]:
    """Return node ``name``'s values from its parameter files, in the system's order."""
    values: dict[str, Any] = {}
    for path in system.parameter_files(name, config_dir):
        values.update(read_parameter_file(path, name))
    return values


# ---------------------------------------------------------------------------------- writing
def _yaml_value(value: Any) -> str:
    """Return a value as flow-style YAML (lists inline, floats as floats)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000).strip()
    return text.removesuffix('...').strip()


def _comment(text: str, indent: int) -> list[str]:
    prefix = ' ' * indent + '# '
    return textwrap.wrap(text, WIDTH - len(prefix), initial_indent=prefix,
                         subsequent_indent=prefix, break_on_hyphens=False)


def _parameter_lines(parameters: Iterable[Parameter], indent: int) -> list[str]:
    """Return YAML lines for ``parameters`` (nested keys grouped), comments above each."""
    lines: list[str] = []
    open_groups: list[str] = []
    section = None
    for p in parameters:
        if p.section and p.section != section:
            section = p.section
            if lines:
                lines.append('')
            lines.append(' ' * indent + f'# --- {p.section} ' + '-' * max(
                3, WIDTH - indent - len(p.section) - 8))
        *groups, key = p.name.split('.')
        while open_groups and open_groups != groups[:len(open_groups)]:
            open_groups.pop()
        for group in groups[len(open_groups):]:
            lines.append(' ' * (indent + 2 * len(open_groups)) + f'{group}:')
            open_groups.append(group)
        pad = indent + 2 * len(open_groups)
        lines += _comment(p.note or p.full_description, pad)
        if p.array_type and not p.default:
            lines.append(' ' * pad + f'# {key}: []   (empty by default; ROS cannot type an '
                         'empty YAML list)')
            if p.example is not None:
                lines.append(' ' * pad + f'# for example {key}: {_yaml_value(p.example)}')
        else:
            lines.append(' ' * pad + f'{key}: {_yaml_value(p.default)}')
    return lines


def scene_file_text() -> str:
    """Return the text of ``config/scene.yaml``."""
    header = [
        "# The workcell, shared by every node: pass it before the node's own file",
        '#   ros2 run etdmp_ros <node> --ros-args --params-file config/scene.yaml \\',
        '#       --params-file config/<node>.yaml',
        '# Written by `make config` from etdmp_ros/ros/system.py (SCENE): change values there.',
        '# Frame: base_link of the UR10 (example-robot-data URDF), metres, radians; the robot '
        'stands on',
        '# the table, whose top is the plane z = 0.',
        '/**:',
        '  ros__parameters:',
    ]
    return '\n'.join(header + _parameter_lines(system.SCENE, 4)) + '\n'


def node_file_text(spec: NodeSpec) -> str:
    """Return the text of ``config/<node>.yaml``: the node's own parameters."""
    scene = ', '.join(p.name for p in spec.scene) or 'nothing'
    header = [f'# {spec.name}: {spec.summary}.',
              f'#   ros2 run etdmp_ros {spec.executable} --ros-args --params-file '
              'config/scene.yaml \\',
              f'#       --params-file config/{spec.name}.yaml']
    header += _comment(f'From scene.yaml it takes: {scene}. Written by `make config` from '
                       'etdmp_ros/ros/system.py: change values there. Every parameter is declared '
                       f'with its description and range (ros2 param describe /{spec.name} '
                       '<name>). Floats must be written as floats (5.0, not 5). '
                       + spec.config_header, 0)
    lines = header + [f'{spec.name}:', '  ros__parameters:']
    return '\n'.join(lines + _parameter_lines(spec.parameters, 4)) + '\n'


def _cell(text: str) -> str:
    return str(text).replace('|', '\\|')


def _default_cell(p: Parameter) -> str:
    if p.array_type and not p.default:
        return '[]'
    value = json.dumps(p.default) if isinstance(p.default, list) else str(p.default)
    if isinstance(p.default, bool):
        value = str(p.default).lower()
    return f'`{value}`' if value != '' else "''"


def _range_cell(p: Parameter) -> str:
    if p.choices:
        return ', '.join(p.choices)
    cells = [f'{p.count} values'] if p.count else []
    if p.value_range is not None:
        cells.insert(0, f'{p.value_range[0]:g} – {p.value_range[1]:g}')
    return '; '.join(cells)


def parameter_table(spec: NodeSpec) -> str:
    """Return the markdown table of node ``spec``'s parameters (scene ones marked)."""
    rows = ['| parameter | type | default | unit | range | runtime | meaning |',
            '|---|---|---|---|---|---|---|']
    for p in spec.all_parameters:
        where = ' (scene.yaml)' if p in spec.scene else ''
        rows.append(f'| `{p.name}`{where} | {p.type_name} | {_cell(_default_cell(p))} | '
                    f'{_cell(p.unit)} | {_cell(_range_cell(p))} | {"yes" if p.dynamic else ""}'
                    f' | {_cell(p.description)} |')
    return '\n'.join(rows)


def services_text(spec: NodeSpec) -> str:
    """Return the markdown of node ``spec``'s request services and their arguments."""
    parameters = {p.name for p in spec.all_parameters}
    blocks = []
    for service in spec.services:
        rows = [f'`/{spec.name}/{service.name}` ({system.ARGUMENTS_SERVICE_TYPE}): '
                f'{service.summary}', '',
                '| argument | type | unit | range | required | meaning |',
                '|---|---|---|---|---|---|']
        for a in service.arguments:
            meaning = a.description
            if a.name in parameters:
                meaning = f'The parameter {a.name} for this request only: {meaning}'
            rows.append(f'| `{a.name}` | {a.type_name} | {_cell(a.unit)} | '
                        f'{_cell(_range_cell(a))} | '
                        f'{"yes" if a.name in service.required else ""} | {_cell(meaning)} |')
        blocks.append('\n'.join(rows))
    return '\n\n'.join(blocks)


def docs_text(spec: NodeSpec, current: str) -> str:
    """Return ``current`` (a docs page) with its parameter table replaced by the generated one."""
    text = replace_block(current, TABLE_BEGIN, TABLE_END, parameter_table(spec),
                         f'docs/{spec.name}.md')
    if spec.services:
        text = replace_block(text, SERVICES_BEGIN, SERVICES_END, services_text(spec),
                             f'docs/{spec.name}.md')
    return text


def _limit_value(value: object) -> str:
    if isinstance(value, tuple):
        return ' – '.join(_limit_value(v) for v in value)
    if isinstance(value, int) and abs(value) >= 10000:
        return f'{value:,}'.replace(',', '\u2009')
    return f'{value:g}' if isinstance(value, float) else str(value)


def limits_table() -> str:
    """
    Return the markdown tables of :mod:`etdmp_ros.limits`: one per section of the module.

    A section starts at a comment line ending in dashes (``# perception ---``); each constant's
    text is its ``#:`` comment lines; the value is the module's.
    """
    source = Path(limits.__file__).read_text(encoding='utf-8')
    lines = source.splitlines()
    out: list[tuple[str, list[str]]] = []
    for node in ast.parse(source).body:
        if not isinstance(node, ast.Assign) or not isinstance(node.targets[0], ast.Name):
            continue
        k = node.lineno - 2
        comment: list[str] = []
        while k >= 0 and lines[k].startswith('#:'):
            comment.insert(0, lines[k][2:].strip())
            k -= 1
        section = next((line.strip('# -') for line in reversed(lines[:node.lineno - 1])
                        if line.startswith('# ') and line.rstrip().endswith('---')), '')
        name = node.targets[0].id
        if not out or out[-1][0] != section:
            out.append((section, []))
        out[-1][1].append(f'| `{name}` | {_cell(_limit_value(getattr(limits, name)))} | '
                          f'{_cell(" ".join(comment))} |')
    return '\n\n'.join(f'**{section}**\n\n| limit | value | what it bounds |\n|---|---|---|\n'
                       + '\n'.join(rows) for section, rows in out)


def replace_block(current: str, begin: str, end: str, table: str, where: str) -> str:
    """
    Return ``current`` with the text between the lines ``begin`` and ``end`` replaced by ``table``.

    The generated parts of the docs (parameter and limit tables here, benchmark results in
    test/benchmarks/_results.py) stand between such marker lines; ValueError names ``where``
    when the markers are missing.
    """
    if begin not in current or end not in current:
        raise ValueError(f'{where} has no "{begin}" ... "{end}" block')
    head, rest = current.split(begin, 1)
    _, tail = rest.split(end, 1)
    return f'{head}{begin}\n{table}\n{end}{tail}'


# ------------------------------------------------------------------------- typed parameters
#: The module of every node's typed parameters, written from the description.
NODE_PARAMETERS_MODULE = Path('etdmp_ros') / 'ros' / 'node_parameters.py'


def parameters_class_name(spec: NodeSpec) -> str:
    """Return the name of a node's typed parameters class (``ur10_sim``: Ur10SimParameters)."""
    return ''.join(part.capitalize() for part in spec.name.split('_')) + 'Parameters'


def node_parameters_text() -> str:
    """Return the text of ``etdmp_ros/ros/node_parameters.py``: a frozen dataclass per node."""
    lines = [
        '"""',
        "Each node's parameters as one typed, frozen object: written by ``make config``, do not "
        'edit.',
        '',
        "Made from the node's description in :mod:`etdmp_ros.ros.system`: a field per parameter "
        '(its',
        'name with ``_`` for ``.``), typed as declared (lists as tuples). ``from_values`` checks '
        'every',
        'value by its description (:meth:`etdmp_ros.ros.specs.Parameter.typed`) and raises '
        'ValueError',
        'naming the first wrong one. What each parameter means: ``docs/<node>.md``.',
        '"""',
        '',
        'from __future__ import annotations',
        '',
        'from collections.abc import Mapping',
        'from dataclasses import dataclass',
        'from typing import Any, ClassVar',
        '',
        'from etdmp_ros.ros import system',
        'from etdmp_ros.ros.specs import NodeSpec, typed_values',
    ]
    for spec in system.ALL_NODES:
        name = parameters_class_name(spec)
        fields = [p.field_name for p in spec.all_parameters]
        clash = {f for f in fields if fields.count(f) > 1 or keyword.iskeyword(f)}
        if clash:
            raise ValueError(f'{spec.name}: parameters {sorted(clash)} make no distinct fields')
        lines += ['', '', '@dataclass(frozen=True)', f'class {name}:',
                  f'    """The parameters of {spec.name} (docs/{spec.name}.md)."""', '',
                  f"    SPEC: ClassVar[NodeSpec] = system.node('{spec.name}')", '']
        lines += [f'    {p.field_name}: {p.python_type}' for p in spec.all_parameters]
        lines += ['', '    @classmethod',
                  f'    def from_values(cls, values: Mapping[str, Any]) -> {name}:',
                  '        """Return the typed parameters of ``values`` ({name: value}); '
                  'ValueError: a bad one."""',
                  '        return cls(**typed_values(cls.SPEC, values))']
    return '\n'.join(lines) + '\n'


def generated_files(root: str | os.PathLike[str]) -> dict[Path, str]:
    """Return ``{path: text}`` of every file written from the system description."""
    folder = Path(root)
    files = {folder / 'config' / system.SCENE_FILE: scene_file_text()}
    for spec in system.ALL_NODES:
        files[folder / 'config' / f'{spec.name}.yaml'] = node_file_text(spec)
        docs = folder / 'docs' / f'{spec.name}.md'
        files[docs] = docs_text(spec, docs.read_text(encoding='utf-8'))
    files[folder / NODE_PARAMETERS_MODULE] = node_parameters_text()
    page = folder / 'docs' / 'limits.md'
    files[page] = replace_block(page.read_text(encoding='utf-8'), LIMITS_BEGIN, LIMITS_END,
                                limits_table(), 'docs/limits.md')
    return files


def main(argv: Sequence[str] | None = None) -> int:
    """Write (or with --check, compare) config/*.yaml and the docs' parameter tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--check', action='store_true', help='only report stale files')
    parser.add_argument('--root', default=Path(__file__).resolve().parents[2], type=Path,
                        help='repository root (default: this checkout)')
    args = parser.parse_args(argv)
    stale: list[Path] = []
    for path, text in generated_files(args.root).items():
        if not path.is_file() or path.read_text(encoding='utf-8') != text:
            stale.append(path)
            if not args.check:
                path.write_text(text, encoding='utf-8')
    for path in stale:
        print(f'{"out of date" if args.check else "written"}: {path}')
    return 1 if args.check and stale else 0


if __name__ == '__main__':
    sys.exit(main())

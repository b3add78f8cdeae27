"""
The documentation is built and checked.

The site builds without a warning, every relative link and image resolves, and every command in
the README's code blocks names something real.

The running graph is compared with the README's topic table by ``test_ros2_cli.py``; here a
command's topic or service must be in that table, its node and parameter in the system
description, its make target in the Makefile, its executable and module in the package.
"""

from functools import lru_cache
import importlib.util
from pathlib import Path
import re
import shlex
import subprocess
import sys

from etdmp_ros.ros import system
import pytest
from support.ros2_cli import readme_topics

REPO = Path(__file__).resolve().parents[2]
README = REPO / 'README.md'
PAGES = (README, REPO / 'CONTRIBUTING.md', *sorted((REPO / 'docs').glob('*.md')))
_LINK = re.compile(r'!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+"[^"]*")?\)')
_HTML_SRC = re.compile(r'<img[^>]*\ssrc="([^"]+)"')
_FENCE = re.compile(r'^```[^\n]*\n(.*?)^```', re.S | re.M)
_SHELL_FENCE = re.compile(r'^```(?:sh|bash|shell|console)\n(.*?)^```', re.S | re.M)


@pytest.mark.linter
def test_the_site_builds_without_a_warning(tmp_path):
    result = subprocess.run(
        [sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q', '-b', 'html',
         str(REPO / 'docs'), str(tmp_path / 'html')],
        capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f'sphinx-build failed:\n{result.stdout}\n{result.stderr}'
    assert (tmp_path / 'html' / 'api.html').stat().st_size > 10_000, 'the API reference is empty'


def _slug(heading):
    """Return GitHub's anchor of a Markdown heading (lower case, punctuation dropped)."""
    text = re.sub(r'[`*_]|<[^>]+>', '', heading.strip().lower())
    text = re.sub(r'\[([^\]]*)\]\([^)]*\)', r'\1', text)
    return re.sub(r'[^\w\- ]', '', text).replace(' ', '-')


@lru_cache(maxsize=None)
def _anchors(path):
    text = _FENCE.sub('', path.read_text())
    anchors, seen = set(), {}
    for heading in re.findall(r'^#{1,6}\s+(.+?)\s*#*$', text, re.M):
        slug = _slug(heading)
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f'{slug}-{count}')
    return anchors


def _links(path):
    text = _FENCE.sub('', path.read_text())
    text = re.sub(r'`[^`\n]*`', '', text)
    return _LINK.findall(text) + _HTML_SRC.findall(text)


@pytest.mark.parametrize('page', PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_and_image_resolves(page):
    broken = []
    for target in _links(page):
        if re.match(r'[a-z][a-z0-9+.-]*:', target):   # http:, https:, mailto: ...
            continue
        file_part, _, anchor = target.partition('#')
        resolved = (page.parent / file_part).resolve() if file_part else page
        if not resolved.exists():
            broken.append(f'{target}: no file {resolved}')
        elif anchor and resolved.suffix == '.md' and anchor not in _anchors(resolved):
            broken.append(f'{target}: no heading #{anchor} in {resolved.name}')
    assert not broken, f'{page.name}:\n' + '\n'.join(broken)


# ------------------------------------------------------------------ the README's commands

def _shell_commands(page):
    """Return every command of a page's shell code blocks, continuation lines joined."""
    commands = []
    for block in _SHELL_FENCE.findall(page.read_text()):
        for line in block.replace('\\\n', ' ').splitlines():
            line = line.split(' # ')[0].strip()
            if line and not line.startswith(('#', '>>>', '$ ')) and not line[0].isupper():
                commands.append(line)
    return commands


def _make_targets():
    text = (REPO / 'Makefile').read_text()
    targets = set(re.findall(r'^([A-Za-z0-9_.%-]+):(?!=)', text, re.M))
    for pattern in [t for t in targets if '%' in t]:
        prefix = pattern.split('%')[0]
        listed = re.search(r'^BENCHMARKS\s*:=\s*(.+)$', text, re.M)
        targets |= {prefix + name for name in (listed.group(1).split() if listed else ())}
    return targets


def _executables():
    setup = (REPO / 'setup.py').read_text()
    return set(re.findall(r"'([a-z0-9_]+) = etdmp_ros\.", setup))


def _check(argv):
    """Return what is wrong with one command (None if it names only real things)."""
    names = {'make': _check_make, 'ros2': _check_ros2, 'python': _check_python,
             'python3': _check_python}
    words = [w for w in argv if not re.match(r'^[A-Z_]+=', w)]   # VAR=value prefixes
    if not words:
        return None
    check = names.get(Path(words[0]).name)
    return check(words) if check else None


def _check_make(words):
    targets = _make_targets()
    wanted = [w for w in words[1:] if not w.startswith('-') and '=' not in w]
    missing = [w for w in wanted if w not in targets]
    return f'make targets {missing} are not in the Makefile' if missing else None


def _check_ros2(words):
    verb = words[1:3]
    topics, services = readme_topics()
    args = [w for w in words[2:] if not w.startswith('-')]
    if words[1] == 'run' and len(args) >= 2 and args[0] == 'etdmp_ros':
        return None if args[1] in _executables() else f'no executable {args[1]}'
    if words[1] == 'launch' and len(args) >= 2 and args[0] == 'etdmp_ros':
        return None if (REPO / 'launch' / args[1]).exists() else f'no launch file {args[1]}'
    if verb[0] == 'topic' and len(args) >= 2 and args[1].startswith('/'):
        return None if args[1] in topics else f'topic {args[1]} is not in the README table'
    if verb[0] == 'service' and len(args) >= 2 and args[1].startswith('/'):
        return None if args[1] in services else f'service {args[1]} is not in the README table'
    if verb[0] == 'param' and len(args) >= 3 and args[1].startswith('/'):
        node, parameter = args[1].rsplit('/', 1)[-1], args[2]
        try:
            system.node(node).parameter(parameter)
        except KeyError as exc:
            return str(exc)
    return None


def _check_python(words):
    if len(words) >= 3 and words[1] == '-m' and words[2].startswith('etdmp_ros'):
        if importlib.util.find_spec(words[2]) is None:
            return f'no module {words[2]}'
    return None


@pytest.mark.parametrize('page', PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_command_names_real_targets_executables_topics_and_parameters(page):
    commands = _shell_commands(page)
    if page == README:
        assert any(c.startswith('make demo') for c in commands), 'the README lost `make demo`'
    problems = []
    for command in commands:
        for part in re.split(r'\s*(?:&&|;|\|)\s*', command):
            try:
                argv = shlex.split(part)
            except ValueError as exc:
                problems.append(f'{part}: {exc}')
                continue
            problem = _check(argv)
            if problem:
                problems.append(f'{part}: {problem}')
    assert not problems, '\n'.join(problems)


def test_the_checks_find_what_is_wrong():
    """The command checks fail on made-up names (so the test above can fail)."""
    assert _check(['make', 'no-such-target'])
    assert _check(['ros2', 'run', 'etdmp_ros', 'no_such_node'])
    assert _check(['ros2', 'topic', 'echo', '/no/such/topic'])
    assert _check(['ros2', 'param', 'set', '/dmp_server', 'no_such_parameter', '1'])
    assert _check(['python', '-m', 'etdmp_ros.no_such_module'])
    assert _check(['make', 'demo', 'SKILL=W']) is None
    assert _slug('3D mode 1: Rodrigues') == '3d-mode-1-rodrigues'


_DOTTED = re.compile(r'etdmp_ros(?:\.[A-Za-z_]\w*)+')
_SOURCES = ('etdmp_ros', 'launch', 'test', 'tools', 'docs')


def _unresolved(name):
    """Return why a dotted ``etdmp_ros.…`` name names nothing (None if it resolves)."""
    parts = name.split('.')
    for end in range(len(parts), 0, -1):
        try:
            found = importlib.import_module('.'.join(parts[:end]))
        except ImportError:
            continue
        for attribute in parts[end:]:
            if not hasattr(found, attribute):
                # An attribute set in __init__ (UR10Sim.contacts) is not on the class.
                if isinstance(found, type) and attribute in _instance_attributes(found):
                    return None
                return f'{".".join(parts[:end])} has no {".".join(parts[end:])}'
            found = getattr(found, attribute)
        return None
    return f'no module {parts[0]}'


def _instance_attributes(cls):
    import inspect
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return set()
    return set(re.findall(r'self\.(\w+)\s*=', source))


def test_every_dotted_name_in_code_and_docs_names_something():
    """
    Every ``etdmp_ros.x.y`` in code, docstrings, comments and pages resolves.

    A module moved without its references is found here, not by a user's ImportError.
    """
    files = [REPO / 'README.md', REPO / 'Makefile', REPO / 'setup.py']
    for folder in _SOURCES:
        files += [f for f in (REPO / folder).rglob('*') if f.suffix in ('.py', '.md')]
    wrong = {}
    for path in files:
        if path == Path(__file__).resolve():
            continue
        for name in set(_DOTTED.findall(path.read_text(errors='replace'))):
            problem = _unresolved(name.rstrip('.'))
            if problem:
                wrong.setdefault(problem, []).append(str(path.relative_to(REPO)))
    assert not wrong, '\n'.join(f'{k}: {v}' for k, v in sorted(wrong.items()))
    assert _unresolved('etdmp_ros.robot.NoSuchClass')
    assert _unresolved('etdmp_ros.no_such_module')


# ------------------------------------------------------------------ the ecosystem files

def test_license_changelog_and_citation_agree_with_package_xml():
    import xml.etree.ElementTree as ElementTree

    import yaml
    package = ElementTree.parse(REPO / 'package.xml').getroot()
    version = package.findtext('version')
    assert package.findtext('license') == 'Apache-2.0'
    assert 'Apache License' in (REPO / 'LICENSE').read_text()
    assert 'Version 2.0, January 2004' in (REPO / 'LICENSE').read_text()
    changelog = (REPO / 'CHANGELOG.rst').read_text()
    assert 'Changelog for package etdmp_ros' in changelog
    # Released versions as catkin_generate_changelog writes them: "X.Y.Z (YYYY-MM-DD)".
    released = re.findall(r'^(\d+\.\d+\.\d+) \(\d{4}-\d{2}-\d{2}\)\n-+$', changelog, re.M)
    assert released and released[0] == version, (released, version)
    citation = yaml.safe_load((REPO / 'CITATION.cff').read_text())
    assert citation['cff-version'] == '1.2.0'
    assert citation['version'] == version and citation['license'] == 'Apache-2.0'
    assert 'Euclidean' in citation['preferred-citation']['title']
    for entry in [citation, citation['preferred-citation'], *citation['references']]:
        assert entry['authors'] and entry['title'], entry


# ------------------------------------------------------------------ the benchmark results

_RESULTS = re.compile(r'^<!-- results: (\S+) -->$', re.M)
BENCHMARKS = REPO / 'test' / 'benchmarks'


def _results_blocks():
    """Return {(page, name)} of the results blocks in the README and docs/ (pages relative)."""
    blocks = set()
    for page in PAGES:
        text = page.read_text()
        for name in _RESULTS.findall(text):
            assert re.search(f'^<!-- end of results: {re.escape(name)} -->$', text, re.M), (
                f'{page.name}: the results block {name!r} has no end marker')
            blocks.add((str(page.relative_to(REPO)), name))
    return blocks


def _publish_calls(scripts):
    """
    Return {(page, name): script} of the ``publish(name, ..., page=...)`` calls in ``scripts``.

    The name and the page must be literal strings (a check that cannot see them fails); the
    page defaults to that of :func:`publish` in test/benchmarks/_results.py.
    """
    import ast
    definition = next(node for node in ast.walk(ast.parse((BENCHMARKS / '_results.py')
                                                          .read_text()))
                      if isinstance(node, ast.FunctionDef) and node.name == 'publish')
    default = definition.args.defaults[definition.args.args.index(
        next(a for a in definition.args.args if a.arg == 'page')) - len(definition.args.args)]
    calls = {}
    for script in scripts:
        for node in ast.walk(ast.parse(script.read_text())):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id == 'publish'):
                continue
            page = next((k.value for k in node.keywords if k.arg == 'page'), default)
            name = node.args[0] if node.args else None
            for value in (name, page):
                assert isinstance(value, ast.Constant) and isinstance(value.value, str), (
                    f'{script.name}:{node.lineno}: publish() with a name or page that is not a '
                    'literal string')
            calls[page.value, name.value] = script.name
    return calls


@lru_cache(maxsize=None)
def _blocks_and_calls():
    """Return the docs' results blocks and the scripts' publish() calls, read once (read-only)."""
    scripts = sorted(p for p in BENCHMARKS.glob('*.py') if p.name != '_results.py')
    return _results_blocks(), _publish_calls(scripts)


@pytest.mark.parametrize('page, name', sorted(_results_blocks()),
                         ids=lambda value: value.replace('/', '_'))
def test_every_results_block_is_written_by_a_benchmark_script(page, name):
    _, calls = _blocks_and_calls()
    assert (page, name) in calls, (
        f'{page}: no script in test/benchmarks/ writes its results block {name!r} '
        f"(publish({name!r}, ..., page='{page}'))")


def test_every_script_s_results_have_their_block_in_their_page():
    blocks, calls = _blocks_and_calls()
    missing = [f'{script}: publish({name!r}) into {page}, which has no such block'
               for (page, name), script in sorted(calls.items()) if (page, name) not in blocks]
    assert not missing, '\n'.join(missing)
    assert len(calls) >= 7, calls       # core (3), dmp_server, sim, controller, perception, ...


def test_the_results_checks_find_what_is_wrong(tmp_path):
    script = tmp_path / 'bench_x.py'
    script.write_text("publish('x', table, command('x'))\n"
                      "publish('y', table, command('y'), page='docs/design.md')\n"
                      'self.pub.publish(message)\n')
    assert _publish_calls([script]) == {('docs/benchmarks.md', 'x'): 'bench_x.py',
                                        ('docs/design.md', 'y'): 'bench_x.py'}
    script.write_text("publish(f'{name}', table, command('x'))\n")
    with pytest.raises(AssertionError, match='not a literal string'):
        _publish_calls([script])

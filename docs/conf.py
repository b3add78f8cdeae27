"""
Sphinx configuration of the package documentation (``make docs-site`` -> build/docs/html).

The pages are the Markdown files of this folder, read by MyST; the API reference is generated
from the docstrings of the public Python API (``api.md``). rosdoc2, which builds ROS 2 package
documentation for docs.ros.org, uses this file too (``rosdoc2.yaml`` points it here).
"""

from pathlib import Path
import sys
import xml.etree.ElementTree as ElementTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
_package = ElementTree.parse(ROOT / 'package.xml').getroot()

project = _package.findtext('name')
release = version = _package.findtext('version')
author = ', '.join(m.text for m in _package.findall('maintainer'))
copyright = f'2026, {author}'   # noqa: A001 - Sphinx's name

extensions = ['myst_parser', 'sphinx.ext.autodoc', 'sphinx.ext.napoleon',
              'sphinx.ext.mathjax']
source_suffix = {'.md': 'markdown'}
root_doc = 'index'
exclude_patterns = ['_build']
myst_heading_anchors = 4
myst_enable_extensions = ['dollarmath']
autodoc_member_order = 'bysource'
autodoc_typehints = 'description'
autodoc_default_options = {'members': True, 'undoc-members': False, 'show-inheritance': True}
html_theme = 'alabaster'
html_title = f'{project} {release}'


def setup(app):
    """Show mermaid diagrams (which GitHub draws) as plain text: Pygments has no lexer."""
    from pygments.lexers.special import TextLexer
    app.add_lexer('mermaid', TextLexer)

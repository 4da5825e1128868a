"""Sphinx configuration of the gcpfree documentation site (``make docs`` -> ``site/``).

Pages are Markdown (MyST). The command reference, the products' schemas and the validation
figures are generated from the code and from ``bench/results/`` when the build starts
(``docs/_ext/gcpfree_docs``). The build is strict: ``make docs`` passes ``-W``, so any warning
(a broken link, a page in no table of contents, a missing figure) fails it.
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path[:0] = [str(DOCS / "_ext"), str(ROOT)]  # the site's extension, the package itself

project = "gcpfree"
author = "the gcpfree developers"
copyright = "the gcpfree developers, Apache-2.0"
release = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
version = release

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "gcpfree_docs"]
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_ext", "reference/notes", "validation/generated/*.md", "studies/_*"]
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath", "fieldlist"]
myst_heading_anchors = 3
suppress_warnings: list[str] = []
smartquotes = False  # "--out" stays two hyphens, as typed
nitpicky = False

html_theme = "furo"
html_title = f"gcpfree {release}"
html_static_path = ["_static"]
html_css_files = ["gcpfree.css"]
html_show_sourcelink = False
html_copy_source = False
html_last_updated_fmt = None
html_theme_options = {"navigation_with_keys": True}

"""Sphinx configuration of the handsim documentation.

Build (warnings are errors, as in CI): ``make docs``, i.e.
``sphinx-build -W --keep-going -b html docs docs/_build/html``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

# Headless: importing handsim must never need a display (autodoc imports every module).
os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).parent / "_ext"))

import handsim  # noqa: E402

project = "handsim"
author = "handsim contributors"
copyright = "handsim contributors, MIT license"  # noqa: A001 (Sphinx's name)
release = handsim.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "myst_parser",
    "handsim_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
templates_path: list[str] = []

# Markdown pages: fenced ```{directive} blocks, $ math, heading anchors for links to sections.
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# API pages: Google-style docstrings with RST roles and tables.
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_class_signature = "mixed"
autodoc_preserve_defaults = True
# Unresolvable references (numpy, mujoco, gymnasium types in signatures) are not errors: the
# build is offline (no intersphinx inventories are downloaded).
nitpicky = False

html_theme = "furo"
html_title = f"handsim {release}"
html_static_path: list[str] = []

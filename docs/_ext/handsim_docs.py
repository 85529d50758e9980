"""Sphinx helpers of the handsim docs.

- ``.. handsim-exports::``: a table of the names that ``import handsim`` re-exports, each linked
  to the module that defines it (generated from ``handsim.__all__``, so it never goes stale).
- ``autodoc-skip-member``: NumPy-scalar defaults of dataclass fields are not separate entries.
- ``autodoc-process-docstring``: RST section titles (a line underlined with ``-`` or ``=``)
  inside docstrings become rubrics; docutils forbids sections inside autodoc content.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re

import numpy as np
from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

_UNDERLINE = re.compile(r"^([-=~^\"'`#*+])\1{2,}\s*$")


def _defining_module(name: str, obj: object) -> str:
    """The module whose ``__all__`` defines ``name`` (not a package that re-exports it)."""
    module = getattr(obj, "__module__", None)
    if module and module.startswith("handsim") and inspect.getmodule(obj) is not None:
        if isinstance(obj, type) or inspect.isfunction(obj):
            return module
    import handsim

    for info in pkgutil.walk_packages(handsim.__path__, "handsim."):
        if info.ispkg or info.name.endswith("__main__"):
            continue
        mod = importlib.import_module(info.name)
        if name in getattr(mod, "__all__", ()):
            return info.name
    raise LookupError(f"handsim.{name} is defined in no handsim module's __all__")


def _summary(obj: object) -> str:
    if not (isinstance(obj, type) or callable(obj)):
        return ""
    doc = inspect.getdoc(obj) or ""
    return doc.strip().split("\n\n")[0].replace("\n", " ")


class HandsimExports(SphinxDirective):
    """Table of ``handsim.__all__`` with links to the defining modules."""

    def run(self) -> list[nodes.Node]:
        """Build the table as RST and parse it in place."""
        import handsim

        lines = [".. list-table::", "   :header-rows: 1", "   :widths: 30 70", ""]
        lines += ["   * - name", "     - what"]
        for name in handsim.__all__:
            obj = getattr(handsim, name)
            target = f"{_defining_module(name, obj)}.{name}"
            lines += [f"   * - :py:obj:`{name} <{target}>`", f"     - {_summary(obj)}"]
        container = nodes.container()
        nested_parse_with_titles(self.state, StringList(lines, "handsim-exports"), container)
        return container.children


def _titles_to_rubrics(app, what, name, obj, options, lines: list[str]) -> None:
    for i in range(1, len(lines)):
        title = lines[i - 1].strip()
        before = lines[i - 2].strip() if i >= 2 else ""
        if title and not before and _UNDERLINE.match(lines[i].strip()):
            indent = lines[i - 1][: len(lines[i - 1]) - len(lines[i - 1].lstrip())]
            lines[i - 1] = f"{indent}.. rubric:: {title}"
            lines[i] = ""


def _skip_numpy_defaults(app, what, name, obj, skip, options) -> bool | None:
    # A dataclass field whose default is a NumPy scalar (``np.deg2rad(45.0)``) "has" the
    # docstring of its type, so autodoc would list it a second time, next to the entry that
    # the class docstring's ``Attributes:`` section already makes.
    if what == "class" and isinstance(obj, np.generic | np.ndarray):
        return True
    return None


def setup(app):
    """Register the directive and the docstring hook."""
    app.add_directive("handsim-exports", HandsimExports)
    app.connect("autodoc-process-docstring", _titles_to_rubrics)
    app.connect("autodoc-skip-member", _skip_numpy_defaults)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}

"""Sphinx helpers of the handsim docs.

- ``.. handsim-submodules:: PACKAGE``: one section with ``automodule`` per public submodule of
  the package (found by ``pkgutil``, so a new module is documented without editing a page), in
  the order of the ``:order:`` option, then alphabetically; modules named in
  ``:docstring-only:`` (facades that re-export) show their docstring without members; names
  that a module's ``__all__`` imports from elsewhere are left to the module that defines them.
- ``.. handsim-exports::``: a table of the names that ``import handsim`` re-exports, each linked
  to the module that defines it (generated from ``handsim.__all__``, so it never goes stale).
- Links from a Markdown page to a file or folder of the repo outside ``docs/`` (``../README.md``,
  ``../scenes/``) work on GitHub but are not Sphinx documents: they are rendered as their text.
  A link to a path that does not exist still fails the build.
- ``autodoc-skip-member``: NumPy-scalar defaults of dataclass fields are not separate entries.
- ``autodoc-process-docstring``: RST section titles (a line underlined with ``-`` or ``=``)
  inside docstrings become rubrics; docutils forbids sections inside autodoc content.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import numpy as np
from docutils import nodes
from docutils.statemachine import StringList
from sphinx import addnodes
from sphinx.transforms.post_transforms import SphinxPostTransform
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

_UNDERLINE = re.compile(r"^([-=~^\"'`#*+])\1{2,}\s*$")


def _reexports(module: str) -> set[str]:
    """Names of ``module.__all__`` that it imports from another module rather than defines."""
    mod = importlib.import_module(module)
    tree = ast.parse(inspect.getsource(mod))
    imported = {
        alias.asname or alias.name.split(".")[0]
        for node in tree.body
        if isinstance(node, ast.Import | ast.ImportFrom)
        for alias in node.names
    }
    return imported & set(getattr(mod, "__all__", ()))


def _defining_module(name: str, obj: object) -> str:
    """The module whose ``__all__`` defines ``name`` (not a package or module re-exporting it)."""
    module = getattr(obj, "__module__", None)
    if module and module.startswith("handsim") and inspect.getmodule(obj) is not None:
        if isinstance(obj, type) or inspect.isfunction(obj):
            return module
    import handsim

    for info in pkgutil.walk_packages(handsim.__path__, "handsim."):
        if info.ispkg or info.name.endswith("__main__"):
            continue
        mod = importlib.import_module(info.name)
        if name in getattr(mod, "__all__", ()) and name not in _reexports(info.name):
            return info.name
    raise LookupError(f"handsim.{name} is defined in no handsim module's __all__")


def public_submodules(package: str) -> list[tuple[str, bool]]:
    """``(name, is_package)`` of the public submodules of ``package``, recursively.

    Private modules (``_name``) and ``__main__`` are left out, and so is everything inside them.
    """
    pkg = importlib.import_module(package)
    return sorted(
        (info.name, info.ispkg)
        for info in pkgutil.walk_packages(pkg.__path__, f"{package}.")
        if not any(part.startswith("_") for part in info.name[len(package) + 1 :].split("."))
    )


class HandsimSubmodules(SphinxDirective):
    """Sections with ``automodule`` for every public submodule of a package."""

    required_arguments = 1
    option_spec = {"order": str.split, "exclude": str.split, "docstring-only": str.split}

    def run(self) -> list[nodes.Node]:
        """Emit the sections as RST and parse them in place."""
        package = self.arguments[0]
        excluded = tuple(f"{package}.{name}" for name in self.options.get("exclude", []))
        found = {
            name: is_pkg
            for name, is_pkg in public_submodules(package)
            if not any(name == e or name.startswith(f"{e}.") for e in excluded)
        }
        order = [f"{package}.{name}" for name in self.options.get("order", [])]
        unknown = sorted(set(order) - set(found))
        if unknown:
            raise self.error(f"handsim-submodules: no such modules in {package}: {unknown}")
        lines: list[str] = []
        facades = {f"{package}.{name}" for name in self.options.get("docstring-only", [])}
        for module in order + sorted(set(found) - set(order)):
            title = f"``{module}``"
            lines += [title, "-" * len(title), "", f".. automodule:: {module}"]
            # A package's (or a facade's) docstring only: its members are re-exports,
            # documented where defined.
            if not found[module] and module not in facades:
                lines += ["   :members:", "   :show-inheritance:"]
                # Names a module re-exports (kept importable after a split) are documented
                # where defined.
                reexports = sorted(_reexports(module))
                if reexports:
                    lines.append(f"   :exclude-members: {', '.join(reexports)}")
            lines.append("")
        container = nodes.section()
        source = StringList(lines, f"submodules of {package}")
        nested_parse_with_titles(self.state, source, container)
        return container.children


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


class RepoLinksAsText(SphinxPostTransform):
    """Render MyST links to repo paths outside the docs as plain text (before MyST resolves)."""

    default_priority = 8  # MyST's resolver runs at 9

    def run(self, **kwargs) -> None:
        """Replace each such link by its own text."""
        srcdir = Path(self.env.srcdir).resolve()
        repo = srcdir.parent
        for node in list(self.document.findall(addnodes.pending_xref)):
            if node.get("reftype") != "myst":
                continue
            target = str(node["reftarget"]).split("#", 1)[0]
            if node.get("refdomain") == "doc":
                if target in self.env.all_docs:
                    continue
                path = Path(target if Path(target).is_absolute() else srcdir / target)
                candidates = [path.with_suffix(s) for s in (".md", ".rst")] + [path]
            else:
                base = (srcdir / node.get("refdoc", self.env.docname)).parent
                candidates = [(base / target).resolve()]
            for path in candidates:
                path = path.resolve()
                outside = srcdir not in path.parents and path != srcdir
                if outside and repo in path.parents and path.exists():
                    node.replace_self(nodes.inline("", "", *node.children))
                    break


def setup(app):
    """Register the directive and the docstring hook."""
    app.add_directive("handsim-exports", HandsimExports)
    app.add_directive("handsim-submodules", HandsimSubmodules)
    app.connect("autodoc-process-docstring", _titles_to_rubrics)
    app.connect("autodoc-skip-member", _skip_numpy_defaults)
    app.add_post_transform(RepoLinksAsText)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}

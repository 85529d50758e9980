"""The docs: self-contained, every public module covered, examples that run, a strict build."""

from __future__ import annotations

import importlib
import os
import pkgutil
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

# Files outside the repo that nothing in it may cite: the docs say things in their own words.
FORBIDDEN = ("../shared", "/work/shared", "shared/facts", "DESIGN.md", "STYLE.md")
# Folders that are not part of the repo's content (built, installed or cached).
SKIP_DIRS = {".git", ".venv", "_build", "__pycache__", ".pytest_cache", ".ruff_cache", "build"}
# Pages whose ```python blocks are run, in order, in one namespace per page.
RUNNABLE_PAGES = ("architecture.md", "conventions.md", "estimators.md")


def _repo_files() -> list[Path]:
    """Tracked files (git), or every file outside the skipped folders when git is missing."""
    git = shutil.which("git")
    if git and (ROOT / ".git").exists():
        out = subprocess.run(
            [git, "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
        ).stdout
        return [ROOT / p for p in out.decode().split("\0") if p]
    return [
        p
        for p in ROOT.rglob("*")
        if p.is_file()
        and not SKIP_DIRS.intersection(p.relative_to(ROOT).parts)
        and not any(part.endswith(".egg-info") for part in p.relative_to(ROOT).parts)
    ]


def test_nothing_cites_files_outside_the_repo():
    """No tracked file (tests aside) cites a document that is not in the repo."""
    offenders = []
    for path in _repo_files():
        rel = path.relative_to(ROOT)
        if rel.parts[0] == "tests" or not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue  # binary asset
        for needle in FORBIDDEN:
            for number, line in enumerate(text.splitlines(), 1):
                if needle in line:
                    offenders.append(f"{rel}:{number}: {needle}")
    assert not offenders, "files cite documents outside the repo:\n" + "\n".join(offenders)


def _public_modules() -> list[str]:
    # envs/, estimators/ and scenes/ are installed into the namespace from their own folders.
    names = []
    for top in ("handsim", "handsim.envs", "handsim.estimators", "handsim.scenes"):
        names.append(top)
        package = importlib.import_module(top)
        for info in pkgutil.walk_packages(package.__path__, f"{top}."):
            if not info.name.rsplit(".", 1)[-1].startswith("_"):  # private, __main__
                names.append(info.name)
    return names


def test_every_public_module_has_an_api_page():
    """Every public module of handsim is on an API page, named or found by its package."""
    named: set[str] = set()
    found_by: list[tuple[str, tuple[str, ...]]] = []  # (package, excluded submodules)
    for page in (DOCS / "api").glob("*.rst"):
        text = page.read_text()
        named |= set(re.findall(r"^\.\. automodule:: (\S+)", text, re.M))
        for package, options in re.findall(
            r"^\.\. handsim-submodules:: (\S+)\n((?:   :.*\n)*)", text, re.M
        ):
            excludes = " ".join(re.findall(r":exclude: (.*)", options)).split()
            found_by.append((package, tuple(f"{package}.{name}" for name in excludes)))
    packages = {package for package, _ in found_by}

    def covered(module: str) -> bool:
        return module in named or any(
            module.startswith(f"{package}.")
            and not any(module == e or module.startswith(f"{e}.") for e in excludes)
            for package, excludes in found_by
        )

    public = _public_modules()
    assert {"handsim.envs", "handsim.estimators", "handsim.hand.pose"} <= set(public)
    missing = [m for m in public if not covered(m)]
    assert not missing, f"modules on no API page (docs/api/*.rst): {missing}"
    unknown = sorted((named | packages) - set(public))
    assert not unknown, f"docs/api/ names modules that do not exist: {unknown}"


def test_every_page_is_in_the_table_of_contents():
    """Every Markdown page of docs/ is reachable from the index."""
    index = (DOCS / "index.md").read_text()
    pages = {p.stem for p in DOCS.glob("*.md")} - {"index"}
    listed = set(re.findall(r"^([a-z_/]+)$", index, re.M))
    assert pages <= listed, f"pages missing from docs/index.md: {sorted(pages - listed)}"


def test_readme_links_to_docs_pages_that_exist():
    """The README's links into docs/ point at pages that exist."""
    readme = (ROOT / "README.md").read_text()
    links = re.findall(r"\]\((docs/[^)#]+)", readme)
    assert "docs/architecture.md" in links and "docs/estimators.md" in links
    missing = [link for link in links if not (ROOT / link).exists()]
    assert not missing, f"README links to missing docs: {missing}"


@pytest.mark.parametrize("page", RUNNABLE_PAGES)
def test_code_examples_run(page, monkeypatch, tmp_path):
    """The ```python blocks of a page run as written, in order."""
    blocks = re.findall(r"^```python\n(.*?)^```", (DOCS / page).read_text(), re.M | re.S)
    assert blocks, f"{page} has no python example"
    monkeypatch.chdir(tmp_path)  # examples that write files write them here
    namespace: dict = {"__name__": f"docs_{page.removesuffix('.md')}"}
    for block in blocks:
        exec(compile(block, str(DOCS / page), "exec"), namespace)


@pytest.mark.slow
def test_sphinx_build_is_strict_and_clean(tmp_path):
    """``sphinx-build -W`` passes: no warning anywhere (the same build as ``make docs``)."""
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    pytest.importorskip("furo")
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html"]
    result = subprocess.run(
        [*cmd, str(DOCS), str(tmp_path / "html")],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert (tmp_path / "html" / "api" / "handsim.html").exists()


def test_a_new_user_is_told_how_to_reach_the_handsim_command():
    """`make demo` installs into .venv: the README and the demo target say how to run handsim."""
    readme = (ROOT / "README.md").read_text()
    setup = readme.split("## Set-up on a fresh machine", 1)[1].split("\n## ", 1)[0]
    assert "source .venv/bin/activate" in setup and ".venv/bin/handsim" in setup
    result = subprocess.run(
        ["make", "-n", "demo", "VENV=/tmp/no-such-venv"], cwd=ROOT, capture_output=True,
        text=True, check=False,
    )  # fmt: skip
    if result.returncode != 0:
        pytest.skip(f"make is not usable here: {result.stderr.strip()}")
    assert "source /tmp/no-such-venv/bin/activate" in result.stdout

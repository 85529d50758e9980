"""Package-level invariants: public names resolve, torch stays out, the CLI answers."""

import os
import subprocess
import sys

import pytest

import handsim


def test_every_name_in_all_resolves():
    """Every name listed in handsim.__all__ is an attribute of the package."""
    for name in handsim.__all__:
        assert getattr(handsim, name) is not None, name
    assert len(set(handsim.__all__)) == len(handsim.__all__)


@pytest.mark.parametrize("module", ["handsim", "handsim.envs"])
def test_import_does_not_pull_torch(module):
    """Importing the core or the envs leaves torch unimported (checked in a fresh process)."""
    code = f"import sys, {module}; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_cli_help_lists_the_subcommands():
    """`handsim --help` names every subcommand."""
    out = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "--help"], capture_output=True, text=True, check=True
    )
    for command in ("demo", "closed-loop", "info"):
        assert command in out.stdout


def test_cli_info_prints_the_hand(capsys):
    """`handsim info` reports the 27 DoF and every joint."""
    from handsim.cli import main
    from handsim.pose import JOINT_NAMES

    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "nv=27" in out
    assert all(name in out for name in JOINT_NAMES)


def test_cli_without_command_prints_help(capsys):
    """A bare `handsim` prints the usage and fails."""
    from handsim.cli import main

    assert main([]) == 2
    assert "usage: handsim" in capsys.readouterr().out


def test_rendering_works_when_mujoco_is_imported_first():
    """Headless, a program that imports mujoco before handsim (GLFW chosen) still renders."""
    code = (
        "import mujoco\n"
        "from handsim.frame import FrameRenderer\n"
        "from handsim.scene import Scene, SceneSpec\n"
        "import numpy as np\n"
        "scene = Scene(SceneSpec())\n"
        "with FrameRenderer(scene, 'third_person') as r:\n"
        "    print(r.render(np.random.default_rng(0)).depth.max() > 0)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY")}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert out.stdout.strip() == "True"

"""Package-level invariants: public names resolve, layers hold, torch stays out, the CLI answers."""

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

import handsim

PUBLIC_NAMES = {
    # errors
    "HandSimError", "InvalidHandParams", "InvalidKeypoints", "InvalidPose", "UnknownName",
    "InvalidEstimate", "InvalidEstimatorInput", "InvalidEstimatorParams", "EstimatorStateError",
    # the estimator protocol
    "Estimate", "Estimator", "EstimatorBase", "PrivilegedEstimator", "estimate_errors",
    "hand_center",
    # the hand
    "HAND_PHYSICS_OPTIONS", "HAND_SIZES", "KEYPOINT_NAMES", "Hand", "HandBinding", "HandParams",
    "build_skeleton", "hand_params", "JOINT_LIMITS", "JOINT_LIMITS_DEG", "JOINT_NAMES",
    "HandPose", "LimitViolation", "ForwardKinematics", "Retargeter", "RetargetResult",
    "GESTURES", "GRASP_TYPES", "gesture", "grasp_pose", "random_motion", "sample_grasp",
    "sample_synergy", "sample_uniform", "smooth_motion", "synergy_basis",
    # metrics
    "evaluate_dexter_object", "evaluate_hand_poses", "evaluate_object_poses", "plot_f_tau",
    "plot_pck",
    # the world
    "OBJECTS", "OBJECT_NAMES", "Symmetry", "YCBObject", "add_object", "get_object",
    "load_object", "CAMERA_PRESETS", "CameraIntrinsics", "camera_preset", "DepthRenderer",
    "SEGMENT_LABELS", "CameraSpec", "ObjectPlacement", "Scene", "SceneSpec",
    "egocentric_camera", "sample_placements", "sample_viewpoint", "third_person_camera",
    "StructuredLight", "TimeOfFlight", "sensor_model",
    # frames
    "Frame", "FrameRenderer", "ObjectLabel",
}  # fmt: skip
"""Names importable from ``handsim``: moving a module must not remove one."""

CORE = Path(handsim.__file__).parent


def test_public_names_stay_importable_from_the_package():
    """Every public name is exported by ``handsim`` (a layout change is not an API change)."""
    missing = PUBLIC_NAMES - set(handsim.__all__)
    assert not missing, f"no longer exported from handsim: {sorted(missing)}"
    for name in PUBLIC_NAMES:
        assert getattr(handsim, name) is not None, name


def test_the_core_is_grouped_by_part_of_the_world():
    """The core has one folder per part of the world (hand, world, data), the CLI, metrics."""
    for folder in ("hand", "world", "data", "cli", "metrics"):
        assert (CORE / folder / "__init__.py").is_file(), folder
    flat = {p.stem for p in CORE.glob("*.py")}
    assert flat <= {"__init__", "_validate", "errors", "estimator", "frame", "viz"}, flat


def _imported_modules(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_layers_the_core_imports_neither_envs_nor_estimators():
    """The core (except the CLI, which glues the layers) never imports envs or estimators."""
    for path in CORE.rglob("*.py"):
        if "cli" in path.relative_to(CORE).parts:
            continue
        for module in _imported_modules(path):
            assert not module.startswith(("handsim.envs", "handsim.estimators")), (path, module)


def test_layers_envs_never_import_estimators():
    """Envs accept any object of the Estimator protocol; they import no estimator."""
    import handsim.envs

    for path in Path(handsim.envs.__file__).parent.rglob("*.py"):
        for module in _imported_modules(path):
            assert not module.startswith("handsim.estimators"), (path, module)


def test_every_name_in_all_resolves():
    """Every name listed in handsim.__all__ is an attribute of the package."""
    for name in handsim.__all__:
        assert getattr(handsim, name) is not None, name
    assert len(set(handsim.__all__)) == len(handsim.__all__)


# Loaded where they are used (meshes, KD-trees, compiled kernels, image ops), never on import.
_LAZY_MODULES = ("torch", "trimesh", "networkx", "scipy.spatial", "scipy.sparse", "numba", "cv2")


@pytest.mark.parametrize("module", ["handsim", "handsim.envs"])
def test_import_does_not_pull_heavy_modules(module):
    """Importing the core or the envs leaves torch, trimesh, scipy.spatial, numba, cv2 unloaded.

    Checked in a fresh process; these are what made ``import handsim`` take ~1 s.
    """
    code = f"import sys, {module}; print([m for m in {_LAZY_MODULES!r} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(
    ("module", "allowed"),
    [("handsim.cli.main", ()), ("handsim.data.generation", ("numba",))],
)
def test_generate_path_does_not_pull_heavy_modules(module, allowed):
    """``handsim generate`` (the CLI's parsers, the generation module) loads no OpenCV/SciPy.

    Every command's parser is built on every call, and the generation module is what each
    dataset worker starts with: their start-up is serial time in a run with workers.
    """
    code = f"import sys, {module}; print([m for m in {_LAZY_MODULES!r} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == str(list(allowed))


def test_lazy_modules_load_on_use():
    """The lazily imported modules do load when their feature is used (the check is live)."""
    code = (
        "import sys, numpy as np, handsim\n"
        "from handsim.metrics import adi_error_mm\n"
        "adi_error_mm(np.eye(4), np.eye(4), np.zeros((3, 3)))\n"
        "handsim.get_object('005_tomato_soup_can')\n"
        "print(sorted(m for m in ('scipy.spatial', 'trimesh') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['scipy.spatial', 'trimesh']"


def test_cli_help_lists_the_subcommands():
    """`handsim --help` names every subcommand."""
    out = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "--help"], capture_output=True, text=True, check=True
    )
    for command in ("demo", "closed-loop", "info", "teleop", "view"):
        assert command in out.stdout


def test_cli_info_prints_the_hand(capsys):
    """`handsim info` reports the 27 DoF and every joint."""
    from handsim.cli import main
    from handsim.hand.pose import JOINT_NAMES

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
        "from handsim.world.scene import Scene, SceneSpec\n"
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


def test_pyproject_lists_every_package():
    """A wheel holds only the listed packages: each folder with an __init__.py is listed."""
    import tomllib

    root = CORE.parent
    pyproject = root / "pyproject.toml"
    if not pyproject.is_file():
        pytest.skip("installed without the source tree")
    setuptools = tomllib.loads(pyproject.read_text())["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    found = set()
    for name, folder in setuptools["package-dir"].items():
        for init in (root / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(root / folder).parts
            found.add(".".join((name, *rel)))
    assert found - listed == set(), "packages missing from pyproject.toml's packages"

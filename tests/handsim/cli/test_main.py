"""The program's conventions: --version, valid values in --help, one-line errors, exit codes."""

import os
import subprocess
import sys

import pytest

import handsim
from handsim.cli import main
from handsim.envs import ENV_IDS
from handsim.envs.config import SENSORS
from handsim.world.camera import CAMERA_PRESETS
from handsim.world.registry import OBJECT_NAMES


def _handsim(*args, **env):
    return subprocess.run(
        [sys.executable, "-m", "handsim.cli", *args],
        capture_output=True,
        text=True,
        env={**os.environ, "MUJOCO_GL": "egl", **env},
        timeout=120,
    )


def test_version_subprocess():
    """`handsim --version` prints the package version and exits 0."""
    result = _handsim("--version")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == f"handsim {handsim.__version__}"


def test_bad_choice_is_a_usage_error_without_traceback():
    """A bad --sensor ends in argparse's usage error: exit 2, one error line, the valid values."""
    result = _handsim("closed-loop", "--sensor", "kinect")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and result.stdout == ""
    errors = [line for line in result.stderr.splitlines() if "error:" in line]
    assert errors == [
        "handsim closed-loop: error: argument --sensor: invalid choice: 'kinect' (choose from "
        + ", ".join(repr(s) for s in SENSORS)
        + ")"
    ]
    assert result.stderr.startswith("usage: handsim closed-loop")


def test_help_lists_valid_values(capsys):
    """--help names every env, sensor, camera, object and built-in estimator."""
    with pytest.raises(SystemExit) as exit_info:
        main(["closed-loop", "--help"])
    assert exit_info.value.code == 0
    # argparse wraps lines: compare without the wrapping.
    text = " ".join(capsys.readouterr().out.split())
    for value in (*ENV_IDS, *SENSORS, *CAMERA_PRESETS, *OBJECT_NAMES, "oracle", "com"):
        assert value in text, value
    assert "module:Class[:kwargs-json]" in text
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "--version" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["closed-loop", "--env", "handsim/Nope-v0"], "invalid choice: 'handsim/Nope-v0'"),
        (["closed-loop", "--camera", "kinect"], "argument --camera: invalid choice: 'kinect'"),
        (["closed-loop", "--objects", "mug", "spoon"], "unknown object 'spoon'.*Valid names:"),
        (["closed-loop", "--episodes", "0"], "--episodes: expected an integer >= 1; received '0'"),
        (["closed-loop", "--episodes", "two"], "expected an integer >= 1; received 'two'"),
        (["closed-loop", "--dropout", "1.5"], r"--dropout: expected a number in \[0, 1\]"),
        (["closed-loop", "--noise-mm", "nan"], r"--noise-mm: expected a number in \[0, 1000\]"),
        (["closed-loop", "--noise-mm", "-1"], r"--noise-mm: expected a number in \[0, 1000\]"),
        (["closed-loop", "--estimator", "deepprior3"], "unknown estimator .deepprior3.; give one"),
        (["demo", "--size", "0"], r"--size: expected an integer in \[32, 1024\]; received '0'"),
        (["demo", "--closed-loop-episodes", "-1"], "expected an integer >= 0"),
        (["teleport"], "invalid choice: 'teleport'"),
    ],
)
def test_bad_values_are_usage_errors(argv, message, capsys):
    """Every checked option fails at parse time with exit status 2 and the valid range."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    import re

    assert re.search(message, err), err


def test_object_aliases_are_canonicalized():
    """--objects takes short aliases and MJCF names and stores canonical names."""
    from handsim.cli.main import build_parser

    args = build_parser().parse_args(
        ["closed-loop", "--objects", "mug", "obj_011_banana", "005_tomato_soup_can"]
    )
    assert args.objects == ["025_mug", "011_banana", "005_tomato_soup_can"]


def test_no_command_prints_help(capsys):
    """`handsim` alone prints the help and returns 2."""
    assert main([]) == 2
    assert "COMMAND" in capsys.readouterr().out


RAISING_ESTIMATOR = """
from handsim.errors import InvalidEstimatorInput


class Broken:
    def predict(self, depth, K):
        raise InvalidEstimatorInput("this depth is not what Broken wants")

    def predict_batch(self, depths, Ks):
        return [self.predict(d, k) for d, k in zip(depths, Ks)]

    def reset(self):
        pass
"""


def test_handsim_error_at_run_time_is_one_line(tmp_path, monkeypatch, capsys):
    """A HandSimError raised while running: `handsim: error: ...`, exit 2; --debug re-raises."""
    (tmp_path / "broken_est.py").write_text(RAISING_ESTIMATOR)
    monkeypatch.chdir(tmp_path)
    argv = [
        "closed-loop",
        "--env",
        "handsim/HandPose-v0",
        "--episodes",
        "1",
        "--sensor",
        "none",
        "--estimator",
        "broken_est:Broken",
        "--out",
        str(tmp_path / "out"),
        "-q",
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == "handsim: error: this depth is not what Broken wants\n"
    from handsim.errors import InvalidEstimatorInput

    with pytest.raises(InvalidEstimatorInput, match="not what Broken wants"):
        main(["--debug", *argv])
    monkeypatch.setenv("HANDSIM_DEBUG", "1")
    with pytest.raises(InvalidEstimatorInput):
        main(argv)


def test_run_time_error_subprocess(tmp_path):
    """The same through the real program: exit 2, one stderr line, no traceback."""
    (tmp_path / "broken_est.py").write_text(RAISING_ESTIMATOR)
    result = subprocess.run(
        [sys.executable, "-m", "handsim.cli", "closed-loop", "--env", "handsim/HandPose-v0"]
        + ["--episodes", "1", "--sensor", "none", "-q", "--estimator", "broken_est:Broken"]
        + ["--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "MUJOCO_GL": "egl"},
        timeout=300,
    )
    assert result.returncode == 2
    assert result.stderr.splitlines() == ["handsim: error: this depth is not what Broken wants"]


def test_command_modules_name_every_command():
    """COMMAND_MODULES maps each command to the module whose parser adds it, and names all."""
    import argparse

    from handsim.cli.main import COMMAND_MODULES, build_parser

    def commands(parser):
        return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))

    assert sorted(commands(build_parser()).choices) == sorted(COMMAND_MODULES)
    for name, module in COMMAND_MODULES.items():
        parser = argparse.ArgumentParser()
        module.add_parser(parser.add_subparsers())
        assert name in commands(parser).choices, (name, module.__name__)
        assert sorted(commands(build_parser(name)).choices) == sorted(commands(parser).choices)


def test_generate_imports_no_envs_nor_estimators_subprocess(tmp_path):
    """`handsim generate` imports neither the envs nor the estimators.

    It builds no other command's parser and prints its summary without them (their imports
    cost every run about 0.1 s of CPU).
    """
    code = (
        "import sys\n"
        "from handsim.cli.main import main\n"
        f"main(['generate', '--preset', 'hand-only', '--frames', '2', '--out', {str(tmp_path)!r},"
        " '--quiet'])\n"
        "print([m for m in ('handsim.envs', 'gymnasium', 'handsim.estimators.deepprior.train')"
        " if m in sys.modules])\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )
    assert result.returncode == 0, result.stderr
    assert '"frames": 2' in result.stdout
    assert result.stdout.strip().splitlines()[-1] == "[]"
    # Every command is still listed where an unknown one is named.
    bogus = _handsim("bogus")
    assert bogus.returncode == 2
    assert "invalid choice: 'bogus' (choose from 'demo', 'closed-loop'" in bogus.stderr
    assert "'train', 'evaluate')" in bogus.stderr


def test_exit_freezes_the_heap_after_the_handlers_registered_later_subprocess():
    """The program's exit freezes what is left, once, after the handlers registered later.

    Python's exit collection then skips the frozen objects; the exit handlers registered while
    the program ran (closing renderers and files) still run first, on an unfrozen heap.
    """
    code = (
        "import atexit, gc\n"
        "atexit.register(lambda: print('registered before, run last:', gc.get_freeze_count() > 0))"
        "\n"
        "from handsim.cli.main import skip_exit_collection\n"
        "count = atexit._ncallbacks()\n"
        "skip_exit_collection()\n"
        "skip_exit_collection()\n"
        "print('handlers added:', atexit._ncallbacks() - count)\n"
        "atexit.register(lambda: print('registered after, run first:', gc.get_freeze_count()))\n"
        "print('running:', gc.get_freeze_count())\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [
        "handlers added: 1",
        "running: 0",
        "registered after, run first: 0",
        "registered before, run last: True",
    ]


def test_only_the_program_freezes_its_start_up_objects(monkeypatch, capsys):
    """main() without argv (the program) freezes what is loaded; main(argv) leaves it be.

    A caller's main(argv) (a test, another program) must not freeze the caller's heap.
    """
    import gc

    from handsim.cli.main import main

    gc.unfreeze()
    main(["info", "--json", "-q"])
    assert gc.get_freeze_count() == 0
    monkeypatch.setattr(sys, "argv", ["handsim", "info", "--json", "-q"])
    try:
        assert main() == 0
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()
    capsys.readouterr()

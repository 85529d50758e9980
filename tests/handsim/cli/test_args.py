"""Command-line values: one range-checked type per numeric option, -q everywhere, exclusions."""

import argparse
import json
import os
import subprocess
import sys

import pytest

from handsim.cli._args import integer, number, port, probability, seed
from handsim.cli.main import build_parser


def _handsim(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "handsim.cli", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "MUJOCO_GL": "egl"},
        timeout=300,
    )


def _leaves(parser, path=()):
    """Every command that runs (``handsim dataset info``, ...), with its parser."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield " ".join(path), parser
    for sub in subs:
        for name, child in sub.choices.items():
            yield from _leaves(child, (*path, name))


LEAVES = dict(_leaves(build_parser()))


def test_every_command_is_listed():
    """The walk finds the commands of the program (a guard for the tests below)."""
    for name in ("demo", "closed-loop", "generate", "dataset check", "dataset info", "export",
                 "info", "teleop replay", "teleop sweep", "teleop serve", "view", "train",
                 "evaluate"):  # fmt: skip
        assert name in LEAVES, name


@pytest.mark.parametrize("command", sorted(LEAVES))
def test_every_command_accepts_q_and_quiet(command):
    """-q / --quiet mean the same on every command (no progress bars)."""
    options = [a.option_strings for a in LEAVES[command]._actions]
    assert ["-q", "--quiet"] in options, command


@pytest.mark.parametrize("command", sorted(LEAVES))
def test_no_numeric_option_takes_a_bare_int_or_float(command):
    """Every number goes through integer() / number(), which check finiteness and range."""
    for action in LEAVES[command]._actions:
        assert action.type not in (int, float), (command, action.option_strings)


def test_integer_and_number_messages_give_the_range():
    """The message names the valid interval (open or closed) and the value received."""
    size = integer(32, 512, "a crop side")
    assert size("64") == 64
    with pytest.raises(argparse.ArgumentTypeError, match=r"in \[32, 512\] \(a crop side\); "):
        size("100000")
    with pytest.raises(argparse.ArgumentTypeError, match=r"expected an integer in \[32, 512\]"):
        size("1.5")
    alpha = number(0, 1, lo_open=True)
    assert alpha("1") == 1.0
    for bad in ("0", "nan", "inf", "-1e-9", "x"):
        with pytest.raises(argparse.ArgumentTypeError, match=r"a number in \(0, 1\]; received"):
            alpha(bad)
    finite = number()
    assert finite("-3.5") == -3.5
    with pytest.raises(argparse.ArgumentTypeError, match="expected a finite number; received"):
        finite("-inf")
    assert probability("0") == 0.0 and port("65535") == 65535 and seed("0") == 0
    with pytest.raises(argparse.ArgumentTypeError, match=r"\[1, 65535\] \(a TCP/UDP port\)"):
        port("0")
    with pytest.raises(argparse.ArgumentTypeError, match=r"\[0, 9223372036854775807\]"):
        seed("-1")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["train", "deepprior++", "--data", "DS", "--out", "R", "--weight-decay", "-1"],
         r"handsim train: error: argument --weight-decay: expected a number in \[0, 1\]; "
         r"received '-1'"),
        (["train", "deepprior++", "--data", "DS", "--out", "R", "--offset-sigma-mm", "nan"],
         r"argument --offset-sigma-mm: expected a number in \[0, 500\]; received 'nan'"),
        (["train", "deepprior++", "--data", "DS", "--out", "R", "--size", "100000"],
         r"argument --size: expected an integer in \[32, 512\] .*received '100000'"),
        (["demo", "--size", "100000"],
         r"handsim demo: error: argument --size: expected an integer in \[32, 1024\]"),
        (["evaluate", "--estimator", "deepprior++", "--env", "handsim/Nope-v0", "--out", "O"],
         r"argument --env: invalid choice: 'handsim/Nope-v0' \(choose from 'handsim/HandPose"),
        (["evaluate", "--estimator", "deepprior++", "--data", "DS", "--env", "handsim/Grasp-v0",
          "--out", "O"],
         "handsim evaluate: error: argument --env: not allowed with argument --data"),
    ],
)  # fmt: skip
def test_bad_numbers_and_exclusive_options_are_usage_errors_subprocess(argv, message, tmp_path):
    """The program itself: exit 2, argparse's usage and one error line, no traceback, no work."""
    result = _handsim(*argv, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    errors = [line for line in result.stderr.splitlines() if "error:" in line]
    assert len(errors) == 1
    import re

    assert re.search(message, errors[0]), errors[0]
    assert list(tmp_path.iterdir()) == []  # nothing written


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--data", "DS", "--every", "3"],
         r"argument --every: not allowed with argument --data \(it applies to --env\)"),
        (["--data", "DS", "--seed", "4"], "argument --seed: not allowed with argument --data"),
        (["--env", "handsim/Grasp-v0", "--split", "val"],
         r"argument --split: not allowed with argument --env \(it splits --data\)"),
        ([], "one of the arguments --data --env is required"),
    ],
)  # fmt: skip
def test_evaluate_refuses_the_other_sources_options(extra, message, capsys):
    """An option --data or --env would ignore is refused (exit 2) before any frame is read."""
    from handsim.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["evaluate", "--estimator", "deepprior++", "--out", "O", *extra])
    assert exit_info.value.code == 2
    import re

    assert re.search(message, capsys.readouterr().err)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["teleop", "send", "f.json", "--udp", "70000"],
         r"argument --udp: expected an integer in \[1, 65535\] \(a TCP/UDP port\)"),
        (["teleop", "send", "f.json", "--udp", "9000", "--speed", "0"],
         r"argument --speed: expected a number in \(0, 1000\]; received '0'"),
        (["view", "r.npz", "--fps", "0"], r"argument --fps: expected a number in \(0, 240\]"),
        (["teleop", "replay", "f.json", "--alpha", "0"], r"--alpha: expected a number in \(0, 1\]"),
        (["teleop", "replay", "f.json", "--min-cutoff-hz", "0"],
         r"--min-cutoff-hz: .* in \(0, 1000\]"),
        (["teleop", "replay", "f.json", "--bias-mm", "0", "nan", "0"],
         r"--bias-mm: expected a number in \[-1000, 1000\]; received 'nan'"),
        (["closed-loop", "--seed", "-1"],
         r"--seed: expected an integer in \[0, 9223372036854775807\]"),
        (["closed-loop", "--object-noise-deg", "200"], r"expected a number in \[0, 180\]"),
        (["train", "deepprior", "--data", "D", "--out", "R", "--prior-dim", "64"],
         r"--prior-dim: expected an integer in \[0, 63\] \(at most the 63 coordinates"),
        (["train", "deepprior", "--data", "D", "--out", "R", "--size", "48"],
         r"--size: expected an integer in \[32, 512\] that is a multiple of 32; received '48'"),
        (["generate", "--preset", "hand-only", "--out", "D", "--frames", "2000000000"],
         r"--frames: expected an integer in \[1, 1000000000\]"),
        (["teleop", "sweep", "--latency", "0,20000"],
         r"--latency: expected an integer in \[0, 10000\] \(frames of delay\)"),
        (["teleop", "replay", "f.json", "--jitter", "-1"], r"--jitter: expected an integer in"),
        (["generate", "--preset", "hand-only", "--out", "D", "--workers", "0"],
         r"--workers: expected an integer in \[1, 1024\]"),
    ],
)  # fmt: skip
def test_more_ranges_are_usage_errors(argv, message, capsys):
    """Ports, rates, filter constants, seeds, angles, network sizes, workers: their ranges."""
    from handsim.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    import re

    assert re.search(message, capsys.readouterr().err)


def test_generate_quiet_keeps_stderr_empty_subprocess(tmp_path):
    """`handsim generate -q`: the JSON report on stdout and nothing on stderr (no progress bar)."""
    config = {"frames": 1, "frames_per_shard": 1, "frames_per_episode": 1, "sensor": "none",
              "num_objects_range": [0, 0]}  # fmt: skip
    (tmp_path / "c.json").write_text(json.dumps(config))
    args = ("generate", "--config", str(tmp_path / "c.json"), "--out", str(tmp_path / "d"))
    result = _handsim(*args, "-q")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["frames"] == 1
    assert result.stderr == ""

"""Bad input on the surfaces added since the original API fuzz, as a case list.

Each :class:`Case` builds its bad input in a scratch folder and calls one entry point (the API,
or the ``handsim`` program in this process with ``HANDSIM_DEBUG=1``, so a ``HandSimError``
propagates instead of being printed). It names the error it must end in (a class name, or
``"usage"`` for argparse's usage error, exit status 2) and a regular expression its message
must match. ``tests/handsim/test_fuzz_surfaces.py`` asserts every case;
``benchmarks/fuzz_tally.py`` runs the list (also on older code) and counts the outcomes by class.

Expected classes are named, not imported, so the list loads on code that lacks them.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import os
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

# The outcome classes of the tally.
CLEAR = "clear HandSimError"
OTHER_CLEAR = "other clear error"
LOW_LEVEL = "low-level error"
SILENT = "silent wrong"
CRASH = "crash"
CLASSES = (CLEAR, OTHER_CLEAR, LOW_LEVEL, SILENT, CRASH)


def _own_code() -> tuple[str, ...]:
    """The folders of the handsim that is imported (this checkout's or another's)."""
    import handsim

    repo = Path(handsim.__file__).resolve().parents[1]
    return tuple(str(repo / d) for d in ("handsim", "envs", "estimators"))


@dataclasses.dataclass(frozen=True)
class Case:
    """One bad input: ``call(scratch, fixtures)`` must raise ``expected`` matching ``match``."""

    name: str
    surface: str
    call: Callable[[Path, dict[str, Path]], Any]
    expected: str
    match: str

    def __repr__(self) -> str:
        return self.name


class UsageError(Exception):
    """argparse's usage error (``SystemExit(2)``) of an in-process ``handsim`` run."""


def cli(*argv: str) -> Any:
    """Run ``handsim argv`` in this process; a HandSimError propagates, usage -> UsageError."""
    from handsim.cli.main import main

    err = io.StringIO()
    old = os.environ.get("HANDSIM_DEBUG")
    os.environ["HANDSIM_DEBUG"] = "1"
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            return main(list(argv))
    except SystemExit as exit_:
        if exit_.code == 2:
            raise UsageError(err.getvalue().strip().splitlines()[-1]) from None
        raise
    finally:
        if old is None:
            os.environ.pop("HANDSIM_DEBUG")
        else:
            os.environ["HANDSIM_DEBUG"] = old


def classify(case: Case, scratch: Path, fixtures: dict[str, Path]) -> tuple[str, bool, str]:
    """Run one case: ``(outcome class, expected error and message, what happened)``."""
    import re

    from handsim.errors import HandSimError

    here = os.getcwd()
    os.chdir(scratch)  # a command that runs writes its default output here, not in the checkout
    try:
        result = case.call(scratch, fixtures)
    except HandSimError as err:
        names = {c.__name__ for c in type(err).__mro__}
        ok = case.expected in names and re.search(case.match, str(err)) is not None
        return CLEAR, ok, f"{type(err).__name__}: {err}"
    except UsageError as err:
        ok = case.expected == "usage" and re.search(case.match, str(err)) is not None
        return OTHER_CLEAR, ok, f"usage: {err}"
    except Exception as err:  # noqa: BLE001 - the point of the tally
        # Clear: raised on purpose by handsim's own code (a `raise` line there), with a message.
        last = traceback.extract_tb(err.__traceback__)[-1]
        deliberate = last.filename.startswith(_own_code()) and (last.line or "").startswith("raise")
        kind = OTHER_CLEAR if deliberate and str(err) else LOW_LEVEL
        where = f"{last.filename}:{last.lineno}"
        return kind, False, f"{type(err).__name__}: {str(err)[:200]} (raised at {where})"
    finally:
        os.chdir(here)
    return SILENT, False, f"returned {str(result)[:200]!r}"


# Fixtures -----------------------------------------------------------------------------------


def make_fixtures(folder: Path) -> dict[str, Path]:
    """A tiny dataset (2 shards of 3 one-frame episodes), made once per run."""
    from handsim.data.generation import GenerationConfig, generate

    data = folder / "data"
    config = GenerationConfig.from_mapping(
        {
            "frames": 6,
            "frames_per_shard": 3,
            "frames_per_episode": 1,
            "sensor": "none",
            "num_objects_range": (0, 0),
        }
    )
    generate(config, data)
    return {"data": data}


def _copy_dataset(fixtures: dict[str, Path], scratch: Path) -> Path:
    import shutil

    out = scratch / "ds"
    shutil.copytree(fixtures["data"], out)
    return out


def _edit_manifest(edit: Callable[[dict], None]) -> Callable[[Path, dict[str, Path]], Path]:
    def make(scratch: Path, fixtures: dict[str, Path]) -> Path:
        out = _copy_dataset(fixtures, scratch)
        doc = json.loads((out / "manifest.json").read_text())
        edit(doc)
        (out / "manifest.json").write_text(json.dumps(doc))
        return out

    return make


def _damage_shard(how: str) -> Callable[[Path, dict[str, Path]], Path]:
    def make(scratch: Path, fixtures: dict[str, Path]) -> Path:
        out = _copy_dataset(fixtures, scratch)
        shard = out / "shard-00000.h5"
        data = bytearray(shard.read_bytes())
        if how == "truncated":
            data = data[: len(data) // 2]
        elif how == "garbage":
            data = bytearray(b"not an hdf5 file" * 64)
        else:  # flipped bytes inside the image chunks (the last third of the file)
            for i in range(len(data) * 2 // 3, len(data) - 2048, 97):
                data[i] ^= 0xFF
        shard.write_bytes(bytes(data))
        return out

    return make


def _dataset_frame(make: Callable) -> Callable[[Path, dict[str, Path]], Any]:
    def call(scratch: Path, fixtures: dict[str, Path]) -> Any:
        from handsim.data.torch_dataset import HandSimDataset

        dataset = HandSimDataset(make(scratch, fixtures))
        return [dataset[i] for i in range(len(dataset))]

    return call


def _shard_read(make: Callable) -> Callable[[Path, dict[str, Path]], Any]:
    def call(scratch: Path, fixtures: dict[str, Path]) -> Any:
        from handsim.data.shards import ShardReader

        reader = ShardReader(make(scratch, fixtures) / "shard-00000.h5")
        return [reader[i] for i in range(len(reader))]

    return call


def _cli_on(make: Callable, *argv: str) -> Callable[[Path, dict[str, Path]], Any]:
    def call(scratch: Path, fixtures: dict[str, Path]) -> Any:
        folder = make(scratch, fixtures)
        return cli(*[str(folder) if a == "{ds}" else str(scratch / a[1:]) if a[0] == "@" else a
                     for a in argv])  # fmt: skip

    return call


def _a_file(scratch: Path) -> Path:
    path = scratch / "a_file"
    path.write_text("x")
    return path


# Checkpoints --------------------------------------------------------------------------------


def _checkpoint(state: Any, config: Any = None, raw: bytes | None = None) -> Callable:
    def call(scratch: Path, fixtures: dict[str, Path]) -> Any:
        import torch

        from handsim.estimators.deepprior.checkpoint import load_model

        path = scratch / "ckpt.pt"
        if raw is not None:
            path.write_bytes(raw)
        else:
            torch.save(state() if callable(state) else state, path)
        default = {"model": {"kind": "deepprior++", "size": 32, "fc": 16, "width": 0.125}}
        path.with_suffix(".json").write_text(json.dumps(default if config is None else config))
        return load_model(path)

    return call


def _trained_run(fixtures: dict[str, Path]) -> tuple[Path, Any]:
    """A one-epoch run on the tiny dataset, trained once per fixture set; its config."""
    import torch

    from handsim.estimators.deepprior.train import TrainConfig, train

    config = TrainConfig(
        kind="deepprior++", epochs=1, batch_size=4, size=32, fc=16, width=0.125,
        prior_dim=4, max_frames=4, seed=0,
    )  # fmt: skip
    run = fixtures["data"].parent / "run"
    if not run.exists():
        torch.set_num_threads(1)
        train([fixtures["data"]], run, config, progress=False, log=lambda s: None)
    return run, config


def _resume_from(raw: bytes | None, state: Callable | None = None) -> Callable:
    def call(scratch: Path, fixtures: dict[str, Path]) -> Any:
        import shutil

        import torch

        from handsim.estimators.deepprior.train import train

        trained, config = _trained_run(fixtures)
        run = scratch / "run"
        shutil.copytree(trained, run)
        last = run / "last.pt"
        if raw is not None:
            last.write_bytes(raw if raw else last.read_bytes()[:200])
        else:
            torch.save(state(torch.load(last, weights_only=True)), last)
        return train([fixtures["data"]], run, config, progress=False, log=lambda s: None)

    return call


def _nan_weights() -> dict:
    import torch

    return {"model": {"conv.weight": torch.full((2, 2), float("nan"))}}


# Streams ------------------------------------------------------------------------------------


def _stream(doc: Any, raw: str | None = None, rate_hz: float | None = None) -> Callable:
    def call(scratch: Path, fixtures: dict[str, Path]) -> Any:
        from handsim.envs.teleop import load_stream

        path = scratch / "s.json"
        path.write_text(raw if raw is not None else json.dumps(doc))
        stream = load_stream(path)
        return stream.resample(rate_hz) if rate_hz else stream

    return call


def _hand_frames(scale: float = 1.0, n: int = 3) -> list[dict]:
    from handsim.hand.kinematics import ForwardKinematics
    from handsim.hand.model import hand_params
    from handsim.hand.pose import HandPose

    kp = ForwardKinematics(hand_params("medium")).keypoints(HandPose.neutral())
    kp = (kp - kp.mean(axis=0)) * scale
    return [{"t": 0.01 * i, "keypoints": kp.tolist()} for i in range(n)]


def _nested(depth: int) -> str:
    return '{"frames": ' + "[" * depth + "]" * depth + "}"


# Original API ------------------------------------------------------------------------------


def _api(fn: Callable[[], Any]) -> Callable[[Path, dict[str, Path]], Any]:
    return lambda scratch, fixtures: fn()


def _retarget(keypoints: Any, **kwargs: Any) -> Any:
    import handsim

    hand = handsim.HandParams()
    kp = handsim.ForwardKinematics(hand).keypoints(handsim.HandPose.neutral())
    return handsim.Retargeter(hand)(kp if keypoints is None else keypoints, **kwargs)


def _set_state(edit: Callable[[dict], Any]) -> Any:
    import gymnasium as gym

    import handsim.envs  # noqa: F401

    env = gym.make("handsim/HandPose-v0", obs_mode="state")
    try:
        env.reset(seed=0)
        return env.unwrapped.set_state(edit(env.unwrapped.get_state()))
    finally:
        env.close()


def _rigid(scale: float) -> np.ndarray:
    T = np.eye(4)  # noqa: N806
    T[:3, :3] *= scale
    return T


def _add_error(T: np.ndarray) -> Any:  # noqa: N803
    from handsim.metrics.objects import add_error_mm

    points = np.random.default_rng(0).normal(size=(20, 3)) * 0.05
    return add_error_mm(T, np.eye(4), points)


def _com(depth: np.ndarray) -> Any:
    import handsim
    from handsim.estimators import CenterOfMassLocalizer

    return CenterOfMassLocalizer().predict(depth, handsim.camera_preset("icvl").K)


def _clutter_repeated() -> Any:
    import gymnasium as gym

    import handsim.envs  # noqa: F401

    env = gym.make("handsim/GraspClutter-v0", objects=["025_mug"] * 6, obs_mode="state")
    try:
        return env.reset(seed=0)
    finally:
        env.close()


def _hand_poses(offset: float) -> Any:
    import handsim

    gt = np.linspace(0.0, 0.2, 63).reshape(1, 21, 3)
    return handsim.evaluate_hand_poses(gt + offset, gt)


# Numeric CLI options -------------------------------------------------------------------------


def _numeric_options() -> list[tuple[tuple[str, ...], str, int, bool]]:
    """``(command path, option, nargs, bounded above)`` of every numeric option.

    An option is numeric when its type is one of ``handsim.cli._args``' range checks (or a
    bare ``int`` / ``float``); it is bounded above when its check says so for NaN.
    """
    from handsim.cli.main import build_parser

    found = []

    def walk(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, (*path, name))
            elif action.option_strings and callable(action.type):
                qualname = getattr(action.type, "__qualname__", "")
                if qualname.startswith(("integer.", "number.")) or action.type in (int, float):
                    try:
                        action.type("nan")
                        says = ""
                    except (argparse.ArgumentTypeError, ValueError, TypeError) as err:
                        says = str(err)
                    bounded = "in [" in says or "in (" in says or "<" in says
                    nargs = action.nargs if isinstance(action.nargs, int) else 1
                    found.append((path, action.option_strings[-1], nargs, bounded))

    walk(build_parser(), ())
    return sorted(set(found))


UNBOUNDED_BY_DESIGN = {
    ("teleop", o)
    for o in ("--beta", "--min-cutoff-hz", "--bias-mm", "--noise-mm", "--duration", "--wait",
              "--speed")
}  # fmt: skip
"""Options without an upper bound, where 1e300 is a valid (if extreme) value: the teleop
filter's gains, the tracking faults, how long to run (the cases do not run them)."""


def _positional_stub(path: tuple[str, ...]) -> list[str]:
    # Positionals some commands need before their options can be reached (parse order).
    stubs = {
        ("train",): ["deepprior++"],
        ("export",): ["bop", "src", "out"],
        ("view",): ["rollout.npz"],
    }
    return stubs.get(path, [])


def _numeric_case(path: tuple[str, ...], option: str, nargs: int, value: str) -> Case:
    def call(scratch: Path, fixtures: dict[str, Path]) -> Any:
        return cli(*path, *_positional_stub(path), option, *[value] * nargs)

    return Case(
        f"cli {' '.join(path)} {option} {value}",
        "numeric CLI option",
        call,
        "usage",
        rf"argument {option}: expected",
    )


# The list -----------------------------------------------------------------------------------


def cases() -> list[Case]:
    """Every case (the numeric options are read from the parser)."""
    out: list[Case] = []
    add = out.append

    # Output folders.
    for command, argv in {
        "generate": ["generate", "--preset", "hand-only", "--frames", "2", "--out"],
        "train": ["train", "localizer", "--data", "{ds}", "--out"],
        "evaluate": ["evaluate", "--estimator", "deepprior++", "--data", "{ds}", "--out"],
        "export bop": ["export", "bop", "{ds}"],
        "export hand-labels": ["export", "hand-labels", "{ds}"],
    }.items():
        for where, target in (("a file", "@a_file"), ("inside a file", "@a_file/sub")):

            def call(s: Path, f: dict[str, Path], argv: list = argv, target: str = target) -> Any:
                _a_file(s)
                return _cli_on(lambda s, f: _copy_dataset(f, s), *argv, target)(s, f)

            add(Case(f"{command} --out {where}", "output folder", call, "usage",
                     r"(is a file|inside a file|not a folder)"))  # fmt: skip

    # Corrupt and truncated shards and manifests.
    for how in ("truncated", "garbage", "flipped"):
        match = r"shard-00000\.h5.*(dataset check|not a|truncated|damaged|cannot be read)"
        add(Case(f"HandSimDataset of a {how} shard", "shard", _dataset_frame(_damage_shard(how)),
                 "InvalidShard", match))  # fmt: skip
        add(Case(f"ShardReader of a {how} shard", "shard", _shard_read(_damage_shard(how)),
                 "InvalidShard", match))  # fmt: skip
        add(Case(f"export hand-labels of a {how} shard", "shard",
                 _cli_on(_damage_shard(how), "export", "hand-labels", "{ds}", "@out"),
                 "InvalidShard", match))  # fmt: skip
    manifests = {
        "depth_scale_mm -1": (lambda d: d.update(depth_scale_mm=-1), r"depth_scale_mm"),
        "depth_scale_mm 'abc'": (lambda d: d.update(depth_scale_mm="abc"), r"depth_scale_mm"),
        "image_shape [0, 0]": (lambda d: d.update(image_shape=[0, 0]), r"image_shape"),
        "no shards key": (lambda d: d.pop("shards"), r"lacks shards"),
        "shards not a list": (lambda d: d.update(shards=5), r"shard record is malformed"),
        "4 frames for a shard of 3": (
            lambda d: d["shards"][0].update(frames=4),
            r"shard-00000\.h5 holds 3 frames but the manifest says 4",
        ),
        "config a string": (lambda d: d.update(config="abc"), r"config"),
    }
    for name, (edit, match) in manifests.items():
        make = _edit_manifest(edit)
        add(Case(f"dataset info: manifest {name}", "manifest",
                 _cli_on(make, "dataset", "info", "{ds}"), "HandSimError", match))  # fmt: skip
        add(Case(f"HandSimDataset: manifest {name}", "manifest", _dataset_frame(make),
                 "HandSimError", match))  # fmt: skip

    def not_json(s: Path, f: dict[str, Path]) -> Any:
        out = _copy_dataset(f, s)
        (out / "manifest.json").write_text("{not json")
        return cli("dataset", "info", str(out))

    add(Case("dataset info: manifest not JSON", "manifest", not_json, "InvalidManifest",
             r"manifest\.json is not valid JSON"))  # fmt: skip

    # Checkpoints.
    checkpoints = {
        "garbage bytes": (_checkpoint(None, raw=b"garbage" * 10), r"cannot read checkpoint"),
        "no model entry": (_checkpoint({"epoch": 1}), r"has no 'model' state dict"),
        "model not tensors": (_checkpoint({"model": {"w": "abc"}}), r"must map parameter"),
        "NaN weights": (_checkpoint(_nan_weights), r"non-finite weights"),
        "wrong keys": (_checkpoint(lambda: {"model": {"w": __import__("torch").zeros(2)}}),
                       r"does not fit its network"),
        "config a list": (_checkpoint(lambda: {"model": {}}, config=[1, 2]),
                          r"must be a JSON object with a 'model' mapping"),
    }  # fmt: skip
    for name, (call, match) in checkpoints.items():
        add(Case(f"checkpoint: {name}", "checkpoint", call, "InvalidCheckpoint", match))
    resumes = {
        "garbage last.pt": (_resume_from(b"garbage"), r"cannot resume from .*last\.pt"),
        "truncated last.pt": (_resume_from(b""), r"cannot resume from .*last\.pt"),
        "last.pt without optimizer": (
            _resume_from(None, lambda s: {k: v for k, v in s.items() if k != "optimizer"}),
            r"cannot resume from .*last\.pt: it lacks optimizer",
        ),
    }
    for name, (call, match) in resumes.items():
        add(Case(f"train resume: {name}", "checkpoint", call, "InvalidCheckpoint", match))

    # Every numeric CLI option at NaN, inf, hugely negative and huge, but for the teleop
    # options where a huge value is valid (a filter gain, a duration: they run that long).
    for path, option, nargs, _ in _numeric_options():
        huge = () if (path[0], option) in UNBOUNDED_BY_DESIGN else ("1e300",)
        for value in ("nan", "inf", "-1e300", *huge):
            add(_numeric_case(path, option, nargs, value))

    # Stream files.
    frames = _hand_frames()
    streams = {
        "metres labelled mm": ({"units": "mm", "frames": frames}, r"look like metres"),
        "millimetres labelled m": (
            {"units": "m", "frames": _hand_frames(500.0)},
            r"look like millimetres",
        ),
        "timestamps going back": (
            {"frames": [frames[1], frames[0], frames[2]]},
            r"strictly increasing",
        ),
        "repeated timestamps": ({"frames": [frames[0], frames[0]]}, r"greater than the previous"),
        "null timestamp": (
            {"frames": [frames[0], {**frames[1], "t": None}]},
            r"frames\[1\]\.t must be",
        ),
        "string timestamp": (
            {"frames": [frames[0], {**frames[1], "t": "0.1"}]},
            r"frames\[1\]\.t must be",
        ),
        "fps 1e-300": (
            {"fps": 1e-300, "frames": [{"keypoints": frames[0]["keypoints"]}] * 2},
            r"fps must be in \[0.01, 10000\] frames per second",
        ),
        "fps 0": ({"fps": 0, "frames": [{"keypoints": frames[0]["keypoints"]}]}, r"fps must be"),
        "null keypoints": ({"frames": [{"t": 0, "keypoints": None}]}, r"keypoints"),
        "null frames": ({"frames": None}, r"frames must be a non-empty list"),
        "a null frame": ({"frames": [frames[0], None]}, r"frames\[1\] must be an object"),
        "null units": ({"units": None, "frames": frames}, r"units"),
        "null format": ({"format": None, "frames": frames}, r"format"),
        "all-zero hand": (
            {"fps": 30, "frames": [{"keypoints": [[0.0, 0.0, 0.0]] * 21}]},
            r"a hand 0 mm long",
        ),
    }
    for name, (doc, match) in streams.items():
        add(Case(f"stream: {name}", "stream", _stream(doc), "InvalidStream", match))
    add(Case("stream: frames 10^6 s apart at 500 Hz", "stream",
             _stream({"frames": [frames[0], {**frames[1], "t": 1e6}]}, rate_hz=500.0),
             "InvalidStream", r"(2 ?000 ?000|span)"))  # fmt: skip
    add(Case("stream: JSON nested 100 000 deep", "stream", _stream(None, _nested(100_000)),
             "InvalidStream", r"nested"))  # fmt: skip
    add(Case("stream: not JSON", "stream", _stream(None, "{frames"), "InvalidStream",
             r"not valid JSON"))  # fmt: skip

    # The original API, the cases still open.
    api = {
        "Retargeter()('keypoints')": (
            lambda: _retarget("keypoints"),
            "InvalidKeypoints",
            r"retargeting expects a \(21, 3\) array of real numbers",
        ),
        "Retargeter()(kp, initial='open')": (
            lambda: _retarget(None, initial="open"),
            "InvalidPose",
            r"initial must be one HandPose.*gesture\(name\)",
        ),
        "ForwardKinematics.keypoints('open')": (
            lambda: (
                __import__("handsim")
                .ForwardKinematics(__import__("handsim").HandParams())
                .keypoints("open")
            ),
            "InvalidPose",
            r"pose must be a HandPose",
        ),
        "set_state without 'time'": (
            lambda: _set_state(lambda s: {k: v for k, v in s.items() if k != "time"}),
            "InvalidEnvConfig",
            r"state lacks time",
        ),
        "set_state('abc')": (
            lambda: _set_state(lambda s: "abc"),
            "InvalidEnvConfig",
            r"state must be a dict from get_state\(\)",
        ),
        "evaluate_hand_poses(+1e300)": (
            lambda: _hand_poses(1e300),
            "InvalidMetricInput",
            r"pred_m has a value beyond 1e\+06 m",
        ),
        "evaluate_hand_poses(-1e300)": (
            lambda: _hand_poses(-1e300),
            "InvalidMetricInput",
            r"pred_m has a value beyond 1e\+06 m",
        ),
        "add_error_mm(scaled T)": (
            lambda: _add_error(_rigid(2.0)),
            "InvalidMetricInput",
            r"T_est must be a rigid transform",
        ),
        "add_error_mm(reflected T)": (
            lambda: _add_error(_rigid(-1.0)),
            "InvalidMetricInput",
            r"T_est must be a rigid transform.*det",
        ),
        "CenterOfMassLocalizer.predict(bool depth)": (
            lambda: _com(np.ones((240, 320), bool)),
            "InvalidEstimatorInput",
            r"depth must be real numbers.*bool",
        ),
        "CenterOfMassLocalizer.predict(complex depth)": (
            lambda: _com(np.ones((240, 320), complex)),
            "InvalidEstimatorInput",
            r"depth must be real numbers.*complex",
        ),
        "GraspClutter-v0 with one object six times": (
            _clutter_repeated,
            "InvalidEnvConfig",
            r"objects must name distinct objects.*025_mug is given more than once",
        ),
        "HandPose.from_vector(complex)": (
            lambda: __import__("handsim").HandPose.from_vector(np.zeros(27, complex)),
            "InvalidPose",
            r"real numbers.*complex",
        ),
    }
    for name, (fn, expected, match) in api.items():
        add(Case(name, "original API", _api(fn), expected, match))
    return out


def run_all(folder: Path, only: list[str] | None = None) -> list[dict[str, Any]]:
    """Run the cases (or those named in ``only``) in scratch folders under ``folder``."""
    fixtures = make_fixtures(folder)
    results = []
    for i, case in enumerate(cases()):
        if only is not None and case.name not in only:
            continue
        scratch = folder / f"case{i}"
        scratch.mkdir()
        start = time.perf_counter()
        outcome, ok, detail = classify(case, scratch, fixtures)
        results.append({"name": case.name, "surface": case.surface, "class": outcome,
                        "as_expected": ok, "detail": detail,
                        "seconds": round(time.perf_counter() - start, 3)})  # fmt: skip
        print(json.dumps(results[-1]), flush=True)
    return results


if __name__ == "__main__":  # one worker of benchmarks/fuzz_tally.py
    import tempfile

    names = json.loads(sys.argv[1]) if len(sys.argv) > 1 else None
    with tempfile.TemporaryDirectory(prefix="handsim_fuzz_") as tmp:
        run_all(Path(tmp), names)

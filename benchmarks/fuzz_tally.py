"""Count the outcomes of the bad-input cases of tests/handsim/fuzz_cases.py by class.

Classes: clear HandSimError / other clear error (argparse's usage error, or an exception that
handsim's own code raises on purpose) / low-level error (anything else raised) / silent wrong
(no error for bad input) / crash (the process died: a signal, a segfault). The cases run in a
child process that reports each as it ends; when the child dies, the case it was running is a
crash and a new child goes on from the next one. ``--python`` runs them against another
checkout's interpreter (its editable install decides which handsim is imported), e.g. the code
of an older commit:

    python benchmarks/fuzz_tally.py --out /tmp/fuzz_after.json
    python benchmarks/fuzz_tally.py --python /tmp/before/.venv/bin/python --out /tmp/b.json

With ``unshare`` allowed, one more case runs ``handsim generate`` on a full 384 KiB tmpfs.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "tests" / "handsim" / "fuzz_cases.py"
CLASSES = ("clear HandSimError", "other clear error", "low-level error", "silent wrong", "crash")

_DISK_FULL = """
set -u
mount -t tmpfs -o size=384k tmpfs "$MNT"
"$PY" -m handsim.cli generate --config "$CFG" --out "$MNT/ds" -q 2>"$ERR"
echo $? >"$RC"
"""


def _names(python: str) -> list[str]:
    code = (
        f"import sys, json; sys.path.insert(0, {str(CASES.parent)!r}); import fuzz_cases; "
        "print(json.dumps([c.name for c in fuzz_cases.cases()]))"
    )
    # Not from the checkout's root: `python -c` would import its handsim, not the interpreter's.
    out = subprocess.run(
        [python, "-c", code], capture_output=True, text=True, check=True, cwd=tempfile.gettempdir()
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _run_cases(python: str, names: list[str]) -> list[dict]:
    results: list[dict] = []
    left = list(names)
    while left:
        proc = subprocess.run(
            [python, str(CASES), json.dumps(left)],
            capture_output=True,
            text=True,
            cwd=tempfile.gettempdir(),
        )
        done = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
        results += done
        finished = {r["name"] for r in done}
        left = [n for n in left if n not in finished]
        if proc.returncode == 0 or not left:
            if left:  # the child ended cleanly without running them: a bug here
                raise RuntimeError(f"cases not run: {left[:3]} ...\n{proc.stderr[-2000:]}")
            break
        crashed = left.pop(0)
        detail = f"exit {proc.returncode}: {proc.stderr.strip()[-300:]}"
        results.append(
            {"name": crashed, "surface": "?", "class": "crash", "as_expected": False,
             "detail": detail}
        )  # fmt: skip
    return results


def _disk_full(python: str) -> dict | None:
    probe = ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"]
    if shutil.which("unshare") is None or subprocess.run(probe, capture_output=True).returncode:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        (t / "mnt").mkdir()
        cfg = {"frames": 60, "frames_per_shard": 20, "frames_per_episode": 10,
               "num_objects_range": [0, 0]}  # fmt: skip
        (t / "c.json").write_text(json.dumps(cfg))
        env = dict(os.environ, MNT=str(t / "mnt"), PY=python, CFG=str(t / "c.json"),
                   ERR=str(t / "err"), RC=str(t / "rc"))  # fmt: skip
        subprocess.run(["unshare", "-rm", "sh", "-c", _DISK_FULL], env=env, check=True, cwd=tmp)
        rc = int((t / "rc").read_text())
        err = (t / "err").read_text()
    if rc > 128 or rc < 0:
        kind = "crash"
    elif rc == 2 and err.startswith("handsim: error:") and "disk is full" in err:
        kind = "clear HandSimError"
    elif "Traceback" in err:
        kind = "low-level error"
    else:
        kind = "other clear error" if rc else "silent wrong"
    last = err.strip().splitlines()[-1] if err.strip() else ""
    return {
        "name": "generate on a full 384 KiB tmpfs",
        "surface": "disk full",
        "class": kind,
        "as_expected": kind == "clear HandSimError",
        "detail": f"exit {rc}: {last[:200]}",
    }


def main(argv: list[str] | None = None) -> int:
    """Run every case and print the counts by class (and by surface)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", default=sys.executable, help="interpreter to run them in")
    parser.add_argument("--out", help="write every case's outcome here (JSON)")
    parser.add_argument("--no-disk-full", action="store_true", help="skip the tmpfs case")
    args = parser.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    results = _run_cases(args.python, _names(args.python))
    if not args.no_disk_full:
        extra = _disk_full(args.python)
        if extra is not None:
            results.append(extra)
    counts = Counter(r["class"] for r in results)
    print(f"{len(results)} cases: " + ", ".join(f"{counts[c]} {c}" for c in CLASSES))
    for surface in sorted({r["surface"] for r in results}):
        sub = Counter(r["class"] for r in results if r["surface"] == surface)
        print(f"  {surface}: " + ", ".join(f"{sub[c]} {c}" for c in CLASSES if sub[c]))
    wrong = [r for r in results if not r["as_expected"]]
    print(f"not the expected error and message: {len(wrong)}")
    for r in wrong:
        print(f"  [{r['class']}] {r['name']}: {r['detail'][:160]}")
    if args.out:
        Path(args.out).write_text(json.dumps({"counts": counts, "cases": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

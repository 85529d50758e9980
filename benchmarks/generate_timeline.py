"""Timeline of ``handsim generate``: where a small job's wall time goes, 1 worker against 2.

Each run is the whole ``handsim generate --preset hand-only --frames N --workers W`` command
in a fresh process, traced: the child wraps the generation's stages (the fork's warm-up, each
shard, the first frame written in each process, the histogram, the workers' shutdown) and logs
the wall time since the command was started and the process's CPU time at each, from the
parent and from every worker; this script times the command from outside (start to exit).
The runs alternate 1 and 2 workers for ``--rounds`` rounds; each stage is reported as its
range over the rounds, wall seconds with CPU seconds. The traced child imports the
generation module before the program's own start (to wrap it), which the program itself does
later: otherwise it runs what ``handsim generate`` runs.

Stages: the interpreter and imports (to the generation module imported); to the first frame
(one worker: config, manifest, numba's set-up, the hand, the scene, the OpenGL context) or to
the fork (two: the same up to numba's set-up and the imports the workers inherit) and each
worker's set-up to its first frame; the frames (first frame to last shard written, per
process); the end (last shard to the program's return: histogram, manifest, summary); the exit
(the program's return to the process's end: exit handlers, waiting for the workers, the
interpreter's teardown).

Run it as a timing measurement (``nice -n -10``, in its own session where Linux's autogroups
share the CPU between sessions), and report the load beside it.

Usage: ``python benchmarks/generate_timeline.py [--frames 600] [--rounds 3]``; writes
``benchmarks/results/generate_timeline.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_CHILD = r"""
import os, sys, time
T0, LOG = float(os.environ["TIMELINE_T0"]), os.environ["TIMELINE_LOG"]


def ev(label):
    with open(LOG, "a") as f:
        f.write(f"{os.getpid()} {time.time() - T0:.4f} {time.process_time():.4f} {label}\n")


ev("start")
import handsim.cli.main  # noqa: E402
import handsim.data.generation as g  # noqa: E402
import handsim.data.shards as shards  # noqa: E402

ev("imported")


def wrap(name):
    fn = getattr(g, name)

    def traced(*args, **kwargs):
        ev(name + ">")
        try:
            return fn(*args, **kwargs)
        finally:
            ev(name + "<")

    setattr(g, name, traced)


for name in ("generate", "_warm_up_for_fork", "generate_shard", "_histogram"):
    wrap(name)
append, seen = shards.ShardWriter.append, set()


def first_append(self, *args, **kwargs):
    out = append(self, *args, **kwargs)
    if os.getpid() not in seen:
        seen.add(os.getpid())
        ev("first-frame")
    return out


shards.ShardWriter.append = first_append
sys.argv = ["handsim", *sys.argv[1:]]
code = sys.modules["handsim.cli.main"].main()
ev("returned")
sys.exit(code)
"""


def _run(frames: int, workers: int, folder: Path) -> list[tuple[int, float, float, str]]:
    """Events ``(pid, wall s, cpu s, label)`` of one traced command; ``end`` is its exit."""
    log = folder / f"events-{workers}.log"
    log.unlink(missing_ok=True)
    out = folder / f"data-{workers}"
    shutil.rmtree(out, ignore_errors=True)  # a new job each time, not a resumed one
    command = [sys.executable, "-c", _CHILD, "generate", "--preset", "hand-only"]
    command += ["--frames", str(frames), "--workers", str(workers), "--seed", "0"]
    command += ["--out", str(out), "--quiet"]
    t0 = time.time()
    env = {**os.environ, "TIMELINE_T0": repr(t0), "TIMELINE_LOG": str(log)}
    env.setdefault("MUJOCO_GL", "egl")
    subprocess.run(command, check=True, env=env, capture_output=True)
    end = time.time() - t0
    events = []
    for line in log.read_text().splitlines():
        pid, wall, cpu, label = line.split(None, 3)
        events.append((int(pid), float(wall), float(cpu), label))
    return [*events, (0, end, float("nan"), "end")]


def _stages(events: list[tuple[int, float, float, str]]) -> dict[str, list[float]]:
    """Each stage's ``[wall s, cpu s]`` (per worker for the workers' stages)."""
    parent = events[0][0]

    def first(label, pid=parent):
        return next(e for e in events if e[0] == pid and e[3] == label)

    workers = sorted({e[0] for e in events} - {parent, 0})
    end = events[-1][1]
    returned = first("returned")
    stages = {"imports": [first("imported")[1], first("imported")[2]]}
    last_shard = [
        [e for e in events if e[0] == pid and e[3] == "generate_shard<"][-1]
        for pid in (workers or [parent])
    ]
    firsts = [first("first-frame", pid) for pid in (workers or [parent])]
    if workers:
        fork = first("_warm_up_for_fork<")
        stages["to the fork"] = [fork[1], fork[2]]
        starts = [first("generate_shard>", pid) for pid in workers]
        for k, (start, one) in enumerate(zip(starts, firsts, strict=True)):
            stages[f"worker {k} set-up"] = [one[1] - start[1], one[2] - start[2]]
    else:
        stages["to the first frame"] = [firsts[0][1], firsts[0][2]]
    for k, (one, last) in enumerate(zip(firsts, last_shard, strict=True)):
        name = f"worker {k} frames" if workers else "frames"
        stages[name] = [last[1] - one[1], last[2] - one[2]]
    done = max(e[1] for e in last_shard)
    # The parent's CPU from its first event after the last shard (its own, or the histogram's).
    after = next(e for e in events if e[0] == parent and e[1] >= done)
    stages["end"] = [returned[1] - done, returned[2] - after[2]]
    stages["exit"] = [end - returned[1], float("nan")]
    stages["whole command"] = [end, float("nan")]
    return stages


def main() -> None:
    """Run the rounds, print each stage's range and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=600, help="frames of the job")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds")
    args = parser.parse_args()
    results: dict = {"frames": args.frames, "rounds": args.rounds}
    results["load_average_1min_start"] = os.getloadavg()[0]
    runs: dict[int, list[dict[str, list[float]]]] = {1: [], 2: []}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.rounds):
            for workers in (1, 2):
                runs[workers].append(_stages(_run(args.frames, workers, Path(tmp))))
    for workers, stages in runs.items():
        print(f"{workers} worker(s), {args.frames} frames: wall s (CPU s), over the rounds")
        table = {}
        for name in stages[0]:
            wall = [s[name][0] for s in stages]
            cpu = [s[name][1] for s in stages]
            table[name] = {"wall_s": wall, "cpu_s": cpu}
            cpu_text = "" if cpu[0] != cpu[0] else f" ({min(cpu):.2f} to {max(cpu):.2f})"
            print(f"  {name:<22} {min(wall):.2f} to {max(wall):.2f}{cpu_text}")
        results[f"workers_{workers}"] = table
    results["load_average_1min_end"] = os.getloadavg()[0]
    start, end = results["load_average_1min_start"], results["load_average_1min_end"]
    print(f"load average {start:.1f} to {end:.1f}")
    out = Path(__file__).parent / "results" / "generate_timeline.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"written {out}")


if __name__ == "__main__":
    main()

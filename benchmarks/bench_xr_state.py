"""Benchmark: what streaming the simulation to the teleop page costs the loop.

Run: ``python benchmarks/bench_xr_state.py [--steps 300] [--out FILE.json]``.

For Grasp-v0 (mustard bottle) and Press-v0 (slider), one page subscribed over a real local
WebSocket (a ``websockets`` client that reads everything), the loop replaying the scripted
expert's stream of seed 0 unpaced (as fast as it steps):

- ``glb_kB``, ``export_ms``, ``bodies``: the scene's glb (:func:`handsim.world.gltf.export_glb`,
  best of 3) and the bodies whose poses stream;
- ``state_bytes``: one state message;
- ``steps_per_s_plain`` / ``steps_per_s_streaming``: the loop without a publisher and with one
  (interleaved, best of 2 each), and their ratio (1.0: free);
- ``states_per_s_at_page``: states the page received per second of the streaming run (the
  most the stream can give a page here; a headset needs its display rate, 72-120 Hz).

Results go to ``benchmarks/results/bench_xr_state.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import threading
import time
from pathlib import Path

import handsim.envs  # noqa: F401 (registers the ids)
from handsim.envs.teleop import TeleopLoop, WebSocketReceiver, stream_from_expert
from handsim.envs.teleop.xr_state import StatePublisher
from handsim.world.gltf import export_glb

TASKS = {
    "handsim/Grasp-v0": {"objects": ["006_mustard_bottle"]},
    "handsim/Press-v0": {"task": "slider"},
}


def _page(port: int, counts: dict[str, int], stop: threading.Event) -> None:
    from websockets.sync.client import connect

    with connect(f"ws://127.0.0.1:{port}", max_size=None) as ws:
        ws.send(json.dumps({"type": "subscribe"}))
        while not stop.is_set():
            try:
                message = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            if isinstance(message, str) and message.startswith('{"type":"state"'):
                counts["states"] += 1
                counts["state_bytes"] = len(message)


def bench(env_id: str, kwargs: dict, steps: int) -> dict:
    """Measure one task (see the module docstring)."""
    stream = stream_from_expert(env_id, 0, env_kwargs=kwargs)
    with WebSocketReceiver(0) as rx, TeleopLoop(env_id, env_kwargs=kwargs) as loop:
        loop.env.reset(seed=0)
        scene = loop.env.unwrapped.scene
        times = []
        for _ in range(3):
            t = time.perf_counter()
            glb = export_glb(scene.model)
            times.append(time.perf_counter() - t)
        plain, streaming, rates = [], [], []
        state_bytes = 0
        for _ in range(2):
            run = loop.run(stream, 0, max_steps=steps, stop_at_success=False)
            plain.append(run.metrics["steps_per_s"])
            counts, stop = {"states": 0, "state_bytes": 0}, threading.Event()
            with StatePublisher(rx, loop.env) as publisher:
                page = threading.Thread(target=_page, args=(rx.port, counts, stop))
                page.start()
                while publisher.counters["subscribers"] == 0:
                    time.sleep(0.01)
                # The first steps wait for the glb export (on the sender thread).
                loop.run(stream, 0, max_steps=20, on_step=publisher.on_step)
                while publisher.counters["scenes_sent"] == 0:
                    time.sleep(0.01)
                start, before = time.perf_counter(), counts["states"]
                run = loop.run(
                    stream, 0, max_steps=steps, stop_at_success=False, on_step=publisher.on_step
                )
                wall = time.perf_counter() - start
                time.sleep(0.2)
                stop.set()
                page.join()
            streaming.append(run.metrics["steps_per_s"])
            rates.append((counts["states"] - before) / wall)
            state_bytes = counts["state_bytes"]
    return {
        "glb_kB": round(len(glb.glb) / 1e3, 1),
        "export_ms": round(min(times) * 1e3, 1),
        "bodies": len(glb.body_ids),
        "state_bytes": state_bytes,
        "steps_per_s_plain": round(max(plain), 1),
        "steps_per_s_streaming": round(max(streaming), 1),
        "ratio_streaming_to_plain": round(max(streaming) / max(plain), 3),
        "states_per_s_at_page": round(max(rates), 1),
    }


def main() -> None:
    """Run the benchmark and write its JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--out", default="benchmarks/results/bench_xr_state.json")
    args = parser.parse_args()
    results = {"machine": platform.processor() or platform.machine(), "steps": args.steps}
    for env_id, kwargs in TASKS.items():
        results[env_id] = bench(env_id, kwargs, args.steps)
        print(env_id, json.dumps(results[env_id]))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

"""The simulation's state, streamed back to the teleop page over the loop's WebSocket.

A page (``handsim teleop serve``) that sends ``{"type": "subscribe"}`` on its WebSocket to
``handsim teleop live --websocket PORT`` receives, on that connection:

1. the scene: a text message ``{"type": "scene", "scene_id", "bodies": [names],
   "glb_bytes"}`` then one binary message, the scene's glTF
   (:func:`handsim.world.gltf.export_glb`: one node per body, named as in ``bodies``); sent
   again whenever the task's scene changes (a reset that draws other objects);
2. one text message per control step, the newest only (a slow page skips states, it never
   slows the loop)::

       {"type": "state", "scene_id", "step", "t_s", "seq", "success",
        "poses": [x, y, z, qw, qx, qy, qz, ...],   # per body of "bodies", MuJoCo world, m
        "tracked": [[x, y, z] | null] * 21,        # what the loop tracks (after faults and
                                                   #   filter), world frame, m: the ghost
        "offset_m": [dx, dy, dz],                  # world = tracked frame + offset (anchor)
        "tracked_hands": {"left": [...] * 21}}     # two hands only: the other hand's ghost

With two hands (:class:`~handsim.envs.teleop.two_hands.TwoHandTeleopLoop`) ``tracked`` is the
first hand's (the right) and ``tracked_hands`` holds the others by side; the glb and ``poses``
hold both physical hands (every body).

``seq`` is the sequence number of the packet the step used; ``offset_m`` is the translation the
loop's anchor added to the stream (zero without one), so a headset page places the world at
``xr = R_y_up (world - offset_m)`` and the physical hand lies over the operator's real hand.
Without a subscriber nothing is encoded.

Usage (what ``handsim teleop live --websocket`` does)::

    with WebSocketReceiver(8765) as rx, TeleopLoop("handsim/Grasp-v0") as loop:
        publisher = StatePublisher(rx, loop.env)
        loop.run(publisher.newest_keypoints, 0, realtime=True, on_step=publisher.on_step)
"""

from __future__ import annotations

import json
import math
import threading
from typing import Any

import numpy as np

from handsim.envs.teleop.live import WebSocketReceiver
from handsim.envs.teleop.streams import InvalidStream
from handsim.world.gltf import SceneGlb, body_poses, export_glb

__all__ = ["StatePublisher", "SUBSCRIBE"]

SUBSCRIBE = "subscribe"
"""The ``type`` of the control message a page sends to receive the state."""


class _Subscriber:
    __slots__ = ("connection", "scene_id", "state_id")

    def __init__(self, connection: Any) -> None:
        self.connection = connection
        self.scene_id = -1
        self.state_id = -1


class StatePublisher:
    """Streams a task env's scene and state to the WebSocket's subscribed pages.

    One background thread sends, so a page that reads slowly (or not at all) delays only
    itself; the loop calls :meth:`on_step`, which only encodes the state when a page is
    subscribed and returns at once.

    Args:
        receiver: the loop's :class:`~handsim.envs.teleop.live.WebSocketReceiver` (started or
            not); its connections may subscribe.
        env: the task env the loop steps (its ``unwrapped.scene`` is read).

    Raises:
        InvalidStream: ``receiver`` is not a WebSocket receiver.
    """

    def __init__(self, receiver: WebSocketReceiver, env: Any) -> None:
        if not isinstance(receiver, WebSocketReceiver):
            raise InvalidStream(
                "the state goes back over the page's WebSocket: receiver must be a "
                f"WebSocketReceiver; received {type(receiver).__name__}"
            )
        self.receiver = receiver
        self.env = env
        self.counters = {"subscribers": 0, "scenes_sent": 0, "states_sent": 0, "send_errors": 0}
        self._cond = threading.Condition()
        self._subscribers: list[_Subscriber] = []
        self._scene_key: tuple[int, int] | None = None
        self._scene_model: Any = None
        self._scene_id = 0
        self._export: SceneGlb | None = None
        self._export_id = 0
        self.export_error: str | None = None
        """Why the scene could not be exported (``None``: it could, or was not asked)."""
        self._state: str | None = None
        self._state_id = 0
        self._seq = -1
        self._closed = False
        receiver.set_control_handler(self._on_control)
        self._thread = threading.Thread(target=self._run, name="handsim-state", daemon=True)
        self._thread.start()

    # -- the loop's side -------------------------------------------------------------------

    def newest_keypoints(self, _step: int) -> np.ndarray | None:
        """The stream function of a live loop: the newest packet's keypoints (world, m)."""
        frame = self.receiver.latest()
        if frame is None:
            return None
        self._seq = frame.seq
        return frame.keypoints_world

    def on_step(self, step: int, record: dict[str, Any]) -> None:
        """The loop's per-step callback: note the scene and encode the state for the pages."""
        with self._cond:
            if not self._subscribers:
                return
        scene = self.env.unwrapped.scene
        key = (id(scene.model), int(getattr(scene, "hand_geometry_version", 0)))
        with self._cond:
            if key != self._scene_key:
                self._scene_key, self._scene_model = key, scene.model
                self._scene_id += 1
            export = self._export if self._export_id == self._scene_id else None
            if export is None:
                # The export runs on the sender thread; until it is done there is no state.
                self._cond.notify_all()
                return
        data = scene.data
        tracked = record.get("tracked_world")
        offset = np.asarray(record.get("anchor_offset_m", np.zeros(3)), dtype=np.float64)
        newest = self.receiver.latest()  # also when a LiveSampler, not newest_keypoints, reads
        if newest is not None:
            self._seq = max(self._seq, newest.seq)
        doc = {
            "type": "state",
            "scene_id": self._scene_id,
            "step": int(step),
            "t_s": round(float(data.time), 6),
            "seq": int(self._seq),
            "success": bool(record.get("success", False)),
            "poses": np.round(body_poses(data, export.body_ids), 5).ravel().tolist(),
            "tracked": _rows(tracked),
            "offset_m": np.round(offset, 5).tolist(),
        }
        hands = record.get("hands") or {}
        if len(hands) > 1:  # the first hand is "tracked"; the page draws a ghost per hand
            doc["tracked_hands"] = {
                side: _rows(h.get("tracked_world")) for side, h in list(hands.items())[1:]
            }
        message = json.dumps(doc, separators=(",", ":"))
        with self._cond:
            self._state, self._state_id = message, self._state_id + 1
            self._cond.notify_all()

    # -- the WebSocket's side --------------------------------------------------------------

    def _on_control(self, connection: Any, doc: dict[str, Any]) -> None:
        if doc.get("type") != SUBSCRIBE:
            return
        with self._cond:
            if self._closed:
                return
            self._subscribers.append(_Subscriber(connection))
            self.counters["subscribers"] += 1
            self._cond.notify_all()

    def _pending(self) -> bool:
        if self._closed:
            return True
        if self._scene_model is not None and self._export_id != self._scene_id:
            return True
        return any(
            s.scene_id != self._scene_id or s.state_id != self._state_id for s in self._subscribers
        )

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(self._pending)
                if self._closed:
                    return
                subscribers = list(self._subscribers)
                model, scene_id = self._scene_model, self._scene_id
                state, state_id = self._state, self._state_id
            if model is not None and self._export_id != scene_id:
                try:
                    export = export_glb(model)
                except Exception as err:  # noqa: BLE001 (the loop runs on without a page view)
                    self.export_error = f"{type(err).__name__}: {err}"
                    export = None
                with self._cond:
                    self._export, self._export_id = export, scene_id
                continue
            export = self._export
            for sub in subscribers:
                try:
                    if export is not None and sub.scene_id != scene_id:
                        header = {
                            "type": "scene",
                            "scene_id": scene_id,
                            "bodies": list(export.body_names),
                            "glb_bytes": len(export.glb),
                        }
                        sub.connection.send(json.dumps(header))
                        sub.connection.send(export.glb)
                        sub.scene_id = scene_id
                        self.counters["scenes_sent"] += 1
                    if state is not None and sub.state_id != state_id and sub.scene_id == scene_id:
                        sub.connection.send(state)
                        self.counters["states_sent"] += 1
                    sub.state_id = state_id
                except Exception:  # noqa: BLE001 (a closed page must not stop the others)
                    self.counters["send_errors"] += 1
                    with self._cond:
                        if sub in self._subscribers:
                            self._subscribers.remove(sub)
                    continue
                if export is None:
                    sub.scene_id = scene_id  # nothing to send for this scene

    def close(self) -> None:
        """Stop the sender thread (the receiver's connections stay the receiver's)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout=2.0)
        self.receiver.set_control_handler(None)

    def __enter__(self) -> StatePublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _rows(points: Any) -> list[list[float] | None]:
    if points is None:
        return [None] * 21
    return [
        [round(float(v), 5) for v in p] if all(math.isfinite(v) for v in p) else None
        for p in np.asarray(points, dtype=np.float64)
    ]

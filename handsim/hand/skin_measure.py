"""Measuring the skin against the skeleton: gap to the collision, joint creases, digit volumes.

Each function takes a posed hand (a binding and its data); :mod:`handsim.hand.skin` builds the skin.
"""

from __future__ import annotations

import numpy as np

from handsim.hand.skin import Sdf, SkinPart, _sd_capsule, build_skin

__all__ = ["collision_gap_m", "joint_crease_depth_m", "digit_volume_m3"]

_BURIED_M = 2e-4  # skin this far inside another part's is buried in a joint


def _world_from_body(binding, data) -> list[tuple[np.ndarray, np.ndarray]]:
    """(R, t) of every skeleton body in the world (``p_world = R p_body + t``)."""
    out = []
    for b in binding.hand.skeleton.bodies:
        body = binding.model.body(binding.hand.prefix + b.name).id
        out.append((data.xmat[body].reshape(3, 3).copy(), data.xpos[body].copy()))
    return out


def _collision_sdf(binding, data, forearm: bool = True) -> Sdf:
    """Signed distance (world, metres) to the union of the hand's collision primitives."""
    frames = _world_from_body(binding, data)
    bodies = binding.hand.skeleton.bodies

    def sdf(p: np.ndarray) -> np.ndarray:
        d = np.full(len(p), np.inf)
        for (rot, t), body in zip(frames, bodies, strict=True):
            local = (p - t) @ rot
            for g in body.geoms:
                if not forearm and body.part == "palm" and hasattr(g, "radius") and g.start[1] < 0:
                    continue
                if hasattr(g, "radius"):
                    gd = _sd_capsule(local, g.start, g.end, g.radius)
                else:
                    q = np.abs(local - g.pos) - g.half_size
                    gd = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0)
                np.minimum(d, gd, out=d)
        return d

    return sdf


def _vertex_normals(part: SkinPart) -> np.ndarray:
    tri = part.vertices[part.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals = np.zeros_like(part.vertices)
    for k in range(3):
        np.add.at(normals, part.faces[:, k], n)
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)


def collision_gap_m(binding, data, parts: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """Distance from the skin to the collision surface where the hand touches things.

    Args:
        binding: the hand's binding in a compiled model (:meth:`Hand.bind`).
        data: its data after ``mj_forward`` (the pose to measure).
        parts: measure only the skin of these hand parts (``"palm"``, ``"thumb"``, ...,
            ``"little"``); default all.

    Returns:
        ``{"pads": ..., "palm": ...}``: (N,) absolute distances, metres, from each skin vertex
        on the palmar side (body-frame normal ``z > 0.5``) of the phalanges, and of the palm
        between the wrist crease and the knuckles, to the union of the collision primitives.
        Vertices more than 0.2 mm inside another part's skin (buried in a joint) are left out,
        and the forearm's collision capsules are not counted: the forearm is no contact
        surface, and for thick hands its capsules stand out of the wrist, where the skin does
        not follow them.
    """
    hand = binding.hand
    parts_wanted = parts
    sdf = _collision_sdf(binding, data, forearm=False)
    frames = _world_from_body(binding, data)
    y_knuckles = max(b.pos[1] for b in hand.skeleton.bodies if b.name.endswith("_proximal"))
    out: dict[str, list[np.ndarray]] = {"pads": [], "palm": []}
    parts = build_skin(hand.params)
    for part in parts:
        if parts_wanted is not None and hand.skeleton.bodies[part.body].part not in parts_wanted:
            continue
        palmar = _vertex_normals(part)[:, 2] > 0.5
        if part.body == 0:
            y = part.vertices[:, 1]
            palmar &= (y >= 0.0) & (y <= y_knuckles)
        rot, t = frames[part.body]
        world = part.vertices[palmar] @ rot.T + t
        # Only the outer surface: skin buried inside another part is never seen nor touched.
        buried = np.zeros(len(world), dtype=bool)
        for other in parts:
            if other.body != part.body:
                orot, ot = frames[other.body]
                buried |= other.sdf((world - ot) @ orot) < -_BURIED_M
        out["palm" if part.body == 0 else "pads"].append(np.abs(sdf(world[~buried])))
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in out.items()}


def joint_crease_depth_m(binding, data, samples: int = 400) -> np.ndarray:
    """How far each joint's distal segment sticks out of its parent's skin, metres.

    The base of a segment is the spheroid its round cone starts with (the joint's envelope).
    Where the parent's skin holds all of it, the joint shows neither a gap nor a step for this
    pose; a point of the envelope outside the parent's skin at depth ``d`` opens a notch about
    ``d`` deep between the two segments (a gap if the parts separate).

    Args:
        binding: the hand's binding in a compiled model.
        data: its data after ``mj_forward``.
        samples: points on each envelope (a Fibonacci sphere).

    Returns:
        (B - 1,) depth per non-palm body in skeleton order, metres (0 = fully held).
    """
    hand = binding.hand
    parts = build_skin(hand.params)
    frames = _world_from_body(binding, data)
    k = np.arange(samples) + 0.5
    polar = np.arccos(1.0 - 2.0 * k / samples)
    azimuth = np.pi * (1.0 + 5.0**0.5) * k
    unit = np.stack(
        [np.sin(polar) * np.cos(azimuth), np.cos(polar), np.sin(polar) * np.sin(azimuth)], 1
    )
    depth = []
    for part in parts[1:]:
        body = hand.skeleton.bodies[part.body]
        base = part.vertices[part.vertices[:, 1] <= 0.0]
        # Half axes of the base spheroid from the proximal cap's vertices.
        half = np.array([np.abs(base[:, 0]).max(), np.abs(base[:, 1]).max(), 0.0])
        half[2] = np.abs(base[:, 2]).max()
        envelope = unit * half
        rot, t = frames[part.body]
        prot, pt = frames[body.parent]
        world = envelope @ rot.T + t
        d = parts[body.parent].sdf((world - pt) @ prot)
        depth.append(max(float(d.max()), 0.0))
    return np.array(depth)


def digit_volume_m3(binding, data, digit: str, samples: int = 200_000, seed: int = 0) -> float:
    """Volume of the union of one digit's skin segments (Monte Carlo, seeded), cubic metres.

    Args:
        binding: the hand's binding in a compiled model.
        data: its data after ``mj_forward``.
        digit: ``"thumb"``, ``"index"``, ``"middle"``, ``"ring"`` or ``"little"``.
        samples: uniform samples in the digit's bounding box (relative error about
            ``1 / sqrt(samples)``).
        seed: sampling seed.
    """
    hand = binding.hand
    parts = [p for p in build_skin(hand.params) if hand.skeleton.bodies[p.body].part == digit]
    frames = _world_from_body(binding, data)
    posed = [p.vertices @ frames[p.body][0].T + frames[p.body][1] for p in parts]
    lo = np.min([v.min(axis=0) for v in posed], axis=0)
    hi = np.max([v.max(axis=0) for v in posed], axis=0)
    points = np.random.default_rng(seed).uniform(lo, hi, (samples, 3))
    inside = np.zeros(samples, dtype=bool)
    for part in parts:
        rot, t = frames[part.body]
        inside |= part.sdf((points - t) @ rot) < 0.0
    return float(inside.mean() * np.prod(hi - lo))

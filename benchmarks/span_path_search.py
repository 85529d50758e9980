"""How the wide box's span path was chosen (``_span_path`` in handsim.envs.grasping.planning).

For each hand length, at the closure where the thumb tip and the middle and ring pads span a
0.164 m wide box (as the planner picks it), the hand is placed as the planner places it (pads
level, ``depth`` under the top, the best of its rolls) and every capsule's distance to the box
is measured: the distal segments may touch the walls but nothing may reach over a top edge,
every other segment should stay 3 mm off. The cost sums the squared shortfalls over
0.165-0.22 m hands.

    python benchmarks/span_path_search.py            # the shipped path, per hand length
    python benchmarks/span_path_search.py --search   # Powell search from a start (~3 min)
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from handsim.envs.grasping.planning import _CLOSURES, _hand_geometry, _span_path, _wide_open
from handsim.hand import JOINT_LIMITS, JOINT_NAMES
from handsim.hand.model import hand_params
from handsim.hand.pose import HandPose

J = {n: i for i, n in enumerate(JOINT_NAMES)}
WIDTH_M, LENGTH_M, HEIGHT_M = 0.164, 0.215, 0.072
FINGERS = ("index", "middle", "ring", "little")
SPAN_FINGERS = ("middle", "ring")
THUMB_FRACTION, FINGER_FRACTION = 1.0, 0.75
SIZES_M = (0.165, 0.18, 0.189, 0.2, 0.21, 0.22)
ROLLS_DEG = (0.0, 10.0, -10.0, 20.0, -20.0, 30.0, -30.0)


def box_distance(p: np.ndarray) -> np.ndarray:
    """Signed distance to the box (top face at z = 0), metres."""
    half = np.array([WIDTH_M, LENGTH_M, HEIGHT_M]) / 2
    q = np.abs(p - np.array([0.0, 0.0, -HEIGHT_M / 2])) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def path_from(p: np.ndarray) -> np.ndarray:
    """A span path from its angles, degrees.

    ``p``: the middle and ring fingers' MCP, PIP and DIP at closure 0 and their change per
    closure (interleaved), the thumb IP at closure 0 and per closure, and the offsets of the
    index and little fingers (which stay at closure 0); the thumb's CMC and MCP at their widest.
    """
    a = _wide_open()
    for name, deg in (
        ("thumb_cmc_flex", -40),
        ("thumb_cmc_abd", 60),
        ("thumb_mcp_flex", -10),
        ("thumb_mcp_abd", 10),
    ):
        a[J[name]] = np.deg2rad(deg)
    path = np.repeat(a[None], len(_CLOSURES), 0)
    c = _CLOSURES
    for f in FINGERS:
        short = f in ("index", "little")
        offset = (p[8], p[9], p[10]) if short else (0.0, 0.0, 0.0)
        for j, (start, delta) in enumerate(((p[0], p[1]), (p[2], p[3]), (p[4], p[5]))):
            joint = ("mcp_flex", "pip_flex", "dip_flex")[j]
            path[:, J[f"{f}_{joint}"]] = np.deg2rad(start + offset[j] + c * delta * (not short))
    path[:, J["thumb_ip_flex"]] = np.deg2rad(p[6] + c * p[7])
    return np.clip(path, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])


def evaluate(path: np.ndarray, length_m: float, depth_m: float, verbose: bool = False) -> float:
    """The squared shortfalls of one hand length (1 if its pads never span the box)."""
    g = _hand_geometry(hand_params(length_m, "right"))
    capsules = [
        (i, geom.start, geom.end, geom.radius, body.name)
        for i, body in enumerate(g.fk.skeleton.bodies)
        for geom in body.geoms
        if type(geom).__name__ == "Capsule"
    ]
    n = len(path)
    rots, poss = g.fk.body_frames(HandPose(np.zeros((n, 3)), np.zeros((n, 3)), path))

    def point(body: int, local: np.ndarray) -> np.ndarray:
        return poss[:, body] + np.einsum("kij,j->ki", rots[:, body], local)

    pads = {}
    for d in ("thumb", *FINGERS):
        f = THUMB_FRACTION if d == "thumb" else FINGER_FRACTION
        pads[d] = point(g.distal_body[d], (1 - f) * g.distal_start[d] + f * g.distal_end[d])
    finger = np.mean([pads[f] for f in SPAN_FINGERS], axis=0)
    v = finger - pads["thumb"]
    radii = g.distal_radius["thumb"] + np.mean([g.distal_radius[f] for f in SPAN_FINGERS])
    gap = np.linalg.norm(v, axis=1) - radii
    if gap.max() < WIDTH_M + 0.004:
        if verbose:
            print(f"{length_m:.3f} m: the pads never span the box")
        return 1.0
    k = min(int(np.argmin(np.abs(gap - (WIDTH_M + 0.004)))) + 3, n - 1)
    t = np.linspace(0.0, 1.0, 9)[:, None]
    best = None
    for roll in ROLLS_DEG:
        R, _ = Rotation.align_vectors(
            [[1, 0, 0], [0, 0, -1]], [v[k] / np.linalg.norm(v[k]), [0, 0, 1]], weights=[1e4, 1]
        )
        R = Rotation.from_rotvec(np.deg2rad(roll) * np.array([1.0, 0.0, 0.0])) * R
        mid = 0.5 * (pads["thumb"][k] + finger[k])
        shift = np.array([0.0, 0.0, -depth_m])
        cost, worst = 0.0, {}
        for body, start, end, radius, name in capsules:
            a = R.apply(point(body, start)[k] - mid) + shift
            b = R.apply(point(body, end)[k] - mid) + shift
            samples = a + t * (b - a)
            clear = box_distance(samples) - radius
            if name.endswith("_distal"):
                high = samples[:, 2] > -0.005
                margin = min(np.min(np.where(high, clear, 1.0)), clear.min() + 0.0015)
                need = 0.0
            else:
                margin, need = clear.min(), 0.003
            worst[name] = margin
            cost += max(0.0, need - margin) ** 2
        if best is None or cost < best[0]:
            best = (cost, roll, worst)
    if verbose:
        tight = sorted(best[2].items(), key=lambda item: item[1])[:3]
        print(
            f"{length_m:.3f} m: closure {_CLOSURES[k]:.2f}, roll {best[1]:+.0f} deg, closest: "
            + ", ".join(f"{name} {1000 * m:+.1f} mm" for name, m in tight)
        )
    return best[0]


def total(p: np.ndarray, depth_m: float) -> float:
    """The cost of a path's angles over every hand length."""
    path = path_from(p)
    return sum(evaluate(path, length, depth_m) for length in SIZES_M)


def main() -> None:
    """Print the shipped (or a searched) path's closest segments per hand length."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--search", action="store_true", help="search the path's angles")
    parser.add_argument("--depth-m", type=float, default=0.010, help="pads under the top")
    args = parser.parse_args()
    if args.search:
        start = np.array([-20, 40, 20, 70, 40, 40, 30, 50.0, 0, -20, -20])
        result = minimize(
            total,
            start,
            args=(args.depth_m,),
            method="Powell",
            options={"maxiter": 3000, "xtol": 0.5, "ftol": 1e-9},
        )
        print("angles (deg):", np.round(result.x, 1).tolist(), "cost", result.fun)
        path = path_from(result.x)
    else:
        path = _span_path()
    for length in SIZES_M:
        evaluate(path, length, args.depth_m, verbose=True)


if __name__ == "__main__":
    main()

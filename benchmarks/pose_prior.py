"""Accuracy of the maximum a posteriori retargeting (the pose prior) against least squares.

Run: ``python benchmarks/pose_prior.py [--poses 100] [--out FILE]``.

Keypoints of the medium right hand (random wrist position within 10 cm and rotation, 0.5 rad
std per axis) with Gaussian noise of 0, 5 and 10 mm per axis are retargeted, warm-started from
the true pose, by :class:`~handsim.hand.retarget.Retargeter` without and with
:func:`~handsim.hand.pose_prior.default_pose_prior` (``keypoint_sigma_m`` = the noise; at 0 mm
the prior is weighed as for 10 mm, the cost of a prior when the keypoints are exact). Poses:

- ``held_out_grasps``: :func:`~handsim.hand.pose_sources.sample_grasp`, uniform closures in
  [0, 1] and 3 deg of angle noise: off the corpus's grid of closures;
- ``left_out_type``: per grasp type, the prior refitted without that type and its poses
  (as above) retargeted: a grasp the prior has never seen;
- ``uniform``: :func:`~handsim.hand.pose_sources.sample_uniform` (coupled): postures far from
  any grasp or gesture.

Prints and writes (``benchmarks/results/pose_prior.json``) the mean absolute angle error
(deg), and the frame-to-frame flexion jitter: the std of the fitted flexion angles over 50
noisy fits of one held pose (the grasp types' poses at closure 0.6, warm-started from the
previous fit, as in a stream), rad, with the median time per fit, ms.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np

from handsim.hand.kinematics import ForwardKinematics
from handsim.hand.model import HandParams
from handsim.hand.pose import JOINT_NAMES, HandPose
from handsim.hand.pose_library import GESTURES, GRASP_TYPES
from handsim.hand.pose_prior import PosePrior, default_pose_prior
from handsim.hand.pose_sources import sample_grasp, sample_uniform
from handsim.hand.retarget import Retargeter

_FLEX = np.array([n.endswith("_flex") for n in JOINT_NAMES])
_NOISE_MM = (0.0, 5.0, 10.0)


def _angle_error_deg(
    retarget: Retargeter, fk: ForwardKinematics, angles: np.ndarray, noise_m: float, rng
) -> float:
    errors = []
    for a in angles:
        pose = HandPose(rng.normal(0, 0.1, 3), rng.normal(0, 0.5, 3), a)
        kp = fk.keypoints(pose) + rng.normal(0.0, noise_m, (21, 3))
        fit = retarget(kp, initial=pose, check_side=False, report_clamped=False)
        errors.append(np.degrees(np.abs(fit.pose.angles - a)).mean())
    return float(np.mean(errors))


def _fitters(params: HandParams, prior: PosePrior, noise_mm: float) -> dict[str, Retargeter]:
    sigma_m = 1e-3 * (noise_mm if noise_mm > 0 else 10.0)
    return {
        "least_squares": Retargeter(params),
        "prior": Retargeter(params, pose_prior=prior, keypoint_sigma_m=sigma_m),
    }


def run(n_poses: int) -> dict:
    """All figures of the module docstring."""
    params = HandParams()
    fk = ForwardKinematics(params)
    prior = default_pose_prior()
    out: dict = {"poses": n_poses, "prior_source": prior.source}
    start = time.perf_counter()
    held = sample_grasp(np.random.default_rng(0), n_poses, closure_range=(0.0, 1.0))[0].angles
    uniform = sample_uniform(np.random.default_rng(1), n_poses).angles
    for name, angles in (("held_out_grasps", held), ("uniform", uniform)):
        for noise_mm in _NOISE_MM:
            for fitter, retarget in _fitters(params, prior, noise_mm).items():
                rng = np.random.default_rng(2)  # the same noise for both fitters
                out[f"{name}_{noise_mm:g}mm_{fitter}_angle_error_deg"] = round(
                    _angle_error_deg(retarget, fk, angles, 1e-3 * noise_mm, rng), 2
                )
    # A grasp type the prior has never seen (gestures kept).
    gestures = np.stack([g.angles for g in GESTURES.values()])
    closures = np.linspace(0.0, 1.0, 11)
    per_type = {"least_squares": [], "prior": []}
    for left_out in GRASP_TYPES:
        others = [g.angles(closures) for k, g in GRASP_TYPES.items() if k != left_out]
        loo = PosePrior.from_angles(np.concatenate(others + [gestures]))
        rng = np.random.default_rng(3)
        angles = sample_grasp(rng, max(4, n_poses // 10), names=[left_out], closure_range=(0, 1))
        for fitter, retarget in _fitters(params, loo, 10.0).items():
            err = _angle_error_deg(retarget, fk, angles[0].angles, 0.01, np.random.default_rng(4))
            per_type[fitter].append(err)
    for fitter, errors in per_type.items():
        out[f"left_out_type_10mm_{fitter}_angle_error_deg"] = round(float(np.mean(errors)), 2)
        out[f"left_out_type_10mm_{fitter}_worst_type_deg"] = round(float(np.max(errors)), 2)
    # Frame-to-frame jitter of the flexion joints on a held pose (a stream, warm-started).
    for fitter, retarget in _fitters(params, prior, 10.0).items():
        stds, times = [], []
        for grasp in GRASP_TYPES.values():
            pose = HandPose(np.zeros(3), np.zeros(3), grasp.angles(0.6))
            rng = np.random.default_rng(5)
            previous, scale, fits = pose, None, []
            for _ in range(50):
                kp = fk.keypoints(pose) + rng.normal(0.0, 0.01, (21, 3))
                tick = time.perf_counter()
                fit = retarget(
                    kp, previous, initial_scale=scale, check_side=False, report_clamped=False
                )
                times.append(time.perf_counter() - tick)
                previous, scale = fit.pose, fit.scale
                fits.append(fit.pose.angles)
            stds.append(np.std(fits, axis=0)[_FLEX].mean())
        out[f"jitter_10mm_{fitter}_flexion_std_rad"] = round(float(np.mean(stds)), 3)
        out[f"warm_10mm_{fitter}_ms_per_fit_median"] = round(1e3 * float(np.median(times)), 2)
    out["wall_s"] = round(time.perf_counter() - start, 1)
    return out


def main() -> None:
    """Parse, run, print and write the figures."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--poses", type=int, default=100)
    p.add_argument("--out", default="benchmarks/results/pose_prior.json")
    args = p.parse_args()
    result = run(args.poses)
    print(json.dumps(result, indent=1))
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()

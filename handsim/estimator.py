"""The estimator protocol: what every hand / hand-object pose estimator returns and accepts.

This module is the contract between the layers (docs/architecture.md): envs run any object that
satisfies :class:`Estimator`, and estimators (``handsim.estimators``) implement it; neither
imports the other. It imports neither torch nor the envs nor the estimators.

- :class:`Estimate`: one frame's output, in the OpenCV camera frame, metres.
- :class:`Estimator`: ``predict(depth, K) -> Estimate``, a batched ``predict_batch`` and
  ``reset()`` (called at every episode start).
- :class:`PrivilegedEstimator`: an :class:`Estimator` that also reads the ground truth
  (``observe_truth(frame)``); only oracles implement it.
- :func:`hand_center`: THE hand centre used by estimates, estimators and errors.
- :func:`estimate_errors`: per-frame errors of an estimate against a
  :class:`~handsim.frame.record.Frame`.
- :class:`EstimatorBase`, :func:`validate_depth_input`, :func:`validate_batch_input`: helpers
  for implementations.

Hand centre: the mean of the wrist and the four finger MCPs (keypoints 0, 5, 9, 13, 17 of
:data:`~handsim.hand.keypoints.KEYPOINT_NAMES`). These five joints are rigid on the palm, so the
centre does not move when the fingers or the thumb flex; it lies inside the palm, about 0.35
hand lengths from the wrist towards the fingers.
"""

from __future__ import annotations

import dataclasses
import math
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from handsim._validate import show, to_real_array
from handsim.errors import (
    InvalidEstimate,
    InvalidEstimatorInput,
    InvalidKeypoints,
    UnknownName,
)
from handsim.hand.keypoints import KEYPOINT_NAMES
from handsim.metrics import MM_PER_M
from handsim.world.objects import YCBObject
from handsim.world.registry import get_object

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

    from handsim.frame import Frame

__all__ = [
    "HAND_CENTER_INDICES",
    "N_KEYPOINTS",
    "Estimate",
    "Estimator",
    "PrivilegedEstimator",
    "EstimatorBase",
    "hand_center",
    "estimate_errors",
    "describe_estimator",
    "validate_depth_input",
    "validate_batch_input",
]

N_KEYPOINTS = len(KEYPOINT_NAMES)
"""Number of hand keypoints of an estimate (21)."""

HAND_CENTER_INDICES: tuple[int, ...] = (0, 5, 9, 13, 17)
"""Keypoints averaged by :func:`hand_center`: the wrist and the index, middle, ring and little
MCPs."""

# A rotation block counts as a rotation when R^T R is within this of I (float32 network outputs
# are ~1e-7 off; a scaled or sheared matrix is far off).
_ROTATION_ATOL = 1e-3


def hand_center(keypoints_cam: Any) -> np.ndarray:
    """The hand centre: the mean of the wrist and the four finger MCPs.

    Args:
        keypoints_cam: (..., 21, 3) keypoints in the canonical order, metres, any frame.

    Returns:
        (..., 3) float64 centre, same frame and units.

    Raises:
        InvalidKeypoints: if the last two axes are not (21, 3).
    """
    try:
        kp = to_real_array(keypoints_cam)
    except ValueError as err:
        raise InvalidKeypoints(
            f"hand_center expects (..., {N_KEYPOINTS}, 3) keypoints in metres; received "
            f"{show(keypoints_cam)}: {err}"
        ) from None
    if kp.ndim < 2 or kp.shape[-2:] != (N_KEYPOINTS, 3):
        raise InvalidKeypoints(
            f"hand_center expects (..., {N_KEYPOINTS}, 3) keypoints in metres; received shape "
            f"{kp.shape}"
        )
    centre = kp[..., HAND_CENTER_INDICES, :]
    if not np.all(np.isfinite(centre)):
        raise InvalidKeypoints(
            "hand_center needs finite wrist and finger MCP keypoints (indices "
            f"{list(HAND_CENTER_INDICES)}); received NaN or inf among them"
        )
    return centre.mean(axis=-2)


def _read_only_array(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = to_real_array(value).copy()
    except (TypeError, ValueError) as err:
        raise InvalidEstimate(
            f"{name} must be a {shape} array of numbers; received {type(value).__name__} ({err})"
        ) from None
    if arr.shape != shape:
        raise InvalidEstimate(f"{name} must have shape {shape}; received shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise InvalidEstimate(
            f"{name} must be finite; received {arr[bad]} at index {bad} (return "
            "Estimate(valid=False) when there is no estimate)"
        )
    arr.setflags(write=False)
    return arr


def _check_pose(name: str, value: Any) -> np.ndarray:
    T = _read_only_array(name, value, (4, 4))  # noqa: N806 (the standard name of a transform)
    if not np.allclose(T[3], (0.0, 0.0, 0.0, 1.0), atol=1e-9):
        raise InvalidEstimate(f"{name} must have the last row (0, 0, 0, 1); received {T[3]}")
    R = T[:3, :3]  # noqa: N806
    if not np.allclose(R.T @ R, np.eye(3), atol=_ROTATION_ATOL) or np.linalg.det(R) <= 0:
        raise InvalidEstimate(
            f"{name}[:3, :3] must be a rotation (R^T R = I within {_ROTATION_ATOL}, det = +1); "
            f"received det {np.linalg.det(R):.6g}, max |R^T R - I| "
            f"{np.abs(R.T @ R - np.eye(3)).max():.3g}"
        )
    return T


@dataclasses.dataclass(frozen=True, eq=False)
class Estimate:
    """One frame's estimate, in the OpenCV camera frame (x right, y down, z forward), metres.

    Arrays are stored as read-only float64 copies. ``center_cam`` defaults to
    :func:`hand_center` of ``keypoints_cam`` when keypoints are given and the centre is not.

    Attributes:
        keypoints_cam: (21, 3) hand keypoints, metres, camera frame, in the order of
            :data:`~handsim.hand.keypoints.KEYPOINT_NAMES`; ``None`` if the estimator gives none
            (a hand localizer, an object-only estimator).
        center_cam: (3,) hand centre (:func:`hand_center`), metres, camera frame; ``None``
            if not estimated.
        object_poses: object instance index (as in :attr:`handsim.frame.record.Frame.objects`) ->
            (4, 4) ``T_cam_from_obj``, metres; empty if no object is estimated.
        confidence: (21,) per-keypoint confidence in ``[0, 1]``, or ``None``; needs
            ``keypoints_cam``.
        valid: ``False`` when the estimator produced nothing this frame (dropout, no hand
            found); an invalid estimate carries no keypoints, centre, poses or confidence, and
            a valid one carries at least one of keypoints, centre or object poses.

    Raises:
        InvalidEstimate: on a wrong shape, a non-finite value, a confidence outside [0, 1], a
            pose that is not rigid, or fields that contradict ``valid``.
    """

    keypoints_cam: np.ndarray | None = None
    center_cam: np.ndarray | None = None
    object_poses: dict[int, np.ndarray] = dataclasses.field(default_factory=dict)
    confidence: np.ndarray | None = None
    valid: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.valid, bool | np.bool_):
            raise InvalidEstimate(f"valid must be a bool; received {self.valid!r}")
        set_ = object.__setattr__  # the dataclass is frozen; fields are normalized once here
        set_(self, "valid", bool(self.valid))
        if not isinstance(self.object_poses, Mapping):
            raise InvalidEstimate(
                "object_poses must be a dict {instance index: (4, 4) T_cam_from_obj}; received "
                f"{type(self.object_poses).__name__}"
            )
        if not self.valid:
            given = [
                name
                for name in ("keypoints_cam", "center_cam", "confidence")
                if getattr(self, name) is not None
            ] + (["object_poses"] if self.object_poses else [])
            if given:
                raise InvalidEstimate(
                    f"an invalid estimate (valid=False) carries nothing; received {given} "
                    "(drop them, or set valid=True)"
                )
            set_(self, "object_poses", {})
            return
        if self.keypoints_cam is not None:
            kp = _read_only_array("keypoints_cam", self.keypoints_cam, (N_KEYPOINTS, 3))
            set_(self, "keypoints_cam", kp)
        if self.center_cam is not None:
            set_(self, "center_cam", _read_only_array("center_cam", self.center_cam, (3,)))
        elif self.keypoints_cam is not None:
            center = hand_center(self.keypoints_cam)
            center.setflags(write=False)
            set_(self, "center_cam", center)
        poses = {}
        for key, pose in self.object_poses.items():
            if isinstance(key, bool) or not isinstance(key, int | np.integer) or key < 0:
                raise InvalidEstimate(
                    f"object_poses keys must be object instance indices (ints >= 0); received "
                    f"{key!r}"
                )
            poses[int(key)] = _check_pose(f"object_poses[{int(key)}]", pose)
        set_(self, "object_poses", poses)
        if self.confidence is not None:
            if self.keypoints_cam is None:
                raise InvalidEstimate(
                    "confidence is per keypoint and needs keypoints_cam; received confidence "
                    "without keypoints"
                )
            conf = _read_only_array("confidence", self.confidence, (N_KEYPOINTS,))
            if np.any((conf < 0) | (conf > 1)):
                raise InvalidEstimate(
                    f"confidence must lie in [0, 1]; received min {conf.min()}, max {conf.max()}"
                )
            set_(self, "confidence", conf)
        if self.keypoints_cam is None and self.center_cam is None and not self.object_poses:
            raise InvalidEstimate(
                "a valid estimate needs keypoints_cam, center_cam or object_poses; received "
                "none (use Estimate(valid=False) for 'no estimate this frame')"
            )


@runtime_checkable
class Estimator(Protocol):
    """What an env accepts as a pose estimator (structural: no base class needed).

    ``isinstance(x, Estimator)`` checks only that the three methods exist.
    """

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """Estimate the hand (and objects) in one depth image.

        Args:
            depth: (H, W) float32 depth along the optical axis, metres, 0 = no measurement.
            K: (3, 3) intrinsic matrix of the OpenCV pinhole camera.

        Returns:
            The estimate, in the camera frame of ``depth``; ``Estimate(valid=False)`` when the
            estimator has nothing this frame.
        """
        ...

    def predict_batch(self, depths: np.ndarray, Ks: np.ndarray) -> list[Estimate]:  # noqa: N803
        """Estimate a batch of independent frames.

        Args:
            depths: (B, H, W) float32 depth images, metres, 0 = no measurement.
            Ks: (B, 3, 3) intrinsic matrices, one per image.

        Returns:
            B estimates, in the order of the batch.
        """
        ...

    def reset(self) -> None:
        """Forget any state (tracking history, latency buffers); called at every episode start."""
        ...


@runtime_checkable
class PrivilegedEstimator(Estimator, Protocol):
    """An estimator that reads the ground truth: oracles that perturb the truth.

    Only oracles implement it (e.g. :class:`handsim.estimators.oracle.OracleEstimator`). The
    closed-loop wrapper checks ``isinstance(estimator, PrivilegedEstimator)`` and, if so, calls
    ``observe_truth(frame)`` with the step's ground-truth :class:`~handsim.frame.record.Frame`
    immediately before ``predict`` on the same step. Learned and classical estimators never
    see the truth.
    """

    def observe_truth(self, frame: Frame) -> None:
        """Receive this step's ground truth (called before ``predict`` on the same step).

        Args:
            frame: the ground-truth frame whose depth is passed to the next ``predict``.
        """
        ...


def validate_depth_input(depth: Any, K: Any) -> tuple[np.ndarray, np.ndarray]:  # noqa: N803
    """Check one ``predict`` input and convert it.

    Args:
        depth: (H, W) depth along the optical axis, metres, 0 = no measurement.
        K: (3, 3) intrinsic matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.

    Returns:
        ``(depth, K)``: (H, W) float32 metres and (3, 3) float64.

    Raises:
        InvalidEstimatorInput: on a wrong shape, a negative or non-finite depth, or a K that
            is not a pinhole matrix with positive focal lengths.
    """
    try:
        dtype = np.asarray(depth).dtype
    except (TypeError, ValueError):
        dtype = None  # ragged: refused below
    if dtype is not None and dtype.kind not in "fiu":
        # A bool mask would read as 1 m everywhere, a complex image lose its imaginary part.
        raise InvalidEstimatorInput(
            f"depth must be real numbers (float metres); received {type(depth).__name__} of "
            f"dtype {dtype}"
        )
    try:
        depth_m = np.asarray(depth, dtype=np.float32)
        K_cv = np.asarray(K, dtype=np.float64)  # noqa: N806
    except (TypeError, ValueError) as err:
        raise InvalidEstimatorInput(
            f"depth and K must be numeric arrays; received {type(depth).__name__} and "
            f"{type(K).__name__} ({err})"
        ) from None
    if depth_m.ndim != 2 or depth_m.size == 0:
        raise InvalidEstimatorInput(
            f"depth must be an (H, W) image in metres with H, W >= 1; received shape "
            f"{depth_m.shape}"
        )
    # Two reductions (NaN propagates through both); the per-pixel masks only on the error path.
    if not (depth_m.min() >= 0 and depth_m.max() < np.inf):
        bad = ~np.isfinite(depth_m) | (depth_m < 0)
        v, u = (int(i) for i in np.argwhere(bad)[0])
        raise InvalidEstimatorInput(
            f"depth must be finite metres >= 0 (0 = no measurement); received "
            f"{float(depth_m[v, u]):.6g} "
            f"at pixel (v={v}, u={u})"
        )
    _check_K(K_cv)
    return depth_m, K_cv


def _check_K(K_cv: np.ndarray) -> None:  # noqa: N802, N803
    if K_cv.shape != (3, 3) or not np.all(np.isfinite(K_cv)):
        raise InvalidEstimatorInput(
            f"K must be a finite (3, 3) intrinsic matrix; received shape {K_cv.shape}"
        )
    # np.allclose(K_cv[2], (0, 0, 1)) (|a - b| <= 1e-8 + 1e-5 |b|) without its ~10 us of calls.
    last = K_cv[2].tolist()
    if not (
        K_cv[0, 0] > 0
        and K_cv[1, 1] > 0
        and abs(last[0]) <= 1e-8
        and abs(last[1]) <= 1e-8
        and abs(last[2] - 1.0) <= 1e-8 + 1e-5
    ):
        raise InvalidEstimatorInput(
            "K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0; received "
            f"{K_cv.tolist()}"
        )


def validate_batch_input(depths: Any, Ks: Any) -> tuple[np.ndarray, np.ndarray]:  # noqa: N803
    """Check one ``predict_batch`` input and convert it.

    Args:
        depths: (B, H, W) depth images, metres, 0 = no measurement.
        Ks: (B, 3, 3) intrinsic matrices.

    Returns:
        ``(depths, Ks)``: (B, H, W) float32 and (B, 3, 3) float64.

    Raises:
        InvalidEstimatorInput: on mismatched batch sizes or an invalid image or matrix.
    """
    try:
        depths_m = np.asarray(depths, dtype=np.float32)
        Ks_cv = np.asarray(Ks, dtype=np.float64)  # noqa: N806
    except (TypeError, ValueError) as err:
        raise InvalidEstimatorInput(f"depths and Ks must be numeric arrays ({err})") from None
    if depths_m.ndim != 3:
        raise InvalidEstimatorInput(
            f"depths must be a (B, H, W) batch of depth images in metres; received shape "
            f"{depths_m.shape}"
        )
    if Ks_cv.shape != (depths_m.shape[0], 3, 3):
        raise InvalidEstimatorInput(
            f"Ks must be ({depths_m.shape[0]}, 3, 3), one matrix per depth image; received "
            f"shape {Ks_cv.shape}"
        )
    for depth_m, K_cv in zip(depths_m, Ks_cv, strict=True):  # noqa: N806
        validate_depth_input(depth_m, K_cv)
    return depths_m, Ks_cv


class EstimatorBase:
    """Optional base of :class:`Estimator` implementations.

    Subclasses implement :meth:`predict`; :meth:`predict_batch` loops over it and
    :meth:`reset` does nothing (override both for batched or stateful estimators).
    """

    def predict(self, depth: np.ndarray, K: np.ndarray) -> Estimate:  # noqa: N803
        """Estimate one frame (see :meth:`Estimator.predict`)."""
        raise NotImplementedError(f"{type(self).__name__} must implement predict(depth, K)")

    def predict_batch(self, depths: np.ndarray, Ks: np.ndarray) -> list[Estimate]:  # noqa: N803
        """Estimate each frame of the batch with :meth:`predict`, in order.

        Args:
            depths: (B, H, W) float32 depth images, metres, 0 = no measurement.
            Ks: (B, 3, 3) intrinsic matrices.

        Returns:
            B estimates.

        Raises:
            InvalidEstimatorInput: on an invalid batch.
        """
        depths_m, Ks_cv = validate_batch_input(depths, Ks)  # noqa: N806
        return [self.predict(d, k) for d, k in zip(depths_m, Ks_cv, strict=True)]

    def reset(self) -> None:
        """Forget any state (stateless by default)."""


def _object_models(frame: Frame, objects: Sequence[YCBObject] | None) -> list[YCBObject]:
    if objects is not None:
        models = list(objects)
        if len(models) != len(frame.objects):
            raise InvalidEstimatorInput(
                f"objects must hold one YCBObject per frame object instance "
                f"({len(frame.objects)}); received {len(models)}"
            )
        return models
    models = []
    for label in frame.objects:
        try:
            models.append(get_object(label.name))
        except UnknownName:
            raise InvalidEstimatorInput(
                f"object instance {label.instance} ({label.name!r}) is not a built-in object; "
                "pass objects=[obj for _, obj in scene.objects] to estimate_errors"
            ) from None
    return models


# KD-trees over object model points (object frame), built once per model: ADI's nearest
# neighbours are searched in the estimate's object frame, where the model points do not move.
_TREE_CACHE: OrderedDict[tuple[str, int, int], tuple[np.ndarray, cKDTree]] = OrderedDict()
_TREE_CACHE_SIZE = 64


def _model_tree(model: YCBObject) -> tuple[np.ndarray, cKDTree]:
    """(model points (M, 3) float64, KD-tree over them), cached per model points."""
    points = np.asarray(model.model_points_m, dtype=np.float64)
    key = (str(getattr(model, "name", "")), points.shape[0], hash(points.tobytes()))
    cached = _TREE_CACHE.get(key)
    if cached is not None and np.array_equal(cached[0], points):
        _TREE_CACHE.move_to_end(key)
        return cached
    from scipy.spatial import cKDTree

    entry = (points.copy(), cKDTree(points))
    _TREE_CACHE[key] = entry
    if len(_TREE_CACHE) > _TREE_CACHE_SIZE:
        _TREE_CACHE.popitem(last=False)
    return entry


def _add_and_adi_mm(
    T_est: np.ndarray,  # noqa: N803
    T_gt: np.ndarray,  # noqa: N803
    model: YCBObject,
) -> tuple[float, float]:
    """ADD and ADI (ADD-S) in mm, as :func:`handsim.metrics.add_error_mm` / ``adi_error_mm``.

    ADI: each ground-truth-posed point's distance to the nearest estimate-posed point, found
    in the estimate's object frame (rigid motions keep distances) with the model's cached tree.
    """
    points, tree = _model_tree(model)
    T_est = np.asarray(T_est, dtype=np.float64)  # noqa: N806
    T_gt = np.asarray(T_gt, dtype=np.float64)  # noqa: N806
    p_est = points @ T_est[:3, :3].T + T_est[:3, 3]
    p_gt = points @ T_gt[:3, :3].T + T_gt[:3, 3]
    add = float(np.mean(np.linalg.norm(p_est - p_gt, axis=1)) * MM_PER_M)
    in_est = (p_gt - T_est[:3, 3]) @ T_est[:3, :3]
    dist, _ = tree.query(in_est, k=1)
    return add, float(np.mean(dist) * MM_PER_M)


def estimate_errors(
    estimate: Estimate,
    frame: Frame,
    *,
    objects: Sequence[YCBObject] | None = None,
) -> dict[str, Any]:
    """Per-frame errors of an estimate against the frame's ground truth, millimetres.

    Every keypoint error is over all 21 keypoints, visible or not. An error that cannot be
    computed is NaN: every error of an invalid estimate (``valid=False``), the keypoint errors
    when ``keypoints_cam`` is ``None``, the centre error when ``center_cam`` is ``None``, and
    the object errors of an instance the estimate has no pose for.

    Args:
        estimate: the estimate of ``frame``'s depth.
        frame: the ground truth (:class:`~handsim.frame.record.Frame`).
        objects: the object models by instance (``[obj for _, obj in scene.objects]``);
            default: the built-in object of each instance's name (imported meshes need this).

    Returns:
        A dict with

        - ``"kp_mean_mm"``, ``"kp_max_mm"``: mean and max 3D keypoint error (float);
        - ``"center_mm"``: distance between ``center_cam`` and :func:`hand_center` of the
          true keypoints (float);
        - ``"add_mm"``, ``"adi_mm"``, ``"add_or_adi_mm"``: ``{instance: float}`` for every
          object instance of the frame: ADD, ADI (ADD-S) and ADD(-S) (ADI for symmetric
          objects), as in :mod:`handsim.metrics` (equal to its functions to rounding). Each is
          computed once per instance, and ADI searches a KD-tree over the model points that is
          built once per object model and cached.

    Raises:
        InvalidEstimate: if ``estimate`` is not an Estimate, or poses an instance the frame
            does not have.
        InvalidEstimatorInput: if ``frame`` is not a Frame, or an object model cannot be found
            (see ``objects``).
    """
    if not isinstance(estimate, Estimate):
        raise InvalidEstimate(
            f"estimate must be an Estimate (what predict returns); received "
            f"{type(estimate).__name__}"
        )
    if not all(hasattr(frame, key) for key in ("keypoints_cam", "objects")):
        raise InvalidEstimatorInput(
            f"frame must be the ground-truth Frame of the estimated depth (env.unwrapped.frame, "
            f"info['frame']); received {type(frame).__name__}"
        )
    nan = math.nan
    instances = [label.instance for label in frame.objects]
    unknown = sorted(set(estimate.object_poses) - set(instances))
    if unknown:
        raise InvalidEstimate(
            f"the estimate poses object instances {unknown} that the frame does not have; "
            f"frame instances: {instances}"
        )
    errors: dict[str, Any] = {"kp_mean_mm": nan, "kp_max_mm": nan, "center_mm": nan}
    truth = np.asarray(frame.keypoints_cam, dtype=np.float64)
    if estimate.valid and estimate.keypoints_cam is not None:
        per_kp_mm = np.linalg.norm(estimate.keypoints_cam - truth, axis=1) * MM_PER_M
        errors["kp_mean_mm"] = float(per_kp_mm.mean())
        errors["kp_max_mm"] = float(per_kp_mm.max())
    if estimate.valid and estimate.center_cam is not None:
        center_err_m = np.linalg.norm(estimate.center_cam - hand_center(truth))
        errors["center_mm"] = float(center_err_m * MM_PER_M)
    add, adi, add_or_adi = (dict.fromkeys(instances, nan) for _ in range(3))
    if estimate.object_poses:
        models = _object_models(frame, objects)
        for label, model in zip(frame.objects, models, strict=True):
            T_est = estimate.object_poses.get(label.instance)  # noqa: N806
            if T_est is None:
                continue
            T_gt = label.T_cam_from_obj  # noqa: N806
            add_mm, adi_mm = _add_and_adi_mm(T_est, T_gt, model)
            add[label.instance], adi[label.instance] = add_mm, adi_mm
            symmetric = model.symmetry.kind != "none"
            add_or_adi[label.instance] = adi_mm if symmetric else add_mm
    errors.update(add_mm=add, adi_mm=adi, add_or_adi_mm=add_or_adi)
    return errors


def describe_estimator(estimator: Any) -> tuple[str, bool]:
    """How reports and plot titles name an estimator, and whether it names itself.

    Its ``describe()`` when it has one (an optional method beside the protocol's three), else
    its ``repr`` when its class defines one, else the class name (an ``object`` repr such as
    ``<MyNet object at 0x7f...>`` says nothing of the estimator's settings).

    Returns:
        ``(text, own)``: the name, and False when it is only the class name.
    """
    describe = getattr(estimator, "describe", None)
    if callable(describe):
        return str(describe()), True
    if type(estimator).__repr__ is not object.__repr__:
        return repr(estimator), True
    return type(estimator).__qualname__, False

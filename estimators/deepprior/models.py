"""The networks of DeepPrior and DeepPrior++ (Oberweger et al., 2015 and 2017), in PyTorch.

Every pose network maps a (B, 1, S, S) normalized depth crop to (B, 21 * 3) normalized
keypoints (:func:`~handsim.estimators.deepprior.preprocess.normalize_keypoints`, flattened).

- :class:`DeepPriorNet`: the first-stage networks of DeepPrior, ``shallow`` (one conv layer),
  ``deep`` (three conv layers, two fully connected) and ``multiscale`` (the deep branch on the
  crop at three resolutions), each with or without the prior bottleneck.
- :class:`DeepPriorPP`: the ResNet-style network of DeepPrior++: a 5x5 conv of 64 filters and
  max-pooling, four residual stages of 64/128/256/256 filters with stride 2, no global average
  pooling, two fully connected layers with dropout 0.3, and the prior.
- :class:`PriorLayer`: the bottleneck: a linear layer to ``prior_dim`` values and a linear
  layer back to pose space, initialized from the PCA components and mean
  (:meth:`PriorLayer.init_from_pca`) and then trained end to end.
- :class:`Localizer`: the refinement CNN (three conv layers with max-pooling, two fully
  connected layers with dropout) that predicts the offset of the middle-finger MCP from the
  crop centre, normalized by half the cube.
- :class:`HandDetector`: a fully convolutional network over the whole (downsampled) depth image
  that scores, per cell of a coarse grid, whether the middle-finger MCP projects into it, with
  the MCP's position in the cell and its depth
  (:mod:`~handsim.estimators.deepprior.detector`).

:func:`build_model` makes any of them from a JSON-able config dict (saved with checkpoints).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

__all__ = [
    "N_OUT",
    "ARCHITECTURES",
    "PriorLayer",
    "DeepPriorNet",
    "DeepPriorPP",
    "Localizer",
    "HandDetector",
    "build_model",
    "inference_forward",
]

N_OUT = 21 * 3
"""Output values of a pose network: 21 keypoints x (x, y, z), normalized."""

ARCHITECTURES = ("shallow", "deep", "multiscale", "resnet", "localizer", "detector")
"""Values of the ``arch`` config key."""


class PriorLayer(nn.Module):
    """The prior bottleneck: ``Linear(in, prior_dim)`` then ``Linear(prior_dim, 63)``.

    The second layer maps prior coefficients to poses; :meth:`init_from_pca` sets it to the PCA
    reconstruction ``pose = mean + coeffs @ components``.

    Args:
        in_features: input features.
        prior_dim: dimension of the bottleneck.
    """

    def __init__(self, in_features: int, prior_dim: int = 30) -> None:
        super().__init__()
        self.encode = nn.Linear(in_features, prior_dim)
        self.decode = nn.Linear(prior_dim, N_OUT)

    def init_from_pca(self, mean: np.ndarray, components: np.ndarray) -> None:
        """Set the decoder to the PCA: weight = components^T, bias = mean.

        Args:
            mean: (63,) PCA mean of normalized poses.
            components: (prior_dim, 63) orthonormal PCA components.
        """
        with torch.no_grad():
            self.decode.weight.copy_(torch.as_tensor(np.asarray(components).T, dtype=torch.float32))
            self.decode.bias.copy_(torch.as_tensor(np.asarray(mean), dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, in) -> (B, 63)."""
        return self.decode(self.encode(x))


def _head(in_features: int, fc: int, prior_dim: int | None, dropout: float) -> nn.Module:
    layers: list[nn.Module] = [
        nn.Flatten(),
        nn.Linear(in_features, fc),
        nn.ReLU(inplace=True),
        nn.Dropout(dropout),
        nn.Linear(fc, fc),
        nn.ReLU(inplace=True),
        nn.Dropout(dropout),
    ]
    layers.append(PriorLayer(fc, prior_dim) if prior_dim else nn.Linear(fc, N_OUT))
    return nn.Sequential(*layers)


def _deep_branch(size: int) -> tuple[nn.Module, int]:
    """DeepPrior's deep feature extractor: conv5-pool4, conv5-pool2, conv3 (8 filters each)."""
    body = nn.Sequential(
        nn.Conv2d(1, 8, 5, padding=2),
        nn.ReLU(inplace=True),
        nn.MaxPool2d(4),
        nn.Conv2d(8, 8, 5, padding=2),
        nn.ReLU(inplace=True),
        nn.MaxPool2d(2),
        nn.Conv2d(8, 8, 3, padding=1),
        nn.ReLU(inplace=True),
    )
    return body, 8 * (size // 8) ** 2


class DeepPriorNet(nn.Module):
    """DeepPrior's first-stage networks, with or without the prior.

    Args:
        variant: ``"shallow"``, ``"deep"`` or ``"multiscale"``.
        prior_dim: bottleneck dimension, or ``None``/0 for direct regression of the 63 values.
        size: crop side, pixels (divisible by 32 for ``multiscale``).
        fc: units of the fully connected layers.
        dropout: dropout of the fully connected layers.
    """

    def __init__(
        self,
        variant: str = "deep",
        prior_dim: int | None = 30,
        size: int = 128,
        fc: int = 1024,
        dropout: float = 0.3,
    ) -> None:
        super().__init__()
        self.variant = variant
        if variant == "shallow":
            self.branches = nn.ModuleList(
                [
                    nn.Sequential(
                        nn.Conv2d(1, 8, 5, padding=2), nn.ReLU(inplace=True), nn.MaxPool2d(4)
                    )
                ]
            )
            features = 8 * (size // 4) ** 2
            self.scales: tuple[int, ...] = (1,)
        elif variant == "deep":
            body, features = _deep_branch(size)
            self.branches = nn.ModuleList([body])
            self.scales = (1,)
        elif variant == "multiscale":
            self.scales = (1, 2, 4)
            bodies = [_deep_branch(size // s) for s in self.scales]
            self.branches = nn.ModuleList([b for b, _ in bodies])
            features = sum(f for _, f in bodies)
        else:
            raise ValueError(f"variant must be shallow, deep or multiscale; received {variant!r}")
        if variant == "shallow":
            self.head = nn.Sequential(
                nn.Flatten(),
                nn.Linear(features, fc),
                nn.ReLU(inplace=True),
                nn.Dropout(dropout),
                PriorLayer(fc, prior_dim) if prior_dim else nn.Linear(fc, N_OUT),
            )
        else:
            self.head = _head(features, fc, prior_dim, dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 1, S, S) -> (B, 63)."""
        feats = []
        for scale, branch in zip(self.scales, self.branches, strict=True):
            xi = x if scale == 1 else nn.functional.max_pool2d(x, scale)
            feats.append(branch(xi).flatten(1))
        return self.head(torch.cat(feats, dim=1))


class _Residual(nn.Module):
    """A pre-activation-free basic residual block with a projection shortcut (stride s)."""

    def __init__(self, cin: int, cout: int, stride: int) -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False),
            nn.BatchNorm2d(cout),
            nn.ReLU(inplace=True),
            nn.Conv2d(cout, cout, 3, padding=1, bias=False),
            nn.BatchNorm2d(cout),
        )
        self.skip = nn.Sequential(
            nn.Conv2d(cin, cout, 1, stride=stride, bias=False), nn.BatchNorm2d(cout)
        )
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Residual sum, then ReLU."""
        return self.relu(self.body(x) + self.skip(x))


class DeepPriorPP(nn.Module):
    """DeepPrior++'s ResNet-style pose network.

    conv 5x5 (64) + BN + ReLU + max-pool 2, residual stages of 64/128/256/256 filters with
    stride 2 (one block each), flatten (no global average pooling), two fully connected layers
    with dropout, and the prior bottleneck.

    Args:
        prior_dim: bottleneck dimension, or ``None``/0 for direct regression.
        size: crop side, pixels (divisible by 32).
        fc: units of the fully connected layers.
        dropout: dropout of the fully connected layers.
        width: factor of every conv layer's filters (1: the paper's 64 / 64-128-256-256;
            0.25 makes the convolutions ~16x cheaper, for CPU training).
    """

    def __init__(
        self,
        prior_dim: int | None = 30,
        size: int = 128,
        fc: int = 1024,
        dropout: float = 0.3,
        width: float = 1.0,
    ) -> None:
        super().__init__()
        stem = max(1, round(64 * width))
        widths = [max(1, round(w * width)) for w in (64, 128, 256, 256)]
        stages: list[nn.Module] = [
            nn.Conv2d(1, stem, 5, padding=2, bias=False),
            nn.BatchNorm2d(stem),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
        ]
        cin = stem
        for w in widths:
            stages.append(_Residual(cin, w, 2))
            cin = w
        self.features = nn.Sequential(*stages)
        side = size // 2 // 2 ** len(widths)
        self.head = _head(cin * side * side, fc, prior_dim, dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 1, S, S) -> (B, 63)."""
        return self.head(self.features(x))


class Localizer(nn.Module):
    """The refinement CNN: three conv layers with max-pooling, two FC layers with dropout.

    Predicts the (3,) offset of the middle-finger MCP from the crop centre, in units of half
    the cube.

    Args:
        size: crop side, pixels (divisible by 8).
        fc: units of the fully connected layers.
        dropout: dropout of the fully connected layers.
    """

    def __init__(self, size: int = 64, fc: int = 256, dropout: float = 0.3) -> None:
        super().__init__()
        self.features = nn.Sequential(
            nn.Conv2d(1, 8, 5, padding=2),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(8, 16, 5, padding=2),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(16, 32, 3, padding=1),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
        )
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Linear(32 * (size // 8) ** 2, fc),
            nn.ReLU(inplace=True),
            nn.Dropout(dropout),
            nn.Linear(fc, fc),
            nn.ReLU(inplace=True),
            nn.Dropout(dropout),
            nn.Linear(fc, 3),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 1, S, S) -> (B, 3)."""
        return self.head(self.features(x))


class HandDetector(nn.Module):
    """The whole-image hand detector: (B, 2, H, W) image -> (B, 4, H / 4, W / 4) cell outputs.

    Input channels: depth / ``depth_max`` (0 where nothing was measured) and the measured
    mask. A stride-2 5x5 conv, a 3x3 conv and max-pooling bring the image to the grid (a cell
    is 4 x 4 input pixels); three 3x3 convs dilated 1, 2 and 4 widen the view to about 65 input
    pixels (a hand at arm's length and its surroundings) and a 1x1 conv gives per cell: the
    MCP's logit, its position in the cell (u, v, in cells) and its depth (decimetres). Every
    conv but the last is followed by batch norm and ReLU.

    Args:
        channels: filters of the grid-resolution convs.
    """

    def __init__(self, channels: int = 48) -> None:
        super().__init__()

        def block(c_in: int, c_out: int, k: int, **kw: Any) -> list[nn.Module]:
            conv = nn.Conv2d(c_in, c_out, k, bias=False, **kw)
            return [conv, nn.BatchNorm2d(c_out), nn.ReLU(inplace=True)]

        c = int(channels)
        self.features = nn.Sequential(
            *block(2, 16, 5, stride=2, padding=2),
            *block(16, 32, 3, padding=1),
            nn.MaxPool2d(2),
            *block(32, c, 3, padding=1),
            *block(c, c, 3, padding=2, dilation=2),
            *block(c, c, 3, padding=4, dilation=4),
        )
        self.head = nn.Conv2d(c, 4, 1)
        with torch.no_grad():  # start at half a cell and half a metre
            self.head.bias.copy_(torch.tensor([0.0, 0.5, 0.5, 5.0]))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 2, H, W) -> (B, 4, H / 4, W / 4)."""
        return self.head(self.features(x))


def build_model(config: dict[str, Any]) -> nn.Module:
    """A network from its config (``arch`` plus the constructor's keyword arguments).

    Config keys: ``arch`` (:data:`ARCHITECTURES`), ``size``, ``fc``, ``dropout``, for pose
    networks ``prior_dim`` (0 = no prior), for ``resnet`` ``width`` (filter factor) and for
    ``detector`` ``channels``.

    Raises:
        ValueError: for an unknown ``arch``.
    """
    arch = config.get("arch")
    size = int(config.get("size", 128))
    fc = int(config.get("fc", 1024))
    dropout = float(config.get("dropout", 0.3))
    prior = int(config.get("prior_dim", 30)) or None
    if arch in ("shallow", "deep", "multiscale"):
        return DeepPriorNet(arch, prior, size=size, fc=fc, dropout=dropout)
    if arch == "resnet":
        width = float(config.get("width", 1.0))
        return DeepPriorPP(prior, size=size, fc=fc, dropout=dropout, width=width)
    if arch == "localizer":
        return Localizer(size=size, fc=fc, dropout=dropout)
    if arch == "detector":
        return HandDetector(channels=int(config.get("channels", 48)))
    raise ValueError(f"arch must be one of {', '.join(ARCHITECTURES)}; received {arch!r}")


# Leaves whose ``forward`` :func:`inference_forward` calls directly (no hooks, no containers).
_LEAVES = (nn.Conv2d, nn.Linear, nn.ReLU, nn.MaxPool2d, nn.BatchNorm2d, nn.Flatten)


def _folded(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> nn.Conv2d:
    """``conv`` then eval-mode ``bn`` as one conv (torch's fusion), in ``conv``'s layout."""
    fused = fuse_conv_bn_eval(conv, bn)
    if conv.weight.is_contiguous(memory_format=torch.channels_last):
        fused = fused.to(memory_format=torch.channels_last)
    return fused


def _unrolled(module: nn.Module) -> list[Callable[[torch.Tensor], torch.Tensor]]:
    """The eval-mode steps of ``module``: unrolled, no dropout, batch norm folded."""
    if isinstance(module, nn.Sequential):
        children, steps = list(module), []
        i = 0
        while i < len(children):
            child = children[i]
            after = children[i + 1] if i + 1 < len(children) else None
            if isinstance(child, nn.Conv2d) and isinstance(after, nn.BatchNorm2d):
                steps.append(_folded(child, after).forward)
                i += 2
            else:
                steps += _unrolled(child)
                i += 1
        return steps
    if isinstance(module, _Residual):
        body, skip = _unrolled(module.body), _unrolled(module.skip)
        return [lambda x: torch.relu_(_chain(body, x) + _chain(skip, x))]
    if isinstance(module, PriorLayer):
        return [module.encode.forward, module.decode.forward]
    if isinstance(module, nn.Dropout):
        return []
    if isinstance(module, nn.ReLU):
        return [torch.relu_ if module.inplace else torch.relu]
    return [module.forward if isinstance(module, _LEAVES) else module]


def _chain(steps: list[Callable[[torch.Tensor], torch.Tensor]], x: torch.Tensor) -> torch.Tensor:
    for step in steps:
        x = step(x)
    return x


def inference_forward(model: nn.Module) -> Callable[[torch.Tensor], torch.Tensor]:
    """``model``'s forward pass for inference, with fewer Python calls and layers.

    At batch 1 on a CPU core, ``nn.Module.__call__`` of every layer (hooks, containers) and
    every batch norm are a measurable part of a small network's time. The returned function
    runs the same layers in the same order, calling their ``forward`` directly, skipping
    dropout and with each eval-mode batch norm folded into the conv before it
    (``torch.nn.utils.fusion.fuse_conv_bn_eval``): the module's results up to float rounding
    (about 1e-6 relative). Use it under ``torch.inference_mode()`` with ``model`` in eval mode;
    it is built once, from the weights of that moment: build it again after changing them.

    Args:
        model: a network of :func:`build_model`, in eval mode.

    Returns:
        A function (B, 1, S, S) -> the model's output.

    Raises:
        ValueError: if ``model`` is in training mode (dropout would be skipped).
    """
    if model.training:
        raise ValueError("inference_forward needs a model in eval mode (call model.eval())")
    if isinstance(model, DeepPriorNet) and model.scales != (1,):
        return model  # the multiscale branches: the plain forward
    if isinstance(model, DeepPriorNet):
        steps = [*_unrolled(model.branches[0]), nn.Flatten().forward, *_unrolled(model.head)]
    elif isinstance(model, DeepPriorPP | Localizer):
        steps = [*_unrolled(model.features), *_unrolled(model.head)]
    elif isinstance(model, HandDetector):
        steps = [*_unrolled(model.features), model.head.forward]
    else:
        return model

    def forward(x: torch.Tensor) -> torch.Tensor:
        return _chain(steps, x)

    return forward

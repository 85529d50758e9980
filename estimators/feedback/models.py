"""The networks of the feedback loop (Oberweger, Wohlhart and Lepetit, ICCV 2015), in PyTorch.

- :class:`LearnedSynthesizer`: normalized joints (B, 63) -> fully connected layers to a 2048-d
  latent reshaped to 32 maps of 8 x 8 -> four stages of 2x unpooling and a 5 x 5 convolution
  to the crop side (128 from 8) -> a 5 x 5 convolution to one map, ``tanh`` (the crop's
  normalized depth is in [-1, 1]). Each stage's convolution is batch-normalized: without it
  the last convolution's input grew to ~185 within the first epoch on handsim crops, ``tanh``
  saturated at +1 (background) on every pixel and stopped learning.
- :class:`Updater`: a Siamese CNN; one path with shared weights is applied to the input crop
  and to the synthesized crop (four convolutions with stride 2 instead of pooling), the two
  feature vectors are concatenated and fully connected layers give the pose update (B, 63),
  in normalized units.

:func:`build_feedback_model` makes either from a JSON-able config (saved with checkpoints).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from handsim.errors import HandSimError

__all__ = [
    "N_POSE",
    "FEEDBACK_ARCHITECTURES",
    "InvalidFeedbackModel",
    "LearnedSynthesizer",
    "Updater",
    "build_feedback_model",
]

N_POSE = 21 * 3
"""Pose values: 21 keypoints x (x, y, z), normalized by the cube."""

FEEDBACK_ARCHITECTURES = ("synthesizer", "updater")
"""Values of the ``arch`` config key of :func:`build_feedback_model`."""


class InvalidFeedbackModel(HandSimError, ValueError):
    """A feedback network's config is invalid; the message says what is valid."""


class LearnedSynthesizer(nn.Module):
    """The thesis's synthesizer: pose -> depth crop.

    Args:
        size: crop side, pixels (8 * 2**k; 128 in the thesis).
        fc: units of the first fully connected layer.
        filters: filters of each unpooling stage's convolution (32 in the thesis).
    """

    def __init__(self, size: int = 128, fc: int = 1024, filters: int = 32) -> None:
        super().__init__()
        stages = (size // 8).bit_length() - 1
        if size < 8 or 8 * 2**stages != size:
            raise InvalidFeedbackModel(f"size must be 8 * 2**k (e.g. 128); received {size}")
        self.size = size
        self.fc = nn.Sequential(
            nn.Linear(N_POSE, fc),
            nn.ReLU(inplace=True),
            nn.Linear(fc, 2048),
            nn.ReLU(inplace=True),
        )
        layers: list[nn.Module] = []
        cin = 32
        for _ in range(stages):
            # Unpooling: each value fills its 2 x 2 block, then a convolution smooths it.
            layers += [
                nn.Upsample(scale_factor=2, mode="nearest"),
                nn.Conv2d(cin, filters, 5, padding=2, bias=False),
                nn.BatchNorm2d(filters),
                nn.ReLU(inplace=True),
            ]
            cin = filters
        layers += [nn.Conv2d(cin, 1, 5, padding=2), nn.Tanh()]
        self.decode = nn.Sequential(*layers)

    def forward(self, pose: torch.Tensor) -> torch.Tensor:
        """(B, 63) normalized joints -> (B, 1, S, S) normalized depth in [-1, 1]."""
        return self.decode(self.fc(pose).reshape(-1, 32, 8, 8))


class Updater(nn.Module):
    """The Siamese updater: (input crop, synthesized crop) -> pose update.

    Args:
        size: crop side, pixels (divisible by 16).
        filters: filters of the four convolutions of each path, doubled every second layer.
        fc: units of the two fully connected layers.
        dropout: dropout of the fully connected layers.
    """

    def __init__(
        self, size: int = 128, filters: int = 32, fc: int = 1024, dropout: float = 0.3
    ) -> None:
        super().__init__()
        if size < 16 or size % 16:
            raise InvalidFeedbackModel(f"size must be a multiple of 16; received {size}")
        widths = [filters, filters, 2 * filters, 2 * filters]
        layers: list[nn.Module] = []
        cin = 1
        for w in widths:
            layers += [nn.Conv2d(cin, w, 5, stride=2, padding=2), nn.ReLU(inplace=True)]
            cin = w
        self.path = nn.Sequential(*layers, nn.Flatten())
        features = cin * (size // 16) ** 2
        self.head = nn.Sequential(
            nn.Linear(2 * features, fc),
            nn.ReLU(inplace=True),
            nn.Dropout(dropout),
            nn.Linear(fc, fc),
            nn.ReLU(inplace=True),
            nn.Dropout(dropout),
            nn.Linear(fc, N_POSE),
        )
        # Start from "no update": the loop then begins as the predictor alone.
        nn.init.zeros_(self.head[-1].weight)
        nn.init.zeros_(self.head[-1].bias)

    def forward(self, depth: torch.Tensor, synthesized: torch.Tensor) -> torch.Tensor:
        """(B, 1, S, S) input and synthesized crops -> (B, 63) update, normalized units."""
        both = self.path(torch.cat([depth, synthesized], dim=0))
        a, b = both.chunk(2, dim=0)
        return self.head(torch.cat([a, b], dim=1))


def build_feedback_model(config: dict[str, Any]) -> nn.Module:
    """A network from its config: ``arch`` (:data:`FEEDBACK_ARCHITECTURES`) and its arguments.

    Raises:
        InvalidFeedbackModel: for an unknown ``arch`` or invalid sizes.
    """
    arch = config.get("arch")
    size = int(config.get("size", 128))
    if arch == "synthesizer":
        return LearnedSynthesizer(
            size, fc=int(config.get("fc", 1024)), filters=int(config.get("filters", 32))
        )
    if arch == "updater":
        return Updater(
            size,
            filters=int(config.get("filters", 32)),
            fc=int(config.get("fc", 1024)),
            dropout=float(config.get("dropout", 0.3)),
        )
    raise InvalidFeedbackModel(
        f"arch must be one of {', '.join(FEEDBACK_ARCHITECTURES)}; received {arch!r}"
    )

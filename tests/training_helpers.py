"""What the training tests share: fitting one batch (``test_awda_net.py``, ``test_tosvi_net.py``),
a frame encoder that counts what it encodes and tiny training recipes (``test_frozen_trunk.py``,
``test_tosvi_frozen.py``)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import torch

TINY_NET = {
    "image_height_px": 64,
    "image_width_px": 80,
    "attention_layers": 1,
    "attention_heads": 2,
    "attention_head_dim": 16,
    "head_hidden_dim": 32,
}
"""A recipe's ``[model]`` for a tiny network on 64 x 80 images."""
FROZEN_LITE0 = {
    "backbone": "efficientnet-lite0",
    "backbone_stride": 16,
    "freeze_backbone": True,
    "backbone_weights": "imagenet",
}
"""``[model]`` keys of the frozen, ImageNet-pretrained EfficientNet-Lite0 trunk."""
SIX_STEPS = {
    "batch_size": 2,
    "max_steps": 6,
    "snapshot_every_steps": 2,
    "validate_every_steps": 5,
    "validation_batches": 1,
}
"""A recipe's ``[train]``: six steps of two samples, a snapshot every two."""


def recipe_toml(
    name: str,
    model: Mapping[str, Any],
    train: Mapping[str, Any] = SIX_STEPS,
    augment: Mapping[str, Any] | None = None,
) -> str:
    """A training recipe (both MOSAIC-style suites) as TOML text; no augmentation unless
    ``augment`` says otherwise."""
    lines = [f"name = {json.dumps(name)}", 'suites = ["pick_place", "mosaic"]']
    tables = {"model": model, "train": train, "augment": augment or {"shift_px": 0}}
    for table, values in tables.items():
        lines += [f"[{table}]", *(f"{key} = {json.dumps(v)}" for key, v in values.items())]
    return "\n".join(lines) + "\n"


def fit_batch(model: Any, batch: Any, steps: int = 250, lr: float = 5e-4) -> list[float]:
    """Train ``model`` on ``batch`` alone (``model.compute_loss``, Adam) for ``steps`` steps;
    returns the loss (``info["loss"]``) at each step."""
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    losses = []
    for _ in range(steps):
        loss, info = model.compute_loss(batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(info["loss"])
    return losses


class CountingEncoder:
    """A fixed random 16 x 16-stride convolution standing in for a trunk; counts the frames it
    has encoded."""

    def __init__(self) -> None:
        self.frames = 0
        torch.manual_seed(0)
        self.conv = torch.nn.Conv2d(3, 4, kernel_size=16, stride=16)

    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        self.frames += len(images)
        with torch.no_grad():
            return self.conv(images)

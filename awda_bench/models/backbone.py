"""ResNet-18 feature extractor with its last two layers (average pool, fc) removed.

Output stride 32: a ``(N, C_in, H, W)`` batch becomes ``(N, 512, ceil(H/32), ceil(W/32))``
(240x320 -> 8x10, 224x224 -> 7x7). Weights come from one of three sources (``backbone_weights``):

- ``imagenet``: torchvision's ``ResNet18_Weights.IMAGENET1K_V1``, fetched through the torch hub
  cache (``$TORCH_HOME/hub/checkpoints``). Without network and without a cached file this raises
  :class:`BackboneWeightsUnavailableError` naming the offline alternatives.
- ``none``: torchvision's random initialization (seeded by the global torch RNG).
- a path: a local ResNet-18 ``state_dict`` (torchvision key names; ``fc.*`` keys are ignored).

A 1-channel variant (wrist depth) sums the pretrained first convolution over its RGB inputs, which
equals feeding the depth image replicated into three channels.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import torch
import torchvision
from torch import nn
from torchvision.models import ResNet18_Weights

from awda_bench.errors import CorruptFileError, UsageError

FEATURE_CHANNELS = 512
"""Channels of ResNet-18's last stage."""

IMAGENET_MEAN = (0.485, 0.456, 0.406)
"""Per-channel mean of RGB in [0, 1] the ImageNet weights were trained with."""
IMAGENET_STD = (0.229, 0.224, 0.225)
"""Per-channel standard deviation matching :data:`IMAGENET_MEAN`."""


class BackboneWeightsUnavailableError(UsageError):
    """The requested backbone weights cannot be loaded (no network, missing file)."""


def _imagenet_state_dict() -> dict[str, torch.Tensor]:
    url = ResNet18_Weights.IMAGENET1K_V1.url
    try:
        state: dict[str, torch.Tensor] = torch.hub.load_state_dict_from_url(
            url, progress=False, check_hash=True, map_location="cpu"
        )
    except (OSError, RuntimeError) as exc:  # URLError is an OSError; hash mismatch a RuntimeError
        reason = " ".join(str(exc).split())[:160]
        raise BackboneWeightsUnavailableError(
            f"cannot fetch torchvision's ImageNet ResNet-18 weights "
            f"({type(exc).__name__}: {reason}); "
            f"offline, use --backbone-weights none or a local .pth path "
            f"(or place resnet18-f37072fd.pth in {torch.hub.get_dir()}/checkpoints)"
        ) from exc
    return state


def _file_state_dict(path: Path) -> dict[str, torch.Tensor]:
    if not path.is_file():
        raise BackboneWeightsUnavailableError(
            f"backbone weights {str(path)!r} are neither 'imagenet', 'none' nor an existing file"
        )
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, pickle.UnpicklingError, EOFError, ValueError) as exc:
        raise CorruptFileError(
            f"backbone weights file {path} is not a torch state_dict ({type(exc).__name__}); "
            "re-export it with torch.save(model.state_dict(), path)"
        ) from exc
    if not isinstance(state, dict):
        raise CorruptFileError(
            f"backbone weights file {path} holds a {type(state).__name__}, not a dict"
        )
    return state


def load_resnet18_weights(source: str) -> dict[str, torch.Tensor] | None:
    """The ResNet-18 ``state_dict`` named by ``source``, or ``None`` for ``"none"``."""
    if source == "none":
        return None
    if source == "imagenet":
        return _imagenet_state_dict()
    return _file_state_dict(Path(source).expanduser())


def build_resnet18_features(
    weights: str, in_channels: int = 3, state: dict[str, torch.Tensor] | None = None
) -> nn.Sequential:
    """ResNet-18 without avgpool and fc: ``conv1 .. layer4`` as one ``nn.Sequential``.

    Args:
        weights: ``imagenet``, ``none`` or a path (see the module docstring).
        in_channels: 3 for RGB; 1 for a depth image.
        state: an already loaded state dict to use instead of reading ``weights`` again.
    """
    net = torchvision.models.resnet18(weights=None)
    if state is None:
        state = load_resnet18_weights(weights)
    if state is not None:
        state = {k: v for k, v in state.items() if not k.startswith("fc.")}
        missing, unexpected = net.load_state_dict(state, strict=False)
        missing = [k for k in missing if not k.startswith("fc.")]
        if missing or unexpected:
            raise CorruptFileError(
                f"backbone weights {weights!r} do not fit ResNet-18 "
                f"(missing {missing[:3]}, unexpected {unexpected[:3]}); "
                "use a torchvision resnet18 state_dict"
            )
    if in_channels != 3:
        conv = nn.Conv2d(in_channels, 64, kernel_size=7, stride=2, padding=3, bias=False)
        if state is not None:
            with torch.no_grad():
                summed = net.conv1.weight.sum(dim=1, keepdim=True)
                conv.weight.copy_(summed.expand(-1, in_channels, -1, -1) / in_channels)
        net.conv1 = conv
    return nn.Sequential(
        net.conv1, net.bn1, net.relu, net.maxpool, net.layer1, net.layer2, net.layer3, net.layer4
    )


class ImageNormalizer(nn.Module):
    """RGB in [0, 1] -> ImageNet-standardized input, as a module so it moves with the model."""

    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return (images - self.mean) / self.std

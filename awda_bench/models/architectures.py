"""The model names used on the command line and in snapshots, and how to build each one."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from torch import nn

from awda_bench.errors import UnknownChoiceError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig, TosviConfig, TrunkConfig, config_from_dict
from awda_bench.models.tosvi_net import TosviNet

ARCHITECTURES: tuple[str, ...] = ("awda", "tosvi", "tosvi-depth")
"""Valid architecture names (``--model``; the ``arch`` field of a snapshot)."""

ModelConfig = AwdaConfig | TosviConfig


def arch_of(model: nn.Module) -> str:
    """The architecture name of a built model."""
    if isinstance(model, AwdaNet | TosviNet):
        return model.arch
    raise UnknownChoiceError("model class", type(model).__name__, ["AwdaNet", "TosviNet"])


def config_class(arch: str) -> type[AwdaConfig] | type[TosviConfig]:
    if arch == "awda":
        return AwdaConfig
    if arch in ("tosvi", "tosvi-depth"):
        return TosviConfig
    raise UnknownChoiceError("architecture", arch, ARCHITECTURES)


def default_config(
    arch: str,
    *,
    height_px: int = 240,
    width_px: int = 320,
    backbone_weights: str = "imagenet",
    **trunk: Any,
) -> ModelConfig:
    """The paper's configuration of ``arch`` at the given image size (extra ``TrunkConfig`` fields
    may be overridden by keyword)."""
    trunk_cfg = TrunkConfig(
        image_height_px=height_px,
        image_width_px=width_px,
        backbone_weights=backbone_weights,
        **trunk,
    )
    if arch == "awda":
        return AwdaConfig(trunk=trunk_cfg)
    if arch in ("tosvi", "tosvi-depth"):
        return TosviConfig(trunk=trunk_cfg, use_depth=arch == "tosvi-depth")
    raise UnknownChoiceError("architecture", arch, ARCHITECTURES)


def config_for_arch(arch: str, data: dict[str, Any]) -> ModelConfig:
    """Rebuild the config of ``arch`` from its dict form (as stored in snapshots)."""
    return config_from_dict(config_class(arch), data)


def build_model(config: ModelConfig, load_backbone_weights: bool = True) -> AwdaNet | TosviNet:
    """A freshly initialized model for ``config``; the backbone weights named by the config are read
    unless ``load_backbone_weights`` is False (a snapshot's weights replace them anyway)."""
    if isinstance(config, AwdaConfig):
        return AwdaNet(config, load_backbone_weights)
    return TosviNet(config, load_backbone_weights)


def with_backbone_weights(config: ModelConfig, weights: str) -> ModelConfig:
    """``config`` with another ``trunk.backbone_weights``."""
    return replace(config, trunk=replace(config.trunk, backbone_weights=weights))

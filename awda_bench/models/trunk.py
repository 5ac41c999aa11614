"""The visual trunk shared by AWDA and T-OSVI (seed S2 "Architecture").

Data flow for one sample of ``T`` frames (AWDA: 10 demo frames + o_1, so T = 11)::

    frames (T, 3, H, W) in [0, 1]
      -> ImageNet normalization -> ResNet-18 conv1..layer4 (weights shared by all frames)
      -> features (512, T, h, w)                     h, w = ceil(H/32), ceil(W/32)
      -> + sinusoidal encoding over the flattened (t, y, x) axis
      -> 2 x [SelfAttention3d: Conv3d Q/K/V, 4 heads, dropout, residual, BatchNorm3d]
      -> spatial softmax -> (T, 1024) keypoints
      -> 2-layer MLP (hidden 256) per frame -> (T, feature_dim)

The caller picks the time step it needs (AWDA: the last one, o_1's).
"""

from __future__ import annotations

import torch
from torch import nn

from awda_bench.models.attention import SelfAttention3d, SpaceTimePositionalEncoding, SpatialSoftmax
from awda_bench.models.backbone import FEATURE_CHANNELS, ImageNormalizer, build_resnet18_features
from awda_bench.models.config import TrunkConfig


class VisualTrunk(nn.Module):
    """ResNet-18 features + space-time self-attention + spatial softmax + per-frame MLP."""

    def __init__(self, config: TrunkConfig, load_backbone_weights: bool = True) -> None:
        """``load_backbone_weights=False`` skips reading ``config.backbone_weights`` (random init),
        for models whose weights come from a snapshot next."""
        super().__init__()
        self.config = config
        self.normalize = ImageNormalizer()
        weights = config.backbone_weights if load_backbone_weights else "none"
        self.backbone = build_resnet18_features(weights, in_channels=3)
        self.positional = SpaceTimePositionalEncoding()
        self.attention = nn.Sequential(
            *(
                SelfAttention3d(
                    FEATURE_CHANNELS,
                    config.attention_heads,
                    config.attention_head_dim,
                    config.dropout,
                )
                for _ in range(config.attention_layers)
            )
        )
        self.spatial_softmax = SpatialSoftmax()
        self.mlp = nn.Sequential(
            nn.Linear(2 * FEATURE_CHANNELS, config.hidden_dim),
            nn.ReLU(),
            nn.Linear(config.hidden_dim, config.feature_dim),
        )

    def frame_features(self, frames: torch.Tensor) -> torch.Tensor:
        """``(B, T, 3, H, W)`` RGB in [0, 1] -> ResNet features ``(B, T, 512, h, w)``."""
        b, t = frames.shape[:2]
        flat = frames.reshape(b * t, *frames.shape[2:])
        features = self.backbone(self.normalize(flat))
        return features.reshape(b, t, *features.shape[1:])

    def temporal(self, features: torch.Tensor) -> torch.Tensor:
        """``(B, T, 512, h, w)`` -> per-frame vectors ``(B, T, feature_dim)``."""
        volume = features.permute(0, 2, 1, 3, 4)  # (B, C, T, h, w)
        volume = self.attention(self.positional(volume))
        return self.mlp(self.spatial_softmax(volume))

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        """``(B, T, 3, H, W)`` RGB in [0, 1] -> ``(B, T, feature_dim)``."""
        return self.temporal(self.frame_features(frames))

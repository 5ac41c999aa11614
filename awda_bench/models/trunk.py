"""The visual trunk shared by AWDA and T-OSVI (seed S2 "Architecture").

Data flow for one sample of ``T`` frames (AWDA: 10 demo frames + o_1, so T = 11)::

    frames (T, 3, H, W) in [0, 1]
      -> the backbone (ResNet-18 conv1..layer4, or EfficientNet-Lite0 up to a stage; weights
         shared by all frames; frozen when ``freeze_backbone``: awda_bench.models.frame_encoder)
      -> features (C, T, h, w)     ResNet-18: C = 512, h, w = ceil(H/32), ceil(W/32)
      -> + sinusoidal encoding over the flattened (t, y, x) axis
      -> 2 x [SelfAttention3d: Conv3d Q/K/V, 4 heads, dropout, residual, BatchNorm3d]
      -> spatial softmax -> (T, 1024) keypoints
      -> 2-layer MLP (hidden 256) per frame -> (T, feature_dim)

The caller picks the time step it needs (AWDA: the last one, o_1's). With a cell head
(``demo-to-scene``, ``demo-pointer``) the trunk stops at the backbone and AWDA's head takes the
feature maps (:mod:`awda_bench.models.demo_to_scene`, :mod:`awda_bench.models.demo_pointer`).
"""

from __future__ import annotations

import torch
from torch import nn

from awda_bench.models.attention import SelfAttention3d, SpaceTimePositionalEncoding, SpatialSoftmax
from awda_bench.models.config import TrunkConfig
from awda_bench.models.efficientnet_lite import EfficientNetLiteFeatures
from awda_bench.models.frame_encoder import build_frame_encoder


class VisualTrunk(nn.Module):
    """Backbone features (+ for the ``self-attention`` head: space-time self-attention, spatial
    softmax and a per-frame MLP)."""

    def __init__(self, config: TrunkConfig, load_backbone_weights: bool = True) -> None:
        """``load_backbone_weights=False`` skips reading ``config.backbone_weights`` (random init),
        for models whose weights come from a snapshot next."""
        super().__init__()
        self.config = config
        self.normalize, self.backbone, channels = build_frame_encoder(config, load_backbone_weights)
        self.channels = channels
        """Channels of the backbone's feature map."""
        if config.freeze_backbone:
            self.backbone.requires_grad_(False)
        self.top_blocks = config.finetune_top_blocks
        """Trained blocks at the top of a frozen backbone (0: none)."""
        if self.top_blocks:
            assert isinstance(self.backbone, EfficientNetLiteFeatures)  # TrunkConfig checks it
            for parameter in self.backbone.top_parameters(self.top_blocks):
                parameter.requires_grad_(True)
        if config.head == "self-attention":
            self.positional = SpaceTimePositionalEncoding()
            self.attention = nn.Sequential(
                *(
                    SelfAttention3d(
                        channels,
                        config.attention_heads,
                        config.attention_head_dim,
                        config.dropout,
                    )
                    for _ in range(config.attention_layers)
                )
            )
            self.spatial_softmax = SpatialSoftmax()
            self.mlp = nn.Sequential(
                nn.Linear(2 * channels, config.hidden_dim),
                nn.ReLU(),
                nn.Linear(config.hidden_dim, config.feature_dim),
            )

    def train(self, mode: bool = True) -> VisualTrunk:
        """A frozen backbone stays in eval mode (its batch-norm statistics are part of it), its
        fine-tuned top blocks included."""
        super().train(mode)
        if self.config.freeze_backbone:
            self.backbone.eval()
        return self

    def frame_features(self, frames: torch.Tensor) -> torch.Tensor:
        """``(B, T, 3, H, W)`` RGB in [0, 1] -> backbone features ``(B, T, C, h, w)``."""
        b, t = frames.shape[:2]
        flat = frames.reshape(b * t, *frames.shape[2:])
        if self.config.freeze_backbone:
            with torch.no_grad():
                features = self.frozen_maps(self.normalize(flat))
            features = self.top(features)
        else:
            features = self.backbone(self.normalize(flat))
        return features.reshape(b, t, *features.shape[1:])

    def frozen_maps(self, images: torch.Tensor) -> torch.Tensor:
        """A frozen backbone's part: normalized images ``(N, 3, H, W)`` -> the map a feature
        cache holds (the stage's, or the one entering the fine-tuned top blocks)."""
        if self.top_blocks:
            assert isinstance(self.backbone, EfficientNetLiteFeatures)
            return self.backbone.bottom(images, self.top_blocks)
        return self.backbone(images)

    def top(self, maps: torch.Tensor) -> torch.Tensor:
        """:meth:`frozen_maps`' output (or a cache's) ``(..., C', h, w)`` -> the stage's map
        ``(..., C, h, w)`` through the fine-tuned top blocks; without them, ``maps`` itself."""
        if not self.top_blocks:
            return maps
        assert isinstance(self.backbone, EfficientNetLiteFeatures)
        flat = maps.reshape(-1, *maps.shape[-3:])
        out = self.backbone.top(flat, self.top_blocks)
        return out.reshape(*maps.shape[:-3], *out.shape[1:])

    def temporal(self, features: torch.Tensor, last_frames: int | None = None) -> torch.Tensor:
        """``(B, T, C, h, w)`` -> per-frame vectors ``(B, T, feature_dim)`` (``self-attention``
        head only; the cell heads read the feature maps themselves). ``last_frames = n`` (eval
        mode): the vectors of the last ``n`` frames only ``(B, n, feature_dim)``, the same values,
        the last attention layer querying with those frames' tokens alone."""
        volume = self.positional(features.permute(0, 2, 1, 3, 4))  # (B, C, T, h, w)
        if last_frames is None or not len(self.attention):
            volume = self.attention(volume)
        else:
            for layer in self.attention[:-1]:
                volume = layer(volume)
            volume = self.attention[-1](volume, queries_from=volume.shape[2] - last_frames)
        vectors = self.mlp(self.spatial_softmax(volume))
        return vectors if last_frames is None else vectors[:, -last_frames:]

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        """``(B, T, 3, H, W)`` RGB in [0, 1] -> ``(B, T, feature_dim)``."""
        return self.temporal(self.frame_features(frames))

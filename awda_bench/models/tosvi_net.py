"""The T-OSVI baseline (Dasari & Gupta, 2020) on the shared trunk, with an optional +depth variant.

Frames enter the trunk as ``[demo_1 .. demo_10, o_{t-5} .. o_t]`` (T-OSVI order). Two heads read the
per-frame vectors ``f``:

- policy: ``f(o_t)`` -> discretized logistic mixture over the 4-D action ``a_t``;
- inverse model: ``[f(o_i), f(o_{i+1})]`` -> mixture over ``a_i`` for each consecutive pair in the
  stack (the auxiliary loss of T-OSVI).

``+depth`` (``use_depth``): a second ResNet-18 (1 input channel) encodes each agent frame's wrist
depth image into a vector (global average pool), which is concatenated to every spatial cell of that
frame's RGB features and mixed back to 512 channels by a 1x1 convolution, *before* the attention
layers (late fusion). Demo frames have no depth; their depth vector is zero.

Batch format (images RGB float in [0, 1], channels first; actions in [-1, 1])::

    "demo":    (B, demo_frames, 3, H, W)
    "frames":  (B, frame_stack, 3, H, W)          o_{t-5} .. o_t
    "actions": (B, frame_stack, 4)                a_i taken at frame i: a_t is the policy target,
                                                  a_{t-5} .. a_{t-1} the inverse-model targets
    "depth":   (B, frame_stack, 1, Hd, Wd) [m]    only with use_depth

With a frozen backbone, training batches carry its cached (pooled) feature maps instead of the
images, ``"demo_features" (B, demo_frames, C, h, w)`` and ``"frame_features" (B, frame_stack, C,
h, w)``: what :meth:`TosviNet.frame_features` returns, the same at evaluation. ``+depth`` keeps its
depth ResNet trainable (it is not the frozen RGB trunk), so ``"depth"`` stays raw depth images.

``feature_pool`` > 1 average-pools every frame's backbone map before the attention layers
(:func:`pool_feature_maps`)::

    frame (3, H, W) -> backbone (frozen or not) -> (C, h, w) -> pool f x f -> (C, ceil(h/f),
    ceil(w/f)) -> [+ depth fusion] -> space-time attention over all frames -> spatial softmax
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F
from torch import nn

from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.models.backbone import FEATURE_CHANNELS, build_resnet18_features
from awda_bench.models.config import TosviConfig
from awda_bench.models.logistic_mixture import DiscretizedLogisticMixture
from awda_bench.models.trunk import VisualTrunk

if TYPE_CHECKING:
    from collections.abc import Mapping


def _mlp(inputs: int, hidden: int, outputs: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, outputs))


def pool_feature_maps(maps: torch.Tensor, factor: int) -> torch.Tensor:
    """``(..., C, h, w)`` -> ``(..., C, ceil(h / factor), ceil(w / factor))``: the mean over each
    ``factor x factor`` window (an edge window averages the cells it covers); 1 returns ``maps``."""
    if factor == 1:
        return maps
    lead = maps.shape[:-3]
    flat = maps.reshape(-1, *maps.shape[-3:])
    pooled = F.avg_pool2d(flat, factor, factor, ceil_mode=True)
    return pooled.reshape(*lead, *pooled.shape[1:])


def _init_mixture_output(layer: nn.Module, config: TosviConfig) -> None:
    """Start every component at scale ``config.initial_scale`` (log-scale bias), not PyTorch's ~1:
    a logistic as wide as the whole action range gives the means almost no gradient."""
    assert isinstance(layer, nn.Linear)
    m = config.mixture_components
    with torch.no_grad():
        bias = layer.bias.view(config.action_dim, 3 * m)
        bias[:, 2 * m :] = math.log(config.initial_scale)


class TosviNet(nn.Module):
    """Demo frames + a stack of agent frames (+ wrist depth) -> action distribution."""

    def __init__(self, config: TosviConfig, load_backbone_weights: bool = True) -> None:
        super().__init__()
        self.config = config
        self.trunk = VisualTrunk(config.trunk, load_backbone_weights)
        params = config.action_dim * 3 * config.mixture_components
        self.policy_head = _mlp(config.trunk.feature_dim, config.head_hidden_dim, params)
        self.inverse_head = _mlp(2 * config.trunk.feature_dim, config.head_hidden_dim, params)
        for head in (self.policy_head, self.inverse_head):
            _init_mixture_output(head[-1], config)
        self.depth_backbone: nn.Module | None = None
        self.depth_fusion: nn.Module | None = None
        if config.use_depth:
            # the depth branch is a ResNet-18 whatever the RGB trunk; with an EfficientNet trunk
            # its ImageNet weights (a torchvision download) are not used: it starts at random
            resnet_weights = config.trunk.backbone == "resnet18" and load_backbone_weights
            weights = config.trunk.backbone_weights if resnet_weights else "none"
            self.depth_backbone = build_resnet18_features(weights, in_channels=1)
            c = self.trunk.channels
            self.depth_fusion = nn.Conv2d(c + FEATURE_CHANNELS, c, kernel_size=1)

    @property
    def arch(self) -> str:
        """Architecture name recorded in snapshots: ``tosvi`` or ``tosvi-depth``."""
        return "tosvi-depth" if self.config.use_depth else "tosvi"

    def _check_inputs(
        self, demo: torch.Tensor, frames: torch.Tensor, depth: torch.Tensor | None
    ) -> None:
        cfg = self.config
        size = (cfg.trunk.image_height_px, cfg.trunk.image_width_px)
        if (
            demo.dim() != 5
            or demo.shape[1] != cfg.trunk.demo_frames
            or tuple(demo.shape[-2:]) != size
        ):
            raise UsageError(
                f"demo must be (B, {cfg.trunk.demo_frames}, 3, {size[0]}, {size[1]}); "
                f"got {tuple(demo.shape)}"
            )
        if (
            frames.dim() != 5
            or frames.shape[1] != cfg.frame_stack
            or tuple(frames.shape[-2:]) != size
        ):
            raise UsageError(
                f"frames must be (B, {cfg.frame_stack}, 3, {size[0]}, {size[1]}); "
                f"got {tuple(frames.shape)}"
            )
        if cfg.use_depth:
            dsize = (cfg.depth_height_px, cfg.depth_width_px)
            if (
                depth is None
                or depth.dim() != 5
                or depth.shape[1:3] != (cfg.frame_stack, 1)
                or tuple(depth.shape[-2:]) != dsize
            ):
                got = None if depth is None else tuple(depth.shape)
                raise UsageError(
                    f"depth must be (B, {cfg.frame_stack}, 1, {dsize[0]}, {dsize[1]}) metres; "
                    f"got {got}"
                )

    def depth_vectors(self, depth: torch.Tensor) -> torch.Tensor:
        """Wrist depth ``(B, S, 1, Hd, Wd)`` [m] -> one vector per frame ``(B, S, 512)`` (the depth
        ResNet sees each frame on its own, so a closed-loop policy encodes each frame once)."""
        assert self.depth_backbone is not None
        cfg = self.config
        b, s = depth.shape[:2]
        scaled = depth.clamp(0.0, cfg.max_depth_m) / cfg.max_depth_m * 2.0 - 1.0
        depth_maps = self.depth_backbone(scaled.reshape(b * s, *depth.shape[2:]))
        return depth_maps.mean(dim=(-2, -1)).view(b, s, FEATURE_CHANNELS)

    def fuse_depth(self, features: torch.Tensor, depth_vectors: torch.Tensor) -> torch.Tensor:
        """Frames' maps ``(B, T, C, h, w)`` + one depth vector per frame ``(B, T, 512)`` (zeros
        for demo frames) -> fused maps ``(B, T, C, h, w)``; frame by frame, so a closed-loop
        policy fuses each frame once."""
        assert self.depth_fusion is not None
        b, t, c, h, w = features.shape
        d = depth_vectors.shape[-1]
        tiled = depth_vectors[..., None, None].expand(-1, -1, -1, h, w)
        stacked = torch.cat((features, tiled), dim=2)
        fused = self.depth_fusion(stacked.reshape(b * t, c + d, h, w))
        return fused.view(b, t, c, h, w)

    def _fuse_depth(self, features: torch.Tensor, depth_vec: torch.Tensor) -> torch.Tensor:
        """RGB features ``(B, T, C, h, w)`` + agent depth vectors ``(B, S, 512)`` -> fused."""
        b, t = features.shape[:2]
        s, d = depth_vec.shape[1:]
        demo_zeros = depth_vec.new_zeros(b, t - s, d)
        return self.fuse_depth(features, torch.cat((demo_zeros, depth_vec), dim=1))

    def frame_features(self, frames: torch.Tensor) -> torch.Tensor:
        """``(B, T, 3, H, W)`` RGB in [0, 1] -> each frame's (pooled) backbone map ``(B, T, C, h,
        w)``: what a frozen backbone's feature cache holds, and what a closed-loop policy keeps
        per frame (each frame's map depends on that frame alone)."""
        return pool_feature_maps(self.trunk.frame_features(frames), self.config.feature_pool)

    def forward(
        self, demo: torch.Tensor, frames: torch.Tensor, depth: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mixture parameters: policy ``(B, A, 3M)`` for a_t, inverse ``(B, S-1, A, 3M)``."""
        self._check_inputs(demo, frames, depth)
        features = self.frame_features(torch.cat((demo, frames), dim=1))
        vectors = self.depth_vectors(depth) if depth is not None and self.config.use_depth else None
        return self.heads_from_features(features, vectors)

    def forward_features(
        self,
        demo_features: torch.Tensor,
        frame_features: torch.Tensor,
        depth: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`forward` from :meth:`frame_features`' maps (a frozen backbone's cache):
        ``demo_features (B, demo_frames, C, h, w)``, ``frame_features (B, frame_stack, C, h, w)``
        and, for +depth, the raw ``depth (B, frame_stack, 1, Hd, Wd)`` [m]."""
        cfg = self.config
        b = demo_features.shape[0]
        if (
            demo_features.dim() != 5
            or frame_features.dim() != 5
            or demo_features.shape[1] != cfg.trunk.demo_frames
            or frame_features.shape[:2] != (b, cfg.frame_stack)
            or demo_features.shape[2:] != frame_features.shape[2:]
        ):
            raise UsageError(
                f"feature maps must be demo (B, {cfg.trunk.demo_frames}, C, h, w) and frames "
                f"(B, {cfg.frame_stack}, C, h, w); got {tuple(demo_features.shape)} and "
                f"{tuple(frame_features.shape)}"
            )
        if cfg.use_depth and depth is None:
            raise UsageError("a T-OSVI +depth model needs the wrist depth stack")
        vectors = self.depth_vectors(depth) if depth is not None and cfg.use_depth else None
        return self.heads_from_features(torch.cat((demo_features, frame_features), 1), vectors)

    def heads_from_features(
        self, features: torch.Tensor, depth_vectors: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The part of :meth:`forward` after the per-frame ResNets: ``features`` ``(B, demo_frames +
        frame_stack, C, h, w)`` from :meth:`frame_features` and, for +depth, ``depth_vectors``
        ``(B, frame_stack, 512)`` from :meth:`depth_vectors`. Each frame's features depend on that
        frame alone, so a closed-loop policy computes each frame's once and keeps them."""
        cfg = self.config
        if cfg.use_depth:
            if depth_vectors is None:
                raise UsageError("a T-OSVI +depth model needs the wrist depth stack")
            features = self._fuse_depth(features, depth_vectors)
        vectors = self.trunk.temporal(features)[:, -cfg.frame_stack :]  # (B, S, F)
        b, s = vectors.shape[:2]
        policy = self.policy_head(vectors[:, -1]).view(b, cfg.action_dim, -1)
        pairs = torch.cat((vectors[:, :-1], vectors[:, 1:]), dim=-1)
        params = 3 * cfg.mixture_components  # explicit: a stack of 1 has no pairs
        inverse = self.inverse_head(pairs).view(b, s - 1, cfg.action_dim, params)
        return policy, inverse

    def policy_from_frames(self, frames: torch.Tensor) -> torch.Tensor:
        """Eval mode: the policy mixture ``(B, A, 3M)`` for a_t from every frame's attention input
        ``(B, demo_frames + frame_stack, C, h, w)`` (:meth:`frame_features`; for +depth then
        :meth:`fuse_depth`, demo frames with zero vectors). The same values as
        :meth:`heads_from_features`' policy, at about half its cost: the last attention layer
        queries with a_t's frame alone and the inverse head is skipped."""
        if self.training:
            raise UsageError("TosviNet.policy_from_frames is for eval mode (model.eval())")
        vector = self.trunk.temporal(frames, last_frames=1)[:, 0]
        return self.policy_head(vector).view(frames.shape[0], self.config.action_dim, -1)

    def distribution(self, params: torch.Tensor) -> DiscretizedLogisticMixture:
        return DiscretizedLogisticMixture(params, bins=self.config.action_bins)

    def compute_loss(
        self, batch: Mapping[str, torch.Tensor]
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """Policy NLL of a_t + ``inverse_loss_weight`` x inverse-model NLL of a_{t-5..t-1}
        (0 with ``frame_stack = 1``: no pairs).

        NLLs are summed over action dimensions and averaged over samples (and pairs) [nats].
        Under a caller's ``torch.autocast`` (``[train] precision = "bf16"``) only the forward pass
        runs in the lower precision: the mixture parameters are cast to float32 and the NLLs are
        computed with autocast off.
        """
        if "demo_features" in batch:  # a frozen backbone's cached features
            policy, inverse = self.forward_features(
                batch["demo_features"], batch["frame_features"], batch.get("depth")
            )
        else:
            policy, inverse = self(batch["demo"], batch["frames"], batch.get("depth"))
        policy, inverse = policy.float(), inverse.float()
        actions = batch["actions"]
        with torch.autocast(policy.device.type, enabled=False):
            policy_nll = -self.distribution(policy).log_prob(actions[:, -1]).sum(-1).mean()
            if inverse.shape[1] == 0:  # frame_stack 1: no consecutive pairs, no inverse model
                inverse_nll = policy_nll.new_zeros(())
            else:
                inverse_nll = -self.distribution(inverse).log_prob(actions[:, :-1]).sum(-1).mean()
            loss = policy_nll + self.config.inverse_loss_weight * inverse_nll
        return loss, {
            "loss": float(loss.detach()),
            "policy_nll": float(policy_nll.detach()),
            "inverse_nll": float(inverse_nll.detach()),
        }

    @torch.no_grad()
    def predict_action(
        self,
        demo: torch.Tensor,
        frames: torch.Tensor,
        depth: torch.Tensor | None = None,
        statistic: str = "mode",
    ) -> torch.Tensor:
        """Action ``(B, 4)`` in [-1, 1] (eval mode for the call): ``mode`` (the most probable
        component's mean) or ``mean`` (the mixture mean; the paper tried both, S3)."""
        if statistic not in ("mode", "mean"):
            raise UnknownChoiceError("action statistic", statistic, ("mode", "mean"))
        was_training = self.training
        self.eval()
        try:
            policy, _ = self(demo, frames, depth)
        finally:
            self.train(was_training)
        dist = self.distribution(policy)
        return dist.mode() if statistic == "mode" else dist.mean()

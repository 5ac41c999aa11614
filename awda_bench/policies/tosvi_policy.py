"""``tosvi``, ``tosvi-depth``: a learned closed-loop policy (T-OSVI, one snapshot file).

Per episode (SPEC §6; the AWDA paper's evaluator for the baseline)::

    demo video (demonstrator, other layout) --10 frames--> backbone maps, once per episode
    every step t:  third-person frame o_t --> backbone map (pooled by ``feature_pool``; + wrist
                   depth d_t --> depth ResNet vector, for +depth)
                   [demo features, features of o_{t-5} .. o_t (+ depth vectors)] --> attention
                   --> action mixture
                   a_t = sample | mean | mode of the mixture; gripper command binarized (+1 / -1)

The agent stack is a sliding window of the last ``frame_stack`` frames; at the start of an episode
the missing older frames repeat the first one, exactly as the training samples do
(:class:`~awda_bench.data.datasets.TosviDataset`). The backbone sees each frame on its own (frozen
BatchNorm statistics in eval mode), and so do +depth's depth ResNet and its 1x1 fusion, so each
frame's attention input is computed once and kept (the demo's once per episode): a step costs one
frame through the backbone (and depth ResNet and fusion) plus the attention layers, not sixteen
RGB and six depth frames; and since only a_t is read, the last attention layer queries with o_t's
tokens alone (``TosviNet.policy_from_frames``, exact in eval mode). A snapshot trained on a
frozen backbone's cached features carries that backbone (its weights are in the snapshot), so
evaluation encodes live frames with exactly the trunk whose features training read.

Frames are rendered by the harness camera (the suite's size) and area-downscaled to the snapshot's
input size with OpenCV, as the ``train`` loader downscales the collected frames. The network only
sees images; it never reads simulator state.

**The action is the env's own.** The network's 4-D output (clipped to [-1, 1], gripper
binarized) goes to the env as it is, on every suite: on ManiSkill the ``panda_awda`` controller's
TCP displacement (a fraction of 2 cm) and gripper command; on Meta-World the package's own action
(the hand's mocap target moves ``a[:3] x 1 cm``, ``a[3] > 0`` closes), which is the 4-D
delta-end-effector-plus-gripper space the supplementary normalizes every suite to. So a snapshot
evaluated on Meta-World must have been trained on the actions Meta-World received (the expert's
raw actions), not on the motor primitives' commands that ``awda`` and ``gt-waypoints`` convert
through the Sawyer's mocap lead (:mod:`awda_bench.metaworld.sawyer`): T-OSVI has no primitives,
and on Meta-World the supplementary's normalized space is the environment's action space itself.

``action_select`` (``run --action-select``): ``sample`` (the reference's evaluator, default),
``mean`` (the mixture mean) or ``mode`` (the heaviest component's mean); the AWDA paper compares
them for T-OSVI (seed S3). ``sample`` draws from torch's global generator, which the harness seeds
per episode, so an episode replays identically.
"""

from __future__ import annotations

import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.data.trajectory_file import as_stored
from awda_bench.episode import ClosedLoopPolicy, EpisodeContext, Observations, observations_of
from awda_bench.errors import UnknownChoiceError
from awda_bench.policies.trained_model import load_trained

ACTION_SELECTS: tuple[str, ...] = ("sample", "mean", "mode")
"""How an action is read from the predicted mixture; the first is the default."""

TOSVI_ARCHS: tuple[str, ...] = ("tosvi", "tosvi-depth")
"""Snapshot architectures this policy runs (the ``no-waypoints`` ablation trains a ``tosvi`` net)."""


def tosvi_method_name(base: str, action_select: str) -> str:
    """``tosvi`` + ``mean`` -> ``tosvi-mean``; the default selection keeps the base name."""
    if action_select not in ACTION_SELECTS:
        raise UnknownChoiceError("--action-select", action_select, ACTION_SELECTS)
    return base if action_select == ACTION_SELECTS[0] else f"{base}-{action_select}"


def _resize(frame: np.ndarray, height: int, width: int, nearest: bool = False) -> np.ndarray:
    import cv2

    if frame.shape[:2] == (height, width):
        return frame
    interpolation = cv2.INTER_NEAREST if nearest else cv2.INTER_AREA
    return cv2.resize(frame, (width, height), interpolation=interpolation)


class TosviPolicy(ClosedLoopPolicy):
    """Closed loop: one forward pass of a :class:`~awda_bench.models.tosvi_net.TosviNet` per step."""

    name = "tosvi"

    def __init__(
        self, snapshot: str | Path, action_select: str = "sample", arch: str | None = None
    ) -> None:
        from awda_bench.models.tosvi_net import TosviNet

        if action_select not in ACTION_SELECTS:
            raise UnknownChoiceError("--action-select", action_select, ACTION_SELECTS)
        wanted = (arch,) if arch is not None else TOSVI_ARCHS
        trained = load_trained(
            snapshot,
            wanted,
            TosviNet,
            f"pick a checkpoint directory trained with --method {' / '.join(wanted)} "
            "(or --ablation no-waypoints)",
        )
        self.device = trained.device
        self.jpeg_quality = trained.jpeg_quality
        """Live frames are JPEG-compressed at this quality first, as the training frames were."""
        model = trained.model
        model.eval()
        self.name = trained.arch  # "tosvi" or "tosvi-depth"
        self.model: TosviNet = model
        self.action_select = action_select
        cfg = model.config
        self.image_size = (cfg.trunk.image_height_px, cfg.trunk.image_width_px)
        self.depth_size = (cfg.depth_height_px, cfg.depth_width_px)
        self.use_depth = cfg.use_depth
        self.frame_stack = cfg.frame_stack
        self._observations: Observations | None = None
        self._demo_features: Any = None
        self._frames: deque[Any] = deque(maxlen=self.frame_stack)
        """The attention inputs of o_{t-5} .. o_t (+depth: already fused with their depth)."""
        self.inference_s = 0.0
        """Wall time of this episode's forward passes [s] (rendering excluded)."""
        self.encode_s = 0.0
        """The part of :attr:`inference_s` spent encoding frames (the demo's once, then one
        live frame a step: the trunk, + depth ResNet and fusion) [s]; the rest is the attention
        layers and the policy head."""
        self.steps = 0
        """Actions produced this episode."""

    def _to_tensor(self, frames: np.ndarray) -> Any:
        """``(N, H, W, 3)`` uint8 at any size -> ``(1, N, 3, h, w)`` float on the model's device."""
        from awda_bench.models.predict import frames_to_tensor

        h, w = self.image_size
        stored = as_stored(frames, self.jpeg_quality)  # as the training frames were
        small = np.stack([_resize(f, h, w) for f in stored])
        return frames_to_tensor(small, h, w).unsqueeze(0).to(self.device)

    def reset(self, ctx: EpisodeContext) -> None:
        import torch

        from awda_bench.models.backbone import FEATURE_CHANNELS  # the depth vectors' length

        observations = observations_of(ctx)
        self._observations = observations
        demo = observations.demo_frames(self.model.config.trunk.demo_frames)
        start = time.perf_counter()
        with torch.no_grad():
            maps = self.model.frame_features(self._to_tensor(np.asarray(demo)))
            if self.use_depth:  # demo frames have no depth: fused with zero vectors, once
                zeros = maps.new_zeros(*maps.shape[:2], FEATURE_CHANNELS)
                maps = self.model.fuse_depth(maps, zeros)
            self._demo_features = maps
        self.inference_s = time.perf_counter() - start
        self.encode_s = self.inference_s
        self._frames.clear()
        self.steps = 0

    def _observe(self) -> None:
        """Render o_t (and d_t), encode it, push it on the stacks (padding the first one)."""
        import torch

        assert self._observations is not None
        rgb = self._observations.rgb()[0]
        depth_m = None
        if self.use_depth:
            h, w = self.depth_size
            depth_m = _resize(self._observations.wrist_depth().depth_m[0], h, w, nearest=True)
        start = time.perf_counter()
        with torch.no_grad():
            features = self.model.frame_features(self._to_tensor(rgb[None]))  # (1, 1, C, h, w)
            if depth_m is not None:
                tensor = torch.from_numpy(depth_m.astype(np.float32)).to(self.device)
                vector = self.model.depth_vectors(tensor[None, None, None])  # (1, 1, 512)
                features = self.model.fuse_depth(features, vector)
        encode = time.perf_counter() - start
        self.inference_s += encode
        self.encode_s += encode
        copies = self.frame_stack if not self._frames else 1
        for _ in range(copies):
            self._frames.append(features[:, 0])

    def act(self, obs: Any) -> np.ndarray:
        import torch

        if self._demo_features is None:
            raise RuntimeError("TosviPolicy.act() before reset(ctx)")
        self._observe()
        start = time.perf_counter()
        with torch.no_grad():
            features = torch.cat((self._demo_features, torch.stack(tuple(self._frames), 1)), 1)
            policy = self.model.policy_from_frames(features)
            dist = self.model.distribution(policy)
            if self.action_select == "sample":
                action = dist.sample()
            elif self.action_select == "mean":
                action = dist.mean()
            else:
                action = dist.mode()
        self.inference_s += time.perf_counter() - start
        self.steps += 1
        out = action.float().cpu().numpy().reshape(1, -1).clip(-1.0, 1.0)
        out[:, 3] = np.where(out[:, 3] > 0.0, 1.0, -1.0)  # gripper command binarized
        return out.astype(np.float32)

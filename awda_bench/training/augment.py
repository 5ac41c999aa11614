"""Training-time data treatment of a collated batch: shifts, colour jitter, then ADM.

Applied to training batches only (never validation), in this order, per sample ``i``::

    demo frames  (B, Td, 3, H, W) --shift s_i^demo, jitter j_i^demo--+
    agent frames (B, 3, H, W) or (B, S, 3, H, W) --shift s_i, jitter j_i--+--> ADM --> model

- **Shift**: all frames of a group (the sample's demo, or its agent frames) move together by
  ``(dy, dx)`` integer pixels, ``|dy|, |dx| <= shift_px``, edges replicated. No flips, no scaling:
  the labels are world-frame metres from a fixed camera.
- **Colour jitter**: brightness, contrast (about the frame's mean grey) and saturation (about
  each pixel's grey) factors ~ U(1 - a, 1 + a), one draw per group; result clipped to [0, 1].
- **Asymmetric Demonstration Mixup** (seed S2, reference code): ``lambda_i ~ U(low, high)``;
  partner ``p = (i + 1) mod B``; every agent frame ``x <- lambda_i x + (1 - lambda_i) a_p`` with
  ``a_p`` the partner's FIRST agent frame, every demo frame ``c <- lambda_i c + (1 - lambda_i)
  c_p`` with ``c_p`` the partner demo's FIRST frame (``adm_mix_agent = false``: the demo frames
  only). Labels (trajectory, actions, head) are never mixed. (The reference mixes
  ImageNet-normalized images; normalization is per-channel affine and the weights sum to 1, so
  mixing [0, 1] images is the same.) For T-OSVI batches the agent frames
  are the frame stack and the partner's first agent frame is the oldest frame of its stack.

With a frozen backbone (batches of cached feature maps, ``"demo_features"`` and
``"first_frame_features"``, or T-OSVI's ``"frame_features"`` stack) there are no images to shift
or jitter: only ADM applies, mixing the feature maps with the same rule (the backbone is not
linear, so this is ADM in feature space, a deviation from the reference, which mixes images).

All draws come from a generator seeded by ``(seed, step)``, so a resumed run (or any re-run)
treats batch ``step`` identically and the global RNG is untouched.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

from awda_bench.training.recipe import AugmentRecipe

AGENT_KEYS: tuple[str, ...] = ("first_frame", "frames")
"""Batch keys holding agent frames (AWDA: ``first_frame``; T-OSVI: ``frames``)."""
AGENT_FEATURE_KEYS: tuple[str, ...] = ("first_frame_features", "frame_features")
"""The same, as cached feature maps (AWDA: ``(B, C, h, w)``; T-OSVI: ``(B, S, C, h, w)``)."""


def step_generator(seed: int, step: int) -> torch.Generator:
    """The CPU generator batch ``step``'s draws come from."""
    return torch.Generator().manual_seed(0x5EED_0000 + seed * 1_000_003 + step)


def shift_frames(
    frames: torch.Tensor, dy: torch.Tensor, dx: torch.Tensor, pad: int
) -> torch.Tensor:
    """``frames (B, T, C, H, W)`` translated per sample by ``(dy[b], dx[b])`` px, edges replicated."""
    if pad == 0:
        return frames
    b, t, c, h, w = frames.shape
    padded = torch.nn.functional.pad(
        frames.reshape(b, t * c, h, w), (pad, pad, pad, pad), mode="replicate"
    )
    out = torch.empty_like(frames)
    for i in range(b):
        y0, x0 = pad - int(dy[i]), pad - int(dx[i])
        out[i] = padded[i, :, y0 : y0 + h, x0 : x0 + w].reshape(t, c, h, w)
    return out


def jitter_colour(
    frames: torch.Tensor, brightness: torch.Tensor, contrast: torch.Tensor, saturation: torch.Tensor
) -> torch.Tensor:
    """``frames (B, T, 3, H, W)`` in [0, 1] with per-sample factors ``(B,)``; clipped to [0, 1]."""
    view = (-1, 1, 1, 1, 1)
    weights = torch.tensor([0.299, 0.587, 0.114], dtype=frames.dtype, device=frames.device)
    out = frames * brightness.view(view)
    grey = (out * weights.view(1, 1, 3, 1, 1)).sum(dim=2, keepdim=True)
    mean = grey.mean(dim=(-2, -1), keepdim=True)
    out = (out - mean) * contrast.view(view) + mean
    grey = (out * weights.view(1, 1, 3, 1, 1)).sum(dim=2, keepdim=True)
    out = (out - grey) * saturation.view(view) + grey
    return out.clamp(0.0, 1.0)


def asymmetric_demo_mixup(
    demo: torch.Tensor, agent: torch.Tensor, lam: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """ADM (module docstring): ``demo (B, Td, 3, H, W)``, ``agent (B, S, 3, H, W)``, ``lam (B,)``."""
    view = (-1, 1, 1, 1, 1)
    lam = lam.to(demo.dtype).view(view)
    partner_demo = torch.roll(demo[:, :1], shifts=-1, dims=0)  # partner's first demo frame
    partner_agent = torch.roll(agent[:, :1], shifts=-1, dims=0)  # partner's first agent frame
    return lam * demo + (1 - lam) * partner_demo, lam * agent + (1 - lam) * partner_agent


@dataclass(frozen=True)
class BatchTreatment:
    """The transform :func:`awda_bench.training.loop.train` applies to each training batch."""

    augment: AugmentRecipe
    """Shift, jitter and ADM parameters."""
    adm: bool
    """Apply ADM (the column decides)."""
    seed: int
    """Recipe seed: draws depend on ``(seed, step)`` only."""

    def __call__(self, batch: dict[str, Any], step: int) -> dict[str, Any]:
        if "demo_features" in batch:
            return self._mix_features(batch, step)
        key = next((k for k in AGENT_KEYS if k in batch), None)
        if key is None or "demo" not in batch:
            return batch
        g = step_generator(self.seed, step)
        demo = batch["demo"]
        agent = batch[key] if key == "frames" else batch[key].unsqueeze(1)
        b = demo.shape[0]
        groups = []
        for frames in (demo, agent):
            frames = self._jitter(self._shift(frames, g, b), g, b)
            groups.append(frames)
        demo, agent = groups
        if self.adm and b > 1:
            a = self.augment
            lam = a.adm_lambda_low + (a.adm_lambda_high - a.adm_lambda_low) * torch.rand(
                b, generator=g
            )
            mixed_demo, mixed_agent = asymmetric_demo_mixup(demo, agent, lam.to(demo.device))
            demo, agent = mixed_demo, mixed_agent if a.adm_mix_agent else agent
        out = dict(batch)
        out["demo"] = demo
        out[key] = agent if key == "frames" else agent[:, 0]
        return out

    def _mix_features(self, batch: dict[str, Any], step: int) -> dict[str, Any]:
        demo = batch["demo_features"]
        b = demo.shape[0]
        if not self.adm or b < 2:
            return batch
        key = next(k for k in AGENT_FEATURE_KEYS if k in batch)
        stack = key == "frame_features"
        a = self.augment
        g = step_generator(self.seed, step)
        lam = a.adm_lambda_low + (a.adm_lambda_high - a.adm_lambda_low) * torch.rand(b, generator=g)
        agent = batch[key] if stack else batch[key].unsqueeze(1)
        mixed_demo, mixed_agent = asymmetric_demo_mixup(demo, agent, lam.to(demo.device))
        if not a.adm_mix_agent:
            return {**batch, "demo_features": mixed_demo}
        return {
            **batch,
            "demo_features": mixed_demo,
            key: mixed_agent if stack else mixed_agent[:, 0],
        }

    def _shift(self, frames: torch.Tensor, g: torch.Generator, b: int) -> torch.Tensor:
        s = self.augment.shift_px
        if s == 0:
            return frames
        dy = torch.randint(-s, s + 1, (b,), generator=g)
        dx = torch.randint(-s, s + 1, (b,), generator=g)
        return shift_frames(frames, dy, dx, s)

    def _jitter(self, frames: torch.Tensor, g: torch.Generator, b: int) -> torch.Tensor:
        a = self.augment
        if a.brightness == a.contrast == a.saturation == 0.0:
            return frames
        factors = [
            1.0 + r * (2.0 * torch.rand(b, generator=g) - 1.0)
            for r in (a.brightness, a.contrast, a.saturation)
        ]
        return jitter_colour(frames, *(f.to(frames.device, frames.dtype) for f in factors))

"""Tiny synthetic datasets in the models' batch formats, for tests, ``describe`` and benchmarks.

Images are seeded noise (each sample distinct, so a network can tell samples apart and overfit
them); targets are known, so a fit can be checked against the truth:

- :class:`SyntheticWaypointDataset`: each sample's ground-truth trajectory is the dense polyline
  (:func:`interpolate_polyline`) from a start point through ``num_waypoints`` random waypoints, the
  grasp flag set on the waypoints in ``grasped``; the true waypoints are kept in ``"waypoints"``
  (not used by the loss).
- :class:`SyntheticActionDataset`: random frames and random actions in [-1, 1] (T-OSVI format).
- :func:`random_forward_inputs`: one random batch of a network's forward-pass inputs (``describe``,
  ``bench inference``).
"""

from __future__ import annotations

import torch

from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.tosvi_net import TosviNet
from awda_bench.models.waypoint_loss import interpolate_polyline

WORKSPACE_LOW_M = (-0.25, -0.25, 0.02)
"""Lower corner of the box synthetic waypoints are drawn in [m]."""
WORKSPACE_HIGH_M = (0.25, 0.25, 0.35)
"""Upper corner of the box synthetic waypoints are drawn in [m]."""


class SyntheticWaypointDataset:
    """AWDA samples: demo, first_frame, trajectory, head (+ ``waypoints``, the truth)."""

    def __init__(
        self,
        size: int,
        *,
        height_px: int,
        width_px: int,
        demo_frames: int,
        num_waypoints: int = 5,
        points_per_segment: int = 10,
        grasped: tuple[int, ...] = (2, 3),
        num_heads: int = 2,
        seed: int = 0,
    ) -> None:
        g = torch.Generator().manual_seed(seed)
        low, high = torch.tensor(WORKSPACE_LOW_M), torch.tensor(WORKSPACE_HIGH_M)
        self.demo = torch.rand(size, demo_frames, 3, height_px, width_px, generator=g)
        self.first_frame = torch.rand(size, 3, height_px, width_px, generator=g)
        nodes = low + (high - low) * torch.rand(size, num_waypoints + 1, 3, generator=g)
        flags = torch.zeros(size, num_waypoints + 1, 1)
        for w in grasped:
            flags[:, w + 1] = 1.0  # waypoint index w is node w + 1 (node 0 is the start)
        self.waypoints = torch.cat((nodes[:, 1:], flags[:, 1:]), dim=-1)  # (N, W, 4)
        # The truth is the loss's own polyline through the true waypoints (attributes interpolated
        # linearly too), so the true waypoints are an exact minimizer of the 5-waypoint set's loss.
        full = torch.cat((nodes, flags), dim=-1)  # (N, W + 1, 4)
        self.trajectory = interpolate_polyline(full[:, 0], full[:, 1:], points_per_segment)
        self.head = torch.arange(size) % num_heads

    def __len__(self) -> int:
        return self.demo.shape[0]

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {
            "demo": self.demo[i],
            "first_frame": self.first_frame[i],
            "trajectory": self.trajectory[i],
            "head": self.head[i],
            "waypoints": self.waypoints[i],
        }


class SyntheticActionDataset:
    """T-OSVI samples: demo, frames, actions (+ ``depth`` [m] when ``depth_size`` is given)."""

    def __init__(
        self,
        size: int,
        *,
        height_px: int,
        width_px: int,
        demo_frames: int,
        frame_stack: int,
        action_dim: int = 4,
        depth_size: tuple[int, int] | None = None,
        seed: int = 0,
    ) -> None:
        g = torch.Generator().manual_seed(seed)
        self.demo = torch.rand(size, demo_frames, 3, height_px, width_px, generator=g)
        self.frames = torch.rand(size, frame_stack, 3, height_px, width_px, generator=g)
        self.actions = torch.rand(size, frame_stack, action_dim, generator=g) * 2.0 - 1.0
        self.depth = (
            0.2 + 1.0 * torch.rand(size, frame_stack, 1, *depth_size, generator=g)
            if depth_size is not None
            else None
        )

    def __len__(self) -> int:
        return self.demo.shape[0]

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        sample = {"demo": self.demo[i], "frames": self.frames[i], "actions": self.actions[i]}
        if self.depth is not None:
            sample["depth"] = self.depth[i]
        return sample


def random_forward_inputs(
    model: AwdaNet | TosviNet, batch: int, device: torch.device
) -> tuple[torch.Tensor, ...]:
    """Random positional inputs of ``model``'s forward pass at its configured image size, on
    ``device``: AwdaNet ``(demo, first_frame, head)``, TosviNet ``(demo, frames[, depth])``."""
    trunk = model.config.trunk
    h, w = trunk.image_height_px, trunk.image_width_px
    demo = torch.rand(batch, trunk.demo_frames, 3, h, w, device=device)
    if isinstance(model, AwdaNet):
        return (
            demo,
            torch.rand(batch, 3, h, w, device=device),
            torch.zeros(batch, dtype=torch.long, device=device),
        )
    cfg = model.config
    frames = torch.rand(batch, cfg.frame_stack, 3, h, w, device=device)
    if cfg.use_depth:
        depth = torch.rand(
            batch, cfg.frame_stack, 1, cfg.depth_height_px, cfg.depth_width_px, device=device
        )
        return demo, frames, depth
    return demo, frames

"""Inference: camera frames in, the 5 attributed waypoints out.

Returned array ``(S, 3 + k)`` (S = 5 with the paper's config), one row per waypoint in execution
order:

- columns 0..2: TCP position x, y, z in metres, in the frame of the training targets (this
  project: the ManiSkill world frame);
- columns 3..3+k-1: attribute probabilities in [0, 1] (sigmoid of the logits); column 3 is
  *object grasped* (> 0.5: the segment ending at this waypoint is travelled holding the object).
"""

from __future__ import annotations

import numpy as np
import torch

from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.models.awda_net import HEAD_NAMES, AwdaNet


def frames_to_tensor(
    frames: np.ndarray | torch.Tensor, height_px: int, width_px: int
) -> torch.Tensor:
    """Images ``(..., H, W, 3)`` uint8 (camera layout) or ``(..., 3, H, W)`` float in [0, 1] ->
    float ``(..., 3, H, W)`` in [0, 1]. The size must already be ``height_px x width_px``."""
    tensor = torch.as_tensor(frames)
    if tensor.dtype == torch.uint8:
        if tensor.shape[-1] != 3:
            raise UsageError(f"uint8 frames must be (..., H, W, 3); got {tuple(tensor.shape)}")
        tensor = tensor.movedim(-1, -3).float() / 255.0
    elif tensor.shape[-3] != 3:
        raise UsageError(
            f"float frames must be (..., 3, H, W) in [0, 1]; got {tuple(tensor.shape)}"
        )
    if tuple(tensor.shape[-2:]) != (height_px, width_px):
        raise UsageError(
            f"frames are {tensor.shape[-2]}x{tensor.shape[-1]} but the model expects "
            f"{height_px}x{width_px}; render the camera at the model's image size"
        )
    return tensor.float()


@torch.no_grad()
def predict_waypoints(
    model: AwdaNet,
    demo_frames: np.ndarray | torch.Tensor,
    first_frame: np.ndarray | torch.Tensor,
    *,
    head: str = "task",
    camera: int = 0,
) -> np.ndarray:
    """One forward pass in eval mode; returns the largest set ``(S, 3 + k)`` as float64 numpy.

    Args:
        model: a trained :class:`AwdaNet`.
        demo_frames: ``(demo_frames, H, W, 3)`` uint8 or ``(demo_frames, 3, H, W)`` float.
        first_frame: ``(H, W, 3)`` uint8 or ``(3, H, W)`` float: the agent's first frame.
        head: ``task`` (default, for real tasks) or ``synthesized``.
        camera: the index of the scene's camera among the config's (``camera_*``; the cell heads
            vote on its rays).
    """
    cfg = model.config
    if head not in HEAD_NAMES[: cfg.num_heads]:
        raise UnknownChoiceError("waypoint head", head, HEAD_NAMES[: cfg.num_heads])
    h, w = cfg.trunk.image_height_px, cfg.trunk.image_width_px
    device = next(model.parameters()).device
    demo = frames_to_tensor(demo_frames, h, w).unsqueeze(0).to(device)
    first = frames_to_tensor(first_frame, h, w).unsqueeze(0).to(device)
    head_index = torch.tensor([HEAD_NAMES.index(head)], device=device)
    camera_index = torch.tensor([camera], device=device)
    was_training = model.training
    model.eval()
    try:
        raw = model(demo, first, head_index, camera_index)
    finally:
        model.train(was_training)
    largest = model.waypoint_sets(raw)[-1][0]  # (S, 3 + k)
    out = torch.cat((largest[:, :3], torch.sigmoid(largest[:, 3:])), dim=-1)
    return out.double().cpu().numpy()

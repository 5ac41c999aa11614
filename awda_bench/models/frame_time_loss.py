r"""The frame-time loss: each waypoint's choice of demo frame supervised by *when* its path
reaches it (``[model] demo_frame_time_weight``; a deviation: the reference has no such loss).

With demo heights (:mod:`awda_bench.models.cell_readout`) a waypoint takes the height of the demo
frame it chooses, but nothing in the Soft-DTW loss says which frame that should be: the loss matches
a path to the trajectory, not a waypoint to a moment, and on Meta-World the choice stayed spread
over the whole demo after 24,000 steps while each cell's vote took the height
(reports/learned/recipe-study-metaworld.md, session 44). This loss names the moment::

    E_s = dR_s / dDelta_s        Soft-DTW's expected alignment of set s's polyline with the
                                 agent's trajectory (T points, uniform in time over its episode)
    tau_j = argmin { Delta_s[n_j, t] : E_s[n_j, t] >= max_t E_s[n_j, t] / 2 } / (T - 1)
                                 the fraction of the episode at which the path reaches waypoint j:
                                 of the trajectory points aligned with its node n_j of the
                                 polyline (n_j = (i + 1) P for the set's i-th waypoint), the
                                 nearest (a set's last node is aligned with every point after
                                 the one it stands for, a pause with a run of points)
    q_j(k) = max(0, 1 - |tau_j (Td - 1) - k|)
                                 the demo frames at the same fraction of the demo (its Td frames
                                 sit at round(linspace(0, T_d, Td))), linearly interpolated
    loss = mean_j  - sum_k q_j(k) log softmax_k(when_j)

The alignment is read off the prediction (detached) and the trajectory, so the target moves with
the path: a waypoint the loss matches to the lift takes the demo's frame of the lift, and with it
the demonstrator's height there. Demo and agent are episodes of one task, scripted to the same
phases, so equal fractions of their episodes are the same moment of the task.

``[model] demo_frame_time_source = "rule"`` takes ``tau`` from the agent's trajectory alone
(:func:`rule_times`): a set of K waypoints is taught the K moments the gt-waypoints rule picks on
it (:func:`awda_bench.waypoints.extract_waypoint_indices`), so the set's third waypoint on
pick-and-place is the lift over the wall whatever the path does (with ``"path"`` a path that
spends a waypoint on the descent teaches the choice that timing).
"""

from __future__ import annotations

import functools

import numpy as np
import torch
import torch.nn.functional as F

from awda_bench.errors import UsageError
from awda_bench.models.waypoint_loss import (
    PolylineArgs,
    interpolate_polyline,
    set_sizes,
    split_waypoint_sets,
    to_cost_space,
)
from awda_bench.soft_dtw.core import soft_dtw_from_cost, squared_euclidean_cost
from awda_bench.waypoints import extract_waypoint_indices


def waypoint_times(
    waypoints: torch.Tensor, trajectory: torch.Tensor, polylines: PolylineArgs
) -> torch.Tensor:
    """``tau`` ``(B, S(S+1)/2)`` in [0, 1]: the fraction of the agent's episode at which the
    Soft-DTW alignment matches each waypoint (module docstring; no gradient). Arguments as
    :func:`awda_bench.models.waypoint_loss.multi_waypoint_sdtw_loss`'s."""
    num_sets, points_per_segment = polylines["num_sets"], polylines["points_per_segment"]
    gamma, scale = polylines["gamma"], polylines["attribute_scale"]
    target = to_cost_space(trajectory.detach().float(), scale, logits=False)
    predicted = to_cost_space(waypoints.detach().float(), scale, logits=True)
    start = target[:, 0]
    times = []
    with torch.enable_grad():
        for wp in split_waypoint_sets(predicted, num_sets):
            line = interpolate_polyline(start, wp, points_per_segment)
            cost = squared_euclidean_cost(line, target).requires_grad_(True)
            (alignment,) = torch.autograd.grad(soft_dtw_from_cost(cost, gamma).sum(), cost)
            nodes = alignment[:, points_per_segment::points_per_segment]  # (B, j, T)
            aligned = nodes >= 0.5 * nodes.amax(-1, keepdim=True)
            near = cost.detach()[:, points_per_segment::points_per_segment]
            times.append(near.masked_fill(~aligned, float("inf")).argmin(-1))
    return torch.cat(times, dim=1).to(target.dtype) / max(target.shape[1] - 1, 1)


def rule_times(trajectory: torch.Tensor, num_sets: int) -> torch.Tensor:
    """``tau`` ``(B, S(S+1)/2)`` in [0, 1] from the trajectory alone: for the set of K waypoints,
    the fractions of the episode at the K steps the gt-waypoints rule picks on the agent's
    trajectory ``(B, P, 3 + k)`` (its attributes those > 0.5; fewer steps than K repeat the
    last). No gradient; each trajectory's are computed once (an episode stands in many batches)."""
    points = trajectory.detach().float().cpu().numpy()
    times = [_rule_times_of(sample.tobytes(), sample.shape, num_sets) for sample in points]
    return torch.from_numpy(np.stack(times)).to(trajectory.device)


@functools.lru_cache(maxsize=1 << 16)
def _rule_times_of(raw: bytes, shape: tuple[int, int], num_sets: int) -> np.ndarray:
    """:func:`rule_times` of one trajectory, given as its float32 bytes and shape."""
    sample = np.frombuffer(raw, np.float32).reshape(shape)
    path, attributes = sample[:, :3], sample[:, 3:] > 0.5
    times = []
    for k in set_sizes(num_sets):
        picked = extract_waypoint_indices(path, attributes, K=k)
        times.append(np.concatenate([picked, np.repeat(picked[-1:], k - len(picked))]))
    return (np.concatenate(times) / max(len(path) - 1, 1)).astype(np.float32)


def frame_targets(times: torch.Tensor, frames: int) -> torch.Tensor:
    """``(B, W)`` fractions in [0, 1] -> ``(B, W, frames)``: weights on the demo frames at the
    same fraction of the demo, linearly interpolated between the two nearest (sum 1)."""
    position = times.clamp(0.0, 1.0)[..., None] * (frames - 1)
    k = torch.arange(frames, dtype=times.dtype, device=times.device)
    return (1.0 - (position - k).abs()).clamp_min(0.0)


def frame_time_loss(
    frame_logits: torch.Tensor, times: torch.Tensor
) -> tuple[torch.Tensor, dict[str, float]]:
    """Cross-entropy of the choice of demo frame ``frame_logits (B, W, Td)`` against the frames
    at each waypoint's matched time ``times (B, W)`` (:func:`waypoint_times`), and what it
    reports: the loss and the mean |chosen - matched| fraction of the episode
    (``frame_time_gap``)."""
    if frame_logits.dim() != 3 or frame_logits.shape[:2] != times.shape:
        raise UsageError(
            f"frame logits (B, W, Td) must match the waypoints' times (B, W): "
            f"{tuple(frame_logits.shape)} vs {tuple(times.shape)}"
        )
    frames = frame_logits.shape[-1]
    target = frame_targets(times, frames)
    log_choice = F.log_softmax(frame_logits.float(), dim=-1)
    loss = -(target * log_choice).sum(-1).mean()
    k = torch.arange(frames, dtype=times.dtype, device=times.device) / max(frames - 1, 1)
    chosen = (log_choice.detach().exp() * k).sum(-1)
    gap = float((chosen - times).abs().mean())
    return loss, {"frame_time": float(loss.detach()), "frame_time_gap": gap}

r"""The multi-waypoint Soft-DTW loss (seed S2 "Loss Computation").

Waypoint layout: the network predicts ``S`` sets (paper: S = 5) with 1, 2, ..., S waypoints, flat
in that order along one axis of length ``S (S + 1) / 2`` (15)::

    index:  0 | 1 2 | 3 4 5 | 6 7 8 9 | 10 11 12 13 14
    set:    1 |  2  |   3   |    4    |       5

Each waypoint is ``3 + k`` numbers: TCP position xyz [m] then k attribute *logits* (attribute 0 =
object grasped). For the loss, each set is prefixed with the current end-effector point ``start``
and linearly interpolated, ``P`` points per segment, into a dense polyline of ``j P + 1`` points::

    start ----P---- w1 ----P---- w2 ... wj        (points at start + (w1 - start) * i / P, ...)

Attributes enter the cost as ``attribute_scale * probability`` (prediction: sigmoid of the logit;
ground truth: the 0/1 flag), so the reference weighting "TCP xyz + 0.2 x grasp flag" is
``attribute_scale = 0.2``. The loss is the Soft-DTW (squared Euclidean cost, temperature gamma)
between each polyline and the ground-truth trajectory points, averaged over the batch and the S
sets.
"""

from __future__ import annotations

from typing import TypedDict

import torch

from awda_bench.errors import UsageError
from awda_bench.soft_dtw.core import soft_dtw


class PolylineArgs(TypedDict):
    """The keyword arguments that say how waypoint sets become paths and meet a trajectory
    (:func:`multi_waypoint_sdtw_loss`; :class:`AwdaConfig` holds them)."""

    num_sets: int
    points_per_segment: int
    gamma: float
    attribute_scale: float


def set_sizes(num_sets: int) -> list[int]:
    """``[1, 2, ..., num_sets]``."""
    return list(range(1, num_sets + 1))


def split_waypoint_sets(waypoints: torch.Tensor, num_sets: int) -> list[torch.Tensor]:
    """``(B, S(S+1)/2, D)`` -> ``[(B, 1, D), (B, 2, D), ..., (B, S, D)]`` (views, no copy)."""
    expected = num_sets * (num_sets + 1) // 2
    if waypoints.shape[-2] != expected:
        raise UsageError(
            f"expected {expected} waypoints for {num_sets} sets, got shape {tuple(waypoints.shape)}"
        )
    return list(torch.split(waypoints, set_sizes(num_sets), dim=-2))


def interpolate_polyline(
    start: torch.Tensor, waypoints: torch.Tensor, points_per_segment: int
) -> torch.Tensor:
    """Dense polyline from ``start (B, D)`` through ``waypoints (B, j, D)``: ``(B, j P + 1, D)``."""
    nodes = torch.cat((start.unsqueeze(1), waypoints), dim=1)  # (B, j+1, D)
    seg_start, seg_end = nodes[:, :-1], nodes[:, 1:]
    t = (
        torch.arange(points_per_segment, device=nodes.device, dtype=nodes.dtype)
        / points_per_segment
    )
    points = seg_start.unsqueeze(2) + t.view(1, 1, -1, 1) * (seg_end - seg_start).unsqueeze(2)
    b, j, p, d = points.shape
    return torch.cat((points.reshape(b, j * p, d), nodes[:, -1:]), dim=1)


def to_cost_space(points: torch.Tensor, attribute_scale: float, logits: bool) -> torch.Tensor:
    """xyz unchanged; attributes -> ``attribute_scale * p`` (``p = sigmoid`` if ``logits``)."""
    attributes = points[..., 3:]
    if logits:
        attributes = torch.sigmoid(attributes)
    return torch.cat((points[..., :3], attribute_scale * attributes), dim=-1)


def multi_waypoint_sdtw_loss(
    waypoints: torch.Tensor,
    trajectory: torch.Tensor,
    *,
    num_sets: int,
    points_per_segment: int,
    gamma: float,
    attribute_scale: float,
    one_call: bool = True,
    implementation: str = "auto",
) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean Soft-DTW over the batch and the ``num_sets`` waypoint sets.

    Args:
        waypoints: ``(B, S(S+1)/2, 3 + k)`` raw network output (xyz [m], attribute logits).
        trajectory: ``(B, T, 3 + k)`` ground truth (xyz [m], attribute flags in [0, 1]); its first
            point is the end-effector at the agent's first frame and starts every polyline.
        num_sets, points_per_segment, gamma, attribute_scale: see :class:`AwdaConfig`.
        one_call: evaluate all sets in one ragged Soft-DTW call (polylines padded to the longest,
            ``S B`` rows, per-row lengths); ``False`` makes one call per set (the reference the
            ragged call is tested against; same values and gradients).
        implementation: Soft-DTW implementation (:data:`~awda_bench.soft_dtw.core.IMPLEMENTATIONS`).

    Returns:
        ``(loss, per_set)``: the scalar loss and the batch-mean Soft-DTW of each set ``(S,)``.
    """
    if waypoints.dim() != 3 or trajectory.dim() != 3 or waypoints.shape[-1] != trajectory.shape[-1]:
        raise UsageError(
            f"waypoints (B, W, 3+k) and trajectory (B, T, 3+k) disagree: "
            f"{tuple(waypoints.shape)} vs {tuple(trajectory.shape)}"
        )
    target = to_cost_space(trajectory, attribute_scale, logits=False)
    predicted = to_cost_space(waypoints, attribute_scale, logits=True)
    start = target[:, 0]
    polylines = [
        interpolate_polyline(start, wp, points_per_segment)
        for wp in split_waypoint_sets(predicted, num_sets)
    ]
    if not one_call:
        per_set = torch.stack(
            [
                soft_dtw(line, target, gamma, implementation=implementation).mean()
                for line in polylines
            ]
        )
        return per_set.mean(), per_set
    b = waypoints.shape[0]
    longest = polylines[-1].shape[1]
    # Pad each set's polyline by repeating its end point (ignored: lengths cut it off), rows
    # ordered set-major: row s * B + i is sample i's set s + 1.
    padded = torch.cat(
        [
            torch.cat((line, line[:, -1:].expand(-1, longest - line.shape[1], -1)), dim=1)
            for line in polylines
        ],
        dim=0,
    )
    lengths = torch.tensor(
        [line.shape[1] for line in polylines], device=waypoints.device
    ).repeat_interleave(b)
    values = soft_dtw(
        padded, target.repeat(num_sets, 1, 1), gamma, lengths=lengths, implementation=implementation
    )
    per_set = values.view(num_sets, b).mean(dim=1)
    return per_set.mean(), per_set

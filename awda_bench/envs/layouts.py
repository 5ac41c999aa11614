"""Random table-top layouts: where a task's loose objects start, and putting them there at rest.

Positions are drawn by whole-layout rejection: per env, many candidate layouts (every object's
position at once) are drawn in one batch and the first whose positions are pairwise far enough
apart (and that the task admits) is kept. Every draw uses the global torch generator, which
ManiSkill seeds from ``reset(seed=...)``. Frames: world, table top at z = 0.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from mani_skill.utils.structs.actor import Actor
from mani_skill.utils.structs.pose import Pose


def first_separated_layout(
    xy: torch.Tensor, min_separation_m: float, allowed: torch.Tensor | None = None
) -> torch.Tensor | None:
    """(b, k, 2) per env the first of the candidate layouts ``xy`` (b, m, k, 2) [m] whose k
    points are pairwise at least ``min_separation_m`` apart and that ``allowed`` (b, m) bool, if
    given, admits; ``None`` when some env has no such candidate (the caller says why)."""
    b, _, k, _ = xy.shape
    d = torch.linalg.norm(xy[:, :, :, None, :] - xy[:, :, None, :, :], dim=-1)
    d = d + torch.eye(k, device=xy.device) * 1e3
    ok = d.flatten(2).min(dim=2).values >= min_separation_m
    if allowed is not None:
        ok = ok & allowed
    if not bool(ok.any(dim=1).all()):
        return None
    first = ok.to(torch.int8).argmax(dim=1)
    return xy[torch.arange(b, device=xy.device), first]


def sample_separated_xy(
    batch: int,
    count: int,
    *,
    center_xy_m: tuple[float, float],
    half_size_m: tuple[float, float],
    min_separation_m: float,
    min_abs_y_m: float = 0.0,
    candidates: int = 2048,
    device: torch.device | str = "cpu",
) -> torch.Tensor:
    """(batch, count, 2) points uniform in ``center +- half_size`` [m], pairwise at least
    ``min_separation_m`` apart (whole-layout rejection: the first valid of ``candidates`` draws
    per env). With ``min_abs_y_m > 0`` the band ``|y - center_y| < min_abs_y_m`` is left empty
    (two side areas; the robot's rest pose hides the middle from the third-person camera).
    Uses the global torch generator (seeded by the env's ``reset(seed)``)."""
    if not 0.0 <= min_abs_y_m < half_size_m[1]:
        raise ValueError(f"min_abs_y_m must be in [0, {half_size_m[1]}), got {min_abs_y_m}")
    u = torch.rand((batch, candidates, count, 2), device=device) * 2 - 1
    x = center_xy_m[0] + u[..., 0] * half_size_m[0]
    sign = torch.where(u[..., 1] >= 0, 1.0, -1.0)
    y = center_xy_m[1] + sign * (min_abs_y_m + u[..., 1].abs() * (half_size_m[1] - min_abs_y_m))
    layout = first_separated_layout(torch.stack([x, y], dim=-1), min_separation_m)
    if layout is None:
        raise RuntimeError(
            f"no layout with {count} points {min_separation_m} m apart among {candidates} "
            "candidates; enlarge the spawn area or the candidate count"
        )
    return layout


def place_upright(
    actors: Sequence[Actor], xy: torch.Tensor, z_m: Sequence[float], yaw_rad: torch.Tensor
) -> None:
    """Put ``actors[j]`` at rest at ``(xy[:, j], z_m[j])`` [m], upright, turned by
    ``yaw_rad[:, j]`` [rad] about the vertical (``xy``: (b, k, 2); ``yaw_rad``: (b, k))."""
    b = len(xy)
    for j, (actor, z) in enumerate(zip(actors, z_m, strict=True)):
        p = torch.zeros((b, 3), device=xy.device)
        p[:, :2] = xy[:, j]
        p[:, 2] = z
        q = torch.zeros((b, 4), device=xy.device)
        q[:, 0] = torch.cos(yaw_rad[:, j] / 2)
        q[:, 3] = torch.sin(yaw_rad[:, j] / 2)
        actor.set_pose(Pose.create_from_pq(p, q))
        actor.set_linear_velocity(torch.zeros((b, 3), device=xy.device))
        actor.set_angular_velocity(torch.zeros((b, 3), device=xy.device))

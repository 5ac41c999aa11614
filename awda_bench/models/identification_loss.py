r"""The ``demo-pointer`` head's identification loss: two cross-entropies onto cells read from the
trajectories themselves.

Soft-DTW on the waypoints alone did not teach the head *which* object the demo shows in a way that
transfers to an unseen (object, compartment) pairing (``reports/learned/recipe-study.md``,
sessions 10-11): it fitted the training pairs and stayed at chance on the held-out tasks. Supervised
directly, the same frozen features identify the object in held-out pairs at 0.96-0.99 within 300
steps (``scripts/screening/identify.py``, in git history at 5c8c53b). The labels come from the
recorded trajectories, as the waypoints do; no simulator state::

    demo cell   where the demonstrator's TCP is at its first grasp, projected through the scene
                camera (the pair's, which agent and demonstrator share) onto the demo's first
                frame's grid                                       -> CE on the what-moved logits
    o_1 cell    where the agent trajectory's first grasping point is, projected onto o_1's grid
                                                                   -> CE on the object logits

Rows without a grasp (synthesized trajectories, tasks that never close the gripper) are left out,
unless the batch carries contact points (``"contact"``, ``"demo_contact"``: where the hand first
moves the task's object, :mod:`awda_bench.data.contact_point`; ``DataRecipe.identification_contact``),
which then label the rows that never grasp: Meta-World's pushes.
With a demo hand path (``AwdaConfig.demo_hand_path``) a third cross-entropy labels the hand logits
of every demo frame with the cell of the demonstrator's TCP in that frame (:func:`hand_loss`).
With demo heights (``AwdaConfig.demo_heights``) a Huber loss labels the hand height read off
every demo frame with the demonstrator's TCP z there (:func:`height_loss`; not a cross-entropy).
With a place target (``AwdaConfig.place_target``) two more label where the object is put down
(:func:`place_loss`)::

    demo cell   where the demonstrator's TCP is when it lets go (its last grasping point, the
                gripper open again after it), on the demo's first frame's grid -> CE on the put logits
    o_1 cell    the same point of the agent trajectory, on o_1's grid       -> CE on the target logits

over the task-driven rows whose demo and agent trajectory both let go (a synthesized trajectory
never grasps on the ManiSkill suites, and on Meta-World lets go at a drawn point, not where its
demo did).
A deviation from the reference, which trains on the Soft-DTW loss alone; it is stated where it is
switched on (``AwdaConfig.identification_weight``, the recipe files).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
import torch.nn.functional as F

from awda_bench.models.cell_readout import Camera

Labels = tuple[torch.Tensor, torch.Tensor]
"""``(cells (B,), ok (B,))``: a label cell per row and whether the row has one."""


GRASP_ATTRIBUTE = 0
"""Index of *object grasped* among a trajectory's attribute channels (``AwdaConfig``)."""


def grasp_cells(
    trajectory: torch.Tensor,
    camera: Camera,
    grid: tuple[int, int],
    contact: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``trajectory (B, P, 3 + k)`` (world xyz [m], attributes in [0, 1]) -> the grid cell
    ``(B,)`` of each row's first grasping point seen through ``camera``, and ``(B,)`` bool: the row
    has a point and it is in front of the camera. ``contact (B, 4)`` (xyz, flag; the datasets'
    ``"contact"``): a row that never grasps takes its contact point instead where the flag is
    set (:mod:`awda_bench.data.contact_point`)."""
    intrinsic, extrinsic, (height, width) = camera
    grasping = trajectory[..., 3 + GRASP_ATTRIBUTE] > 0.5  # (B, P)
    first = torch.argmax(grasping.to(torch.int8), dim=1)  # first True (0 when none)
    point = trajectory[torch.arange(len(trajectory)), first, :3].double()
    has_point = grasping.any(dim=1)
    if contact is not None:
        touched = ~has_point & (contact[:, 3] > 0.5)
        point = torch.where(touched[:, None], contact[:, :3].to(point), point)
        has_point = has_point | touched
    cells, ahead = point_cells(point, camera, grid)
    return cells, has_point & ahead


def release_cells(
    trajectory: torch.Tensor, camera: Camera, grid: tuple[int, int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """``trajectory (B, P, 3 + k)`` -> the grid cell ``(B,)`` of each row's last grasping point
    (where it lets go) seen through ``camera``, and ``(B,)`` bool: the row grasps, opens again
    before its end, and the point is in front of the camera."""
    grasping = trajectory[..., 3 + GRASP_ATTRIBUTE] > 0.5  # (B, P)
    points = grasping.shape[1]
    last = points - 1 - torch.argmax(grasping.flip(1).to(torch.int8), dim=1)
    released = grasping.any(dim=1) & ~grasping[:, -1]
    point = trajectory[torch.arange(len(trajectory)), last, :3]
    cells, ahead = point_cells(point, camera, grid)
    return cells, released & ahead


def point_cells(
    point: torch.Tensor, camera: Camera, grid: tuple[int, int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """World points ``(..., 3)`` -> the grid cell each projects into through ``camera``
    (clamped to the grid) and whether it is in front of the camera, both ``(...)``."""
    intrinsic, extrinsic, (height, width) = camera
    point = point.double()
    cam = point @ extrinsic[:, :3].T.to(point) + extrinsic[:, 3].to(point)
    uvw = cam @ intrinsic.T.to(point)
    ahead = uvw[..., 2] > 1e-6
    uv = uvw[..., :2] / uvw[..., 2:3].clamp_min(1e-6)
    h, w = grid
    row = torch.floor(uv[..., 1] * h / height).clamp(0, h - 1).long()
    col = torch.floor(uv[..., 0] * w / width).clamp(0, w - 1).long()
    return row * w + col, ahead


def demo_frame_points(demo_trajectory: torch.Tensor, demo_frames: int) -> torch.Tensor:
    """The demonstrator's TCP ``(B, Td, 3)`` at its ``demo_frames`` frames, read off its
    trajectory ``(B, P, 3 + k)``: both span the episode evenly (the frames at
    round(linspace(0, T, Td)), the points at linspace(0, T, P)), so frame i sits at point
    i (P - 1) / (Td - 1), interpolated linearly."""
    points = demo_trajectory.shape[1]
    where = torch.linspace(0.0, points - 1.0, demo_frames, device=demo_trajectory.device)
    low = where.floor().long().clamp(max=points - 1)
    high = (low + 1).clamp(max=points - 1)
    frac = (where - low.to(where))[None, :, None].to(demo_trajectory)
    xyz = demo_trajectory[..., :3]
    return xyz[:, low] * (1 - frac) + xyz[:, high] * frac


def hand_loss(
    hand_logits: torch.Tensor,
    demo_trajectory: torch.Tensor,
    cameras: Sequence[Camera],
    camera: torch.Tensor | None,
    grid: tuple[int, int],
) -> tuple[torch.Tensor, dict[str, float]]:
    """Cross-entropy of the demo-pointer's hand logits ``(B, Td, h*w)`` onto the cell of the
    demonstrator's TCP in each demo frame (:func:`demo_frame_points`, projected through each
    row's camera), over the (row, frame) pairs in front of the camera."""
    b, frames, cells = hand_logits.shape
    points = demo_frame_points(demo_trajectory, frames)
    index = torch.zeros(b, dtype=torch.long) if camera is None else camera.cpu()
    labels = torch.zeros(b, frames, dtype=torch.long, device=hand_logits.device)
    ok = torch.zeros(b, frames, dtype=torch.bool, device=hand_logits.device)
    for i in torch.unique(index).tolist():
        rows = (index == i).to(hand_logits.device)
        labels[rows], ok[rows] = point_cells(points[rows], cameras[i], grid)
    if not bool(ok.any()):
        return hand_logits.sum() * 0.0, {"id_hand": 0.0}
    loss = F.cross_entropy(hand_logits[ok], labels[ok])
    return loss, {"id_hand": float(loss.detach())}


HEIGHT_SCALE_M = 0.05
"""The height loss's unit [m]: a Huber loss on heights in units of 5 cm (quadratic within 5 cm,
linear beyond), so that it weighs as the cross-entropies beside it do."""


def height_errors_m(heights: torch.Tensor, demo_trajectory: torch.Tensor) -> torch.Tensor:
    """``(B, Td)``: the demo-pointer's hand heights [m] minus the demonstrator's TCP z in each
    demo frame (:func:`demo_frame_points`)."""
    return heights - demo_frame_points(demo_trajectory, heights.shape[1])[..., 2]


def height_loss(
    heights: torch.Tensor, demo_trajectory: torch.Tensor
) -> tuple[torch.Tensor, dict[str, float]]:
    """Huber loss of the demo-pointer's hand heights ``(B, Td)`` [m] against the demonstrator's
    TCP z in each demo frame, in units of :data:`HEIGHT_SCALE_M`; also reports the mean absolute
    error [cm]."""
    error = height_errors_m(heights, demo_trajectory) / HEIGHT_SCALE_M
    loss = F.smooth_l1_loss(error, torch.zeros_like(error))
    error_cm = float(error.abs().mean().detach()) * HEIGHT_SCALE_M * 100.0
    return loss, {"id_height": float(loss.detach()), "id_height_err_cm": error_cm}


def release_cells_per_camera(
    trajectory: torch.Tensor,
    cameras: Sequence[Camera],
    camera: torch.Tensor | None,
    grid: tuple[int, int],
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`release_cells` with each row seen through its own camera: ``cameras[camera[i]]``
    (``camera`` ``None``: every row through the first)."""
    return _per_camera(trajectory, cameras, camera, lambda t, c, _: release_cells(t, c, grid))


def place_loss(
    put_logits: torch.Tensor,
    target_logits: torch.Tensor,
    demo_trajectory: torch.Tensor,
    trajectory: torch.Tensor,
    head: torch.Tensor,
    cameras: Sequence[Camera],
    camera: torch.Tensor | None,
    grid: tuple[int, int],
) -> tuple[torch.Tensor, dict[str, float]]:
    """Mean of the two place cross-entropies (module docstring) over the task-driven rows
    (``head == 0``) whose demo and agent trajectory both let go; zero (with the graph) when none
    does. ``*_logits (B, h*w)``."""
    demo_cell, demo_ok = release_cells_per_camera(demo_trajectory, cameras, camera, grid)
    agent_cell, agent_ok = release_cells_per_camera(trajectory, cameras, camera, grid)
    rows = demo_ok & agent_ok & (head == 0)
    names = ("id_put", "id_target", "id_place_rows")
    return _paired_cross_entropy(put_logits, target_logits, demo_cell, agent_cell, rows, names)


def grasp_cells_per_camera(
    trajectory: torch.Tensor,
    cameras: Sequence[Camera],
    camera: torch.Tensor | None,
    grid: tuple[int, int],
    contact: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`grasp_cells` with each row seen through its own camera: ``cameras[camera[i]]``
    (``camera`` ``None``: every row through the first)."""

    def label(rows: torch.Tensor, seen_by: Camera, where: torch.Tensor) -> Labels:
        return grasp_cells(rows, seen_by, grid, None if contact is None else contact[where])

    return _per_camera(trajectory, cameras, camera, label)


def _per_camera(
    trajectory: torch.Tensor,
    cameras: Sequence[Camera],
    camera: torch.Tensor | None,
    label: Callable[[torch.Tensor, Camera, torch.Tensor], Labels],
) -> Labels:
    """``label(rows of trajectory, their camera, the rows' mask)`` for the rows of each camera
    ``cameras[camera[i]]`` (``camera`` ``None``: every row through the first), put together."""
    if camera is None or len(cameras) == 1:
        return label(trajectory, cameras[0], torch.ones(len(trajectory), dtype=torch.bool))
    cells = torch.zeros(len(trajectory), dtype=torch.long, device=trajectory.device)
    ok = torch.zeros(len(trajectory), dtype=torch.bool, device=trajectory.device)
    for index in torch.unique(camera).tolist():
        rows = camera == index
        cells[rows], ok[rows] = label(trajectory[rows], cameras[index], rows)
    return cells, ok


def identification_loss(
    moved_logits: torch.Tensor,
    object_logits: torch.Tensor,
    demo_trajectory: torch.Tensor,
    trajectory: torch.Tensor,
    cameras: Sequence[Camera],
    camera: torch.Tensor | None,
    grid: tuple[int, int],
    demo_contact: torch.Tensor | None = None,
    contact: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict[str, float]]:
    """Mean of the two cross-entropies (module docstring) over the rows where both the demo and
    the agent trajectory grasp (or, given ``*contact (B, 4)``, have a contact point where they
    never grasp); zero (with the graph) when none does. ``*_logits (B, h*w)``; each row projects
    through ``cameras[camera[row]]`` (``camera`` ``None``: the first)."""
    demo_cell, demo_ok = grasp_cells_per_camera(
        demo_trajectory, cameras, camera, grid, demo_contact
    )
    agent_cell, agent_ok = grasp_cells_per_camera(trajectory, cameras, camera, grid, contact)
    rows = demo_ok & agent_ok
    names = ("id_moved", "id_object", "id_rows")
    return _paired_cross_entropy(moved_logits, object_logits, demo_cell, agent_cell, rows, names)


def _paired_cross_entropy(
    demo_logits: torch.Tensor,
    agent_logits: torch.Tensor,
    demo_cell: torch.Tensor,
    agent_cell: torch.Tensor,
    rows: torch.Tensor,
    names: tuple[str, str, str],
) -> tuple[torch.Tensor, dict[str, float]]:
    """The demo's and o_1's cross-entropies over ``rows`` (zero, with the graph, when there is
    none) and their logged values under ``names`` (demo, o_1, the rows' fraction)."""
    if not bool(rows.any()):
        zero = (demo_logits.sum() + agent_logits.sum()) * 0.0
        return zero, dict.fromkeys(names, 0.0)
    demo = F.cross_entropy(demo_logits[rows], demo_cell[rows])
    agent = F.cross_entropy(agent_logits[rows], agent_cell[rows])
    values = (float(demo.detach()), float(agent.detach()), float(rows.float().mean()))
    return demo + agent, dict(zip(names, values, strict=True))

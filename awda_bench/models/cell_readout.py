r"""Waypoints read off o_1's cells: for each of the N waypoints, a softmax over the cells of where
it is, and each cell's vote for it, an attributed point; the waypoint is the weighted vote.

Shared by the heads that end in a choice of o_1 cells (:mod:`awda_bench.models.demo_to_scene`,
:mod:`awda_bench.models.demo_pointer`). One sample, tokens ``x`` ``(L, d)`` of o_1's ``L = h*w``
cells, per waypoint head::

    p_j = softmax over cells of  w_j . x(cell) [+ a_j prior(cell)]   (where waypoint j is)
    v_j(cell) = MLP_j([x(cell), cell x, y])  read as an attributed point (3 + k):
        with cameras:   the point at height z_j + dz(cell) on the ray through the cell's centre
                        of the camera the sample was filmed with (its index, ``camera``), moved
                        by (dx, dy); |dx|, |dy| <= offset_m, |dz| <= height_offset_m (5 cm
                        each unless the config says otherwise); z_j a parameter per waypoint,
                        the MLP gives dz, dx, dy and attributes
        without:        the MLP gives xyz and attributes
    waypoint_j = sum over cells of p_j(cell) v_j(cell)

With a demo hand path (``hand_path``: the demo's hand positions relative to the object it moved,
``r`` ``(Td, 2)`` in the cells' [-1, 1] image coordinates, and o_1's object position ``o``)::

    q_j = o + sum_t softmax(phase_j)_t r_t          where the demo's hand went, moved to o_1's object
    p_j = softmax over cells of  ... - c_j |cell xy - q_j|^2    (c_j learned per waypoint, from 0)
    v_j(cell) = MLP_j([x(cell), cell x, y, r_1 .. r_Td])

With demo heights (``demo_heights``: the demonstrator's hand height read off each demo frame,
``zeta`` ``(Td,)`` [m], and what the frame shows where the hand is, ``f_t`` ``(Td, d)``:
:class:`DemoHeights`, from :mod:`awda_bench.models.demo_pointer`), a waypoint's height is no
longer one number shared by every task::

    when_j(t) = phase_j(t) + u_j . [f_t, zeta_t / unit]  which demo frame waypoint j's height is
    z_j = z_j0 + sum_t softmax_t(when_j) zeta_t        (z_j0, phase_j, u_j learned per head and
                                                        waypoint; ``height_unit_m``: 1 m or 5 cm)

``u_j`` lets a waypoint pick its frame by what it shows (the grasp, the hand over a wall), not by
its time alone: a fixed phase put pick-place-wall's carry at its grasp's height
(recipe-study-metaworld.md, V14).

The rays make the choice learnable: from the first step, moving p_j towards the cells that image a
point moves the waypoint towards that point (free xyz votes start equal, and the loss then only
sees their mean). The reference also went through its camera: it predicted image-plane
coordinates and mapped them to the world with the camera matrix.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import torch
from torch import nn

MAX_OFFSET_M = 0.05
"""Largest horizontal offset [m] a ray vote may take from its ray, and its height from its
waypoint's, unless the config says otherwise (``offset_m``, ``height_offset_m``)."""

INITIAL_HEIGHT_M = 0.1
"""Every waypoint's height [m, world z] before training (a TCP height above a tabletop)."""

Camera = tuple[torch.Tensor, torch.Tensor, tuple[int, int]]
"""``(intrinsic 3x3, world-to-camera extrinsic 3x4, (height, width) [px])``, OpenCV conventions."""


def cell_rays(
    intrinsic: torch.Tensor,
    extrinsic: torch.Tensor,
    camera_size: tuple[int, int],
    grid: tuple[int, int],
) -> tuple[torch.Tensor, torch.Tensor]:
    """World-frame camera centre ``(3,)`` and unit ray directions ``(h*w, 3)`` through the centres
    of a ``grid`` of cells over the image (OpenCV conventions: ``x_cam = R x_world + t``)."""
    (hc, wc), (h, w) = camera_size, grid
    v, u = torch.meshgrid(
        (torch.arange(h, dtype=torch.float64) + 0.5) * hc / h,
        (torch.arange(w, dtype=torch.float64) + 0.5) * wc / w,
        indexing="ij",
    )
    pixels = torch.stack((u, v, torch.ones_like(u)), dim=-1).reshape(-1, 3)
    rotation, translation = extrinsic[:, :3], extrinsic[:, 3]
    directions = pixels @ torch.linalg.inv(intrinsic).T @ rotation  # R^T K^-1 [u v 1]
    directions = directions / directions.norm(dim=-1, keepdim=True)
    return -rotation.T @ translation, directions


class DemoHeights(NamedTuple):
    """The demonstrator's hand in each demo frame, for waypoint heights (module docstring)."""

    heights: torch.Tensor
    """``(B, Td)``: its height [m]."""
    frames: torch.Tensor
    """``(B, Td, d)``: what each frame shows where the hand is."""


class HandPath(NamedTuple):
    """The demo's hand path relative to its object, and where o_1's object is (module docstring)."""

    relative: torch.Tensor
    """``(B, Td, 2)``: the hand in each demo frame minus the moved object, cell coordinates."""
    anchor: torch.Tensor
    """``(B, 2)``: o_1's object, cell coordinates ([-1, 1], as ``CellReadout.cell_xy``)."""


@dataclass(frozen=True)
class CellHeadShape:
    """What every cell head (and its readout) is built from."""

    channels: int
    """Channels of the backbone's feature map."""
    grid: tuple[int, int]
    """``(h, w)`` cells of the feature map."""
    demo_frames: int
    dim: int
    """Token width ``d``."""
    dropout: float
    hidden: int
    """Hidden width of the heads' MLPs."""
    waypoints: int
    """N, all sets together (15)."""
    waypoint_dim: int
    """3 + k."""
    num_heads: int
    """Waypoint heads (task-driven, synthesized)."""
    cameras: tuple[Camera, ...] = ()
    """The agent cameras, for ray votes (a sample names its own by index); empty: free xyz
    votes."""
    height_offset_m: float = MAX_OFFSET_M
    """How far a ray vote's height may be from its waypoint's height parameter [m]."""
    offset_m: float = MAX_OFFSET_M
    """How far a ray vote may move horizontally from its cell's ray [m]."""
    hand_path: bool = False
    """The readout takes a :class:`HandPath` (module docstring)."""
    place_target: bool = False
    """The head identifies where the object goes as it identifies the object (a second prior:
    :mod:`awda_bench.models.demo_pointer`)."""
    place_pool: bool = True
    """``place_target``: compare 3x3 max-pooled neighbourhoods (False: the cells themselves)."""
    place_match: bool = False
    """``place_target``: the target logits are a learned multiple of the cosine between each o_1
    cell's and the demo's target appearance."""
    demo_heights: bool = False
    """The readout takes the demonstrator's hand height per demo frame (:class:`DemoHeights`),
    and each waypoint's height follows the frame it picks (module docstring; needs
    ``cameras``)."""
    height_unit_m: float = 1.0
    """``demo_heights``: the unit [m] in which the choice of frame reads the heights
    (``AwdaConfig.demo_height_unit_m``)."""


class CellReadout(nn.Module):
    """``(tokens (B, h*w, d), head (B,))`` -> waypoints ``(B, N, 3 + k)`` (module docstring)."""

    def __init__(self, shape: CellHeadShape, prior: bool = False) -> None:
        """``prior``: ``forward`` takes a logit per cell that every waypoint adds to its own,
        scaled by a weight ``a_j`` learned per head and waypoint, starting at 0 (with
        ``shape.place_target`` two logits per cell, ``(B, L, 2)``: the object's and the place
        target's, the second scaled by its own ``b_j``)."""
        super().__init__()
        dim, hidden, cameras = shape.dim, shape.hidden, shape.cameras
        waypoints, waypoint_dim, num_heads = shape.waypoints, shape.waypoint_dim, shape.num_heads
        h, w = grid = shape.grid
        self.waypoints, self.waypoint_dim, self.num_heads = waypoints, waypoint_dim, num_heads
        ys, xs = torch.meshgrid(
            torch.linspace(-1.0, 1.0, h), torch.linspace(-1.0, 1.0, w), indexing="ij"
        )
        self.register_buffer("cell_xy", torch.stack((xs, ys), dim=-1).reshape(h * w, 2))
        self.rays = bool(cameras)
        self.height_offset_m, self.offset_m = shape.height_offset_m, shape.offset_m
        if cameras:
            rays = [cell_rays(k.double(), e.double(), size, grid) for k, e, size in cameras]
            self.register_buffer("ray_origin", torch.stack([o for o, _ in rays]).float())
            self.register_buffer("ray_direction", torch.stack([d for _, d in rays]).float())
            self.height = nn.Parameter(torch.full((num_heads, waypoints), INITIAL_HEIGHT_M))
        self.demo_heights, self.height_unit_m = shape.demo_heights, shape.height_unit_m
        if shape.demo_heights:
            if not cameras:
                raise ValueError("demo heights need ray votes (cameras)")
            self.height_phase = nn.Parameter(torch.zeros(num_heads, waypoints, shape.demo_frames))
            self.height_when = nn.ModuleList(
                nn.Linear(dim + 1, waypoints) for _ in range(num_heads)
            )
        self.where_logits = nn.ModuleList(nn.Linear(dim, waypoints) for _ in range(num_heads))
        self.prior_weight = nn.Parameter(torch.zeros(num_heads, waypoints)) if prior else None
        self.place_target = prior and shape.place_target
        if self.place_target:
            self.target_weight = nn.Parameter(torch.zeros(num_heads, waypoints))
        self.hand_path = shape.hand_path
        path_inputs = 2 * shape.demo_frames if shape.hand_path else 0
        if shape.hand_path:
            self.path_weight = nn.Parameter(torch.zeros(num_heads, waypoints))
            self.path_phase = nn.Parameter(torch.zeros(num_heads, waypoints, shape.demo_frames))
        self.vote = nn.ModuleList(
            nn.Sequential(
                nn.Linear(dim + 2 + path_inputs, hidden),
                nn.ReLU(),
                nn.Linear(hidden, waypoints * waypoint_dim),
            )
            for _ in range(num_heads)
        )

    cell_xy: torch.Tensor
    ray_origin: torch.Tensor
    """``(cameras, 3)``: each camera's centre (world frame)."""
    ray_direction: torch.Tensor
    """``(cameras, h*w, 3)``: each camera's unit rays through the cell centres."""

    def _load_from_state_dict(self, state_dict: dict[str, Any], prefix: str, *args: Any) -> None:
        # snapshots from before cameras were listed hold one camera's rays without the axis
        for name, dims in (("ray_origin", 1), ("ray_direction", 2)):
            key = prefix + name
            if key in state_dict and state_dict[key].dim() == dims:
                state_dict[key] = state_dict[key].unsqueeze(0)
        super()._load_from_state_dict(state_dict, prefix, *args)

    def _frame_logits(self, heights: DemoHeights, head: int) -> torch.Tensor:
        """``when_j(t)`` of samples of waypoint head ``head``: ``(b, N, Td)`` logits of which demo
        frame's height each waypoint takes (module docstring)."""
        unit = heights.heights[..., None] / self.height_unit_m
        read = torch.cat((heights.frames, unit), dim=-1)  # (b, Td, d + 1)
        return self.height_phase[head] + self.height_when[head](read).transpose(1, 2)

    def frame_logits(self, heights: DemoHeights, head: torch.Tensor) -> torch.Tensor:
        """The choice of demo frame for every sample (each through its own head ``(B,)``):
        ``(B, N, Td)`` logits, the softmax of which blends the demo's heights into each
        waypoint's (what :meth:`forward` uses; exposed for the frame-time loss,
        :mod:`awda_bench.models.frame_time_loss`)."""
        if not self.demo_heights:
            raise ValueError("only a readout built with demo_heights=True chooses demo frames")
        out: torch.Tensor | None = None
        for i in range(self.num_heads):
            rows = head == i
            if bool(rows.any()):
                logits = self._frame_logits(DemoHeights(*(t[rows] for t in heights)), i)
                if out is None:  # its dtype is the forward pass's (bfloat16 under autocast)
                    out = logits.new_empty(len(head), *logits.shape[1:])
                out[rows] = logits
        if out is None:
            raise ValueError(f"head indices {head.tolist()} name none of {self.num_heads} heads")
        return out

    def _ray_points(
        self,
        votes: torch.Tensor,
        head: int,
        camera: torch.Tensor,
        heights: DemoHeights | None = None,
        when: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Raw votes ``(b, L, N, 3 + k)`` read as (z, dx, dy, attributes) on the rays of each
        sample's ``camera`` ``(b,)`` -> attributed points: a waypoint's height is its own
        parameter (plus, with ``heights`` and their choice ``when``, a blend of the demo's hand heights) plus
        at most ``height_offset_m`` from the cell (and the point at most ``offset_m`` off its ray
        horizontally), so that votes start ordered along the image (a free height per cell would
        scatter them)."""
        height = self.height[head].view(1, 1, -1, 1)  # (1, 1, N, 1)
        if heights is not None and when is not None:
            chosen = torch.einsum("bnt,bt->bn", torch.softmax(when, dim=-1), heights.heights)
            height = height + chosen[:, None, :, None]  # (b, 1, N, 1)
        z = height + self.height_offset_m * torch.tanh(votes[..., :1])
        offset, attributes = votes[..., 1:3], votes[..., 3:]
        direction = self.ray_direction[camera][:, :, None, :]  # (b, L, 1, 3)
        origin = self.ray_origin[camera][:, None, None, :]  # (b, 1, 1, 3)
        reach = (z - origin[..., 2:3]) / direction[..., 2:3]  # distance along the ray
        point = origin + reach * direction
        shift = self.offset_m * torch.tanh(offset)
        point = torch.cat((point[..., :2] + shift, point[..., 2:]), dim=-1)
        return torch.cat((point, attributes), dim=-1)

    def where(
        self,
        x: torch.Tensor,
        head: int,
        prior: torch.Tensor | None = None,
        path: HandPath | None = None,
    ) -> torch.Tensor:
        """``p_j``: tokens ``(B, L, d)`` of samples of waypoint head ``head`` (and their prior
        ``(B, L)`` or ``(B, L, 2)``, their hand path) -> ``(B, L, N)``, a softmax over the cells
        per waypoint."""
        logits = self.where_logits[head](x)
        if (prior is None) != (self.prior_weight is None):
            raise ValueError("a readout built with prior=True takes a prior, and only such a one")
        if (path is None) == self.hand_path:
            raise ValueError(
                "a readout built with hand_path=True takes a path, and only such a one"
            )
        if prior is not None and self.prior_weight is not None:
            if (prior.dim() == 3) != self.place_target:
                raise ValueError(
                    "a readout built with place_target=True takes priors (B, L, 2), "
                    "and only such a one"
                )
            if self.place_target:
                logits = logits + prior[..., 1:2] * self.target_weight[head]
                prior = prior[..., 0]
            logits = logits + prior[..., None] * self.prior_weight[head]
        if path is not None:
            phase = torch.softmax(self.path_phase[head], dim=-1)  # (N, Td)
            target = path.anchor[:, None] + torch.einsum("nt,btc->bnc", phase, path.relative)
            apart = (self.cell_xy[None, :, None] - target[:, None]).square().sum(-1)  # (B, L, N)
            logits = logits - apart * self.path_weight[head]
        return torch.softmax(logits, dim=1)

    def forward(
        self,
        x: torch.Tensor,
        head: torch.Tensor,
        prior: torch.Tensor | None = None,
        camera: torch.Tensor | None = None,
        path: HandPath | None = None,
        heights: DemoHeights | None = None,
        frame_logits: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``camera`` ``(B,)``: each sample's camera index (``None``: all the first);
        ``heights``: the demo's hand heights (a readout built with ``demo_heights`` takes them,
        and only such a one); ``frame_logits``: their :meth:`frame_logits` when the caller has
        them already (computed here otherwise)."""
        if (heights is None) == self.demo_heights:
            raise ValueError(
                "a readout built with demo_heights=True takes heights, and only such a one"
            )
        b, cells = x.shape[:2]
        if camera is None:
            camera = torch.zeros(b, dtype=torch.long, device=x.device)
        values_in = torch.cat((x, self.cell_xy.expand(b, -1, -1)), dim=-1)
        if path is not None:
            context = path.relative.flatten(1)[:, None].expand(-1, cells, -1)
            values_in = torch.cat((values_in, context), dim=-1)
        if heights is not None and frame_logits is None:
            frame_logits = self.frame_logits(heights, head)
        out = x.new_empty(b, self.waypoints, self.waypoint_dim)
        for i in range(self.num_heads):
            rows = head == i
            if not bool(rows.any()):
                continue
            where = self.where(
                x[rows],
                i,
                None if prior is None else prior[rows],
                None if path is None else HandPath(path.relative[rows], path.anchor[rows]),
            )  # (b_i, L, N)
            votes = self.vote[i](values_in[rows]).view(-1, cells, self.waypoints, self.waypoint_dim)
            if self.rays:
                votes = self._ray_points(
                    votes,
                    i,
                    camera[rows],
                    None if heights is None else DemoHeights(*(t[rows] for t in heights)),
                    None if frame_logits is None else frame_logits[rows],
                )
            out[rows] = torch.einsum("bln,blnk->bnk", where, votes)
        return out

r"""The ``demo-to-scene`` head: o_1's cells attend to the demonstration's cells, then every
waypoint is read off o_1's cells.

Not the reference's architecture (which runs self-attention over every frame's cells and reads a
spatial softmax of o_1 through an MLP, ``head = "self-attention"``); made for a frozen,
ImageNet-pretrained backbone on a CPU budget, where the reference's head was measured to output
the training set's mean path (``reports/learned/recipe-study.md``). What it keeps: frozen
features shared by demo and agent frames, attention between the demo and o_1, keypoints from a
spatial softmax over o_1, two waypoint heads, the multi-waypoint Soft-DTW loss. Data flow, one
sample (``d`` = ``attention_head_dim * attention_heads``)::

    demo features (Td, C, h, w) --2x2 avg pool, 1x1 conv, + position (h, w), + time,
                                  [+ 1x1 conv of the same cell in the demo's FIRST frame]--> Td*h'*w' tokens
    o_1 features  (C, h, w)     --1x1 conv, + position (h, w)-----------------------> h*w tokens
    attention_layers x [o_1 self-attention; o_1 -> demo cross-attention; MLP]  (pre-norm, residual)
    per head, per waypoint j of the 15:
        p_j = softmax over o_1's cells of  w_j . token            (where waypoint j is)
        v_j(cell) = the cell's vote, an attributed point (3 + k), from MLP_j([token, cell x, y]):
            with a camera:    the point at height z_j + dz(cell) on the camera ray through the
                              cell's centre, moved by (dx, dy); |dz|, |dx|, |dy| <= 5 cm; z_j is a
                              parameter per waypoint, the MLP gives dz, dx, dy and attributes
            without:          the MLP gives xyz and attributes
        waypoint_j = sum over cells of p_j(cell) v_j(cell)

With ``demo_reference`` each demo token holds its cell now and as the demo's first frame showed it: an o_1 cell that
looks like what stood at a demo cell at the start can see, in one attention step, whether that
cell changed (the demonstrated object was taken from there) or not (a distractor).

A waypoint is therefore a soft choice of o_1 cells, each voting an attributed point: a grasp
waypoint can land on the cell holding the object the demonstration picked up, whatever task
that is, and a place waypoint reads where to go from the demo through its tokens. The rays are
what makes the choice learnable: from the first step, moving p_j towards the cells that image a
point moves the waypoint towards that point (free xyz votes start equal, and the loss then only
sees their mean). The reference also went through its camera: it predicted image-plane
coordinates and mapped them to the world with the camera matrix.
"""

from __future__ import annotations

import torch
from torch import nn

MAX_OFFSET_M = 0.05
"""Largest horizontal offset [m] a ray vote may take from its ray, and its height from its
waypoint's."""

INITIAL_HEIGHT_M = 0.1
"""Every waypoint's height [m, world z] before training (a TCP height above a tabletop)."""


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


class _Layer(nn.Module):
    """Pre-norm: x += SelfAttn(x); x += CrossAttn(x, demo); x += MLP(x)."""

    def __init__(self, dim: int, heads: int, dropout: float) -> None:
        super().__init__()
        self.norm_self = nn.LayerNorm(dim)
        self.norm_cross = nn.LayerNorm(dim)
        self.norm_mlp = nn.LayerNorm(dim)
        # no dropout on the attention weights: it would force the materialized (math) attention
        # path on the CPU, measured at ~45 % of a step; dropout stays in the MLP
        self.self_attention = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.cross_attention = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.mlp = nn.Sequential(
            nn.Linear(dim, 2 * dim), nn.GELU(), nn.Dropout(dropout), nn.Linear(2 * dim, dim)
        )

    def forward(self, x: torch.Tensor, demo: torch.Tensor) -> torch.Tensor:
        y = self.norm_self(x)
        x = x + self.self_attention(y, y, y, need_weights=False)[0]
        x = x + self.cross_attention(self.norm_cross(x), demo, demo, need_weights=False)[0]
        return x + self.mlp(self.norm_mlp(x))


class DemoToScene(nn.Module):
    """``(demo (B, Td, C, h, w), o_1 (B, C, h, w), head (B,))`` -> waypoints ``(B, N, 3 + k)``."""

    def __init__(
        self,
        channels: int,
        grid: tuple[int, int],
        demo_frames: int,
        dim: int,
        heads: int,
        layers: int,
        dropout: float,
        hidden: int,
        waypoints: int,
        waypoint_dim: int,
        num_heads: int,
        camera: tuple[torch.Tensor, torch.Tensor, tuple[int, int]] | None = None,
        demo_reference: bool = False,
    ) -> None:
        """``camera``: ``(intrinsic 3x3, extrinsic 3x4, (height, width))`` of the agent camera, for
        ray votes (module docstring)."""
        super().__init__()
        h, w = grid
        self.waypoints, self.waypoint_dim, self.num_heads = waypoints, waypoint_dim, num_heads
        self.project = nn.Conv2d(channels, dim, kernel_size=1)
        self.demo_reference = demo_reference
        if demo_reference:
            self.project_reference = nn.Conv2d(channels, dim, kernel_size=1, bias=False)
        self.position = nn.Parameter(torch.randn(dim, h, w) * 0.02)
        self.time = nn.Parameter(torch.randn(demo_frames, dim) * 0.02)
        self.demo_pool = nn.AvgPool2d(2, ceil_mode=True)
        self.layers = nn.ModuleList(_Layer(dim, heads, dropout) for _ in range(layers))
        self.norm = nn.LayerNorm(dim)
        ys, xs = torch.meshgrid(
            torch.linspace(-1.0, 1.0, h), torch.linspace(-1.0, 1.0, w), indexing="ij"
        )
        self.register_buffer("cell_xy", torch.stack((xs, ys), dim=-1).reshape(h * w, 2))
        self.rays = camera is not None
        if camera is not None:
            origin, directions = cell_rays(camera[0].double(), camera[1].double(), camera[2], grid)
            self.register_buffer("ray_origin", origin.float())
            self.register_buffer("ray_direction", directions.float())
            self.height = nn.Parameter(torch.full((num_heads, waypoints), INITIAL_HEIGHT_M))
        self.where = nn.ModuleList(nn.Linear(dim, waypoints) for _ in range(num_heads))
        self.vote = nn.ModuleList(
            nn.Sequential(
                nn.Linear(dim + 2, hidden), nn.ReLU(), nn.Linear(hidden, waypoints * waypoint_dim)
            )
            for _ in range(num_heads)
        )

    cell_xy: torch.Tensor
    ray_origin: torch.Tensor
    ray_direction: torch.Tensor

    def _ray_points(self, votes: torch.Tensor, head: int) -> torch.Tensor:
        """Raw votes ``(..., L, N, 3 + k)`` read as (z, dx, dy, attributes) -> attributed points:
        a waypoint's height is its own parameter plus at most ``MAX_OFFSET_M`` from the cell, so
        that votes start ordered along the image (a free height per cell would scatter them)."""
        height = self.height[head].view(-1, 1)  # (N, 1)
        z = height + MAX_OFFSET_M * torch.tanh(votes[..., :1])
        offset, attributes = votes[..., 1:3], votes[..., 3:]
        direction = self.ray_direction[:, None, :]  # (L, 1, 3)
        reach = (z - self.ray_origin[2]) / direction[..., 2:3]  # distance along the ray
        point = self.ray_origin + reach * direction
        shift = MAX_OFFSET_M * torch.tanh(offset)
        point = torch.cat((point[..., :2] + shift, point[..., 2:]), dim=-1)
        return torch.cat((point, attributes), dim=-1)

    def tokens(self, demo: torch.Tensor, first: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Demo tokens ``(B, Td*h'*w', d)`` and o_1 tokens ``(B, h*w, d)``."""
        b, t, c, h, w = demo.shape
        # pooling commutes with the (linear) projections and position: pool first, 4x cheaper
        pooled = self.demo_pool(demo.reshape(b * t, c, h, w))
        maps = self.project(pooled) + self.demo_pool(self.position[None])
        if self.demo_reference:  # + each cell as the demo's first frame showed it
            start = pooled.view(b, t, *pooled.shape[1:])[:, :1].expand(-1, t, -1, -1, -1)
            maps = maps + self.project_reference(start.reshape(pooled.shape))
        d = maps.shape[1]
        demo_tokens = maps.flatten(2).transpose(1, 2).reshape(b, t, -1, d)
        demo_tokens = (demo_tokens + self.time[None, :, None]).reshape(b, -1, d)
        scene = (self.project(first) + self.position).flatten(2).transpose(1, 2)
        return demo_tokens, scene

    def forward(self, demo: torch.Tensor, first: torch.Tensor, head: torch.Tensor) -> torch.Tensor:
        demo_tokens, x = self.tokens(demo, first)
        for layer in self.layers:
            x = layer(x, demo_tokens)
        x = self.norm(x)  # (B, L, d)
        b, cells = x.shape[:2]
        values_in = torch.cat((x, self.cell_xy.expand(b, -1, -1)), dim=-1)
        out = x.new_empty(b, self.waypoints, self.waypoint_dim)
        for i in range(self.num_heads):
            rows = head == i
            if not bool(rows.any()):
                continue
            where = torch.softmax(self.where[i](x[rows]), dim=1)  # (b_i, L, N)
            votes = self.vote[i](values_in[rows]).view(-1, cells, self.waypoints, self.waypoint_dim)
            if self.rays:
                votes = self._ray_points(votes, i)
            out[rows] = torch.einsum("bln,blnk->bnk", where, votes)
        return out

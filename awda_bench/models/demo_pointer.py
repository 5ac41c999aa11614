r"""The ``demo-pointer`` head: every waypoint points at o_1's cells by what they hold, never by
where they are.

Not the reference's architecture (self-attention over every frame's cells, then an MLP over a
spatial softmax of o_1: ``head = "self-attention"``); made for a frozen ImageNet-pretrained
backbone on a CPU budget after two measurements (``reports/learned/recipe-study.md``):

- heads whose tokens carry a learned absolute position (the reference's, ``demo-to-scene``)
  memorize their training scenes: told where the soda can is, ``demo-to-scene`` fits it in the
  280 training scenes and finds it in new scenes at chance (0.25, four slots);
- a detector that scores each cell from its own features alone (two 1x1 convolutions over the
  frozen stride-16 map, a softmax over cells) finds the can in *new* scenes within 200 steps
  (4 px median, 100 % nearest).

So every score here is computed cell by cell from content, and the demonstration reaches o_1 in two
ways only, both translation-equivariant. The third-person camera is the same for demonstrator and
agent (a scene camera), so a cell of a demo frame and the same cell of o_1 image the same place on
the table. Data flow, one sample (``d`` = ``attention_heads * attention_head_dim``, ``L = h*w``)::

    embed:    e(frame, cell) = 1x1 conv, GELU, 1x1 conv (C -> d), shared by demo frames and o_1
    history:  hist(cell) = MLP([e(demo_1, cell), ..., e(demo_Td, cell)])    (d)
              what happened at this place during the demo: an object taken away, one put down
    object:   a_q = softmax over cells of  w_q . hist(cell),  q = 1..attention_heads
              g = Linear(concat_q  sum_cells a_q(cell) [e(demo_1, cell), hist(cell)])   (d)
              what stood, in the demo's first frame, where something moved
    o_1 cell: x(cell) = MLP([e(o_1, cell), hist(cell), e(o_1, cell) * g, g])
              + 3x3 conv of x (its neighbours), LayerNorm
    waypoints read off x: a softmax over the cells per waypoint, each cell voting an attributed
              point on its camera ray (:mod:`awda_bench.models.cell_readout`)

A grasp waypoint can so land on the o_1 cell that looks like what the demonstrator took (``e * g``),
wherever it stands in this scene; a place waypoint on the cell where, in the demo, something was
put down (``hist`` of the same cell). What it keeps from the reference: frozen features shared by
demo and agent frames, keypoints from a spatial softmax over o_1, two waypoint heads, the
multi-waypoint Soft-DTW loss, image-plane predictions mapped to the world through the camera.
"""

from __future__ import annotations

import torch
from torch import nn

from awda_bench.models.cell_readout import Camera, CellReadout


class DemoPointer(nn.Module):
    """``(demo (B, Td, C, h, w), o_1 (B, C, h, w), head (B,))`` -> waypoints ``(B, N, 3 + k)``."""

    def __init__(
        self,
        channels: int,
        grid: tuple[int, int],
        demo_frames: int,
        dim: int,
        queries: int,
        dropout: float,
        hidden: int,
        waypoints: int,
        waypoint_dim: int,
        num_heads: int,
        camera: Camera | None = None,
    ) -> None:
        """``queries``: softmaxes over the demo's cells that pick what moved (module docstring);
        ``camera``: ``(intrinsic 3x3, extrinsic 3x4, (height, width))`` for ray votes."""
        super().__init__()
        self.grid = grid
        self.embed = nn.Sequential(
            nn.Conv2d(channels, dim, kernel_size=1), nn.GELU(), nn.Conv2d(dim, dim, kernel_size=1)
        )
        self.history = nn.Sequential(
            nn.Linear(demo_frames * dim, hidden),
            nn.GELU(),
            nn.Dropout(dropout),
            nn.Linear(hidden, dim),
        )
        self.moved = nn.Linear(dim, queries)
        self.describe = nn.Linear(queries * 2 * dim, dim)
        self.cell = nn.Sequential(
            nn.Linear(4 * dim, hidden), nn.GELU(), nn.Dropout(dropout), nn.Linear(hidden, dim)
        )
        self.context = nn.Conv2d(dim, dim, kernel_size=3, padding=1)
        self.norm = nn.LayerNorm(dim)
        self.readout = CellReadout(dim, grid, hidden, waypoints, waypoint_dim, num_heads, camera)

    def tokens(self, demo: torch.Tensor, first: torch.Tensor) -> torch.Tensor:
        """o_1's cell tokens ``(B, h*w, d)``, what the readout points at."""
        b, t, c, h, w = demo.shape
        cells = h * w
        demo_cells = self.embed(demo.reshape(b * t, c, h, w)).view(b, t, -1, cells)
        d = demo_cells.shape[2]
        history = self.history(demo_cells.permute(0, 3, 1, 2).reshape(b, cells, t * d))
        start = demo_cells[:, 0].transpose(1, 2)  # (B, L, d): the demo's first frame
        moved = torch.softmax(self.moved(history), dim=1)  # (B, L, Q)
        what = torch.einsum("blq,bld->bqd", moved, torch.cat((start, history), dim=-1))
        g = self.describe(what.flatten(1))[:, None].expand(-1, cells, -1)  # (B, L, d)
        scene = self.embed(first).flatten(2).transpose(1, 2)  # (B, L, d)
        x = self.cell(torch.cat((scene, history, scene * g, g), dim=-1))
        x = x + self.context(x.transpose(1, 2).reshape(b, d, h, w)).flatten(2).transpose(1, 2)
        return self.norm(x)

    def forward(self, demo: torch.Tensor, first: torch.Tensor, head: torch.Tensor) -> torch.Tensor:
        return self.readout(self.tokens(demo, first), head)

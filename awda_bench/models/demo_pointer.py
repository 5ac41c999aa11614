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
              what happened at this place during the whole demo (an object put down)
    early:    early(cell), the same over the demo's first half only (Td // 2 frames: the
              demonstrator has grasped and not yet placed; pick-place: grasps at demo frames 3-4
              of 10, releases at 7-8)
    object:   a_q = softmax over cells of  w_q . early(cell),  q = 1..attention_heads
              g = Linear(concat_q  sum_cells a_q(cell) [e(demo_1, cell), early(cell)])   (d)
              what stood, in the demo's first frame, where something moved before the placing
    o_1 cell: x(cell) = MLP_object([e(o_1, cell), e(o_1, cell) * g, g])
                      + MLP_place([e(o_1, cell), hist(cell)])
              + 3x3 conv of x (its neighbours), LayerNorm
    waypoints read off x: a softmax over the cells per waypoint, each cell voting an attributed
              point on its camera ray (:mod:`awda_bench.models.cell_readout`)

A grasp waypoint can so land on the o_1 cell that looks like what the demonstrator took (``e * g``),
wherever it stands in this scene; a place waypoint on the cell where, in the demo, something was
put down (``hist`` of the same cell). What is identified never sees where it went: with one
descriptor over the whole demo (and ``hist`` inside the object MLP) the head learned the 14
training (object, compartment) pairs as wholes and, shown the can going into compartment 2 or 3
(the held-out tasks, a pairing training never shows), grasped the bread in 48 of 50 held-out pairs
(``reports/learned/recipe-study.md``). What it keeps from the reference: frozen features shared by
demo and agent frames, keypoints from a spatial softmax over o_1, two waypoint heads, the
multi-waypoint Soft-DTW loss, image-plane predictions mapped to the world through the camera.
"""

from __future__ import annotations

import torch
from torch import nn

from awda_bench.models.cell_readout import CellHeadShape, CellReadout


def _mlp(inputs: int, hidden: int, outputs: int, dropout: float) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(inputs, hidden), nn.GELU(), nn.Dropout(dropout), nn.Linear(hidden, outputs)
    )


class DemoPointer(nn.Module):
    """``(demo (B, Td, C, h, w), o_1 (B, C, h, w), head (B,))`` -> waypoints ``(B, N, 3 + k)``."""

    def __init__(self, shape: CellHeadShape, queries: int) -> None:
        """``queries``: softmaxes over the demo's cells that pick what moved (module docstring)."""
        super().__init__()
        channels, grid, demo_frames = shape.channels, shape.grid, shape.demo_frames
        dim, hidden, dropout = shape.dim, shape.hidden, shape.dropout
        self.grid = grid
        self.embed = nn.Sequential(
            nn.Conv2d(channels, dim, kernel_size=1), nn.GELU(), nn.Conv2d(dim, dim, kernel_size=1)
        )
        self.early_frames = max(1, demo_frames // 2)
        self.history = _mlp(demo_frames * dim, hidden, dim, dropout)
        self.early = _mlp(self.early_frames * dim, hidden, dim, dropout)
        self.moved = nn.Linear(dim, queries)
        self.describe = nn.Linear(queries * 2 * dim, dim)
        self.object_cell = _mlp(3 * dim, hidden, dim, dropout)
        self.place_cell = _mlp(2 * dim, hidden, dim, dropout)
        self.context = nn.Conv2d(dim, dim, kernel_size=3, padding=1)
        self.norm = nn.LayerNorm(dim)
        self.readout = CellReadout(shape)

    def what_moved(self, per_cell: torch.Tensor) -> torch.Tensor:
        """``g`` ``(B, d)`` from the demo's embedded cells ``(B, L, Td, d)``: what stood where
        something moved in the demo's first half (module docstring)."""
        b, cells = per_cell.shape[:2]
        early = self.early(per_cell[:, :, : self.early_frames].reshape(b, cells, -1))
        start = per_cell[:, :, 0]  # (B, L, d): the demo's first frame
        moved = torch.softmax(self.moved(early), dim=1)  # (B, L, Q)
        what = torch.einsum("blq,bld->bqd", moved, torch.cat((start, early), dim=-1))
        return self.describe(what.flatten(1))

    def tokens(self, demo: torch.Tensor, first: torch.Tensor) -> torch.Tensor:
        """o_1's cell tokens ``(B, h*w, d)``, what the readout points at."""
        b, t, c, h, w = demo.shape
        cells = h * w
        demo_cells = self.embed(demo.reshape(b * t, c, h, w)).view(b, t, -1, cells)
        d = demo_cells.shape[2]
        per_cell = demo_cells.permute(0, 3, 1, 2)  # (B, L, Td, d)
        history = self.history(per_cell.reshape(b, cells, t * d))
        g = self.what_moved(per_cell)[:, None].expand(-1, cells, -1)  # (B, L, d)
        scene = self.embed(first).flatten(2).transpose(1, 2)  # (B, L, d)
        x = self.object_cell(torch.cat((scene, scene * g, g), dim=-1))
        x = x + self.place_cell(torch.cat((scene, history), dim=-1))
        x = x + self.context(x.transpose(1, 2).reshape(b, d, h, w)).flatten(2).transpose(1, 2)
        return self.norm(x)

    def forward(self, demo: torch.Tensor, first: torch.Tensor, head: torch.Tensor) -> torch.Tensor:
        return self.readout(self.tokens(demo, first), head)

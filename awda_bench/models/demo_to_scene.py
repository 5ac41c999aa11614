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
    waypoints read off o_1's tokens: a softmax over the cells per waypoint, each cell voting an
    attributed point on its camera ray (:mod:`awda_bench.models.cell_readout`)

With ``demo_reference`` each demo token holds its cell now and as the demo's first frame showed it: an o_1 cell that
looks like what stood at a demo cell at the start can see, in one attention step, whether that
cell changed (the demonstrated object was taken from there) or not (a distractor).

A waypoint is therefore a soft choice of o_1 cells, each voting an attributed point: a grasp
waypoint can land on the cell holding the object the demonstration picked up, whatever task
that is, and a place waypoint reads where to go from the demo through its tokens.

Measured (``reports/learned/recipe-study.md``): with learned absolute positions in every token
this head memorizes its training scenes (it finds the soda can in them, and in new scenes at
chance); :mod:`awda_bench.models.demo_pointer` is the head that generalizes.
"""

from __future__ import annotations

import torch
from torch import nn

from awda_bench.models.cell_readout import CellHeadShape, CellReadout


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
        self, shape: CellHeadShape, heads: int, layers: int, demo_reference: bool = False
    ) -> None:
        """``heads`` x ``layers`` attention; ``demo_reference``: module docstring."""
        super().__init__()
        channels, dim, dropout = shape.channels, shape.dim, shape.dropout
        h, w = shape.grid
        self.project = nn.Conv2d(channels, dim, kernel_size=1)
        self.demo_reference = demo_reference
        if demo_reference:
            self.project_reference = nn.Conv2d(channels, dim, kernel_size=1, bias=False)
        self.position = nn.Parameter(torch.randn(dim, h, w) * 0.02)
        self.time = nn.Parameter(torch.randn(shape.demo_frames, dim) * 0.02)
        self.demo_pool = nn.AvgPool2d(2, ceil_mode=True)
        self.layers = nn.ModuleList(_Layer(dim, heads, dropout) for _ in range(layers))
        self.norm = nn.LayerNorm(dim)
        self.readout = CellReadout(shape)

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

    def forward(
        self,
        demo: torch.Tensor,
        first: torch.Tensor,
        head: torch.Tensor,
        camera: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``camera`` ``(B,)``: each sample's camera index (``None``: the first camera)."""
        demo_tokens, x = self.tokens(demo, first)
        for layer in self.layers:
            x = layer(x, demo_tokens)
        return self.readout(self.norm(x), head, camera=camera)

r"""The ``demo-pointer`` head: every waypoint points at o_1's cells by what they hold, never by
where they are, and the object to grasp is identified by its appearance in the demo's first frame.

Not the reference's architecture (self-attention over every frame's cells, then an MLP over a
spatial softmax of o_1: ``head = "self-attention"``); made for a frozen ImageNet-pretrained
backbone on a CPU budget after these measurements (``reports/learned/recipe-study.md``):

- heads whose tokens carry a learned absolute position (the reference's, ``demo-to-scene``)
  memorize their training scenes: told where the soda can is, ``demo-to-scene`` fits it in the
  280 training scenes and finds it in new scenes at chance (0.25, four slots);
- a detector that scores each cell from its own features alone finds the can in *new* scenes
  within 200 steps (4 px median, 100 % nearest);
- a descriptor of "what moved" shaped by the Soft-DTW loss alone learned the 14 training
  (object, compartment) pairings as wholes: shown the can going into compartment 2 or 3 (the
  held-out tasks) it grasped the bread (48 of 50 held-out pairs), and read from the demo's first
  half only it stayed at chance; supervised directly (:mod:`awda_bench.models.identification_loss`)
  and read as the demo's *first frame's* appearance, it finds the held-out object in 0.96-0.99 of
  held-out pairs within 300 steps.

Data flow, one sample (``d = attention_heads * attention_head_dim``, ``L = h*w``)::

    embed:    e(frame, cell) = 1x1 conv, GELU, 1x1 conv (C -> d), shared by demo frames and o_1
    history:  hist(cell) = MLP([e(demo_1, cell), ..., e(demo_Td, cell)])    (d)
              what happened at this place during the demo (an object put down: place waypoints)
    moved:    m(cell) = convs over [e(demo_1), ..., e(demo_Td)] (1x1, 3x3, 1x1) -> a logit per cell
              where the demonstrator took something (supervised: the demo's grasp cell)
    object:   g = sum over cells of softmax(m)(cell) e(demo_1, cell)     (d)
              what stood there in the demo's first frame: an appearance, never a destination
    o_1 cell: f(cell) = MLP_object([e(o_1, cell), e(o_1, cell) * g])      (d)
              s(cell) = w . f(cell), the object logit (supervised: the agent's grasp cell)
              x(cell) = f(cell) + MLP_place([e(o_1, cell), hist(cell)]) + 3x3 conv (neighbours),
              LayerNorm
    waypoints read off x: a softmax over the cells per waypoint of  w_j . x(cell) + a_j s(cell)
              (a_j learned per waypoint, from 0), each cell voting an attributed point on its
              camera ray (:mod:`awda_bench.models.cell_readout`)

With ``demo_hand_path`` (a deviation; ``AwdaConfig.demo_hand_path``)::

    hand:     k_t(cell) = convs over e(demo_t) -> a logit per cell: where the demonstrator's hand is
              in demo frame t (supervised: its TCP projected onto the frame)
    path:     r_t = E_softmax(k_t)[cell xy] - E_softmax(m)[cell xy]: the hand relative to the object
              it moved; o = E_softmax(s)[cell xy], o_1's object
    the readout pulls each waypoint's softmax towards o + a learned blend of the r_t and lets
    every vote see r (:class:`awda_bench.models.cell_readout.HandPath`): what a push demo shows
    is where the hand goes around its object, which appearance and per-cell history cannot carry
    to a scene whose object stands elsewhere.

The third-person camera is the same for demonstrator and agent (a scene camera), so a cell of a
demo frame and the same cell of o_1 image the same place on the table. What it keeps from the
reference: frozen features shared by demo and agent frames, keypoints from a spatial softmax over
o_1, two waypoint heads, the multi-waypoint Soft-DTW loss, image-plane predictions mapped to the
world through the camera.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from awda_bench.models.cell_readout import CellHeadShape, CellReadout, HandPath


def _mlp(inputs: int, hidden: int, outputs: int, dropout: float) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(inputs, hidden), nn.GELU(), nn.Dropout(dropout), nn.Linear(hidden, outputs)
    )


HAND_NARROWING = 4
"""The hand convolutions are this many times narrower than the head's MLPs: they run on every demo
frame (10 of them), and at full width they doubled a training step (2.4 s against 1.1 s on the
busy 2-core machine)."""


class PointerOutput(NamedTuple):
    """One forward pass: the waypoints and the two identification logits."""

    waypoints: torch.Tensor
    """``(B, N, 3 + k)``."""
    moved_logits: torch.Tensor
    """``(B, h*w)``: where in the demo's first frame the demonstrator took something."""
    object_logits: torch.Tensor
    """``(B, h*w)``: which of o_1's cells holds that object."""
    hand_logits: torch.Tensor | None = None
    """``(B, Td, h*w)``: where the demonstrator's hand is in each demo frame (``hand_path``
    heads; ``None`` otherwise)."""


class DemoPointer(nn.Module):
    """``(demo (B, Td, C, h, w), o_1 (B, C, h, w), head (B,))`` -> waypoints ``(B, N, 3 + k)``."""

    def __init__(self, shape: CellHeadShape) -> None:
        super().__init__()
        channels, demo_frames = shape.channels, shape.demo_frames
        dim, hidden, dropout = shape.dim, shape.hidden, shape.dropout
        self.grid = shape.grid
        self.embed = nn.Sequential(
            nn.Conv2d(channels, dim, kernel_size=1), nn.GELU(), nn.Conv2d(dim, dim, kernel_size=1)
        )
        self.history = _mlp(demo_frames * dim, hidden, dim, dropout)
        self.moved = nn.Sequential(
            nn.Conv2d(demo_frames * dim, hidden, kernel_size=1),
            nn.GELU(),
            nn.Conv2d(hidden, hidden, kernel_size=3, padding=1),
            nn.GELU(),
            nn.Conv2d(hidden, 1, kernel_size=1),
        )
        self.object_cell = _mlp(2 * dim, hidden, dim, dropout)
        self.object_logit = nn.Linear(dim, 1)
        self.place_cell = _mlp(2 * dim, hidden, dim, dropout)
        self.context = nn.Conv2d(dim, dim, kernel_size=3, padding=1)
        self.norm = nn.LayerNorm(dim)
        self.readout = CellReadout(shape, prior=True)
        narrow = max(hidden // HAND_NARROWING, 1)  # it runs on every demo frame
        self.hand = (
            nn.Sequential(
                nn.Conv2d(dim, narrow, kernel_size=1),
                nn.GELU(),
                nn.Conv2d(narrow, narrow, kernel_size=3, padding=1),
                nn.GELU(),
                nn.Conv2d(narrow, 1, kernel_size=1),
            )
            if shape.hand_path
            else None
        )

    def what_moved(self, demo_cells: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Embedded demo frames ``(B, Td, d, h, w)`` -> the what-moved logits ``(B, h*w)`` and
        ``g`` ``(B, d)``: the demo's first frame where they point (module docstring)."""
        b, t, d, h, w = demo_cells.shape
        logits = self.moved(demo_cells.reshape(b, t * d, h, w)).flatten(1)
        start = demo_cells[:, 0].flatten(2)  # (B, d, L): the demo's first frame
        return logits, torch.einsum("bl,bdl->bd", torch.softmax(logits, dim=1), start)

    def tokens(
        self, demo: torch.Tensor, first: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """o_1's cell tokens ``(B, h*w, d)`` (what the readout points at), the what-moved logits
        and the object logits (both ``(B, h*w)``), and the embedded demo frames
        ``(B, Td, d, h, w)``."""
        b, t, c, h, w = demo.shape
        cells = h * w
        demo_cells = self.embed(demo.reshape(b * t, c, h, w)).view(b, t, -1, h, w)
        d = demo_cells.shape[2]
        moved, g = self.what_moved(demo_cells)
        per_cell = demo_cells.flatten(3).permute(0, 3, 1, 2)  # (B, L, Td, d)
        history = self.history(per_cell.reshape(b, cells, t * d))
        scene = self.embed(first).flatten(2).transpose(1, 2)  # (B, L, d)
        found = self.object_cell(torch.cat((scene, scene * g[:, None]), dim=-1))
        x = found + self.place_cell(torch.cat((scene, history), dim=-1))
        x = x + self.context(x.transpose(1, 2).reshape(b, d, h, w)).flatten(2).transpose(1, 2)
        return self.norm(x), moved, self.object_logit(found)[..., 0], demo_cells

    def hand_path(
        self, demo_cells: torch.Tensor, moved: torch.Tensor, found: torch.Tensor
    ) -> tuple[HandPath, torch.Tensor]:
        """The demo's hand path relative to its moved object, o_1's object (module docstring),
        and the hand logits ``(B, Td, h*w)``."""
        if self.hand is None:
            raise ValueError("this head was built without a hand path (CellHeadShape.hand_path)")
        b, t, d, h, w = demo_cells.shape
        logits = self.hand(demo_cells.reshape(b * t, d, h, w)).view(b, t, h * w)
        xy = self.readout.cell_xy  # (L, 2)
        hand = torch.softmax(logits, dim=-1) @ xy  # (B, Td, 2)
        start = torch.softmax(moved, dim=-1) @ xy  # (B, 2)
        anchor = torch.softmax(found, dim=-1) @ xy
        return HandPath(hand - start[:, None], anchor), logits

    def pointer(
        self,
        demo: torch.Tensor,
        first: torch.Tensor,
        head: torch.Tensor,
        camera: torch.Tensor | None = None,
    ) -> PointerOutput:
        """``camera`` ``(B,)``: each sample's camera index (``None``: the first camera)."""
        x, moved, found, demo_cells = self.tokens(demo, first)
        if self.hand is None:
            return PointerOutput(self.readout(x, head, prior=found, camera=camera), moved, found)
        path, hand = self.hand_path(demo_cells, moved, found)
        waypoints = self.readout(x, head, prior=found, camera=camera, path=path)
        return PointerOutput(waypoints, moved, found, hand)

    def forward(
        self,
        demo: torch.Tensor,
        first: torch.Tensor,
        head: torch.Tensor,
        camera: torch.Tensor | None = None,
    ) -> torch.Tensor:
        return self.pointer(demo, first, head, camera).waypoints

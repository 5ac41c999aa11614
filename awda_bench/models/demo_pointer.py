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

With ``place_target`` (a deviation; ``AwdaConfig.place_target``), the place is identified as the
object is, by appearance (the history above is where something was put *in the demo's scene*,
which says nothing about where the same target stands in o_1's)::

    put:      u(cell) = convs over [e(demo_1), ..., e(demo_Td)] -> a logit per cell
              where the demonstrator put its object down (supervised: the demo's release cell)
    target:   q = sum over cells of softmax(u)(cell) pool3(e(demo_1))(cell)   (d)
              what stood there (and around: the release point images 1-2 cells off the target
              it hovers over) in the demo's first frame
    o_1 cell: t(cell) = MLP_target([e(o_1, cell), pool3(e(o_1))(cell) * q])   (d), added to x
              r(cell) = w' . t(cell), the target logit (supervised: the agent's release cell),
              a second prior: w_j . x(cell) + a_j s(cell) + b_j r(cell)

``place_pool`` off compares the cells themselves instead of their 3x3 neighbourhoods;
``place_match`` makes the target logit ``r(cell) = c cos(pool3(e(o_1))(cell), q)`` (``c`` learned,
from :data:`MATCH_SCALE`) instead of ``w' . t(cell)``: a comparison that needs no training on the
target's kind. (A synthetic leave-kind-out check, bases of kinds never a base in training: pooled
MLP 0.00 of held-out targets found, unpooled MLP 0.54, unpooled cosine 0.71; seen kinds 0.99-1.00.)

With ``demo_hand_path`` (a deviation; ``AwdaConfig.demo_hand_path``)::

    hand:     k_t(cell) = convs over e(demo_t) -> a logit per cell: where the demonstrator's hand is
              in demo frame t (supervised: its TCP projected onto the frame)
    path:     r_t = E_softmax(k_t)[cell xy] - E_softmax(m)[cell xy]: the hand relative to the object
              it moved; o = E_softmax(s)[cell xy], o_1's object
    the readout pulls each waypoint's softmax towards o + a learned blend of the r_t and lets
    every vote see r (:class:`awda_bench.models.cell_readout.HandPath`): what a push demo shows
    is where the hand goes around its object, which appearance and per-cell history cannot carry
    to a scene whose object stands elsewhere.

With ``demo_heights`` (a deviation; ``AwdaConfig.demo_heights``)::

    hand:     k_t(cell) as above (supervised: the demo's TCP projected onto frame t)
    height:   zeta_t = MLP([sum softmax(k_t) e(demo_t), mean e(demo_t), E_softmax(k_t)[cell xy]])
              the demonstrator's hand height [m] in demo frame t, read where its hand is
              (supervised: its TCP's z)
    the readout sets each waypoint's height from the zeta_t of the frame it picks by what the
    hand's cells show there and when
    (:mod:`awda_bench.models.cell_readout`) instead of one number per waypoint: on Meta-World a
    task's objects keep their heights across layouts, so the demonstrator's heights are the
    agent's, and a held-out task's (a button 10 cm below its training sibling's) are in its demo.

The third-person camera is the same for demonstrator and agent (a scene camera), so a cell of a
demo frame and the same cell of o_1 image the same place on the table. What it keeps from the
reference: frozen features shared by demo and agent frames, keypoints from a spatial softmax over
o_1, two waypoint heads, the multi-waypoint Soft-DTW loss, image-plane predictions mapped to the
world through the camera.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from awda_bench.models.cell_readout import CellHeadShape, CellReadout, DemoHeights, HandPath


def _mlp(inputs: int, hidden: int, outputs: int, dropout: float) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(inputs, hidden), nn.GELU(), nn.Dropout(dropout), nn.Linear(hidden, outputs)
    )


def _demo_logits(inputs: int, hidden: int) -> nn.Sequential:
    """Convolutions over the stacked demo frames' cells -> one logit per cell (what moved, where
    it was put; over one frame's cells: where the hand is, where to read its height)."""
    return nn.Sequential(
        nn.Conv2d(inputs, hidden, kernel_size=1),
        nn.GELU(),
        nn.Conv2d(hidden, hidden, kernel_size=3, padding=1),
        nn.GELU(),
        nn.Conv2d(hidden, 1, kernel_size=1),
    )


def _point_in_demo(
    convs: nn.Module, demo_cells: torch.Tensor, start: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """``convs`` (:func:`_demo_logits`) over the embedded demo frames ``(B, Td, d, h, w)`` -> their
    logits ``(B, h*w)`` and what ``start`` ``(B, d, h, w)`` (the demo's first frame, as read)
    holds where they point, softmax-weighted ``(B, d)``."""
    b, t, d, h, w = demo_cells.shape
    logits = convs(demo_cells.reshape(b, t * d, h, w)).flatten(1)
    return logits, torch.einsum("bl,bdl->bd", torch.softmax(logits, dim=1), start.flatten(2))


def _pool3(cells: torch.Tensor) -> torch.Tensor:
    """``(B, d, h, w)`` -> each cell's 3x3 neighbourhood maximum per channel, same shape (the
    border padded so that it never wins)."""
    return F.max_pool2d(cells, kernel_size=3, stride=1, padding=1)


HAND_NARROWING = 4
"""The hand convolutions are this many times narrower than the head's MLPs: they run on every demo
frame (10 of them), and at full width they doubled a training step (2.4 s against 1.1 s on the
busy 2-core machine)."""


MATCH_SCALE = 5.0
"""``place_match``: the cosine's initial scale as the target logit (learned after)."""


class CellTokens(NamedTuple):
    """What :meth:`DemoPointer.tokens` reads off the demo and o_1."""

    x: torch.Tensor
    """``(B, h*w, d)``: o_1's cell tokens, what the readout points at."""
    moved: torch.Tensor
    """``(B, h*w)``: the what-moved logits over the demo's first frame."""
    found: torch.Tensor
    """``(B, h*w)``: the object logits over o_1's cells."""
    demo_cells: torch.Tensor
    """``(B, Td, d, h, w)``: the embedded demo frames."""
    put: torch.Tensor | None = None
    """``(B, h*w)``: where in the demo the demonstrator put its object (``place_target``)."""
    target: torch.Tensor | None = None
    """``(B, h*w)``: which of o_1's cells the object goes to (``place_target``)."""


class PointerOutput(NamedTuple):
    """One forward pass: the waypoints and the identification logits."""

    waypoints: torch.Tensor
    """``(B, N, 3 + k)``."""
    moved_logits: torch.Tensor
    """``(B, h*w)``: where in the demo's first frame the demonstrator took something."""
    object_logits: torch.Tensor
    """``(B, h*w)``: which of o_1's cells holds that object."""
    hand_logits: torch.Tensor | None = None
    """``(B, Td, h*w)``: where the demonstrator's hand is in each demo frame (``hand_path``
    and ``demo_heights`` heads; ``None`` otherwise)."""
    put_logits: torch.Tensor | None = None
    """``(B, h*w)``: where in the demo the object was put down (``place_target`` heads)."""
    target_logits: torch.Tensor | None = None
    """``(B, h*w)``: which of o_1's cells it goes to (``place_target`` heads)."""
    demo_heights: torch.Tensor | None = None
    """``(B, Td)``: the demonstrator's hand height [m] read off each demo frame
    (``demo_heights`` heads)."""
    frame_logits: torch.Tensor | None = None
    """``(B, N, Td)``: which demo frame's height each waypoint takes, logits (``demo_heights``
    heads)."""


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
        self.moved = _demo_logits(demo_frames * dim, hidden)
        self.object_cell = _mlp(2 * dim, hidden, dim, dropout)
        self.object_logit = nn.Linear(dim, 1)
        self.place_cell = _mlp(2 * dim, hidden, dim, dropout)
        self.context = nn.Conv2d(dim, dim, kernel_size=3, padding=1)
        self.norm = nn.LayerNorm(dim)
        self.readout = CellReadout(shape, prior=True)
        self.put = _demo_logits(demo_frames * dim, hidden) if shape.place_target else None
        self.target_cell = _mlp(2 * dim, hidden, dim, dropout) if shape.place_target else None
        matching = shape.place_target and shape.place_match
        self.target_logit = nn.Linear(dim, 1) if shape.place_target and not matching else None
        self.target_match = nn.Parameter(torch.tensor(MATCH_SCALE)) if matching else None
        self.place_pool = shape.place_pool
        narrow = max(hidden // HAND_NARROWING, 1)  # it runs on every demo frame
        # where the hand is in each demo frame: narrow, it runs on every one
        hand = shape.hand_path or shape.demo_heights
        self.hand = _demo_logits(dim, narrow) if hand else None
        self.follow_hand = shape.hand_path
        self.height_value = _mlp(2 * dim + 2, hidden, 1, dropout) if shape.demo_heights else None

    def what_moved(self, demo_cells: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Embedded demo frames ``(B, Td, d, h, w)`` -> the what-moved logits ``(B, h*w)`` and
        ``g`` ``(B, d)``: the demo's first frame where they point (module docstring)."""
        return _point_in_demo(self.moved, demo_cells, demo_cells[:, 0])

    def where_put(self, demo_cells: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Embedded demo frames ``(B, Td, d, h, w)`` -> the put logits ``(B, h*w)`` and ``q``
        ``(B, d)``: the demo's first frame around where they point (module docstring)."""
        if self.put is None:
            raise ValueError("this head was built without a place target (place_target)")
        return _point_in_demo(self.put, demo_cells, self._around(demo_cells[:, 0]))

    def _around(self, cells: torch.Tensor) -> torch.Tensor:
        """``(B, d, h, w)`` -> what the place target compares: each cell's 3x3 neighbourhood
        (max-pooled) or, with ``place_pool`` off, the cell itself."""
        return _pool3(cells) if self.place_pool else cells

    def tokens(self, demo: torch.Tensor, first: torch.Tensor) -> CellTokens:
        """o_1's cell tokens (what the readout points at), the identification logits and the
        embedded demo frames (:class:`CellTokens`)."""
        b, t, c, h, w = demo.shape
        cells = h * w
        demo_cells = self.embed(demo.reshape(b * t, c, h, w)).view(b, t, -1, h, w)
        d = demo_cells.shape[2]
        moved, g = self.what_moved(demo_cells)
        per_cell = demo_cells.flatten(3).permute(0, 3, 1, 2)  # (B, L, Td, d)
        history = self.history(per_cell.reshape(b, cells, t * d))
        embedded = self.embed(first)
        scene = embedded.flatten(2).transpose(1, 2)  # (B, L, d)
        found = self.object_cell(torch.cat((scene, scene * g[:, None]), dim=-1))
        x = found + self.place_cell(torch.cat((scene, history), dim=-1))
        put = target_logits = None
        if self.target_cell is not None:
            put, q = self.where_put(demo_cells)
            around = self._around(embedded).flatten(2).transpose(1, 2)  # (B, L, d)
            target = self.target_cell(torch.cat((scene, around * q[:, None]), dim=-1))
            x = x + target
            if self.target_match is not None:
                match = F.cosine_similarity(around, q[:, None], dim=-1)  # (B, L)
                target_logits = self.target_match * match
            elif self.target_logit is not None:
                target_logits = self.target_logit(target)[..., 0]
        x = x + self.context(x.transpose(1, 2).reshape(b, d, h, w)).flatten(2).transpose(1, 2)
        found_logits = self.object_logit(found)[..., 0]
        return CellTokens(self.norm(x), moved, found_logits, demo_cells, put, target_logits)

    def hand_logits(self, demo_cells: torch.Tensor) -> torch.Tensor:
        """Embedded demo frames ``(B, Td, d, h, w)`` -> where the demonstrator's hand is in
        each, logits ``(B, Td, h*w)``."""
        if self.hand is None:
            raise ValueError("this head was built without a hand (hand_path, demo_heights)")
        b, t, d, h, w = demo_cells.shape
        return self.hand(demo_cells.reshape(b * t, d, h, w)).view(b, t, h * w)

    def hand_path(
        self, hand_logits: torch.Tensor, moved: torch.Tensor, found: torch.Tensor
    ) -> HandPath:
        """The demo's hand path relative to its moved object and o_1's object (module
        docstring), from the hand logits ``(B, Td, h*w)``."""
        xy = self.readout.cell_xy  # (L, 2)
        hand = torch.softmax(hand_logits, dim=-1) @ xy  # (B, Td, 2)
        start = torch.softmax(moved, dim=-1) @ xy  # (B, 2)
        anchor = torch.softmax(found, dim=-1) @ xy
        return HandPath(hand - start[:, None], anchor)

    def hand_heights(self, demo_cells: torch.Tensor, hand_logits: torch.Tensor) -> DemoHeights:
        """Embedded demo frames ``(B, Td, d, h, w)`` and their hand logits -> the
        demonstrator's hand height [m] in each and what the frame shows where the hand is
        (module docstring)."""
        if self.height_value is None:
            raise ValueError("this head was built without demo heights (CellHeadShape)")
        b, t, d, h, w = demo_cells.shape
        flat = demo_cells.reshape(b * t, d, h * w)
        look = torch.softmax(hand_logits.reshape(b * t, h * w), dim=-1)
        seen = torch.einsum("nl,ndl->nd", look, flat)
        where = look @ self.readout.cell_xy  # (B*Td, 2)
        value = self.height_value(torch.cat((seen, flat.mean(-1), where), dim=-1))
        return DemoHeights(value.view(b, t), seen.view(b, t, d))

    def pointer(
        self,
        demo: torch.Tensor,
        first: torch.Tensor,
        head: torch.Tensor,
        camera: torch.Tensor | None = None,
    ) -> PointerOutput:
        """``camera`` ``(B,)``: each sample's camera index (``None``: the first camera)."""
        x, moved, found, demo_cells, put, target = self.tokens(demo, first)
        prior = found if target is None else torch.stack((found, target), dim=-1)
        hand = path = heights = None
        if self.hand is not None:
            hand = self.hand_logits(demo_cells)
            if self.follow_hand:
                path = self.hand_path(hand, moved, found)
            if self.height_value is not None:
                heights = self.hand_heights(demo_cells, hand)
        zeta = choice = None
        if heights is not None:
            zeta, choice = heights.heights, self.readout.frame_logits(heights, head)
        waypoints = self.readout(
            x, head, prior=prior, camera=camera, path=path, heights=heights, frame_logits=choice
        )
        return PointerOutput(waypoints, moved, found, hand, put, target, zeta, choice)

    def forward(
        self,
        demo: torch.Tensor,
        first: torch.Tensor,
        head: torch.Tensor,
        camera: torch.Tensor | None = None,
    ) -> torch.Tensor:
        return self.pointer(demo, first, head, camera).waypoints

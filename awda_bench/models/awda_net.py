"""The AWDA waypoint network (seed S2): trunk + two multi-waypoint heads.

Batch format (what a dataset's samples stack into; images RGB float in [0, 1], channels first)::

    "demo":        (B, demo_frames, 3, H, W)   demonstration frames, first and last included
    "first_frame": (B, 3, H, W)                the agent's first frame o_1
    "trajectory":  (B, T, 3 + k)   ground truth: TCP xyz [m] + k attribute flags in [0, 1];
                                   trajectory[:, 0] is the TCP at o_1 (polylines start there)
    "head":        (B,) int64      0 = task-driven sample, 1 = synthesized (trajectory synthesis)
    "demo_trajectory": (B, T, 3 + k)  the demo's own TCP path and attributes, as "trajectory";
                                   read only by the identification loss (``demo-pointer`` with
                                   ``identification_weight > 0``)
    "camera":      (B,) int64      optional: the index of the agent camera (``config.camera_*``)
                                   each sample was filmed with; absent: the first. The cell heads
                                   vote on its rays, and the identification loss projects through
                                   it (demonstrator and agent of a pair share the scene camera)

With a frozen backbone, training batches carry its cached feature maps instead of the images:
``"demo_features" (B, demo_frames, C, h, w)`` and ``"first_frame_features" (B, C, h, w)`` (with
``trunk.finetune_top_blocks`` the maps entering those blocks, which the loss then runs).

Output coordinate convention: waypoints live in whatever frame the ``trajectory`` targets are given
in; this project's datasets use the ManiSkill **world frame, metres**, TCP position
(``panda_hand_tcp``). The network emits xyz directly and k attribute logits;
:func:`awda_bench.models.predict.predict_waypoints` turns the logits into probabilities.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch
from torch import nn

from awda_bench.errors import UsageError
from awda_bench.models.agent_cameras import config_ray_cameras
from awda_bench.models.cell_readout import CellHeadShape
from awda_bench.models.config import CELL_HEADS, AwdaConfig
from awda_bench.models.demo_pointer import DemoPointer, PointerOutput
from awda_bench.models.demo_to_scene import DemoToScene
from awda_bench.models.frame_encoder import feature_map_size
from awda_bench.models.frame_time_loss import frame_time_loss, rule_times, waypoint_times
from awda_bench.models.identification_loss import (
    hand_loss,
    height_loss,
    identification_loss,
    place_loss,
)
from awda_bench.models.trunk import VisualTrunk
from awda_bench.models.waypoint_loss import (
    PolylineArgs,
    multi_waypoint_sdtw_loss,
    split_waypoint_sets,
)

if TYPE_CHECKING:
    from collections.abc import Mapping

HEAD_NAMES: tuple[str, ...] = ("task", "synthesized")
"""Head index -> name: 0 task-driven data, 1 trajectory synthesis."""


class AwdaNet(nn.Module):
    """Demo frames + o_1 -> 5 attributed waypoint sets (15 waypoints of 3 + k numbers)."""

    arch = "awda"
    """Architecture name recorded in snapshots."""

    def __init__(self, config: AwdaConfig, load_backbone_weights: bool = True) -> None:
        super().__init__()
        self.config = config
        self.trunk = VisualTrunk(config.trunk, load_backbone_weights)
        self.ray_cameras = config_ray_cameras(config)
        """The config's cameras, read once (the readout's rays, the identification labels)."""
        trunk = config.trunk
        self.scene_head: DemoToScene | DemoPointer | None = None
        if trunk.head in CELL_HEADS:
            shape = CellHeadShape(
                channels=self.trunk.channels,
                grid=feature_map_size(trunk, trunk.image_height_px, trunk.image_width_px),
                demo_frames=trunk.demo_frames,
                dim=trunk.attention_heads * trunk.attention_head_dim,
                dropout=trunk.dropout,
                hidden=config.head_hidden_dim,
                waypoints=config.total_waypoints,
                waypoint_dim=config.waypoint_dim,
                num_heads=config.num_heads,
                cameras=self.ray_cameras,
                height_offset_m=config.ray_height_offset_m,
                offset_m=config.ray_offset_m,
                hand_path=config.demo_hand_path,
                demo_heights=config.demo_heights,
                height_unit_m=config.demo_height_unit_m,
                place_target=config.place_target,
                place_pool=config.place_target_pool,
                place_match=config.place_target_match,
            )
            self.grid = shape.grid
            if trunk.head == "demo-pointer":
                self.scene_head = DemoPointer(shape)
            else:
                self.scene_head = DemoToScene(
                    shape,
                    heads=trunk.attention_heads,
                    layers=trunk.attention_layers,
                    demo_reference=config.demo_reference_frame,
                )
            return
        out = config.total_waypoints * config.waypoint_dim
        self.heads = nn.ModuleList(
            nn.Sequential(
                nn.Linear(config.trunk.feature_dim, config.head_hidden_dim),
                nn.ReLU(),
                nn.Linear(config.head_hidden_dim, out),
            )
            for _ in range(config.num_heads)
        )

    def forward(
        self,
        demo: torch.Tensor,
        first_frame: torch.Tensor,
        head: torch.Tensor,
        camera: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``demo (B, Td, 3, H, W)``, ``first_frame (B, 3, H, W)``, ``head (B,)`` (and
        ``camera (B,)``, each sample's camera index; ``None``: the first) -> raw waypoints
        ``(B, 15, 3 + k)`` (xyz [m], attribute logits), sets flat in order 1..5."""
        demo_maps, first_maps = self.image_maps(demo, first_frame)
        return self.forward_features(demo_maps, first_maps, head, camera)

    def image_maps(
        self, demo: torch.Tensor, first_frame: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Images ``demo (B, Td, 3, H, W)``, ``first_frame (B, 3, H, W)`` (checked: one-line
        errors for the wrong rank, frame count or size) -> the backbone's maps of each."""
        cfg = self.config
        if demo.dim() != 5 or first_frame.dim() != 4 or demo.shape[1] != cfg.trunk.demo_frames:
            raise UsageError(
                f"expected demo (B, {cfg.trunk.demo_frames}, 3, H, W), first_frame (B, 3, H, W); "
                f"got {tuple(demo.shape)} and {tuple(first_frame.shape)}"
            )
        size = (cfg.trunk.image_height_px, cfg.trunk.image_width_px)
        if tuple(demo.shape[-2:]) != size or tuple(first_frame.shape[-2:]) != size:
            raise UsageError(
                f"images must be {size[0]}x{size[1]} (config trunk.image_height_px/width_px); "
                f"got demo {tuple(demo.shape[-2:])}, first frame {tuple(first_frame.shape[-2:])}"
            )
        frames = torch.cat((demo, first_frame.unsqueeze(1)), dim=1)
        features = self.trunk.frame_features(frames)
        return features[:, :-1], features[:, -1]

    def cached_maps(
        self, demo: torch.Tensor, first_frame: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """A feature cache's maps ``demo (B, Td, C', h, w)``, ``first_frame (B, C', h, w)`` ->
        the backbone's: through the fine-tuned top blocks (``trunk.finetune_top_blocks``), else
        as they are (the cache then holds the stage's map itself)."""
        if not self.trunk.top_blocks:
            return demo, first_frame
        td = demo.shape[1]
        features = self.trunk.top(torch.cat((demo, first_frame.unsqueeze(1)), dim=1))
        return features[:, :td], features[:, td]

    def camera_indices(self, camera: torch.Tensor | None, b: int) -> torch.Tensor | None:
        """``camera`` checked against the config's cameras (``None`` stays ``None``)."""
        if camera is None:
            return None
        n = max(self.config.num_cameras, 1)
        if camera.shape != (b,) or int(camera.min()) < 0 or int(camera.max()) >= n:
            raise UsageError(
                f"camera indices must be shape ({b},) in [0, {n}) (the config lists {n} "
                f"camera(s)); got {camera.tolist()}"
            )
        return camera.long()

    def forward_features(
        self,
        demo: torch.Tensor,
        first_frame: torch.Tensor,
        head: torch.Tensor,
        camera: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """:meth:`forward` from backbone feature maps: ``demo (B, Td, C, h, w)``,
        ``first_frame (B, C, h, w)`` (a frozen backbone's cached features, or the backbone's
        output) -> raw waypoints ``(B, 15, 3 + k)``."""
        cfg = self.config
        b = first_frame.shape[0]
        if head.shape != (b,) or int(head.min()) < 0 or int(head.max()) >= cfg.num_heads:
            raise UsageError(
                f"head indices must be shape ({b},) in [0, {cfg.num_heads}); got {head.tolist()}"
            )
        if self.scene_head is not None:
            return self.scene_head(demo, first_frame, head.long(), self.camera_indices(camera, b))
        frames = torch.cat((demo, first_frame.unsqueeze(1)), dim=1)
        features = self.trunk.temporal(frames)[:, -1]  # o_1 is the last time step
        all_heads = torch.stack([h(features) for h in self.heads], dim=1)  # (B, heads, out)
        chosen = all_heads[torch.arange(b, device=all_heads.device), head.long()]
        return chosen.view(b, cfg.total_waypoints, cfg.waypoint_dim)

    def compute_loss(
        self, batch: Mapping[str, torch.Tensor]
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """The multi-waypoint Soft-DTW loss of a batch (format in the module docstring).

        Under a caller's ``torch.autocast`` (``[train] precision = "bf16"``) only the network's
        forward pass runs in the lower precision: its outputs are cast to float32 and every loss
        (Soft-DTW, the identification cross-entropies) is computed with autocast off."""
        cfg = self.config
        pointed: PointerOutput | None = None
        camera = self.camera_indices(batch.get("camera"), len(batch["trajectory"]))
        if "demo_features" in batch:  # a frozen backbone's cached maps
            demo, first = self.cached_maps(batch["demo_features"], batch["first_frame_features"])
        else:
            demo, first = self.image_maps(batch["demo"], batch["first_frame"])
        if cfg.identification_weight > 0.0 and isinstance(self.scene_head, DemoPointer):
            pointed = self.scene_head.pointer(demo, first, batch["head"].long(), camera)
            waypoints = pointed.waypoints
        else:
            waypoints = self.forward_features(demo, first, batch["head"], camera)
        # the losses in float32 whatever the forward pass ran in (Soft-DTW's gamma is 1e-3)
        waypoints = waypoints.float()
        if pointed is not None:
            pointed = PointerOutput._make(t.float() if t is not None else None for t in pointed)
        polylines: PolylineArgs = {
            "num_sets": cfg.num_waypoint_sets,
            "points_per_segment": cfg.points_per_segment,
            "gamma": cfg.gamma,
            "attribute_scale": cfg.attribute_scale,
        }
        with torch.autocast(waypoints.device.type, enabled=False):
            loss, per_set = multi_waypoint_sdtw_loss(waypoints, batch["trajectory"], **polylines)
            info = {f"sdtw_set{j + 1}": float(v) for j, v in enumerate(per_set.detach())}
            if pointed is not None:
                found, found_info = identification_loss(
                    pointed.moved_logits,
                    pointed.object_logits,
                    batch["demo_trajectory"],
                    batch["trajectory"],
                    self.ray_cameras,  # AwdaConfig checks there is one
                    camera,
                    self.grid,
                    demo_contact=batch.get("demo_contact"),
                    contact=batch.get("contact"),
                )
                loss = loss + cfg.identification_weight * found
                info.update(found_info)
                if pointed.hand_logits is not None:
                    hand, hand_info = hand_loss(
                        pointed.hand_logits,
                        batch["demo_trajectory"],
                        self.ray_cameras,
                        camera,
                        self.grid,
                    )
                    loss = loss + cfg.identification_weight * hand
                    info.update(hand_info)
                if pointed.demo_heights is not None:
                    height, height_info = height_loss(
                        pointed.demo_heights, batch["demo_trajectory"]
                    )
                    loss = loss + cfg.identification_weight * height
                    info.update(height_info)
                if pointed.frame_logits is not None and cfg.demo_frame_time_weight > 0.0:
                    times = (
                        rule_times(batch["trajectory"], cfg.num_waypoint_sets)
                        if cfg.demo_frame_time_source == "rule"
                        else waypoint_times(waypoints, batch["trajectory"], polylines)
                    )
                    when, when_info = frame_time_loss(pointed.frame_logits, times)
                    loss = loss + cfg.demo_frame_time_weight * when
                    info.update(when_info)
                if pointed.put_logits is not None and pointed.target_logits is not None:
                    place, place_info = place_loss(
                        pointed.put_logits,
                        pointed.target_logits,
                        batch["demo_trajectory"],
                        batch["trajectory"],
                        batch["head"].long(),
                        self.ray_cameras,
                        camera,
                        self.grid,
                    )
                    loss = loss + cfg.identification_weight * place
                    info.update(place_info)
        return loss, {"loss": float(loss.detach()), **info}

    def waypoint_sets(self, waypoints: torch.Tensor) -> list[torch.Tensor]:
        """Split raw output ``(B, 15, 3 + k)`` into sets of 1..5 waypoints."""
        return split_waypoint_sets(waypoints, self.config.num_waypoint_sets)

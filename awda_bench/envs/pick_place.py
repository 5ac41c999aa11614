"""AWDA-PickPlace-v1: one env serving all 16 pick-and-place tasks (SPEC §3.1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from mani_skill.utils.registration import register_env

from awda_bench.envs.bins import BinSpec, build_bin
from awda_bench.envs.embodiments import AGENT_UID
from awda_bench.envs.layouts import first_separated_layout, place_upright
from awda_bench.envs.objects import (
    PICK_PLACE_OBJECTS,
    ObjectSpec,
    build_object,
    distance_to_objects,
)
from awda_bench.envs.task_base import AwdaTaskEnv

NUM_TASKS = 16
"""``task = 4 * object + compartment``."""


@dataclass(frozen=True)
class PickPlaceLayout:
    """Geometry of the pick-and-place scene (world: table top z = 0, robot base x = -0.615)."""

    source_bin: BinSpec = BinSpec(
        center_xy_m=(-0.08, -0.20), inner_half_size_m=(0.14, 0.17), wall_height_m=0.05
    )
    """The open bin the four objects start in."""
    target_bin: BinSpec = BinSpec(
        center_xy_m=(-0.08, 0.21),
        inner_half_size_m=(0.13, 0.13),
        wall_height_m=0.06,
        divided=True,
        color=(0.30, 0.50, 0.35, 1.0),
    )
    """The bin with 4 compartments (see :meth:`BinSpec.compartment_box` for the numbering)."""
    spawn_half_size_m: tuple[float, float] = (0.10, 0.11)
    """Object centres are drawn uniformly in source-bin centre +- this [m] (reference: 0.125 x
    0.155, shrunk so every layout stays in the Panda's top-down reach and the open fingers clear
    the walls)."""
    min_separation_m: float = 0.12
    """Minimum distance between any two object centres [m]."""
    layout_candidates: int = 4096
    """Whole layouts drawn per env at reset; the first one meeting ``min_separation_m`` is kept."""
    success_max_height_m: float = 0.10
    """Success: the target's centre at most this far above the compartment floor [m]."""


@register_env("AWDA-PickPlace-v1", max_episode_steps=180)
class PickPlaceEnv(AwdaTaskEnv):
    """
    **Task Description:**
    Pick the target object out of the source bin and put it into one of the 4 compartments of the
    target bin. Four objects are always present (milk carton, bread, cereal box, soda can); the
    three non-targets are distractors. ``reset(options={"task": i})`` selects object ``i // 4``
    and compartment ``i % 4`` (per env: an int or an (n,) sequence; default 0; kept until the
    next reset).

    **Randomizations:**
    - the four object centres are drawn uniformly in the source bin's spawn area
      (``PickPlaceLayout.spawn_half_size_m``), all pairwise at least ``min_separation_m`` apart
    - each object's yaw is uniform in [0, 2 pi); objects stand upright on the bin floor
    - the robot starts at its rest keyframe (no noise)

    **Success Conditions:**
    - the target object's centre is inside its compartment's inner x/y box and at most
      ``success_max_height_m`` above the compartment floor
    - grasp analysis (latched over the episode): ``reached`` = TCP within ``reach_threshold_m``
      of the target's surface before the gripper was first commanded closed; ``grasped`` =
      reached, then the target raised at least ``lift_threshold_m`` above its start height;
      first grip (:meth:`grip_outcome`): which of the four objects, if any, was nearest within
      ``reach_threshold_m`` when the gripper was first commanded closed
    """

    family = "pick_place"
    num_variations = NUM_TASKS
    has_grasp_target = True
    objects_spec: tuple[ObjectSpec, ...] = PICK_PLACE_OBJECTS

    def __init__(
        self,
        *args: Any,
        robot_uids: str = AGENT_UID,
        layout: PickPlaceLayout | None = None,
        **kwargs: Any,
    ) -> None:
        self.layout = layout or PickPlaceLayout()
        super().__init__(*args, robot_uids=robot_uids, **kwargs)

    # ------------------------------------------------------------------ scene
    def _load_task_scene(self, options: dict) -> None:
        self.source_bin = build_bin(self.scene, self.layout.source_bin, name="source_bin")
        self.target_bin = build_bin(self.scene, self.layout.target_bin, name="target_bin")
        floor = self.layout.source_bin.floor_z_m
        self.objects = [
            build_object(self.scene, s, floor + s.half_height_m) for s in self.objects_spec
        ]
        boxes = [self.layout.target_bin.compartment_box(c) for c in range(4)]
        self._compartment_lo = torch.tensor(
            [[b[0][0], b[1][0]] for b in boxes], dtype=torch.float32, device=self.device
        )
        self._compartment_hi = torch.tensor(
            [[b[0][1], b[1][1]] for b in boxes], dtype=torch.float32, device=self.device
        )

    def _sample_layouts(self, b: int) -> torch.Tensor:
        """(b, 4, 2) object centres, pairwise >= ``min_separation_m`` (whole-layout rejection)."""
        lay = self.layout
        m, k = lay.layout_candidates, len(self.objects_spec)
        half = torch.tensor(lay.spawn_half_size_m, device=self.device)
        center = torch.tensor(lay.source_bin.center_xy_m, device=self.device)
        xy = (torch.rand((b, m, k, 2), device=self.device) * 2 - 1) * half + center
        layout = first_separated_layout(xy, lay.min_separation_m)
        if layout is None:
            raise RuntimeError(
                f"no layout with objects {lay.min_separation_m} m apart among {m} candidates; "
                "enlarge spawn_half_size_m or layout_candidates"
            )
        return layout

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        b = len(env_idx)
        xy = self._sample_layouts(b)
        yaw = torch.rand((b, len(self.objects)), device=self.device) * 2 * np.pi
        floor = self.layout.source_bin.floor_z_m
        place_upright(self.objects, xy, [floor + s.half_height_m for s in self.objects_spec], yaw)

    # ------------------------------------------------------------------ task state
    @property
    def target_object_index(self) -> torch.Tensor:
        """(n,) index into :attr:`objects` of each env's target."""
        return self.task // 4

    @property
    def target_compartment(self) -> torch.Tensor:
        """(n,) compartment index (0-3) of each env's task."""
        return self.task % 4

    def object_poses(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Positions (n, 4, 3) [m] and quaternions (n, 4, 4, wxyz) of the four objects."""
        raw = torch.stack([o.pose.raw_pose for o in self.objects], dim=1)
        return raw[..., :3], raw[..., 3:]

    def _select_target(self, values: torch.Tensor) -> torch.Tensor:
        """Pick each env's target row out of per-object ``values`` (n, 4, ...)."""
        return values[torch.arange(self.num_envs, device=self.device), self.target_object_index]

    def target_pose(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Position (n, 3) and quaternion (n, 4) of each env's target object."""
        pos, quat = self.object_poses()
        return self._select_target(pos), self._select_target(quat)

    def compartment_center(self) -> torch.Tensor:
        """(n, 3) centre of each env's goal compartment on its floor [m]."""
        c = self.target_compartment
        xy = (self._compartment_lo[c] + self._compartment_hi[c]) / 2
        z = torch.full((self.num_envs, 1), self.layout.target_bin.floor_z_m, device=self.device)
        return torch.cat([xy, z], dim=1)

    def is_grasping_target(self) -> torch.Tensor:
        """(n,) simulator truth: both fingers press on the target (Panda's contact-force test)."""
        return self._is_grasping_per_env(self.objects, self.target_object_index)

    def place_goal(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The goal compartment's floor centre; over it within the compartment's half width
        (the smaller half side: the inscribed circle of the success test's rectangle)."""
        c = self.target_compartment
        half = (self._compartment_hi[c] - self._compartment_lo[c]).min(dim=1).values / 2
        return self.compartment_center(), half

    def target_position(self) -> torch.Tensor:
        return self.target_pose()[0]

    def target_distance(self) -> torch.Tensor:
        """(n,) TCP distance to the target object's surface [m]."""
        pos, quat = self.target_pose()
        return self._target_surface_distance(self.agent.tcp_pose.p, pos, quat)

    def object_distances(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(n, 4) TCP distance to each object's surface [m] and (n,) the target's column."""
        pos, quat = self.object_poses()
        distances = distance_to_objects(self.agent.tcp_pose.p, pos, quat, self.objects_spec)
        return distances, self.target_object_index

    def _target_surface_distance(
        self, points: torch.Tensor, target_pos: torch.Tensor, target_quat: torch.Tensor
    ) -> torch.Tensor:
        """(n,) distance of ``points`` to each env's target object only (not all four: this runs
        every step, and the three distractors' distances were computed and thrown away)."""
        idx = self.target_object_index
        kinds = [int(idx[0])] if self.num_envs == 1 else torch.unique(idx).tolist()
        out = torch.zeros(self.num_envs, dtype=points.dtype, device=self.device)
        for j in kinds:
            d = distance_to_objects(
                points, target_pos[:, None], target_quat[:, None], (self.objects_spec[j],)
            )[:, 0]
            out = d if len(kinds) == 1 else torch.where(idx == j, d, out)
        return out

    def _evaluate_task(self) -> dict[str, torch.Tensor]:
        pos, quat = self.object_poses()
        target_pos = self._select_target(pos)
        c = self.target_compartment
        lo, hi = self._compartment_lo[c], self._compartment_hi[c]
        inside_xy = ((target_pos[:, :2] >= lo) & (target_pos[:, :2] <= hi)).all(dim=1)
        height = target_pos[:, 2] - self.layout.target_bin.floor_z_m
        success = inside_xy & (height >= 0) & (height <= self.layout.success_max_height_m)
        tcp_pos = self.agent.tcp_pose.p
        distance = self._target_surface_distance(tcp_pos, target_pos, self._select_target(quat))
        # the contact-force grasp test costs ~2 ms per step: call is_grasping_target() on demand;
        # tcp_pos and object_raw_poses (n, 4, 7: xyz + wxyz) are reused by _get_obs_extra
        return {
            "success": success,
            "target_distance_m": distance,
            "target_pos": target_pos,
            "tcp_pos": tcp_pos,
            "object_raw_poses": torch.cat([pos, quat], dim=2),
        }

    def _get_obs_extra(self, info: dict) -> dict:
        obs = dict(
            tcp_pos=info["tcp_pos"],
            gripper_opening_m=self.gripper_opening_m()[:, None],
            task_one_hot=torch.nn.functional.one_hot(self.task, NUM_TASKS).float(),
        )
        if "state" in self.obs_mode:
            raw = info["object_raw_poses"]
            pos, quat = raw[..., :3], raw[..., 3:]
            obs.update(
                object_poses=raw.flatten(1),
                target_pos=self._select_target(pos),
                target_quat=self._select_target(quat),
                goal_pos=self.compartment_center(),
            )
        return obs

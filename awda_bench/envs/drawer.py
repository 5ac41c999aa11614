"""AWDA-Drawer-v1: open or close one of four drawers in two cabinets (MOSAIC-style ``drawer``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.link import Link
from mani_skill.utils.structs.pose import Pose

from awda_bench.envs.articulated import (
    DrawerCabinetSpec,
    PlacementNoise,
    build_drawer_cabinet,
    rotate_z,
    sample_placements,
    yaw_quat,
)
from awda_bench.envs.cabinet_task import CabinetTaskEnv

NUM_DRAWER_VARIATIONS = 8
"""``variation = 2 * drawer + action`` with ``drawer = 2 * cabinet + level`` (level 0 = lower,
1 = upper); action 0 = open, 1 = close."""


def _default_cabinets() -> tuple[DrawerCabinetSpec, DrawerCabinetSpec]:
    return (
        DrawerCabinetSpec(
            name="drawer_cabinet_0",
            center_xy_m=(0.065, -0.25),
            front_color=(0.20, 0.58, 0.28, 1.0),
            carcass_color=(0.74, 0.84, 0.72, 1.0),
            handle_y_m=(0.07, -0.07),
        ),
        DrawerCabinetSpec(
            name="drawer_cabinet_1",
            center_xy_m=(0.065, 0.25),
            front_color=(0.92, 0.66, 0.12, 1.0),
            carcass_color=(0.90, 0.84, 0.68, 1.0),
            handle_y_m=(-0.07, 0.07),
        ),
    )


@dataclass(frozen=True)
class DrawerLayout:
    """The two drawer cabinets, their randomization and the success thresholds."""

    cabinets: tuple[DrawerCabinetSpec, DrawerCabinetSpec] = field(default_factory=_default_cabinets)
    """Cabinet 0 (green fronts, at the robot's right) and cabinet 1 (yellow fronts, at its left);
    each cabinet's lower handle is on the side facing the other cabinet, its upper handle on the
    outer side (so the hand reaching the lower one passes beside the upper one)."""
    placement: PlacementNoise = PlacementNoise()
    """Per-episode offset of each cabinet's position and yaw."""
    open_success_m: float = 0.12
    """Open: success once the target drawer is slid out at least this far [m]."""
    close_success_m: float = 0.005
    """Close: success once the target drawer is within this of shut [m]."""
    close_start_m: tuple[float, float] = (0.15, 0.20)
    """Close variations: the target drawer, and one random drawer of the other cabinet, start
    slid out by a uniform distance in this range [m]."""

    def __post_init__(self) -> None:
        lo, hi = self.close_start_m
        top = min(c.max_slide_m for c in self.cabinets)
        if not self.open_success_m <= lo <= hi <= top:
            raise ValueError(
                f"close_start_m {self.close_start_m} must be ordered, from open_success_m "
                f"{self.open_success_m} up to the slide limit {top}"
            )
        if not 0 < self.close_success_m < self.open_success_m:
            raise ValueError(
                f"close_success_m {self.close_success_m} must be in (0, open_success_m)"
            )


@register_env("AWDA-Drawer-v1", max_episode_steps=200)
class DrawerEnv(CabinetTaskEnv):
    """
    **Task Description:**
    Two cabinets stand left and right in front of the robot, each with two stacked drawers
    (0 = lower, 1 = upper) that slide out toward the robot; every drawer front carries a short pull
    handle on a stem whose sides the downward-pointing gripper closes on. Cabinet 0 has green
    fronts (robot's right), cabinet 1 yellow (its left). ``reset(options={"task": v})`` selects
    drawer ``d = v // 2`` (cabinet ``d // 2``, level ``d % 2``) and action ``v % 2``
    (0 = open, 1 = close).

    **Randomizations:**
    - each cabinet's position is offset uniformly by up to ``PlacementNoise.xy_m`` (2 cm) in x and
      y, and its yaw by up to ``PlacementNoise.yaw_rad`` (0.06 rad), independently per cabinet
    - open variations: all drawers start shut; close variations: the target drawer and one random
      drawer of the *other* cabinet start slid out by a uniform distance in ``close_start_m``
      (so the first frame alone leaves the cabinet ambiguous)
    - the robot starts at its rest keyframe (no noise)

    **Success Conditions:**
    - open: the target drawer is slid out at least ``open_success_m`` (12 cm)
    - close: the target drawer is within ``close_success_m`` (0.5 cm) of shut
    - no grasp analysis (``has_grasp_target`` is False: nothing is lifted); ``truth_signals()``
      reports ``grasp`` (both fingers hold the target drawer, i.e. its handle) and ``press``
      (a finger pushes on the target drawer without grasping it)
    """

    family: ClassVar[str] = "drawer"
    num_variations: ClassVar[int] = NUM_DRAWER_VARIATIONS
    openings_key: ClassVar[str] = "drawer_slides"
    opening_key: ClassVar[str] = "drawer_slide_m"

    def __init__(self, *args: Any, layout: DrawerLayout | None = None, **kwargs: Any) -> None:
        self.layout = layout or DrawerLayout()
        super().__init__(*args, **kwargs)

    # ------------------------------------------------------------------ scene
    def _load_task_scene(self, options: dict) -> None:
        self.cabinets = [build_drawer_cabinet(self.scene, spec) for spec in self.layout.cabinets]
        self.drawer_links = [c.links_map[f"drawer_{k}"] for c in self.cabinets for k in range(2)]
        """The four drawer links in drawer-index order (cabinet-major)."""
        dev = self.device
        handles = []
        for spec in self.layout.cabinets:
            for z, y in zip(spec.drawer_center_z_m, spec.handle_y_m, strict=True):
                handles.append((spec.handle_center_x_m, y, z))
        self._handle_local = torch.tensor(handles, device=dev)
        """(4, 3) handle head centres in their cabinet's root frame, drawers shut [m]."""

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        b = len(env_idx)
        lay = self.layout
        dev = self.device
        closing = (variation % 2) == 1
        drawer = variation // 2
        cabinet, level = drawer // 2, drawer % 2
        distractor_level = (torch.rand(b, device=dev) < 0.5).long()
        lo, hi = lay.close_start_m
        for c, (art, spec) in enumerate(zip(self.cabinets, lay.cabinets, strict=True)):
            p, yaw = sample_placements(spec.center_xy_m, lay.placement, b, dev)
            art.set_pose(Pose.create_from_pq(p, yaw_quat(yaw)))
            slide = lo + torch.rand((b, 2), device=dev) * (hi - lo)
            open_level = torch.where(cabinet == c, level, distractor_level)
            is_open = closing[:, None] & (
                torch.arange(2, device=dev)[None, :] == open_level[:, None]
            )
            art.set_qpos(torch.where(is_open, slide, torch.zeros_like(slide)))
            art.set_qvel(torch.zeros((b, 2), device=dev))

    # ------------------------------------------------------------------ task geometry
    target_drawer = CabinetTaskEnv.target_part
    """(n,) index 0..3 of each env's target drawer (``2 * cabinet + level``)."""
    drawer_slides = CabinetTaskEnv.part_openings
    """(n, 4) slide-out distance of every drawer [m] (0 = shut), drawer-index order."""
    target_slide = CabinetTaskEnv.target_opening
    """(n,) slide-out distance of each env's target drawer [m]."""

    def slide_axis(self) -> torch.Tensor:
        """(n, 3) world unit vector along which each env's target drawer opens (to the robot)."""
        yaw = self._target_root_yaw()[1]
        out = torch.zeros((self.num_envs, 3), device=self.device)
        out[:, 0] = -1.0
        return rotate_z(out, yaw)

    def _target_root_yaw(self) -> tuple[torch.Tensor, torch.Tensor]:
        rows = torch.arange(self.num_envs, device=self.device)
        root = torch.stack([c.pose.raw_pose for c in self.cabinets], dim=1)[
            rows, self.target_drawer // 2
        ]
        return root[:, :3], 2 * torch.atan2(root[:, 6], root[:, 3])

    def handle_position(self, slide_m: torch.Tensor | None = None) -> torch.Tensor:
        """(n, 3) centre of each env's target handle head [m] with the drawer slid out by
        ``slide_m`` (n,) (default: its current slide)."""
        slide = self.target_slide() if slide_m is None else slide_m
        p, yaw = self._target_root_yaw()
        local = self._handle_local[self.target_drawer].clone()
        local[:, 0] -= slide
        return p + rotate_z(local, yaw)

    def target_spec(self, i: int) -> DrawerCabinetSpec:
        """Spec of the cabinet holding env ``i``'s target drawer."""
        return self.layout.cabinets[int(self.target_drawer[i]) // 2]

    # ------------------------------------------------------------------ truths
    def _part_links(self) -> list[Link]:
        return self.drawer_links

    def _target_contacts(self) -> torch.Tensor:
        """(n, 2) contact force magnitudes [N] of the two fingers on each env's target drawer."""
        drawer = self.target_drawer
        forces = torch.zeros(self.num_envs, 2, device=self.device)
        for j, link in enumerate(self.drawer_links):
            if not bool((drawer == j).any()):
                continue
            for k, finger in enumerate((self.agent.finger1_link, self.agent.finger2_link)):
                f = torch.linalg.norm(self.scene.get_pairwise_contact_forces(finger, link), dim=1)
                forces[:, k] = torch.where(drawer == j, f, forces[:, k])
        return forces

    # ------------------------------------------------------------------ evaluation
    def _success_thresholds(self) -> tuple[float, float]:
        return self.layout.open_success_m, self.layout.close_success_m

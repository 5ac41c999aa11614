"""AWDA-Door-v1: open or close one of two hinged cabinet doors (MOSAIC-style family ``door``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.link import Link
from mani_skill.utils.structs.pose import Pose

from awda_bench.envs.articulated import (
    DoorCabinetSpec,
    PlacementNoise,
    build_door_cabinet,
    rotate_z,
    sample_placements,
    yaw_quat,
)
from awda_bench.envs.cabinet_task import CabinetTaskEnv
from awda_bench.envs.task_base import AwdaTaskEnv

NUM_DOOR_VARIATIONS = 4
"""``variation = 2 * door + action``; action 0 = open, 1 = close."""


def _default_doors() -> tuple[DoorCabinetSpec, DoorCabinetSpec]:
    return (
        DoorCabinetSpec(
            name="door_cabinet_0",
            center_xy_m=(0.07, -0.20),
            hinge_side=-1,
            panel_color=(0.72, 0.22, 0.16, 1.0),
            carcass_color=(0.86, 0.74, 0.70, 1.0),
        ),
        DoorCabinetSpec(
            name="door_cabinet_1",
            center_xy_m=(0.07, 0.20),
            hinge_side=1,
            panel_color=(0.16, 0.45, 0.70, 1.0),
            carcass_color=(0.70, 0.78, 0.87, 1.0),
        ),
    )


@dataclass(frozen=True)
class DoorLayout:
    """The two door cabinets, their randomization and the success thresholds."""

    doors: tuple[DoorCabinetSpec, DoorCabinetSpec] = field(default_factory=_default_doors)
    """Door 0 (red, hinged on its -y edge, at the robot's right) and door 1 (blue, hinged on its +y
    edge, at the robot's left); both swing open toward the robot."""
    placement: PlacementNoise = PlacementNoise()
    """Per-episode offset of each cabinet's position and yaw."""
    open_success_rad: float = 0.4
    """Open: success once the target hinge is at least this far from shut [rad]."""
    close_success_rad: float = 0.1
    """Close: success once the target hinge is within this of shut [rad] (about 6 deg: a 2 cm
    gap at the free edge). Close episodes start at least ``close_start_rad[0]`` open, so success
    also means the door moved more than the SPEC's 0.4 rad toward shut."""
    close_start_rad: tuple[float, float] = (0.6, 0.8)
    """Close variations: both doors start open by a uniform angle in this range [rad]."""

    def __post_init__(self) -> None:
        lo, hi = self.close_start_rad
        if not self.close_success_rad + 0.4 <= lo <= hi:
            raise ValueError(
                f"close_start_rad {self.close_start_rad} must be ordered and start at least "
                f"0.4 rad beyond close_success_rad {self.close_success_rad}"
            )
        if not 0 < self.open_success_rad < min(d.max_angle_rad for d in self.doors):
            raise ValueError(f"open_success_rad {self.open_success_rad} outside the hinge range")


@register_env("AWDA-Door-v1", max_episode_steps=200)
class DoorEnv(CabinetTaskEnv):
    """
    **Task Description:**
    Two cabinets stand side by side in front of the robot, each closed by one door on a vertical
    hinge: door 0 (red, right of the robot, hinged on its outer edge) and door 1 (blue, left, hinged
    on its outer edge). Both doors swing open toward the robot and carry a vertical bar handle whose
    top the downward-pointing gripper can close around. ``reset(options={"task": v})`` selects door
    ``v // 2`` and action ``v % 2`` (0 = open, 1 = close).

    **Randomizations:**
    - each cabinet's position is offset uniformly by up to ``PlacementNoise.xy_m`` (2 cm) in x and
      y, and its yaw by up to ``PlacementNoise.yaw_rad`` (0.06 rad), independently per cabinet
    - open variations: both doors start shut; close variations: *both* doors start open by a
      uniform angle in ``close_start_rad`` (so the first frame does not tell which door is meant)
    - the robot starts at its rest keyframe (no noise)

    **Success Conditions:**
    - open: the target door's hinge angle is at least ``open_success_rad`` (0.4 rad)
    - close: the target door's hinge angle is at most ``close_success_rad`` (0.1 rad)
    - no grasp analysis (``has_grasp_target`` is False: nothing is lifted); ``truth_signals()``
      reports ``grasp`` (both fingers hold the target door's link, i.e. its handle) and ``press``
      (a finger pushes on the target door without grasping it)
    """

    family: ClassVar[str] = "door"
    num_variations: ClassVar[int] = NUM_DOOR_VARIATIONS
    openings_key: ClassVar[str] = "door_angles"
    opening_key: ClassVar[str] = "door_angle_rad"

    _TASK_STATE: ClassVar[tuple[str, ...]] = (*AwdaTaskEnv._TASK_STATE,)

    def __init__(self, *args: Any, layout: DoorLayout | None = None, **kwargs: Any) -> None:
        self.layout = layout or DoorLayout()
        super().__init__(*args, **kwargs)

    # ------------------------------------------------------------------ scene
    def _load_task_scene(self, options: dict) -> None:
        self.cabinets = [build_door_cabinet(self.scene, spec) for spec in self.layout.doors]
        self.door_links = [c.links_map["door"] for c in self.cabinets]
        specs = self.layout.doors
        dev = self.device
        self._hinge_local = torch.tensor([s.hinge_local_m for s in specs], device=dev)
        self._handle_rel = torch.tensor([s.handle_from_hinge_local_m() for s in specs], device=dev)
        self._opening_sign = torch.tensor([float(s.opening_sign) for s in specs], device=dev)
        self._handle_top_z = torch.tensor([s.handle_top_z_m for s in specs], device=dev)

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        b = len(env_idx)
        lay = self.layout
        closing = (variation % 2) == 1
        lo, hi = lay.close_start_rad
        for cabinet, spec in zip(self.cabinets, lay.doors, strict=True):
            p, yaw = sample_placements(spec.center_xy_m, lay.placement, b, self.device)
            cabinet.set_pose(Pose.create_from_pq(p, yaw_quat(yaw)))
            start = lo + torch.rand(b, device=self.device) * (hi - lo)
            angle = torch.where(closing, start, torch.zeros_like(start))
            cabinet.set_qpos(angle[:, None])
            cabinet.set_qvel(torch.zeros((b, 1), device=self.device))

    # ------------------------------------------------------------------ task geometry
    target_door = CabinetTaskEnv.target_part
    """(n,) index of each env's target door."""
    door_angles = CabinetTaskEnv.part_openings
    """(n, 2) hinge angles of both doors [rad] (0 = shut, positive = open)."""
    target_angle = CabinetTaskEnv.target_opening
    """(n,) hinge angle of each env's target door [rad]."""

    def _gather(self, per_door: torch.Tensor) -> torch.Tensor:
        """Pick each env's target door from a (n, 2, ...) tensor."""
        rows = torch.arange(self.num_envs, device=self.device)
        return per_door[rows, self.target_door]

    def door_point(
        self,
        rel_m: torch.Tensor,
        angle: torch.Tensor | None = None,
        z_m: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(n, 3) world position of a point of each env's target door.

        ``rel_m`` (n, 3): the point relative to the hinge axis in the door frame at angle 0 (see
        :meth:`DoorCabinetSpec.point_from_hinge_local_m`); ``angle`` (n,): the hinge angle to place
        it at (default: the current one) [rad]; ``z_m`` (n,): its height (default ``rel_m[:, 2]``).
        """
        door = self.target_door
        angle = self.target_angle() if angle is None else angle
        root = self._gather(torch.stack([c.pose.raw_pose for c in self.cabinets], dim=1))
        yaw = 2 * torch.atan2(root[:, 6], root[:, 3])
        hinge = root[:, :3] + rotate_z(self._hinge_local[door], yaw)
        point = hinge + rotate_z(rel_m, yaw + self._opening_sign[door] * angle)
        if z_m is not None:
            point[:, 2] = z_m
        return point

    def handle_position(self, angle: torch.Tensor | None = None) -> torch.Tensor:
        """(n, 3) top centre of each env's target handle bar [m] at ``angle`` (default: now)."""
        door = self.target_door
        return self.door_point(self._handle_rel[door], angle, z_m=self._handle_top_z[door])

    def door_normal(self, angle: torch.Tensor | None = None) -> torch.Tensor:
        """(n, 3) outward (robot-side) unit normal of each env's target panel at ``angle``."""
        zero = torch.zeros((self.num_envs, 3), device=self.device)
        out = zero.clone()
        out[:, 0] = -1.0
        return self.door_point(out, angle) - self.door_point(zero, angle)

    def target_spec(self, i: int) -> DoorCabinetSpec:
        """Spec of env ``i``'s target door."""
        return self.layout.doors[int(self.target_door[i])]

    # ------------------------------------------------------------------ truths
    def _part_links(self) -> list[Link]:
        return self.door_links

    def _target_contacts(self) -> torch.Tensor:
        """(n, 2) contact force magnitudes [N] of the two fingers on each env's target door."""
        door = self.target_door
        forces = []
        for finger in (self.agent.finger1_link, self.agent.finger2_link):
            per_door = torch.stack(
                [
                    torch.linalg.norm(self.scene.get_pairwise_contact_forces(finger, link), dim=1)
                    for link in self.door_links
                ],
                dim=1,
            )
            forces.append(per_door[torch.arange(self.num_envs, device=self.device), door])
        return torch.stack(forces, dim=1)

    # ------------------------------------------------------------------ evaluation
    def _success_thresholds(self) -> tuple[float, float]:
        return self.layout.open_success_rad, self.layout.close_success_rad

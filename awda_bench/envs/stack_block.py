"""AWDA-StackBlock-v1: three coloured cubes; put cube A on cube B, C is a distractor (SPEC §3.2).

Variation ``v`` picks the ordered pair ``STACK_ORDERS[v] = (A, B)`` of the cubes red (0), green (1)
and blue (2)::

    v :  0       1       2       3       4       5
    A/B: red/gr  red/bl  gr/red  gr/bl   bl/red  bl/gr
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import permutations
from typing import Any, ClassVar

import numpy as np
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.actor import Actor

from awda_bench.envs.layouts import first_separated_layout, place_upright
from awda_bench.envs.objects import ObjectSpec, build_object, distance_to_objects
from awda_bench.envs.task_base import AwdaTaskEnv

STACK_ORDERS: tuple[tuple[int, int], ...] = tuple(permutations(range(3), 2))
"""``(A, B)`` per variation: the cube to pick (A) and the cube to put it on (B)."""


def _cube(name: str, color: tuple[float, float, float, float], edge_m: float) -> ObjectSpec:
    return ObjectSpec(
        name=name, shape="box", size_m=(edge_m, edge_m, edge_m), color=color, density_kg_m3=600.0
    )


@dataclass(frozen=True)
class StackBlockLayout:
    """Geometry, randomization and success tolerances of the stacking scene (table top z = 0)."""

    edge_m: float = 0.045
    """Cube edge length [m] (the Panda fingers open to 8 cm, > the 6.4 cm diagonal)."""
    colors: tuple[tuple[float, float, float, float], ...] = (
        (0.90, 0.12, 0.12, 1.0),
        (0.12, 0.75, 0.18, 1.0),
        (0.12, 0.28, 0.90, 1.0),
    )
    """RGBA colour of cubes 0 (red), 1 (green), 2 (blue)."""
    spawn_center_xy_m: tuple[float, float] = (-0.07, 0.0)
    """Centre of the area the cubes are drawn in (world) [m]."""
    spawn_half_size_m: tuple[float, float] = (0.13, 0.26)
    """Cube centres are drawn uniformly in ``spawn_center_xy_m`` +- this [m]."""
    hidden_box_xy_m: tuple[tuple[float, float], tuple[float, float]] = (
        (-0.30, 0.02),
        (-0.14, 0.14),
    )
    """(x range, y range) [m] of the table area the robot's rest pose hides from the third-person
    camera; layouts with a cube centre inside are rejected (every cube shows in the first frame)."""
    min_separation_m: float = 0.11
    """Minimum distance between any two cube centres [m] (open fingers clear the neighbours)."""
    layout_candidates: int = 1024
    """Whole layouts drawn per env at reset; the first one meeting ``min_separation_m`` is kept."""
    stack_gap_tolerance_m: float = 0.006
    """Success: A's bottom within this of B's top (resting on it, in contact or a few mm) [m]."""
    max_resting_speed_m_s: float = 0.03
    """Success: A moves slower than this (it rests, it is not falling or being carried) [m/s]."""

    @property
    def cubes(self) -> tuple[ObjectSpec, ...]:
        """The three cube specs (red, green, blue)."""
        return tuple(
            _cube(name, color, self.edge_m)
            for name, color in zip(
                ("red_cube", "green_cube", "blue_cube"), self.colors, strict=True
            )
        )


@register_env("AWDA-StackBlock-v1", max_episode_steps=200)
class StackBlockEnv(AwdaTaskEnv):
    """
    **Task Description:**
    Three cubes (red, green, blue; 4.5 cm) lie on the table. Pick cube A and put it on cube B; the
    third cube is a distractor. ``reset(options={"task": v})`` selects the ordered pair
    ``STACK_ORDERS[v]`` (6 permutations of 2 of the 3 cubes).

    **Randomizations:**
    - the three cube centres are drawn uniformly in the spawn area (``spawn_half_size_m`` around
      ``spawn_center_xy_m``), pairwise at least ``min_separation_m`` apart, none inside
      ``hidden_box_xy_m`` (behind the robot's rest pose in the third-person view)
    - each cube's yaw is uniform in [0, pi/2) (a cube's full symmetry); cubes rest on the table
    - the robot starts at its rest keyframe (no noise)

    **Success Conditions:**
    - A's centre lies within B's footprint (in B's frame, ``|x|, |y| <= edge / 2``), A's bottom is
      within ``stack_gap_tolerance_m`` of B's top, A is not grasped (released), and A moves slower
      than ``max_resting_speed_m_s``
    - grasp analysis (latched, see :class:`AwdaTaskEnv`): ``reached`` = TCP within 4 cm of A's
      surface before the first grip command; ``grasped`` = reached, then A raised >= 5 cm
    """

    family: ClassVar[str] = "stack_block"
    num_variations: ClassVar[int] = len(STACK_ORDERS)
    has_grasp_target: ClassVar[bool] = True

    def __init__(self, *args: Any, layout: StackBlockLayout | None = None, **kwargs: Any) -> None:
        self.layout = layout or StackBlockLayout()
        self.cube_specs = self.layout.cubes
        super().__init__(*args, **kwargs)

    # ------------------------------------------------------------------ scene
    def _load_task_scene(self, options: dict) -> None:
        self.cubes = [
            build_object(self.scene, spec, spec.half_height_m) for spec in self.cube_specs
        ]
        self._orders = torch.tensor(STACK_ORDERS, dtype=torch.long, device=self.device)

    def _sample_layouts(self, b: int) -> torch.Tensor:
        """(b, 3, 2) cube centres, pairwise >= ``min_separation_m`` (whole-layout rejection)."""
        lay = self.layout
        m, k = lay.layout_candidates, len(self.cubes)
        half = torch.tensor(lay.spawn_half_size_m, device=self.device)
        center = torch.tensor(lay.spawn_center_xy_m, device=self.device)
        xy = (torch.rand((b, m, k, 2), device=self.device) * 2 - 1) * half + center
        (x_lo, x_hi), (y_lo, y_hi) = lay.hidden_box_xy_m
        hidden = (
            (xy[..., 0] > x_lo) & (xy[..., 0] < x_hi) & (xy[..., 1] > y_lo) & (xy[..., 1] < y_hi)
        )
        layout = first_separated_layout(xy, lay.min_separation_m, allowed=~hidden.any(dim=2))
        if layout is None:
            raise RuntimeError(
                f"no layout with cubes {lay.min_separation_m} m apart, none hidden, among {m} "
                "candidates; "
                "enlarge spawn_half_size_m or layout_candidates"
            )
        return layout

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        b = len(env_idx)
        xy = self._sample_layouts(b)
        yaw = torch.rand((b, len(self.cubes))) * (np.pi / 2)
        place_upright(self.cubes, xy, [spec.half_height_m for spec in self.cube_specs], yaw)

    # ------------------------------------------------------------------ task state
    @property
    def cube_a(self) -> torch.Tensor:
        """(n,) index of the cube to pick (A) per env."""
        return self._orders[self.task, 0]

    @property
    def cube_b(self) -> torch.Tensor:
        """(n,) index of the cube to stack on (B) per env."""
        return self._orders[self.task, 1]

    def cube_poses(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Positions (n, 3, 3) [m] and quaternions (n, 3, 4, wxyz) of the three cubes."""
        raw = torch.stack([c.pose.raw_pose for c in self.cubes], dim=1)
        return raw[..., :3], raw[..., 3:]

    def _per_env_cube(
        self, index: torch.Tensor, read: Callable[[Actor], torch.Tensor]
    ) -> torch.Tensor:
        """``read(cube)`` of cube ``index[i]`` for each env ``i`` (reads only the cubes in use:
        actor pose reads dominate the step time on the CPU sim)."""
        out: torch.Tensor | None = None
        for j in torch.unique(index).tolist():
            value = read(self.cubes[j])
            out = value if out is None else torch.where((index == j)[:, None], value, out)
        assert out is not None
        return out

    def target_position(self) -> torch.Tensor:
        """(n, 3) centre of cube A [m]."""
        return self._per_env_cube(self.cube_a, lambda c: c.pose.p)

    def base_pose(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Position (n, 3) and quaternion (n, 4) of cube B."""
        raw = self._per_env_cube(self.cube_b, lambda c: c.pose.raw_pose)
        return raw[:, :3], raw[:, 3:]

    def target_distance(self) -> torch.Tensor:
        """(n,) TCP distance to cube A's surface [m]."""
        return self._distance_to(self._per_env_cube(self.cube_a, lambda c: c.pose.raw_pose))

    def object_distances(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(n, 3) TCP distance to each cube's surface [m] and (n,) cube A's column."""
        distances = [self._distance_to(cube.pose.raw_pose) for cube in self.cubes]
        return torch.stack(distances, dim=1), self.cube_a

    def _distance_to(self, raw_pose: torch.Tensor) -> torch.Tensor:
        """(n,) TCP distance to the surface of the cubes at ``raw_pose`` (n, 7) [m]."""
        pos, quat = raw_pose[:, None, :3], raw_pose[:, None, 3:]
        spec = self.cube_specs[:1]  # the three cubes share one geometry
        return distance_to_objects(self.agent.tcp_pose.p, pos, quat, spec)[:, 0]

    def is_grasping_target(self) -> torch.Tensor:
        """(n,) simulator truth: the fingers hold cube A (the agent's contact-force test)."""
        return self._is_grasping_per_env(self.cubes, self.cube_a)

    def place_goal(self) -> tuple[torch.Tensor, torch.Tensor]:
        """A's centre one edge above B's; over B within half an edge (the footprint's inscribed
        circle)."""
        edge = self.layout.edge_m
        b_pos = self.base_pose()[0]
        goal = b_pos + torch.tensor([0.0, 0.0, edge], device=self.device)
        return goal, torch.full((self.num_envs,), edge / 2, device=self.device)

    def _evaluate_task(self) -> dict[str, torch.Tensor]:
        lay = self.layout
        a_raw = self._per_env_cube(self.cube_a, lambda c: c.pose.raw_pose)
        a_pos = a_raw[:, :3]
        b_pos, b_quat = self.base_pose()
        # A's centre in B's frame (B's yaw only: a resting cube is upright)
        yaw = 2 * torch.atan2(b_quat[:, 3], b_quat[:, 0])
        d = a_pos - b_pos
        local_x = torch.cos(yaw) * d[:, 0] + torch.sin(yaw) * d[:, 1]
        local_y = -torch.sin(yaw) * d[:, 0] + torch.cos(yaw) * d[:, 1]
        half = lay.edge_m / 2
        on_footprint = (local_x.abs() <= half) & (local_y.abs() <= half)
        gap = d[:, 2] - lay.edge_m
        touching = gap.abs() <= lay.stack_gap_tolerance_m
        a_vel = self._per_env_cube(self.cube_a, lambda c: c.linear_velocity)
        resting = torch.linalg.norm(a_vel, dim=1) <= lay.max_resting_speed_m_s
        grasped = self.is_grasping_target()
        return {
            "success": on_footprint & touching & resting & ~grasped,
            "is_grasped": grasped,
            "a_on_b_gap_m": gap,
            "target_pos": a_pos,
            "target_distance_m": self._distance_to(a_raw),
        }

    def _get_obs_extra(self, info: dict) -> dict:
        obs = super()._get_obs_extra(info)
        if "state" in self.obs_mode:
            pos, quat = self.cube_poses()
            obs.update(
                cube_poses=torch.cat([pos, quat], dim=2).flatten(1),
                target_pos=self.target_position(),
                base_pos=self.base_pose()[0],
            )
        return obs


__all__ = ["STACK_ORDERS", "StackBlockEnv", "StackBlockLayout"]

"""AWDA-NutAssembly-v1: put one of 3 nuts onto one of 3 pegs (SPEC §3.2, 9 variations).

Horizon: 200 control steps (10 s at 20 Hz), the MOSAIC suite's (``tasks/mosaic.toml``: about
twice the longest scripted expert episode of any family with the tracking controller).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import sapien
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.actor import Actor

from awda_bench.envs.layouts import place_upright, sample_separated_xy
from awda_bench.envs.static_props import (
    RGBA,
    PegSpec,
    add_box,
    add_square_ring,
    build_peg,
)
from awda_bench.envs.task_base import AwdaTaskEnv


def rotate(quat: torch.Tensor, vec: torch.Tensor, *, inverse: bool = False) -> torch.Tensor:
    """Rotate ``vec`` (n, 3) by the unit quaternions ``quat`` (n, 4, wxyz), or by their inverse.

    ``v' = v + 2 w (u x v) + 2 u x (u x v)`` with ``q = (w, u)`` (cheaper per step than building
    rotation matrices).
    """
    w, u = quat[:, :1], quat[:, 1:]
    if inverse:
        u = -u
    t = 2 * torch.linalg.cross(u, vec, dim=1)
    return vec + w * t + torch.linalg.cross(u, t, dim=1)


@dataclass(frozen=True)
class NutSpec:
    """A square nut (4 boxes around a square hole) with a flat handle sticking out along -x.

    Top view in the nut's frame (origin at the hole's centre, the handle towards the robot)::

                 +--------+
        ====h====|  hole  |      h: handle, grasped across its width (y) by the fingers
                 +--------+
        -x                   +x
    """

    name: str
    """Name used in actor names."""
    color: RGBA
    """Base colour."""
    hole_half_m: float = 0.018
    """Half the square hole's side [m] (3.6 cm hole over a 2 cm peg)."""
    wall_m: float = 0.012
    """Wall thickness [m]."""
    height_m: float = 0.02
    """Thickness of the nut (walls and handle) [m]."""
    handle_length_m: float = 0.045
    """Handle length beyond the outer wall [m]."""
    handle_half_width_m: float = 0.008
    """Half the handle's width across the grip (y) [m]."""
    density_kg_m3: float = 300.0
    """Density [kg/m^3] (a ~15 g nut)."""
    friction: float = 1.0
    """Static and dynamic friction coefficient."""

    @property
    def outer_half_m(self) -> float:
        """Half the nut body's outer side [m]."""
        return self.hole_half_m + self.wall_m

    @property
    def grasp_point_m(self) -> tuple[float, float, float]:
        """The handle's centre in the nut's frame: where the fingers close [m]."""
        return (-(self.outer_half_m + self.handle_length_m / 2), 0.0, 0.0)

    @property
    def bounds_m(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Lower and upper corners of the nut's box (body + handle) in its frame [m]."""
        o, h = self.outer_half_m, self.height_m / 2
        return (-(o + self.handle_length_m), -o, -h), (o, o, h)


NUTS: tuple[NutSpec, ...] = (
    NutSpec(name="red_nut", color=(0.90, 0.12, 0.10, 1.0)),
    NutSpec(name="yellow_nut", color=(0.95, 0.80, 0.05, 1.0)),
    NutSpec(name="blue_nut", color=(0.12, 0.30, 0.90, 1.0)),
)
"""Nut ``i`` is the target of variations ``3 i .. 3 i + 2``."""

PEGS: tuple[PegSpec, ...] = (
    PegSpec(center_xy_m=(0.03, -0.20), color=(0.10, 0.65, 0.20, 1.0)),
    PegSpec(center_xy_m=(0.05, 0.00), color=(0.75, 0.15, 0.70, 1.0)),
    PegSpec(center_xy_m=(0.03, 0.20), color=(0.05, 0.70, 0.80, 1.0)),
)
"""Peg ``j`` is the goal of variations ``j, 3 + j, 6 + j`` (green, magenta, cyan; -y to +y)."""


@dataclass(frozen=True)
class NutAssemblyLayout:
    """Geometry of the nut-assembly scene (world: table top z = 0, robot base x = -0.615)."""

    nuts: tuple[NutSpec, ...] = NUTS
    """The three nuts."""
    pegs: tuple[PegSpec, ...] = PEGS
    """The three pegs (static; not randomized)."""
    spawn_center_xy_m: tuple[float, float] = (-0.15, 0.0)
    """Centre of the area nut centres are drawn in [m]."""
    spawn_half_size_m: tuple[float, float] = (0.08, 0.30)
    """Nut centres are uniform in ``spawn_center_xy_m +- spawn_half_size_m`` [m] ..."""
    spawn_min_abs_y_m: float = 0.17
    """... outside the middle band ``|y| < spawn_min_abs_y_m`` [m] (hidden behind the robot's
    hand at rest in the third-person view)."""
    min_separation_m: float = 0.12
    """Minimum distance between nut centres [m]."""
    max_yaw_rad: float = 0.15
    """Nut yaw is uniform in +- this [rad] (the handle points roughly at the robot: the gripper
    cannot turn)."""
    xy_tolerance_m: float = 0.012
    """Success: the nut's hole centre within this horizontal distance of the peg's axis [m]
    (a nut threaded on the peg is at most ``hole_half - peg_half`` = 8 mm off per axis)."""
    height_tolerance_m: float = 0.01
    """Success: the nut's bottom at most this far above the peg's base plate [m]."""
    release_clearance_m: float = 0.03
    """Success: the TCP at least this far from the nut's box (body + handle) [m]."""

    def __post_init__(self) -> None:
        for nut in self.nuts:
            for peg in self.pegs:
                if nut.hole_half_m <= peg.half_width_m * 2**0.5:
                    raise ValueError(
                        f"{nut.name}'s hole (half {nut.hole_half_m} m) must clear the peg's "
                        f"diagonal ({peg.half_width_m * 2**0.5:.4f} m) at any yaw"
                    )


@register_env("AWDA-NutAssembly-v1", max_episode_steps=200)
class NutAssemblyEnv(AwdaTaskEnv):
    """
    **Task Description:**
    Pick up the target nut by its handle and put it down over the target peg. Three square nuts
    (red, yellow, blue; 3.6 cm square hole, a flat handle pointing at the robot) lie on the table
    behind three square 2 cm pegs (green, magenta, cyan, 9 cm tall, on base plates).
    ``reset(options={"task": v})`` selects nut ``v // 3`` and peg ``v % 3``.

    **Randomizations:**
    - the three nut centres are drawn uniformly in the two side areas of the spawn region
      (``NutAssemblyLayout.spawn_half_size_m``, ``spawn_min_abs_y_m``), pairwise at least
      ``min_separation_m`` apart
    - each nut's yaw is uniform in ``+- max_yaw_rad`` (handle towards the robot)
    - pegs are fixed; the robot starts at its rest keyframe (no noise)

    **Success Conditions:**
    - the target nut is down on its peg: its hole's centre within ``xy_tolerance_m`` of the peg's
      axis and its bottom within ``height_tolerance_m`` of the peg's base plate, and
    - the gripper is away: the TCP at least ``release_clearance_m`` from the nut's box (a held
      nut has the TCP inside its handle), so a nut still held down on the peg does not count
    - grasp analysis (latched): ``reached`` = TCP within 4 cm of the target nut's box before the
      first grip command; ``grasped`` = reached, then the nut raised >= 5 cm
    """

    family = "nut_assembly"
    num_variations = 9
    has_grasp_target = True

    def __init__(self, *args: Any, layout: NutAssemblyLayout | None = None, **kwargs: Any) -> None:
        self.layout = layout or NutAssemblyLayout()
        count = len(self.layout.nuts) * len(self.layout.pegs)
        if count != self.num_variations:
            raise ValueError(
                f"the layout gives {count} variations (nuts x pegs); the task has "
                f"{self.num_variations}: use 3 nuts and 3 pegs"
            )
        super().__init__(*args, **kwargs)

    # ------------------------------------------------------------------ scene
    def _load_task_scene(self, options: dict) -> None:
        lay = self.layout
        self.pegs = [build_peg(self.scene, p, name=f"peg_{j}") for j, p in enumerate(lay.pegs)]
        self.nuts = [self._build_nut(nut) for nut in lay.nuts]
        dev = self.device
        self._peg_xy = torch.tensor(
            [p.center_xy_m for p in lay.pegs], dtype=torch.float32, device=dev
        )
        self._peg_base_z = torch.tensor(
            [p.base_z_m for p in lay.pegs], dtype=torch.float32, device=dev
        )
        self._half_heights = torch.tensor(
            [nut.height_m / 2 for nut in lay.nuts], dtype=torch.float32, device=dev
        )
        self._grasp_points = torch.tensor(
            [nut.grasp_point_m for nut in lay.nuts], dtype=torch.float32, device=dev
        )
        self._bounds_lo = torch.tensor(
            [nut.bounds_m[0] for nut in lay.nuts], dtype=torch.float32, device=dev
        )
        self._bounds_hi = torch.tensor(
            [nut.bounds_m[1] for nut in lay.nuts], dtype=torch.float32, device=dev
        )

    def _build_nut(self, spec: NutSpec) -> Actor:
        builder = self.scene.create_actor_builder()
        physics = sapien.physx.PhysxMaterial(
            static_friction=spec.friction, dynamic_friction=spec.friction, restitution=0.0
        )
        add_square_ring(
            builder,
            hole_half_m=spec.hole_half_m,
            wall_m=spec.wall_m,
            height_m=spec.height_m,
            color=spec.color,
            physics=physics,
            density_kg_m3=spec.density_kg_m3,
        )
        add_box(
            builder,
            spec.grasp_point_m,
            (spec.handle_length_m / 2, spec.handle_half_width_m, spec.height_m / 2),
            spec.color,
            physics=physics,
            density_kg_m3=spec.density_kg_m3,
        )
        builder.initial_pose = sapien.Pose(p=[0.0, 0.0, spec.height_m / 2])
        return builder.build(name=spec.name)

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        lay = self.layout
        b = len(env_idx)
        xy = sample_separated_xy(
            b,
            len(self.nuts),
            center_xy_m=lay.spawn_center_xy_m,
            half_size_m=lay.spawn_half_size_m,
            min_separation_m=lay.min_separation_m,
            min_abs_y_m=lay.spawn_min_abs_y_m,
            device=self.device,
        )
        yaw = (torch.rand((b, len(self.nuts)), device=self.device) * 2 - 1) * lay.max_yaw_rad
        place_upright(self.nuts, xy, [spec.height_m / 2 for spec in lay.nuts], yaw)

    # ------------------------------------------------------------------ task state
    @property
    def target_nut_index(self) -> torch.Tensor:
        """(n,) index into :attr:`nuts` of each env's target nut."""
        return self.task // len(self.layout.pegs)

    @property
    def target_peg_index(self) -> torch.Tensor:
        """(n,) index into :attr:`pegs` of each env's goal peg."""
        return self.task % len(self.layout.pegs)

    def nut_poses(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Positions (n, 3, 3) [m] (hole centres) and quaternions (n, 3, 4, wxyz) of the nuts."""
        pos = torch.stack([nut.pose.p for nut in self.nuts], dim=1)
        quat = torch.stack([nut.pose.q for nut in self.nuts], dim=1)
        return pos, quat

    def target_pose(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Position (n, 3) and quaternion (n, 4) of each env's target nut."""
        idx = self.target_nut_index
        first = int(idx[0])
        if bool(
            (idx == first).all()
        ):  # one pose read instead of three (called several times a step)
            raw = self.nuts[first].pose.raw_pose
            return raw[:, :3], raw[:, 3:]
        pos, quat = self.nut_poses()
        rows = torch.arange(self.num_envs, device=self.device)
        return pos[rows, idx], quat[rows, idx]

    def target_position(self) -> torch.Tensor:
        """(n, 3) centre of each env's target nut's hole [m]."""
        return self.target_pose()[0]

    def target_half_height(self) -> torch.Tensor:
        """(n,) half the thickness of each env's target nut [m]."""
        return self._half_heights[self.target_nut_index]

    def grasp_point(self) -> torch.Tensor:
        """(n, 3) world position of the target nut's handle centre [m]."""
        pos, quat = self.target_pose()
        return pos + rotate(quat, self._grasp_points[self.target_nut_index])

    def peg_position(self) -> torch.Tensor:
        """(n, 3) goal peg's axis at the top of its base plate, per env [m]."""
        j = self.target_peg_index
        return torch.cat([self._peg_xy[j], self._peg_base_z[j, None]], dim=1)

    def target_distance(self) -> torch.Tensor:
        """(n,) TCP distance to the target nut's box (body + handle) [m] (0 inside)."""
        pos, quat = self.target_pose()
        return self._box_distance(pos, quat, self.target_nut_index)

    def object_distances(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(n, 3) TCP distance to each nut's box [m] (0 inside) and (n,) the target's column."""
        pos, quat = self.nut_poses()
        every = torch.arange(len(self.nuts), device=self.device)
        distances = [
            self._box_distance(pos[:, j], quat[:, j], every[j].expand(self.num_envs))
            for j in range(len(self.nuts))
        ]
        return torch.stack(distances, dim=1), self.target_nut_index

    def _box_distance(
        self, pos: torch.Tensor, quat: torch.Tensor, nut: torch.Tensor
    ) -> torch.Tensor:
        """(n,) TCP distance to the box (body + handle) of nut ``nut`` (n,) at ``pos``/``quat``."""
        local = rotate(quat, self.agent.tcp_pose.p - pos, inverse=True)
        lo, hi = self._bounds_lo[nut], self._bounds_hi[nut]
        outside = torch.clamp(lo - local, min=0.0) + torch.clamp(local - hi, min=0.0)
        return torch.linalg.norm(outside, dim=1)

    def is_grasping_target(self) -> torch.Tensor:
        """(n,) simulator truth: both fingers press on the target nut."""
        return self._is_grasping_per_env(self.nuts, self.target_nut_index)

    def place_goal(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The target nut's hole centre resting on the goal peg's base plate; over the peg within
        ``xy_tolerance_m`` (the success test's)."""
        goal = self.peg_position().clone()
        goal[:, 2] += self.target_half_height()
        tolerance = torch.full((self.num_envs,), self.layout.xy_tolerance_m, device=self.device)
        return goal, tolerance

    def _evaluate_task(self) -> dict[str, torch.Tensor]:
        lay = self.layout
        nut = self.target_position()
        peg = self.peg_position()
        xy_error = torch.linalg.norm(nut[:, :2] - peg[:, :2], dim=1)
        height = nut[:, 2] - self.target_half_height() - peg[:, 2]
        clearance = self.target_distance()
        success = (
            (xy_error <= lay.xy_tolerance_m)
            & (height <= lay.height_tolerance_m)
            & (clearance >= lay.release_clearance_m)
        )
        return {
            "success": success,
            "xy_error_m": xy_error,
            "height_m": height,
            "tcp_clearance_m": clearance,
        }

    def _get_obs_extra(self, info: dict) -> dict:
        obs = super()._get_obs_extra(info)
        if "state" in self.obs_mode:
            pos, quat = self.nut_poses()
            target_pos, target_quat = self.target_pose()
            obs.update(
                nut_poses=torch.cat([pos, quat], dim=2).flatten(1),
                target_pos=target_pos,
                target_quat=target_quat,
                goal_pos=self.peg_position(),
            )
        return obs

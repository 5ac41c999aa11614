"""AWDA-Basketball-v1: put one of 3 balls through one of 4 hoops (SPEC §3.2, 12 variations).

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
    HoopSpec,
    build_hoop,
    material,
)
from awda_bench.envs.task_base import AwdaTaskEnv


@dataclass(frozen=True)
class BallSpec:
    """A ball with a small flat spot underneath (so it stays where it is put)."""

    name: str
    """Name used in actor names."""
    color: RGBA
    """Base colour."""
    radius_m: float = 0.027
    """Sphere radius [m] (5.4 cm ball: the Panda's 8 cm fingers close around it)."""
    flat_half_m: float = 0.011
    """Half side of the square flat spot under the ball [m]."""
    flat_below_m: float = 0.001
    """The flat spot's bottom face lies this far below the sphere's lowest point [m]: the ball
    rests on it, and tipping it over raises the centre (no rolling away at rest)."""
    density_kg_m3: float = 250.0
    """Density [kg/m^3] (a ~20 g ball)."""
    friction: float = 1.2
    """Static and dynamic friction coefficient."""

    @property
    def rest_height_m(self) -> float:
        """Height of the centre above a flat support the ball rests on [m]."""
        return self.radius_m + self.flat_below_m


BALLS: tuple[BallSpec, ...] = (
    BallSpec(name="red_ball", color=(0.90, 0.12, 0.10, 1.0)),
    BallSpec(name="yellow_ball", color=(0.95, 0.80, 0.05, 1.0)),
    BallSpec(name="blue_ball", color=(0.12, 0.30, 0.90, 1.0)),
)
"""Ball ``i`` is the target of variations ``4 i .. 4 i + 3``."""

HOOPS: tuple[HoopSpec, ...] = (
    HoopSpec(goal_m=(0.04, -0.27, 0.13), color=(0.10, 0.65, 0.20, 1.0)),
    HoopSpec(goal_m=(0.05, -0.12, 0.17), color=(0.75, 0.15, 0.70, 1.0)),
    HoopSpec(goal_m=(0.05, 0.12, 0.15), color=(0.05, 0.70, 0.80, 1.0)),
    HoopSpec(goal_m=(0.04, 0.27, 0.18), color=(0.15, 0.15, 0.15, 1.0)),
)
"""Hoop ``j`` is the goal of variations ``j, 4 + j, 8 + j`` (green, magenta, cyan, black; -y to
+y), at four different heights. The two inner hoops stand at ``|y| = 0.12`` m so that the agent's
open fingers at its rest pose (TCP at (0, 0, 0.17), fingers at y = +-0.04) clear their rings by
~2 cm: at ``|y| = 0.09`` a finger touched the magenta ring at rest, and PhysX carried that contact
into the next episode (a seeded sequence of episodes did not repeat)."""


@dataclass(frozen=True)
class BasketballLayout:
    """Geometry of the basketball scene (world: table top z = 0, robot base x = -0.615)."""

    balls: tuple[BallSpec, ...] = BALLS
    """The three balls."""
    hoops: tuple[HoopSpec, ...] = HOOPS
    """The four hoops (static; not randomized)."""
    spawn_center_xy_m: tuple[float, float] = (-0.16, 0.0)
    """Centre of the area ball centres are drawn in [m]."""
    spawn_half_size_m: tuple[float, float] = (0.085, 0.30)
    """Ball centres are uniform in ``spawn_center_xy_m +- spawn_half_size_m`` [m] ..."""
    spawn_min_abs_y_m: float = 0.17
    """... outside the middle band ``|y| < spawn_min_abs_y_m`` [m] (hidden behind the robot's
    hand at rest in the third-person view)."""
    min_separation_m: float = 0.11
    """Minimum distance between ball centres [m] (open fingers clear the neighbours)."""
    success_radius_m: float = 0.03
    """Success: the target ball's centre within this distance of its hoop's goal point [m]."""

    def __post_init__(self) -> None:
        if len(self.balls) * len(self.hoops) < 1:
            raise ValueError("need at least one ball and one hoop")
        for hoop in self.hoops:
            for ball in self.balls:
                rest = hoop.net_floor_z_m + ball.rest_height_m
                if abs(rest - hoop.goal_m[2]) >= self.success_radius_m:
                    raise ValueError(
                        f"a {ball.name} resting in the net is {abs(rest - hoop.goal_m[2]):.3f} m "
                        f"below the goal point; must be < success_radius_m"
                    )


@register_env("AWDA-Basketball-v1", max_episode_steps=200)
class BasketballEnv(AwdaTaskEnv):
    """
    **Task Description:**
    Pick up the target ball and drop it through the target hoop. Three balls (red, yellow, blue)
    lie on the table in front of four hoops (green, magenta, cyan, black, from right to left as
    the robot sees them, at four heights). Each hoop is a ring over a shallow net, so a ball
    dropped through the ring comes to rest in the net, its centre ~1 cm below the ring's centre.
    ``reset(options={"task": v})`` selects ball ``v // 4`` and hoop ``v % 4``.

    **Randomizations:**
    - the three ball centres are drawn uniformly in the spawn area in front of the hoops
      (``BasketballLayout.spawn_half_size_m``), pairwise at least ``min_separation_m`` apart
    - each ball's yaw is uniform in [0, 2 pi) (flat spot down)
    - hoops are fixed; the robot starts at its rest keyframe (no noise)

    **Success Conditions:**
    - the target ball's centre is within ``success_radius_m`` (3 cm) of its hoop's goal point
      (the ring's centre). Whether the ball is still held does not matter. A ball dropped through
      the ring rests in the net within that distance, so *success at end* means "the ball is in
      the hoop's net" and *success once* additionally counts a ball that passed the goal point
      and left (which the net prevents unless the ball is taken out again)
    - grasp analysis (latched): ``reached`` = TCP within 4 cm of the target ball's surface before
      the first grip command; ``grasped`` = reached, then the ball raised >= 5 cm
    """

    family = "basketball"
    num_variations = 12
    has_grasp_target = True

    def __init__(self, *args: Any, layout: BasketballLayout | None = None, **kwargs: Any) -> None:
        self.layout = layout or BasketballLayout()
        count = len(self.layout.balls) * len(self.layout.hoops)
        if count != self.num_variations:
            raise ValueError(
                f"the layout gives {count} variations (balls x hoops); the task has "
                f"{self.num_variations}: use 3 balls and 4 hoops"
            )
        super().__init__(*args, **kwargs)

    # ------------------------------------------------------------------ scene
    def _load_task_scene(self, options: dict) -> None:
        lay = self.layout
        self.hoops = [build_hoop(self.scene, h, name=f"hoop_{j}") for j, h in enumerate(lay.hoops)]
        self.balls = [self._build_ball(b) for b in lay.balls]
        self._goals = torch.tensor(
            [h.goal_m for h in lay.hoops], dtype=torch.float32, device=self.device
        )
        self._radii = torch.tensor(
            [b.radius_m for b in lay.balls], dtype=torch.float32, device=self.device
        )

    def _build_ball(self, spec: BallSpec) -> Actor:
        builder = self.scene.create_actor_builder()
        physics = sapien.physx.PhysxMaterial(
            static_friction=spec.friction, dynamic_friction=spec.friction, restitution=0.0
        )
        builder.add_sphere_collision(
            radius=spec.radius_m, material=physics, density=spec.density_kg_m3
        )
        flat_half_z = 0.002
        builder.add_box_collision(
            pose=sapien.Pose(p=[0.0, 0.0, -spec.rest_height_m + flat_half_z]),
            half_size=[spec.flat_half_m, spec.flat_half_m, flat_half_z],
            material=physics,
            density=spec.density_kg_m3,
        )
        builder.add_sphere_visual(radius=spec.radius_m, material=material(spec.color))
        builder.initial_pose = sapien.Pose(p=[0.0, 0.0, spec.rest_height_m])
        ball = builder.build(name=spec.name)
        for obj in ball._objs:
            body = obj.find_component_by_type(sapien.physx.PhysxRigidDynamicComponent)
            body.angular_damping = 1.0
        return ball

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        lay = self.layout
        b = len(env_idx)
        xy = sample_separated_xy(
            b,
            len(self.balls),
            center_xy_m=lay.spawn_center_xy_m,
            half_size_m=lay.spawn_half_size_m,
            min_separation_m=lay.min_separation_m,
            min_abs_y_m=lay.spawn_min_abs_y_m,
            device=self.device,
        )
        yaw = torch.rand((b, len(self.balls)), device=self.device) * 2 * torch.pi
        place_upright(self.balls, xy, [spec.rest_height_m for spec in lay.balls], yaw)

    # ------------------------------------------------------------------ task state
    @property
    def target_ball_index(self) -> torch.Tensor:
        """(n,) index into :attr:`balls` of each env's target ball."""
        return self.task // len(self.layout.hoops)

    @property
    def target_hoop_index(self) -> torch.Tensor:
        """(n,) index into :attr:`hoops` of each env's goal hoop."""
        return self.task % len(self.layout.hoops)

    def ball_positions(self) -> torch.Tensor:
        """(n, 3, 3) centres of the balls [m]."""
        return torch.stack([b.pose.p for b in self.balls], dim=1)

    def target_position(self) -> torch.Tensor:
        """(n, 3) centre of each env's target ball [m]."""
        idx = self.target_ball_index
        first = int(idx[0])
        if bool(
            (idx == first).all()
        ):  # one pose read instead of three (called several times a step)
            return self.balls[first].pose.p
        rows = torch.arange(self.num_envs, device=self.device)
        return self.ball_positions()[rows, idx]

    def target_radius(self) -> torch.Tensor:
        """(n,) radius of each env's target ball [m]."""
        return self._radii[self.target_ball_index]

    def goal_position(self) -> torch.Tensor:
        """(n, 3) goal point (centre of the target hoop's ring) per env [m]."""
        return self._goals[self.target_hoop_index]

    def target_distance(self) -> torch.Tensor:
        """(n,) TCP distance to the target ball's surface [m] (0 inside)."""
        d = torch.linalg.norm(self.agent.tcp_pose.p - self.target_position(), dim=1)
        return torch.clamp(d - self.target_radius(), min=0.0)

    def object_distances(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(n, 3) TCP distance to each ball's surface [m] (0 inside) and (n,) the target's
        column."""
        d = torch.linalg.norm(self.agent.tcp_pose.p[:, None] - self.ball_positions(), dim=2)
        return torch.clamp(d - self._radii, min=0.0), self.target_ball_index

    def is_grasping_target(self) -> torch.Tensor:
        """(n,) simulator truth: both fingers press on the target ball."""
        return self._is_grasping_per_env(self.balls, self.target_ball_index)

    def place_goal(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The target hoop's goal point (its ring's centre); over it within ``success_radius_m``
        (a ball released there above the ring drops through it)."""
        radius = torch.full((self.num_envs,), self.layout.success_radius_m, device=self.device)
        return self.goal_position(), radius

    def _evaluate_task(self) -> dict[str, torch.Tensor]:
        dist = torch.linalg.norm(self.target_position() - self.goal_position(), dim=1)
        return {
            "success": dist <= self.layout.success_radius_m,
            "goal_distance_m": dist,
        }

    def _get_obs_extra(self, info: dict) -> dict:
        obs = super()._get_obs_extra(info)
        if "state" in self.obs_mode:
            obs.update(
                ball_positions=self.ball_positions().flatten(1),
                target_pos=self.target_position(),
                goal_pos=self.goal_position(),
            )
        return obs

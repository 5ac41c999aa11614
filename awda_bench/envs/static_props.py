"""Procedural props shared by the MOSAIC-style tasks: basketball hoops, pegs, ring shapes.

Everything is built from boxes (and one flat cylinder) on ManiSkill's actor builder, one actor per
parallel scene, no downloaded assets. Frames: world, table top at z = 0, x away from the robot,
y to its left.

Top view of a :class:`HoopSpec` (``o`` = goal point, the ring's centre; the post stands on the +x
side, away from the robot, so the arm reaching from -x never meets it)::

        -x (robot)          +x
               ____
             /      \\
            |   o    |----[post]
             \\ ____ /
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import sapien
from mani_skill.envs.scene import ManiSkillScene
from mani_skill.utils.building.actor_builder import ActorBuilder
from mani_skill.utils.structs.actor import Actor

RGBA = tuple[float, float, float, float]
"""Red, green, blue, alpha in [0, 1]."""

_CYLINDER_UP = sapien.Pose(q=[math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0])
"""SAPIEN cylinders lie along x; this turns their axis to z."""


def material(color: RGBA) -> sapien.render.RenderMaterial:
    """A plain render material of base colour ``color``."""
    return sapien.render.RenderMaterial(base_color=list(color))


def yaw_pose(x: float, y: float, z: float, yaw_rad: float) -> sapien.Pose:
    """Pose at (x, y, z) [m] turned by ``yaw_rad`` about the vertical axis."""
    return sapien.Pose(p=[x, y, z], q=[math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)])


def add_box(
    builder: ActorBuilder,
    center_m: tuple[float, float, float],
    half_size_m: tuple[float, float, float],
    color: RGBA,
    *,
    yaw_rad: float = 0.0,
    collision: bool = True,
    physics: sapien.physx.PhysxMaterial | None = None,
    density_kg_m3: float = 1000.0,
) -> None:
    """Add one box (visual, and collision unless ``collision=False``) in the builder's frame."""
    pose = yaw_pose(*center_m, yaw_rad)
    if collision:
        builder.add_box_collision(
            pose=pose, half_size=list(half_size_m), material=physics, density=density_kg_m3
        )
    builder.add_box_visual(pose=pose, half_size=list(half_size_m), material=material(color))


def add_polygon_ring(
    builder: ActorBuilder,
    *,
    center_m: tuple[float, float, float],
    inner_radius_m: float,
    tube_half_m: float,
    segments: int,
    color: RGBA,
) -> None:
    """A horizontal ring of ``segments`` boxes (a regular polygon) around ``center_m``.

    Each segment's inner face is tangent to the circle of ``inner_radius_m``; its cross-section is
    ``2 tube_half_m`` square; segments overlap slightly at the corners so the ring is closed.
    """
    if segments < 6:
        raise ValueError(f"segments must be >= 6 for a ring, got {segments}")
    mid = inner_radius_m + tube_half_m
    half_len = (inner_radius_m + 2 * tube_half_m) * math.tan(math.pi / segments)
    for k in range(segments):
        theta = 2 * math.pi * k / segments
        c = (
            center_m[0] + mid * math.cos(theta),
            center_m[1] + mid * math.sin(theta),
            center_m[2],
        )
        add_box(builder, c, (tube_half_m, half_len, tube_half_m), color, yaw_rad=theta)


def add_square_ring(
    builder: ActorBuilder,
    *,
    hole_half_m: float,
    wall_m: float,
    height_m: float,
    color: RGBA,
    physics: sapien.physx.PhysxMaterial | None = None,
    density_kg_m3: float = 1000.0,
) -> None:
    """A hollow square (4 boxes) centred on the builder's origin: hole ``2 hole_half_m`` wide,
    walls ``wall_m`` thick, ``height_m`` tall (z from ``-height_m / 2`` to ``+height_m / 2``)."""
    h, w, hz = hole_half_m, wall_m, height_m / 2
    outer = h + w
    for center, half in (
        ((h + w / 2, 0.0, 0.0), (w / 2, outer, hz)),
        ((-h - w / 2, 0.0, 0.0), (w / 2, outer, hz)),
        ((0.0, h + w / 2, 0.0), (h, w / 2, hz)),
        ((0.0, -h - w / 2, 0.0), (h, w / 2, hz)),
    ):
        add_box(builder, center, half, color, physics=physics, density_kg_m3=density_kg_m3)


# --------------------------------------------------------------------------------------- hoops
@dataclass(frozen=True)
class HoopSpec:
    """A basketball hoop: a coloured ring over a shallow white net (a cup) on a post.

    The ball dropped through the ring comes to rest on the net's floor with its centre
    ``net_depth_m - ball radius`` below the goal point (see the basketball task).
    """

    goal_m: tuple[float, float, float]
    """The ring's centre in the world: the goal point [m]."""
    color: RGBA
    """Ring and post colour."""
    inner_radius_m: float = 0.05
    """Radius of the ring's opening [m]."""
    tube_half_m: float = 0.005
    """Half the ring's square cross-section [m]."""
    segments: int = 12
    """Boxes making up the ring."""
    net_depth_m: float = 0.036
    """The net floor's top surface is this far below the goal point [m]."""
    net_bars: int = 8
    """Vertical bars of the net's cage."""
    net_color: RGBA = (0.95, 0.95, 0.95, 1.0)
    """Net colour."""
    post_gap_m: float = 0.025
    """Gap between the ring's outer edge and the post [m]."""
    post_half_m: float = 0.009
    """Half the post's square cross-section [m]."""

    @property
    def outer_radius_m(self) -> float:
        """Radius of the ring's outer edge [m]."""
        return self.inner_radius_m + 2 * self.tube_half_m

    @property
    def rim_top_z_m(self) -> float:
        """Height of the ring's top surface [m]."""
        return self.goal_m[2] + self.tube_half_m

    @property
    def net_floor_z_m(self) -> float:
        """Height of the net floor's top surface [m]."""
        return self.goal_m[2] - self.net_depth_m


def build_hoop(scene: ManiSkillScene, spec: HoopSpec, name: str) -> Actor:
    """Build ``spec`` as one static actor (ring, net cage and floor, arm, post)."""
    builder = scene.create_actor_builder()
    gx, gy, gz = spec.goal_m
    add_polygon_ring(
        builder,
        center_m=(0.0, 0.0, gz),
        inner_radius_m=spec.inner_radius_m,
        tube_half_m=spec.tube_half_m,
        segments=spec.segments,
        color=spec.color,
    )
    floor_half = 0.003
    floor_z = spec.net_floor_z_m - floor_half
    radius = spec.outer_radius_m
    builder.add_cylinder_collision(
        pose=sapien.Pose(p=[0.0, 0.0, floor_z], q=_CYLINDER_UP.q),
        radius=radius,
        half_length=floor_half,
    )
    builder.add_cylinder_visual(
        pose=sapien.Pose(p=[0.0, 0.0, floor_z], q=_CYLINDER_UP.q),
        radius=radius,
        half_length=floor_half,
        material=material(spec.net_color),
    )
    bar_half = 0.0025
    bar_r = spec.inner_radius_m + spec.tube_half_m
    bar_len = (gz - spec.tube_half_m) - spec.net_floor_z_m
    for k in range(spec.net_bars):
        theta = 2 * math.pi * (k + 0.5) / spec.net_bars
        add_box(
            builder,
            (bar_r * math.cos(theta), bar_r * math.sin(theta), spec.net_floor_z_m + bar_len / 2),
            (bar_half, bar_half, bar_len / 2),
            spec.net_color,
            yaw_rad=theta,
        )
    # a horizontal band halfway down makes the cage read as a net
    add_polygon_ring(
        builder,
        center_m=(0.0, 0.0, spec.net_floor_z_m + bar_len / 2),
        inner_radius_m=spec.inner_radius_m,
        tube_half_m=bar_half,
        segments=spec.segments,
        color=spec.net_color,
    )
    post_x = radius + spec.post_gap_m + spec.post_half_m
    p = spec.post_half_m
    top = gz + spec.tube_half_m
    add_box(builder, (post_x, 0.0, top / 2), (p, p, top / 2), spec.color)
    arm_len = post_x - spec.inner_radius_m - spec.tube_half_m
    add_box(
        builder,
        (spec.inner_radius_m + spec.tube_half_m + arm_len / 2, 0.0, gz),
        (arm_len / 2, spec.tube_half_m, spec.tube_half_m),
        spec.color,
    )
    # a foot plate keeps the post from looking like it floats
    add_box(builder, (post_x, 0.0, 0.003), (0.03, 0.03, 0.003), spec.color)
    builder.initial_pose = sapien.Pose(p=[gx, gy, 0.0])
    return builder.build_static(name=name)


# ---------------------------------------------------------------------------------------- pegs
@dataclass(frozen=True)
class PegSpec:
    """A vertical square peg standing on a square base plate."""

    center_xy_m: tuple[float, float]
    """Peg axis in the world [m]."""
    color: RGBA
    """Peg and plate colour."""
    half_width_m: float = 0.01
    """Half the peg's square cross-section [m] (2 cm peg)."""
    height_m: float = 0.09
    """Peg height above the plate's top surface [m]."""
    plate_half_m: float = 0.045
    """Half the base plate's side [m]."""
    plate_thickness_m: float = 0.006
    """Base plate thickness [m]; the nut comes to rest on its top surface."""

    @property
    def base_z_m(self) -> float:
        """Height of the plate's top surface (the bottom of the peg) [m]."""
        return self.plate_thickness_m

    @property
    def top_z_m(self) -> float:
        """Height of the peg's top [m]."""
        return self.plate_thickness_m + self.height_m


def build_peg(scene: ManiSkillScene, spec: PegSpec, name: str) -> Actor:
    """Build ``spec`` as one static actor (plate + peg)."""
    builder = scene.create_actor_builder()
    t = spec.plate_thickness_m
    r, g, b, _ = spec.color
    plate_color = (0.55 * r, 0.55 * g, 0.55 * b, 1.0)
    add_box(builder, (0.0, 0.0, t / 2), (spec.plate_half_m, spec.plate_half_m, t / 2), plate_color)
    w = spec.half_width_m
    add_box(builder, (0.0, 0.0, t + spec.height_m / 2), (w, w, spec.height_m / 2), spec.color)
    builder.initial_pose = sapien.Pose(p=[spec.center_xy_m[0], spec.center_xy_m[1], 0.0])
    return builder.build_static(name=name)

"""Static bins built from boxes: an open source bin and a target bin split into 4 compartments."""

from __future__ import annotations

from dataclasses import dataclass

import sapien
from mani_skill.envs.scene import ManiSkillScene
from mani_skill.utils.structs.actor import Actor


@dataclass(frozen=True)
class BinSpec:
    """An open box on the table, optionally split into 2 x 2 compartments by a cross divider."""

    center_xy_m: tuple[float, float]
    """Centre of the bin in the world [m]."""
    inner_half_size_m: tuple[float, float]
    """Half the inner floor extent along x and y [m]."""
    wall_height_m: float = 0.06
    """Wall height above the floor's top surface [m]."""
    wall_thickness_m: float = 0.01
    """Thickness of walls and divider [m]."""
    floor_thickness_m: float = 0.01
    """Floor plate thickness [m]; the floor's top surface is at this height."""
    divided: bool = False
    """Add a cross divider making 4 compartments."""
    color: tuple[float, float, float, float] = (0.35, 0.42, 0.50, 1.0)
    """RGBA base colour."""

    @property
    def floor_z_m(self) -> float:
        """Height of the floor's top surface above the table [m]."""
        return self.floor_thickness_m

    def compartment_box(self, index: int) -> tuple[tuple[float, float], tuple[float, float]]:
        """Inner x/y bounds ``((x_lo, x_hi), (y_lo, y_hi))`` [m] of compartment ``index`` (0-3).

        Numbering (x away from the robot, y to its left)::

            +x  | 2 | 3 |
                | 0 | 1 |
                  -y  +y
        """
        if not self.divided or index not in range(4):
            raise ValueError(f"compartment index must be 0-3 of a divided bin, got {index}")
        cx, cy = self.center_xy_m
        hx, hy = self.inner_half_size_m
        t = self.wall_thickness_m / 2
        xs = ((cx - hx, cx - t), (cx + t, cx + hx))
        ys = ((cy - hy, cy - t), (cy + t, cy + hy))
        return xs[index // 2], ys[index % 2]

    def compartment_center(self, index: int) -> tuple[float, float]:
        """Centre x, y of compartment ``index`` [m]."""
        (x_lo, x_hi), (y_lo, y_hi) = self.compartment_box(index)
        return (x_lo + x_hi) / 2, (y_lo + y_hi) / 2


def build_bin(scene: ManiSkillScene, spec: BinSpec, name: str) -> Actor:
    """Build ``spec`` as one static actor (floor + 4 walls [+ divider])."""
    builder = scene.create_actor_builder()
    material = sapien.render.RenderMaterial(base_color=list(spec.color))
    hx, hy = spec.inner_half_size_m
    t, h, f = spec.wall_thickness_m, spec.wall_height_m, spec.floor_thickness_m
    boxes = [
        # (centre xyz, half size xyz) in the bin frame (origin on the table, at the bin centre)
        ((0.0, 0.0, f / 2), (hx + t, hy + t, f / 2)),
        ((hx + t / 2, 0.0, f + h / 2), (t / 2, hy + t, h / 2)),
        ((-hx - t / 2, 0.0, f + h / 2), (t / 2, hy + t, h / 2)),
        ((0.0, hy + t / 2, f + h / 2), (hx, t / 2, h / 2)),
        ((0.0, -hy - t / 2, f + h / 2), (hx, t / 2, h / 2)),
    ]
    if spec.divided:
        boxes += [
            ((0.0, 0.0, f + h / 2), (t / 2, hy, h / 2)),
            ((0.0, 0.0, f + h / 2), (hx, t / 2, h / 2)),
        ]
    for center, half in boxes:
        pose = sapien.Pose(p=list(center))
        builder.add_box_collision(pose=pose, half_size=list(half))
        builder.add_box_visual(pose=pose, half_size=list(half), material=material)
    builder.initial_pose = sapien.Pose(p=[spec.center_xy_m[0], spec.center_xy_m[1], 0.0])
    return builder.build_static(name=name)

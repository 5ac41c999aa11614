"""The four pick-and-place objects of SPEC §3.1 (primitives, distinct colours), geometry helpers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sapien
import torch
from mani_skill.envs.scene import ManiSkillScene
from mani_skill.utils.structs.actor import Actor


@dataclass(frozen=True)
class ObjectSpec:
    """One graspable object, standing upright; its local z axis is vertical."""

    name: str
    """Name used in task names and actor names."""
    shape: str
    """``"box"`` or ``"cylinder"``."""
    size_m: tuple[float, float, float]
    """Full extent x, y, z [m]; for a cylinder x = y = diameter."""
    color: tuple[float, float, float, float]
    """RGBA base colour."""
    density_kg_m3: float = 400.0
    """Density [kg/m^3] (light packaging, not solid water)."""

    def __post_init__(self) -> None:
        if self.shape not in ("box", "cylinder"):
            raise ValueError(f"shape must be 'box' or 'cylinder', got {self.shape!r}")
        if self.shape == "cylinder" and self.size_m[0] != self.size_m[1]:
            raise ValueError(
                f"cylinder {self.name!r} needs equal x and y extents, got {self.size_m}"
            )

    @property
    def half_height_m(self) -> float:
        """Half the height [m]: the centre's height above its support when standing."""
        return self.size_m[2] / 2

    @property
    def footprint_radius_m(self) -> float:
        """Radius of the smallest vertical cylinder around the object [m]."""
        if self.shape == "cylinder":
            return self.size_m[0] / 2
        return float(np.hypot(self.size_m[0], self.size_m[1]) / 2)


PICK_PLACE_OBJECTS: tuple[ObjectSpec, ...] = (
    ObjectSpec(name="milk", shape="box", size_m=(0.04, 0.04, 0.14), color=(0.95, 0.95, 0.95, 1.0)),
    ObjectSpec(
        name="bread", shape="box", size_m=(0.035, 0.035, 0.05), color=(0.80, 0.52, 0.22, 1.0)
    ),
    ObjectSpec(
        name="cereal", shape="box", size_m=(0.035, 0.025, 0.054), color=(0.95, 0.85, 0.10, 1.0)
    ),
    ObjectSpec(
        name="can", shape="cylinder", size_m=(0.05, 0.05, 0.08), color=(0.85, 0.10, 0.10, 1.0)
    ),
)
"""Object ``i`` is the target of tasks ``4 i .. 4 i + 3`` (milk carton, bread, cereal, soda can)."""

_CYLINDER_UP = sapien.Pose(q=[np.sqrt(0.5), 0.0, np.sqrt(0.5), 0.0])
"""SAPIEN cylinders lie along x; this turns their axis to z."""


def build_object(scene: ManiSkillScene, spec: ObjectSpec, initial_z_m: float) -> Actor:
    """Build ``spec`` as a dynamic actor (one per parallel scene)."""
    builder = scene.create_actor_builder()
    material = sapien.render.RenderMaterial(base_color=list(spec.color))
    if spec.shape == "box":
        half = [s / 2 for s in spec.size_m]
        builder.add_box_collision(half_size=half, density=spec.density_kg_m3)
        builder.add_box_visual(half_size=half, material=material)
    else:
        radius, half_length = spec.size_m[0] / 2, spec.size_m[2] / 2
        builder.add_cylinder_collision(
            pose=_CYLINDER_UP, radius=radius, half_length=half_length, density=spec.density_kg_m3
        )
        builder.add_cylinder_visual(
            pose=_CYLINDER_UP, radius=radius, half_length=half_length, material=material
        )
    builder.initial_pose = sapien.Pose(p=[0.0, 0.0, initial_z_m])
    return builder.build(name=spec.name)


def distance_to_objects(
    points: torch.Tensor,
    positions: torch.Tensor,
    quats: torch.Tensor,
    specs: tuple[ObjectSpec, ...],
) -> torch.Tensor:
    """Euclidean distance [m] from ``points`` (n, 3) to the surface of each object (0 inside).

    ``positions`` (n, k, 3) and ``quats`` (n, k, 4, wxyz) are the objects' poses; returns (n, k).
    """
    from mani_skill.utils.geometry.rotation_conversions import quaternion_apply, quaternion_invert

    rel = points[:, None, :] - positions
    local = quaternion_apply(quaternion_invert(quats), rel)
    out = []
    for j, spec in enumerate(specs):
        p = local[:, j]
        half = torch.tensor([s / 2 for s in spec.size_m], dtype=p.dtype, device=p.device)
        if spec.shape == "box":
            outside = torch.clamp(p.abs() - half, min=0.0)
        else:
            radial = torch.clamp(torch.linalg.norm(p[:, :2], dim=1) - half[0], min=0.0)
            vertical = torch.clamp(p[:, 2].abs() - half[2], min=0.0)
            outside = torch.stack([radial, vertical], dim=1)
        out.append(torch.linalg.norm(outside, dim=1))
    return torch.stack(out, dim=1)

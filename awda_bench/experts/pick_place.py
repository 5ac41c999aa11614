"""Scripted pick-and-place expert: the pick-carry-place core (:mod:`.pick_carry_place`) told
where the target object is and which compartment it goes to.

Grasp: the fingertips ``grasp_depth_m`` below the object's top (not below its centre). Carry: the
object's bottom clears the highest bin wall. Release: the object's bottom just above the
compartment floor. The object's pose is re-read every step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.experts.base import check_config
from awda_bench.experts.pick_carry_place import (
    PickCarryPlaceConfig,
    PickCarryPlaceExpert,
    PickScene,
)


@dataclass(frozen=True)
class PickPlaceExpertConfig(PickCarryPlaceConfig):
    """Where the pick-and-place expert grasps and releases (plus the core's settings)."""

    hover_clearance_m: float = 0.06
    """HOVER goal: this far above the target object's top [m]."""
    min_hover_z_m: float = 0.14
    """HOVER goal never lower than this TCP height [m]."""
    grasp_depth_m: float = 0.03
    """DESCEND goal: TCP this far below the object's top, but not below its centre [m]
    (the Panda fingertips' TCP; a per-end-effector parameter)."""
    release_clearance_m: float = 0.02
    """LOWER goal: the held object's bottom this far above the compartment floor [m]."""
    min_carry_z_m: float = 0.14
    xy_tolerance_m: float = 0.006
    carry_xy_tolerance_m: float = 0.006
    z_tolerance_m: float = 0.006

    def __post_init__(self) -> None:
        super().__post_init__()
        check_config(self, positive=("hover_clearance_m", "grasp_depth_m", "release_clearance_m"))


class PickPlaceExpert(PickCarryPlaceExpert):
    """Scripted expert of the ``pick_place`` suite (the ``scripted`` method); batched over envs."""

    config: PickPlaceExpertConfig
    config_type = PickPlaceExpertConfig

    def read_scene(self, env: Any, tcp: np.ndarray) -> PickScene:
        cfg = self.config
        obj, _ = (t.cpu().numpy().astype(np.float64) for t in env.target_pose())
        half_h = np.array(
            [env.objects_spec[i].half_height_m for i in env.target_object_index.cpu().numpy()]
        )
        top = obj[:, 2] + half_h
        lay = env.layout
        walls = max(b.floor_z_m + b.wall_height_m for b in (lay.source_bin, lay.target_bin))
        n = len(obj)
        return PickScene(
            grasp=np.column_stack([obj[:, :2], np.maximum(top - cfg.grasp_depth_m, obj[:, 2])]),
            hover_z=np.maximum(top + cfg.hover_clearance_m, cfg.min_hover_z_m),
            held=obj,
            bottom_z=obj[:, 2] - half_h,
            place_xy=env.compartment_center().cpu().numpy()[:, :2].astype(np.float64),
            clear_z=np.full(n, walls),
            release_bottom_z=np.full(n, lay.target_bin.floor_z_m + cfg.release_clearance_m),
        )

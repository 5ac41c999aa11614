"""Scripted nut-assembly expert: the pick-carry-place core (:mod:`.pick_carry_place`) told to put
the target nut on its peg.

Grasp: the fingers close on the nut's handle, ~5 cm from the hole's centre. Carry: the nut's
bottom clears the highest peg top, with *the hole* (read every step from the nut's pose) as the
reference the core aims at the peg's axis, so the grasp offset and any swing of the nut in the
fingers are compensated; it lowers only once the hole is centred. Release: the nut's bottom just
above the peg's base plate.
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
class NutAssemblyExpertConfig(PickCarryPlaceConfig):
    """Where the nut-assembly expert grasps and releases (plus the core's settings)."""

    hover_clearance_m: float = 0.08
    """HOVER goal: the TCP this far above the handle's centre [m]."""
    grasp_offset_m: float = 0.003
    """DESCEND goal: the TCP this far above the handle's centre [m]."""
    min_grasp_z_m: float = 0.012
    """DESCEND goal never lower than this TCP height (fingertips hang ~1 cm below it) [m]."""
    release_height_m: float = 0.006
    """LOWER goal: the held nut's bottom this far above the peg's base plate [m]."""
    carry_clearance_m: float = 0.025
    xy_tolerance_m: float = 0.004
    carry_xy_tolerance_m: float = 0.004
    """The hole clears the peg by 8 mm per side."""
    z_tolerance_m: float = 0.006

    def __post_init__(self) -> None:
        super().__post_init__()
        check_config(self, positive=("hover_clearance_m", "min_grasp_z_m", "release_height_m"))


class NutAssemblyExpert(PickCarryPlaceExpert):
    """Scripted expert of the ``nut_assembly`` family; batched over envs."""

    config: NutAssemblyExpertConfig
    config_type = NutAssemblyExpertConfig

    def read_scene(self, env: Any, tcp: np.ndarray) -> PickScene:
        cfg = self.config
        nut = env.target_position().cpu().numpy().astype(np.float64)
        half_h = env.target_half_height().cpu().numpy().astype(np.float64)
        handle = env.grasp_point().cpu().numpy().astype(np.float64)
        peg = env.peg_position().cpu().numpy().astype(np.float64)
        highest_peg = max(p.top_z_m for p in env.layout.pegs)
        return PickScene(
            grasp=np.column_stack(
                [handle[:, :2], np.maximum(handle[:, 2] + cfg.grasp_offset_m, cfg.min_grasp_z_m)]
            ),
            hover_z=handle[:, 2] + cfg.hover_clearance_m,
            held=nut,
            bottom_z=nut[:, 2] - half_h,
            place_xy=peg[:, :2],
            clear_z=np.full(len(nut), highest_peg),
            release_bottom_z=peg[:, 2] + cfg.release_height_m,
        )

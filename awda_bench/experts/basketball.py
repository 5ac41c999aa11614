"""Scripted basketball expert: the pick-carry-place core (:mod:`.pick_carry_place`) told to drop
the target ball through its hoop.

Grasp: the fingertips at the ball's equator. Carry: the ball's bottom clears the highest rim.
Release: the ball's bottom just above the target rim with its centre over the ring's centre, so
the open fingers let it drop straight into the net.
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
class BasketballExpertConfig(PickCarryPlaceConfig):
    """Where the basketball expert grasps and releases (plus the core's settings)."""

    hover_clearance_m: float = 0.08
    """HOVER goal: the TCP this far above the ball's centre [m]."""
    grasp_offset_m: float = 0.0
    """DESCEND goal: the TCP this far above the ball's centre (0: fingertips at the equator) [m]."""
    min_grasp_z_m: float = 0.015
    """DESCEND goal never lower than this TCP height (fingertips hang ~1 cm below it) [m]."""
    release_clearance_m: float = 0.015
    """LOWER goal: the held ball's bottom this far above the target hoop's rim [m]."""
    release_steps: int = 6
    z_tolerance_m: float = 0.006

    def __post_init__(self) -> None:
        super().__post_init__()
        check_config(self, positive=("hover_clearance_m", "min_grasp_z_m", "release_clearance_m"))


class BasketballExpert(PickCarryPlaceExpert):
    """Scripted expert of the ``basketball`` family; batched over envs."""

    config: BasketballExpertConfig
    config_type = BasketballExpertConfig

    def read_scene(self, env: Any, tcp: np.ndarray) -> PickScene:
        cfg = self.config
        ball = env.target_position().cpu().numpy().astype(np.float64)
        radius = env.target_radius().cpu().numpy().astype(np.float64)
        goal = env.goal_position().cpu().numpy().astype(np.float64)
        rims = np.array([h.rim_top_z_m for h in env.layout.hoops])
        rim = rims[env.target_hoop_index.cpu().numpy()]
        return PickScene(
            grasp=np.column_stack(
                [ball[:, :2], np.maximum(ball[:, 2] + cfg.grasp_offset_m, cfg.min_grasp_z_m)]
            ),
            hover_z=ball[:, 2] + cfg.hover_clearance_m,
            held=ball,
            bottom_z=ball[:, 2] - radius,
            place_xy=goal[:, :2],
            clear_z=np.full(len(ball), rims.max()),
            release_bottom_z=rim + cfg.release_clearance_m,
        )

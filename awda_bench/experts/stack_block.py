"""Scripted stack-block expert: the pick-carry-place core (:mod:`.pick_carry_place`) told to put
cube A on cube B.

Grasp: the fingertips ``grasp_depth_m`` below A's top. Carry: A's bottom clears the highest cube
top. Release: A's bottom just above B's actual top, A's centre within ``carry_xy_tolerance_m``
of B's (A must land on B's 4.5 cm top).
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
class StackBlockExpertConfig(PickCarryPlaceConfig):
    """Where the stack-block expert grasps and releases (plus the core's settings)."""

    hover_clearance_m: float = 0.06
    """HOVER goal: TCP this far above cube A's top [m]."""
    grasp_depth_m: float = 0.025
    """DESCEND goal: TCP this far below A's top, but not below its centre [m]."""
    release_clearance_m: float = 0.004
    """LOWER goal: A's bottom this far above B's top [m]."""
    carry_clearance_m: float = 0.03
    min_carry_z_m: float = 0.12
    release_steps: int = 6
    carry_xy_tolerance_m: float = 0.003

    def __post_init__(self) -> None:
        super().__post_init__()
        check_config(self, positive=("hover_clearance_m", "grasp_depth_m", "release_clearance_m"))


class StackBlockExpert(PickCarryPlaceExpert):
    """Scripted expert of the ``stack_block`` family (``AWDA-StackBlock-v1``); batched over envs."""

    config: StackBlockExpertConfig
    config_type = StackBlockExpertConfig

    def read_scene(self, env: Any, tcp: np.ndarray) -> PickScene:
        cfg = self.config
        half = env.layout.edge_m / 2
        a = env.target_position().cpu().numpy().astype(np.float64)
        b = env.base_pose()[0].cpu().numpy().astype(np.float64)
        tops = env.cube_poses()[0].cpu().numpy()[:, :, 2].max(axis=1) + half
        a_top = a[:, 2] + half
        return PickScene(
            grasp=np.column_stack([a[:, :2], np.maximum(a_top - cfg.grasp_depth_m, a[:, 2])]),
            hover_z=a_top + cfg.hover_clearance_m,
            held=a,
            bottom_z=a[:, 2] - half,
            place_xy=b[:, :2],
            clear_z=tops.astype(np.float64),
            release_bottom_z=b[:, 2] + half + cfg.release_clearance_m,
        )

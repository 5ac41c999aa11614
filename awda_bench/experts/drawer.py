"""Scripted drawer expert: the handle core (:mod:`.handle_pull`) told about a sliding drawer.

Opening grasps the handle head by its sides and pulls it straight out along the slide axis;
closing pushes the handle head's front with the closed fingers. The led point is the handle (or
the head's front) ``lead_m`` beyond its measured position along the axis; the hand climbs to its
hover height before moving sideways (it never sweeps into an open drawer).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.experts.base import check_config
from awda_bench.experts.handle_pull import HandleConfig, HandleExpert, HandleScene


@dataclass(frozen=True)
class DrawerExpertConfig(HandleConfig):
    """Targets, heights, tolerances and step budgets of the scripted drawer expert."""

    open_target_m: float = 0.16
    """Open: pull until the drawer is slid out this far [m] (success needs 0.12)."""
    close_target_m: float = 0.002
    """Close: push until the drawer is at most this far out [m] (success needs 0.005)."""
    lead_m: float = 0.012
    """MOVE goal: this far ahead of the measured slide [m] (not clipped at the target; it also caps
    the pull speed: a faster pull slips out of the pads on the fast demonstrator)."""
    hover_clearance_m: float = 0.09
    """HOVER height above the handle head's centre [m] (the fingertips, 1 cm below the TCP, pass
    over the drawer front's top edge, 6.3 cm above the handle)."""
    rise_first_m: float = 0.01
    """HOVER moves straight up while the TCP is more than this below the hover height [m] (the
    hand never sweeps sideways into an open drawer)."""
    grasp_offset_m: float = -0.003
    """Open: TCP height relative to the head's centre when closing [m] (the pads straddle it)."""
    closed_fingers_half_extent_m: tuple[float, float] = (0.011, 0.027)
    """Half extent of the closed fingertips along world x and y [m] (Panda hand pointing down)."""
    approach_margin_m: float = 0.02
    """Close: HOVER/DESCEND keep the fingertips this far in front of the head [m]."""
    press_in_m: float = 0.004
    """Close: MOVE aims the fingertips this far into the head (keeps them in contact) [m]."""
    slide_tolerance_m: float = 0.005
    """Open: MOVE ends within this of ``open_target_m`` [m]."""

    def __post_init__(self) -> None:
        super().__post_init__()
        check_config(
            self, positive=("open_target_m", "lead_m", "hover_clearance_m", "slide_tolerance_m")
        )


class DrawerExpert(HandleExpert):
    """Scripted expert of the ``drawer`` family (``AWDA-Drawer-v1``); batched over envs."""

    config: DrawerExpertConfig
    config_type = DrawerExpertConfig

    def read_scene(self, env: Any, tcp: np.ndarray) -> HandleScene:
        cfg = self.config
        n = env.num_envs
        slide = env.target_slide().cpu().numpy().astype(np.float64)
        handle = env.handle_position().cpu().numpy().astype(np.float64)
        axis = env.slide_axis().cpu().numpy().astype(np.float64)  # toward the robot
        head_half_x = np.array([env.target_spec(i).handle_head_size_m[0] / 2 for i in range(n)])
        hx, hy = cfg.closed_fingers_half_extent_m
        support = hx * np.abs(axis[:, 0]) + hy * np.abs(axis[:, 1])  # fingertips along the axis
        head_front = handle + axis * head_half_x[:, None]
        push_approach = head_front + axis * (support + cfg.approach_margin_m)[:, None]
        # fingertips pressed on the head, led inward along the axis
        push_led = head_front - axis * cfg.lead_m + axis * (support - cfg.press_in_m)[:, None]
        hover_z = handle[:, 2] + cfg.hover_clearance_m
        arrived = np.where(
            self.pull,
            slide >= cfg.open_target_m - cfg.slide_tolerance_m,
            slide <= cfg.close_target_m,
        )
        return HandleScene(
            work_xy=np.where(self.pull[:, None], handle[:, :2], push_approach[:, :2]),
            hover_z=hover_z,
            work_z=handle[:, 2] + np.where(self.pull, cfg.grasp_offset_m, 0.0),
            rise_below_z=hover_z - cfg.rise_first_m,
            handle=handle,
            pull_goal=handle + axis * cfg.lead_m,
            push_goal=push_led[:, :2],
            arrived=arrived,
        )

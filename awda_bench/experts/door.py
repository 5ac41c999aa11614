"""Scripted door expert: the handle core (:mod:`.handle_pull`) told about a hinged door.

Opening grasps the handle bar and carries it along the door's arc; closing pushes the panel's
front face with the closed fingers (the door swings toward the robot, so a push toward shut never
needs a grasp). The led point is the handle (or the push point on the panel) with the hinge
``lead_rad`` ahead of the measured angle; the hand rises above the handle's top before it moves
across (it never sweeps into the doors' top edges).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from awda_bench.experts.base import check_config
from awda_bench.experts.handle_pull import HandleConfig, HandleExpert, HandleScene


@dataclass(frozen=True)
class DoorExpertConfig(HandleConfig):
    """Targets, heights, tolerances and step budgets of the scripted door expert."""

    open_target_rad: float = 0.62
    """Open: swing until the hinge reaches this angle [rad] (success needs 0.4)."""
    close_target_rad: float = 0.02
    """Close: push until the hinge is at most this angle [rad] (success needs 0.1)."""
    lead_rad: float = 0.10
    """MOVE goal: this far ahead of the measured hinge angle [rad] (not clipped at the target, so
    the arm never stalls short of it)."""
    hover_clearance_m: float = 0.07
    """HOVER height above the handle's (or panel's) top [m]."""
    rise_clearance_m: float = 0.02
    """HOVER moves straight up until the TCP is this far above the handle's top [m] (the hand
    body never sweeps across the doors' top edges)."""
    grasp_depth_m: float = 0.02
    """Open: the TCP closes this far below the handle bar's top [m] (the hand body, 3.7 cm above
    the TCP, stays above the panel)."""
    push_depth_m: float = 0.025
    """Close: the TCP pushes this far below the panel's top [m]."""
    push_along_m: float = 0.085
    """Close: push point's distance from the hinge along the panel [m] (clear of the handle)."""
    closed_fingers_half_extent_m: tuple[float, float] = (0.011, 0.027)
    """Half extent of the closed fingertips along world x and y [m] (Panda hand pointing down)."""
    approach_margin_m: float = 0.025
    """Close: HOVER/DESCEND keep the fingers this far in front of the panel [m]."""
    press_in_m: float = 0.004
    """Close: MOVE aims the fingers this far into the panel (keeps them in contact) [m]."""
    xy_tolerance_m: float = 0.006
    angle_tolerance_rad: float = 0.02
    """MOVE ends within this of its target angle [rad]."""

    def __post_init__(self) -> None:
        super().__post_init__()
        check_config(
            self,
            positive=(
                "open_target_rad",
                "lead_rad",
                "hover_clearance_m",
                "grasp_depth_m",
                "push_depth_m",
                "push_along_m",
                "angle_tolerance_rad",
            ),
        )


class DoorExpert(HandleExpert):
    """Scripted expert of the ``door`` family (``AWDA-Door-v1``); batched over envs."""

    config: DoorExpertConfig
    config_type = DoorExpertConfig

    def read_scene(self, env: Any, tcp: np.ndarray) -> HandleScene:
        cfg = self.config
        n = env.num_envs
        angle_t = env.target_angle()
        angle = angle_t.cpu().numpy().astype(np.float64)
        pull = torch.as_tensor(self.pull, device=env.device)
        # geometry at the current angle and at the led angle (batched on the env's device)
        lead = torch.where(pull, angle_t + cfg.lead_rad, angle_t - cfg.lead_rad)
        handle_now = env.handle_position().cpu().numpy().astype(np.float64)
        handle_led = env.handle_position(lead).cpu().numpy().astype(np.float64)
        top = np.array([env.target_spec(i).handle_top_z_m for i in range(n)])
        push_approach = self._push_point(env, angle_t, cfg.approach_margin_m)
        push_led = self._push_point(env, lead, -cfg.press_in_m)
        arrived = np.where(
            self.pull,
            angle >= cfg.open_target_rad - cfg.angle_tolerance_rad,
            angle <= cfg.close_target_rad,
        )
        return HandleScene(
            work_xy=np.where(self.pull[:, None], handle_now[:, :2], push_approach[:, :2]),
            hover_z=top + cfg.hover_clearance_m,
            work_z=top - np.where(self.pull, cfg.grasp_depth_m, cfg.push_depth_m),
            rise_below_z=top + cfg.rise_clearance_m,
            handle=handle_now,
            pull_goal=handle_led,
            push_goal=push_led[:, :2],
            arrived=arrived,
        )

    # ------------------------------------------------------------------ geometry
    def _push_point(self, env: Any, angle: torch.Tensor, gap_m: float) -> np.ndarray:
        """(n, 3) TCP position putting the closed fingertips ``gap_m`` in front of the panel's front
        face (negative: into it), ``push_along_m`` from the hinge, with the panel at ``angle``."""
        cfg = self.config
        n = env.num_envs
        rel = torch.tensor(
            [env.target_spec(i).point_from_hinge_local_m(cfg.push_along_m, 0.0) for i in range(n)],
            dtype=torch.float32,
            device=env.device,
        )
        on_face = env.door_point(rel, angle)
        normal = env.door_normal(angle)
        hx, hy = cfg.closed_fingers_half_extent_m
        reach = hx * normal[:, 0].abs() + hy * normal[:, 1].abs()  # fingertip support along normal
        point = on_face + normal * (reach + gap_m)[:, None]
        return point.cpu().numpy().astype(np.float64)

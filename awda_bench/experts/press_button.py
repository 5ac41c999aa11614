"""Scripted press-button expert from privileged state, acting only through the 4-D action space.

Phases per env (straight-line moves, at most ``max_step_m`` per axis per step)::

    HOVER --> CLOSE --> PRESS --> HOLD --> RELEASE --> DONE
    above the   fingers   straight   keep       straight up
    target cap  shut      down       pushing    (the spring pops the button back)

PRESS aims ``overshoot_m`` below the depth at which the fingertips would hold the cap on its lower
stop, so the arm keeps pushing once the button bottoms out; it ends when the button is within
``bottom_tolerance_m`` of its full travel. HOLD keeps the same goal for ``hold_steps``: the button
stays down and the TCP stays blocked, which is what the pressing attribute sees (see
:mod:`awda_bench.mining`: while the button travels, the arm moves as fast as in free space, so
only the held part of a press is visible to the miner: ~4 of the truth's steps are not, so a
2 s hold keeps the mined attribute's recall above 90 %). Works for any embodiment of
:mod:`awda_bench.envs.embodiments` (step size and grip sign from there).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from awda_bench.experts.base import PhaseExpert, check_config


class Phase(IntEnum):
    HOVER = 0
    CLOSE = 1
    PRESS = 2
    HOLD = 3
    RELEASE = 4
    DONE = 5


_GRIP_CLOSED = {Phase.CLOSE, Phase.PRESS, Phase.HOLD, Phase.RELEASE}
"""Phases during which the gripper is commanded closed (fingers shut: a blunt pusher)."""


@dataclass(frozen=True)
class PressScene:
    """Where things are, per env (arrays over the envs), read from the state every step."""

    cap: np.ndarray
    """(n, 3) the target cap's top at rest [m]."""
    depth: np.ndarray
    """(n,) how far the target button is pressed in [m]."""
    travel_m: float
    """The buttons' full travel [m]."""
    hover_z: np.ndarray
    """(n,) TCP height of HOVER and RELEASE [m]."""
    press_z: np.ndarray
    """(n,) TCP height PRESS and HOLD aim at [m]."""


@dataclass(frozen=True)
class PressButtonExpertConfig:
    """Heights, tolerances and step budgets of the scripted press-button expert."""

    hover_clearance_m: float = 0.05
    """HOVER goal: TCP this far above the target cap's top at rest [m]."""
    fingertip_below_tcp_m: float = 0.009
    """The closed fingertips reach this far below the TCP [m] (measured on the Panda hand)."""
    overshoot_m: float = 0.01
    """PRESS/HOLD goal: this far below where the fingertips hold the cap on its stop [m]."""
    bottom_tolerance_m: float = 0.002
    """PRESS ends when the button is within this of its full travel [m]."""
    close_steps: int = 4
    """Control steps the gripper is commanded closed before pressing."""
    hold_steps: int = 40
    """Control steps the button is held down (2 s at 20 Hz; see the module docstring)."""
    xy_tolerance_m: float = 0.004
    """Horizontal goal tolerance of HOVER [m] (the cap radius is 2.2 cm)."""
    z_tolerance_m: float = 0.006
    """Vertical goal tolerance [m]."""
    phase_budget_steps: int = 90
    """Most control steps any moving phase may take (a full step moves the TCP 2 cm)."""

    def __post_init__(self) -> None:
        check_config(
            self,
            positive=(
                "hover_clearance_m",
                "overshoot_m",
                "bottom_tolerance_m",
                "xy_tolerance_m",
                "z_tolerance_m",
            ),
            at_least_one=(
                "close_steps",
                "hold_steps",
                "phase_budget_steps",
            ),
        )


class PressButtonExpert(PhaseExpert):
    """Scripted expert of the ``press_button`` family (``AWDA-PressButton-v1``), batched."""

    config: PressButtonExpertConfig
    config_type = PressButtonExpertConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE
    grip_closed_phases = _GRIP_CLOSED

    # ------------------------------------------------------------------ Policy protocol
    def read_scene(self, env: Any, tcp: np.ndarray) -> PressScene:
        cfg = self.config
        lay = env.layout
        cap = env.target_rest_cap_top().cpu().numpy().astype(np.float64)
        depth = env.target_depth_m().cpu().numpy().astype(np.float64)
        return PressScene(
            cap=cap,
            depth=depth,
            travel_m=lay.travel_m,
            hover_z=cap[:, 2] + cfg.hover_clearance_m,
            press_z=cap[:, 2] - lay.travel_m + cfg.fingertip_below_tcp_m - cfg.overshoot_m,
        )

    def _set_goal(self, i: int, tcp: np.ndarray, scene: PressScene, goal: np.ndarray) -> None:
        phase = Phase(self.phase[i])
        cap = scene.cap[i]
        if phase == Phase.HOVER:
            goal[:] = (cap[0], cap[1], scene.hover_z[i])
        elif phase in (Phase.PRESS, Phase.HOLD):
            goal[:] = (cap[0], cap[1], scene.press_z[i])
        elif phase == Phase.RELEASE:
            goal[:] = (cap[0], cap[1], scene.hover_z[i])
        # CLOSE, DONE: hold position

    # ------------------------------------------------------------------ phase logic
    def _advance(self, i: int, tcp: np.ndarray, scene: PressScene) -> None:
        cfg = self.config
        cap, hover_z, depth, travel = scene.cap[i], scene.hover_z[i], scene.depth[i], scene.travel_m
        phase = Phase(self.phase[i])
        steps = self.phase_steps[i]
        over_budget = steps >= cfg.phase_budget_steps
        xy_err = float(np.linalg.norm(tcp[:2] - cap[:2]))
        nxt = phase
        if phase == Phase.HOVER:
            if (
                xy_err <= cfg.xy_tolerance_m and abs(tcp[2] - hover_z) <= cfg.z_tolerance_m
            ) or over_budget:
                nxt = Phase.CLOSE
        elif phase == Phase.CLOSE:
            if steps >= cfg.close_steps:
                nxt = Phase.PRESS
        elif phase == Phase.PRESS:
            if depth >= travel - cfg.bottom_tolerance_m or over_budget:
                nxt = Phase.HOLD
        elif phase == Phase.HOLD:
            if steps >= cfg.hold_steps:
                nxt = Phase.RELEASE
        elif phase == Phase.RELEASE:
            if tcp[2] >= hover_z - cfg.z_tolerance_m or over_budget:
                nxt = Phase.DONE
        if nxt != phase:
            self.phase[i] = int(nxt)
            self.phase_steps[i] = 0

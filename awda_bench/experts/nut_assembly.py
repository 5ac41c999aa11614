"""Scripted nut-assembly expert from privileged state, acting only through the 4-D action space.

Phases per env (each moves the TCP in a straight line, at most ``max_step_m`` per axis per step)::

    HOVER --> DESCEND --> CLOSE --> LIFT --> CARRY --> LOWER --> RELEASE --> RETREAT --> DONE
    above the  fingers     grip      nut above hole over  nut down    grip        straight
    handle     around the  closed    the peg   the peg    the peg     open        up
               handle                tops      axis       (to ~plate)

The fingers close on the handle, ~5 cm from the hole's centre. After the grasp the expert aims
*the hole* (read every step from the nut's pose) at the peg's axis, so the grasp offset and any
slip or swing of the nut in the fingers are compensated; it lowers only once the hole is centred.
Works for any embodiment of :mod:`awda_bench.envs.embodiments`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.experts.base import PICK_GRIP_CLOSED as _GRIP_CLOSED
from awda_bench.experts.base import PhaseExpert, check_config, straight_line_action
from awda_bench.experts.base import PickPhase as Phase


@dataclass(frozen=True)
class NutAssemblyExpertConfig:
    """Heights, tolerances and step budgets of the scripted nut-assembly expert."""

    hover_clearance_m: float = 0.08
    """HOVER goal: the TCP this far above the handle's centre [m]."""
    grasp_offset_m: float = 0.003
    """DESCEND goal: the TCP this far above the handle's centre [m]."""
    min_grasp_z_m: float = 0.012
    """DESCEND goal never lower than this TCP height (fingertips hang ~1 cm below it) [m]."""
    carry_clearance_m: float = 0.025
    """LIFT/CARRY: the held nut's bottom this far above the highest peg top [m]."""
    release_height_m: float = 0.006
    """LOWER goal: the held nut's bottom this far above the peg's base plate [m]."""
    retreat_m: float = 0.08
    """RETREAT: rise this far above the release height [m]."""
    close_steps: int = 6
    """Control steps the gripper is commanded closed before lifting."""
    release_steps: int = 5
    """Control steps the gripper is commanded open before retreating."""
    xy_tolerance_m: float = 0.004
    """Horizontal goal tolerance [m] (the hole clears the peg by 8 mm per side)."""
    z_tolerance_m: float = 0.006
    """Vertical goal tolerance [m]."""
    phase_budget_steps: int = 80
    """Most control steps any moving phase may take (the agent tracks ~8 mm per full step)."""

    def __post_init__(self) -> None:
        check_config(
            self,
            positive=(
                "hover_clearance_m",
                "min_grasp_z_m",
                "carry_clearance_m",
                "release_height_m",
                "retreat_m",
                "xy_tolerance_m",
                "z_tolerance_m",
            ),
            at_least_one=(
                "close_steps",
                "release_steps",
                "phase_budget_steps",
            ),
        )


class NutAssemblyExpert(PhaseExpert):
    """Scripted expert of the ``nut_assembly`` family; batched over envs."""

    config: NutAssemblyExpertConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE

    def __init__(
        self, config: NutAssemblyExpertConfig | None = None, name: str = "scripted"
    ) -> None:
        super().__init__(config or NutAssemblyExpertConfig(), name)
        self._carry_z = np.zeros(0)
        self._release_z = np.zeros(0)

    # ------------------------------------------------------------------ Policy protocol
    def _reset_state(self, n: int) -> None:
        self._carry_z = np.zeros(n)
        self._release_z = np.zeros(n)

    def act(self, obs: Any) -> np.ndarray:
        """(n, 4) action for the loaded embodiment: straight-line step towards the phase goal."""
        if self._env is None:
            raise RuntimeError("act() before reset(ctx)")
        env, cfg = self._env, self.config
        tcp = env.agent.tcp_pose.p.cpu().numpy().astype(np.float64)
        nut = env.target_position().cpu().numpy().astype(np.float64)
        half_h = env.target_half_height().cpu().numpy().astype(np.float64)
        handle = env.grasp_point().cpu().numpy().astype(np.float64)
        peg = env.peg_position().cpu().numpy().astype(np.float64)
        highest_peg = max(p.top_z_m for p in env.layout.pegs)

        grasp_z = np.maximum(handle[:, 2] + cfg.grasp_offset_m, cfg.min_grasp_z_m)
        hover_z = handle[:, 2] + cfg.hover_clearance_m
        bottom = nut[:, 2] - half_h
        # where the TCP must be for the *hole* to be over the peg (grasp offset compensated)
        aim_xy = peg[:, :2] + (tcp[:, :2] - nut[:, :2])

        target = tcp.copy()
        for i in range(len(tcp)):
            self._advance(
                i, tcp[i], handle[i], nut[i], peg[i], bottom[i], grasp_z[i], hover_z[i], highest_peg
            )
            phase = Phase(self.phase[i])
            if phase == Phase.HOVER:
                target[i] = (handle[i, 0], handle[i, 1], max(hover_z[i], tcp[i, 2]))
            elif phase == Phase.DESCEND:
                target[i] = (handle[i, 0], handle[i, 1], grasp_z[i])
            elif phase == Phase.LIFT:
                target[i, 2] = self._carry_z[i]
            elif phase == Phase.CARRY:
                target[i] = (aim_xy[i, 0], aim_xy[i, 1], self._carry_z[i])
            elif phase == Phase.LOWER:
                target[i] = (aim_xy[i, 0], aim_xy[i, 1], self._release_z[i])
            elif phase == Phase.RETREAT:
                target[i, 2] = self._release_z[i] + cfg.retreat_m
            # CLOSE, RELEASE, DONE: hold position
            self.phase_steps[i] += 1

        closed = np.isin(self.phase, [int(p) for p in _GRIP_CLOSED])
        return straight_line_action(target, tcp, closed, env)

    # ------------------------------------------------------------------ phase logic
    def _advance(
        self,
        i: int,
        tcp: np.ndarray,
        handle: np.ndarray,
        nut: np.ndarray,
        peg: np.ndarray,
        bottom: float,
        grasp_z: float,
        hover_z: float,
        highest_peg: float,
    ) -> None:
        """Move env ``i`` to its next phase once the current one is finished (one per step)."""
        cfg = self.config
        phase = Phase(self.phase[i])
        steps = self.phase_steps[i]
        over_budget = steps >= cfg.phase_budget_steps
        to_handle = float(np.linalg.norm(tcp[:2] - handle[:2]))
        hole_to_peg = float(np.linalg.norm(nut[:2] - peg[:2]))
        nxt = phase
        if phase == Phase.HOVER:
            if (to_handle <= cfg.xy_tolerance_m and tcp[2] >= hover_z - 2 * cfg.z_tolerance_m) or (
                over_budget
            ):
                nxt = Phase.DESCEND
        elif phase == Phase.DESCEND:
            if (
                abs(tcp[2] - grasp_z) <= cfg.z_tolerance_m and to_handle <= 2 * cfg.xy_tolerance_m
            ) or over_budget:
                nxt = Phase.CLOSE
        elif phase == Phase.CLOSE:
            if steps >= cfg.close_steps:
                nxt = Phase.LIFT
                self._carry_z[i] = tcp[2] + (highest_peg + cfg.carry_clearance_m - bottom)
        elif phase == Phase.LIFT:
            if tcp[2] >= self._carry_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.CARRY
        elif phase == Phase.CARRY:
            if hole_to_peg <= cfg.xy_tolerance_m or over_budget:
                nxt = Phase.LOWER
                # lower the TCP by as much as the held nut's bottom must drop
                self._release_z[i] = min(
                    tcp[2] - (bottom - (peg[2] + cfg.release_height_m)), self._carry_z[i]
                )
        elif phase == Phase.LOWER:
            if abs(tcp[2] - self._release_z[i]) <= cfg.z_tolerance_m or over_budget:
                nxt = Phase.RELEASE
        elif phase == Phase.RELEASE:
            if steps >= cfg.release_steps:
                nxt = Phase.RETREAT
        elif phase == Phase.RETREAT:
            if tcp[2] >= self._release_z[i] + cfg.retreat_m - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.DONE
        if nxt != phase:
            self.phase[i] = int(nxt)
            self.phase_steps[i] = 0

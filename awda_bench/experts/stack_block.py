"""Scripted stack-block expert from privileged state, acting only through the 4-D action space.

Phases per env (each moves the TCP in a straight line, at most ``max_step_m`` per axis per step)::

    HOVER --> DESCEND --> CLOSE --> LIFT --> CARRY --> LOWER --> RELEASE --> RETREAT --> DONE
    above A    to grasp    grip      straight  above B    A's bottom  grip        straight
               height      closed    up                   ~ B's top   open        up

As in :mod:`awda_bench.experts.pick_place`: a phase ends at its goal (within a tolerance) or when
its step budget runs out; A's pose is re-read until the grasp closes, and the lowering height is
computed from the *held* cube's actual bottom and B's actual top, so a grasp that slipped still
sets A down just above B. Works for any embodiment of :mod:`awda_bench.envs.embodiments`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.experts.base import PICK_GRIP_CLOSED as _GRIP_CLOSED
from awda_bench.experts.base import PhaseExpert, check_config, straight_line_action
from awda_bench.experts.base import PickPhase as Phase


@dataclass(frozen=True)
class StackBlockExpertConfig:
    """Heights, tolerances and step budgets of the scripted stack-block expert."""

    hover_clearance_m: float = 0.06
    """HOVER goal: TCP this far above cube A's top [m]."""
    grasp_depth_m: float = 0.025
    """DESCEND goal: TCP this far below A's top, but not below its centre [m]."""
    carry_clearance_m: float = 0.03
    """LIFT/CARRY: A's bottom this far above the highest cube top [m]."""
    min_carry_z_m: float = 0.12
    """LIFT/CARRY TCP height never lower than this [m]."""
    release_clearance_m: float = 0.004
    """LOWER goal: A's bottom this far above B's top [m]."""
    retreat_m: float = 0.08
    """RETREAT: rise this far above the release height [m]."""
    close_steps: int = 6
    """Control steps the gripper is commanded closed before lifting."""
    release_steps: int = 6
    """Control steps the gripper is commanded open before retreating."""
    xy_tolerance_m: float = 0.005
    """Horizontal goal tolerance [m]."""
    carry_xy_tolerance_m: float = 0.003
    """Horizontal tolerance over B before lowering [m] (A must land on B's 4.5 cm top)."""
    z_tolerance_m: float = 0.005
    """Vertical goal tolerance [m]."""
    phase_budget_steps: int = 90
    """Most control steps any moving phase may take (the agent tracks ~8 mm per full step)."""

    def __post_init__(self) -> None:
        check_config(
            self,
            positive=(
                "hover_clearance_m",
                "grasp_depth_m",
                "carry_clearance_m",
                "retreat_m",
                "xy_tolerance_m",
                "carry_xy_tolerance_m",
                "z_tolerance_m",
            ),
            at_least_one=(
                "close_steps",
                "release_steps",
                "phase_budget_steps",
            ),
        )


class StackBlockExpert(PhaseExpert):
    """Scripted expert of the ``stack_block`` family (``AWDA-StackBlock-v1``); batched over envs."""

    config: StackBlockExpertConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE

    def __init__(
        self, config: StackBlockExpertConfig | None = None, name: str = "scripted"
    ) -> None:
        super().__init__(config or StackBlockExpertConfig(), name)
        self._carry_z = np.zeros(0)
        self._release_z = np.zeros(0)

    # ------------------------------------------------------------------ Policy protocol
    def _reset_state(self, n: int) -> None:
        self._carry_z = np.full(n, self.config.min_carry_z_m)
        self._release_z = np.zeros(n)

    def act(self, obs: Any) -> np.ndarray:
        """(n, 4) action for the loaded embodiment: straight-line step towards the phase goal."""
        if self._env is None:
            raise RuntimeError("act() before reset(ctx)")
        env, cfg = self._env, self.config
        half = env.layout.edge_m / 2
        tcp = env.agent.tcp_pose.p.cpu().numpy().astype(np.float64)
        a_pos = env.target_position().cpu().numpy().astype(np.float64)
        b_pos = env.base_pose()[0].cpu().numpy().astype(np.float64)
        tops = env.cube_poses()[0].cpu().numpy()[:, :, 2].max(axis=1) + half

        a_top = a_pos[:, 2] + half
        grasp_z = np.maximum(a_top - cfg.grasp_depth_m, a_pos[:, 2])
        hover_z = a_top + cfg.hover_clearance_m

        # carried: aim the held cube's centre (not the TCP) over B
        place_xy = b_pos[:, :2] + (tcp[:, :2] - a_pos[:, :2])

        goal = tcp.copy()
        for i in range(len(tcp)):
            self._advance(i, tcp[i], a_pos[i], b_pos[i], grasp_z[i], hover_z[i], tops[i], half)
            phase = Phase(self.phase[i])
            if phase == Phase.HOVER:
                goal[i] = (a_pos[i, 0], a_pos[i, 1], hover_z[i])
            elif phase == Phase.DESCEND:
                goal[i] = (a_pos[i, 0], a_pos[i, 1], grasp_z[i])
            elif phase == Phase.LIFT:
                goal[i, 2] = self._carry_z[i]
            elif phase == Phase.CARRY:
                goal[i] = (place_xy[i, 0], place_xy[i, 1], self._carry_z[i])
            elif phase == Phase.LOWER:
                goal[i] = (place_xy[i, 0], place_xy[i, 1], self._release_z[i])
            elif phase == Phase.RETREAT:
                goal[i, 2] = self._release_z[i] + cfg.retreat_m
            # CLOSE, RELEASE, DONE: hold position
            self.phase_steps[i] += 1

        closed = np.isin(self.phase, [int(p) for p in _GRIP_CLOSED])
        return straight_line_action(goal, tcp, closed, env)

    # ------------------------------------------------------------------ phase logic
    def _advance(
        self,
        i: int,
        tcp: np.ndarray,
        a_pos: np.ndarray,
        b_pos: np.ndarray,
        grasp_z: float,
        hover_z: float,
        tops: float,
        half: float,
    ) -> None:
        """Move env ``i`` to its next phase once the current one is finished (one per step)."""
        cfg = self.config
        phase = Phase(self.phase[i])
        steps = self.phase_steps[i]
        over_budget = steps >= cfg.phase_budget_steps
        xy_err = float(np.linalg.norm(tcp[:2] - a_pos[:2]))
        b_xy_err = float(np.linalg.norm(a_pos[:2] - b_pos[:2]))
        a_bottom = a_pos[2] - half
        nxt = phase
        if phase == Phase.HOVER:
            if (
                xy_err <= cfg.xy_tolerance_m and abs(tcp[2] - hover_z) <= 2 * cfg.z_tolerance_m
            ) or over_budget:
                nxt = Phase.DESCEND
        elif phase == Phase.DESCEND:
            if (
                abs(tcp[2] - grasp_z) <= cfg.z_tolerance_m and xy_err <= 2 * cfg.xy_tolerance_m
            ) or over_budget:
                nxt = Phase.CLOSE
        elif phase == Phase.CLOSE:
            if steps >= cfg.close_steps:
                nxt = Phase.LIFT
                self._carry_z[i] = max(
                    cfg.min_carry_z_m, tops + (tcp[2] - a_bottom) + cfg.carry_clearance_m
                )
        elif phase == Phase.LIFT:
            if tcp[2] >= self._carry_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.CARRY
        elif phase == Phase.CARRY:
            if b_xy_err <= cfg.carry_xy_tolerance_m or over_budget:
                nxt = Phase.LOWER
                # lower the TCP by as much as the held cube's bottom must drop onto B's top
                b_top = b_pos[2] + half
                self._release_z[i] = min(
                    tcp[2] - (a_bottom - (b_top + cfg.release_clearance_m)), self._carry_z[i]
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

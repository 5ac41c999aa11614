"""Scripted basketball expert from privileged state, acting only through the 4-D action space.

Phases per env (each moves the TCP in a straight line, at most ``max_step_m`` per axis per step)::

    HOVER --> DESCEND --> CLOSE --> LIFT --> CARRY --> LOWER --> RELEASE --> RETREAT --> DONE
    above the  fingertips  grip      straight  ball over  ball just   grip        straight
    ball       at the      closed    up        the ring   above the   open (the   up
               equator                                    rim         ball drops
                                                                      into the net)

A phase ends when its goal is reached within a tolerance or its step budget runs out. The ball is
re-read every step: before the grasp to aim at it, after the grasp to aim *the ball* (not the
TCP) at the ring's centre, so a ball held off-centre between the fingers still drops straight
through. Works for any embodiment of :mod:`awda_bench.envs.embodiments`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.experts.base import PICK_GRIP_CLOSED as _GRIP_CLOSED
from awda_bench.experts.base import PhaseExpert, check_config, straight_line_action
from awda_bench.experts.base import PickPhase as Phase


@dataclass(frozen=True)
class BasketballExpertConfig:
    """Heights, tolerances and step budgets of the scripted basketball expert."""

    hover_clearance_m: float = 0.08
    """HOVER goal: the TCP this far above the ball's centre [m]."""
    grasp_offset_m: float = 0.0
    """DESCEND goal: the TCP this far above the ball's centre (0: fingertips at the equator) [m]."""
    min_grasp_z_m: float = 0.015
    """DESCEND goal never lower than this TCP height (fingertips hang ~1 cm below it) [m]."""
    carry_clearance_m: float = 0.04
    """LIFT/CARRY: the held ball's bottom this far above the highest hoop rim [m]."""
    release_clearance_m: float = 0.015
    """LOWER goal: the held ball's bottom this far above the target hoop's rim [m]."""
    retreat_m: float = 0.08
    """RETREAT: rise this far above the release height [m]."""
    close_steps: int = 6
    """Control steps the gripper is commanded closed before lifting."""
    release_steps: int = 6
    """Control steps the gripper is commanded open before retreating."""
    xy_tolerance_m: float = 0.005
    """Horizontal goal tolerance [m]."""
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
                "release_clearance_m",
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


class BasketballExpert(PhaseExpert):
    """Scripted expert of the ``basketball`` family; batched over envs."""

    config: BasketballExpertConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE

    def __init__(
        self, config: BasketballExpertConfig | None = None, name: str = "scripted"
    ) -> None:
        super().__init__(config or BasketballExpertConfig(), name)
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
        ball = env.target_position().cpu().numpy().astype(np.float64)
        radius = env.target_radius().cpu().numpy().astype(np.float64)
        goal = env.goal_position().cpu().numpy().astype(np.float64)
        hoop_idx = env.target_hoop_index.cpu().numpy()
        rims = np.array([h.rim_top_z_m for h in env.layout.hoops])
        highest_rim = float(rims.max())

        grasp_z = np.maximum(ball[:, 2] + cfg.grasp_offset_m, cfg.min_grasp_z_m)
        hover_z = ball[:, 2] + cfg.hover_clearance_m
        bottom = ball[:, 2] - radius
        # where the TCP must be for the *ball* to be over the goal (grasp offset compensated)
        aim_xy = goal[:, :2] + (tcp[:, :2] - ball[:, :2])

        target = tcp.copy()
        for i in range(len(tcp)):
            self._advance(
                i,
                tcp[i],
                ball[i],
                goal[i],
                bottom[i],
                grasp_z[i],
                hover_z[i],
                highest_rim,
                rims[hoop_idx[i]],
            )
            phase = Phase(self.phase[i])
            if phase == Phase.HOVER:
                target[i] = (ball[i, 0], ball[i, 1], max(hover_z[i], tcp[i, 2]))
            elif phase == Phase.DESCEND:
                target[i] = (ball[i, 0], ball[i, 1], grasp_z[i])
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
        ball: np.ndarray,
        goal: np.ndarray,
        bottom: float,
        grasp_z: float,
        hover_z: float,
        highest_rim: float,
        rim: float,
    ) -> None:
        """Move env ``i`` to its next phase once the current one is finished (one per step)."""
        cfg = self.config
        phase = Phase(self.phase[i])
        steps = self.phase_steps[i]
        over_budget = steps >= cfg.phase_budget_steps
        to_ball = float(np.linalg.norm(tcp[:2] - ball[:2]))
        ball_to_goal = float(np.linalg.norm(ball[:2] - goal[:2]))
        nxt = phase
        if phase == Phase.HOVER:
            if (to_ball <= cfg.xy_tolerance_m and tcp[2] >= hover_z - 2 * cfg.z_tolerance_m) or (
                over_budget
            ):
                nxt = Phase.DESCEND
        elif phase == Phase.DESCEND:
            if (
                abs(tcp[2] - grasp_z) <= cfg.z_tolerance_m and to_ball <= 2 * cfg.xy_tolerance_m
            ) or over_budget:
                nxt = Phase.CLOSE
        elif phase == Phase.CLOSE:
            if steps >= cfg.close_steps:
                nxt = Phase.LIFT
                self._carry_z[i] = tcp[2] + (highest_rim + cfg.carry_clearance_m - bottom)
        elif phase == Phase.LIFT:
            if tcp[2] >= self._carry_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.CARRY
        elif phase == Phase.CARRY:
            if ball_to_goal <= cfg.xy_tolerance_m or over_budget:
                nxt = Phase.LOWER
                # lower the TCP by as much as the held ball's bottom must drop
                self._release_z[i] = min(
                    tcp[2] - (bottom - (rim + cfg.release_clearance_m)), self._carry_z[i]
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

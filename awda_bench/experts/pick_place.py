"""Scripted pick-and-place expert from privileged state, acting only through the 4-D action space.

Phases per env (each moves the TCP in a straight line, at most ``max_step_m`` per axis per step)::

    HOVER --> DESCEND --> CLOSE --> LIFT --> CARRY --> LOWER --> RELEASE --> RETREAT --> DONE
    above the  to grasp     grip       straight  above the  object     grip        straight
    target     height       closed     up        compartment ~floor    open        up

A phase ends when its goal is reached within a tolerance or its step budget runs out (so a stuck
phase never stalls the episode). The object's pose is re-read every step until the grasp closes; the
release height is computed from the *held* object's actual bottom, so a grasp that slipped still
lowers the object to just above the compartment floor. Works for any embodiment listed in
:mod:`awda_bench.envs.embodiments` (the step size and grip sign come from there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.experts.base import PICK_GRIP_CLOSED as _GRIP_CLOSED
from awda_bench.experts.base import PhaseExpert, check_config, straight_line_action
from awda_bench.experts.base import PickPhase as Phase


@dataclass(frozen=True)
class PickPlaceExpertConfig:
    """Heights, tolerances and step budgets of the scripted expert."""

    hover_clearance_m: float = 0.06
    """HOVER goal: this far above the target object's top [m]."""
    min_hover_z_m: float = 0.14
    """HOVER goal never lower than this TCP height [m]."""
    grasp_depth_m: float = 0.03
    """DESCEND goal: TCP this far below the object's top, but not below its centre [m]
    (the Panda fingertips' TCP; a per-end-effector parameter)."""
    carry_clearance_m: float = 0.04
    """LIFT/CARRY height: the held object's bottom this far above the highest bin wall [m]
    (computed from the object's actual bottom when the grasp closes)."""
    min_carry_z_m: float = 0.14
    """LIFT/CARRY TCP height never lower than this [m]."""
    retreat_m: float = 0.08
    """RETREAT: rise this far above the release height [m]."""
    release_clearance_m: float = 0.02
    """LOWER goal: the held object's bottom this far above the compartment floor [m]."""
    close_steps: int = 6
    """Control steps the gripper is commanded closed before lifting."""
    release_steps: int = 5
    """Control steps the gripper is commanded open before retreating."""
    xy_tolerance_m: float = 0.006
    """Horizontal goal tolerance [m]."""
    z_tolerance_m: float = 0.006
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
                "z_tolerance_m",
            ),
            at_least_one=(
                "close_steps",
                "release_steps",
                "phase_budget_steps",
            ),
        )


class PickPlaceExpert(PhaseExpert):
    """Scripted expert of the ``pick_place`` suite (the ``scripted`` method); batched over envs."""

    config: PickPlaceExpertConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE

    def __init__(self, config: PickPlaceExpertConfig | None = None, name: str = "scripted") -> None:
        super().__init__(config or PickPlaceExpertConfig(), name)
        self._release_z = np.zeros(0)
        self._carry_z = np.zeros(0)

    # ------------------------------------------------------------------ Policy protocol
    def _reset_state(self, n: int) -> None:
        self._release_z = np.zeros(n)
        self._carry_z = np.full(n, self.config.min_carry_z_m)

    def act(self, obs: Any) -> np.ndarray:
        """(n, 4) action for the loaded embodiment: straight-line step towards the phase goal."""
        if self._env is None:
            raise RuntimeError("act() before reset(ctx)")
        env, cfg = self._env, self.config
        tcp = env.agent.tcp_pose.p.cpu().numpy().astype(np.float64)
        obj_pos, _ = (t.cpu().numpy().astype(np.float64) for t in env.target_pose())
        obj_idx = env.target_object_index.cpu().numpy()
        half_h = np.array([env.objects_spec[i].half_height_m for i in obj_idx])
        goal_xy = env.compartment_center().cpu().numpy()[:, :2].astype(np.float64)
        floor = env.layout.target_bin.floor_z_m
        walls = max(
            b.floor_z_m + b.wall_height_m for b in (env.layout.source_bin, env.layout.target_bin)
        )

        top = obj_pos[:, 2] + half_h
        grasp_z = np.maximum(top - cfg.grasp_depth_m, obj_pos[:, 2])
        hover_z = np.maximum(top + cfg.hover_clearance_m, cfg.min_hover_z_m)
        bottom = obj_pos[:, 2] - half_h

        goal = tcp.copy()
        for i in range(len(tcp)):
            self._advance(
                i, tcp[i], obj_pos[i], grasp_z[i], hover_z[i], goal_xy[i], bottom[i], floor, walls
            )
            phase = Phase(self.phase[i])
            if phase == Phase.HOVER:
                goal[i] = (obj_pos[i, 0], obj_pos[i, 1], hover_z[i])
            elif phase == Phase.DESCEND:
                goal[i] = (obj_pos[i, 0], obj_pos[i, 1], grasp_z[i])
            elif phase == Phase.LIFT:
                goal[i, 2] = self._carry_z[i]
            elif phase == Phase.CARRY:
                goal[i] = (goal_xy[i, 0], goal_xy[i, 1], self._carry_z[i])
            elif phase == Phase.LOWER:
                goal[i] = (goal_xy[i, 0], goal_xy[i, 1], self._release_z[i])
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
        obj: np.ndarray,
        grasp_z: float,
        hover_z: float,
        goal_xy: np.ndarray,
        bottom: float,
        floor: float,
        walls: float,
    ) -> None:
        """Move env ``i`` to its next phase once the current one is finished (one per step)."""
        cfg = self.config
        phase = Phase(self.phase[i])
        steps = self.phase_steps[i]
        over_budget = steps >= cfg.phase_budget_steps
        xy_err = float(np.linalg.norm(tcp[:2] - obj[:2]))
        goal_xy_err = float(np.linalg.norm(tcp[:2] - goal_xy))
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
                    cfg.min_carry_z_m, walls + (tcp[2] - bottom) + cfg.carry_clearance_m
                )
        elif phase == Phase.LIFT:
            if tcp[2] >= self._carry_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.CARRY
        elif phase == Phase.CARRY:
            if goal_xy_err <= cfg.xy_tolerance_m or over_budget:
                nxt = Phase.LOWER
                # lower the TCP by as much as the held object's bottom must drop
                self._release_z[i] = min(
                    tcp[2] - (bottom - (floor + cfg.release_clearance_m)), self._carry_z[i]
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

"""Scripted drawer expert from privileged state (handle pose, slide axis), acting via 4-D actions.

Opening grasps the handle head by its sides and pulls it straight out along the slide axis;
closing pushes the handle head's front with the closed fingers::

    open:   HOVER --> DESCEND --> CLOSE --> SLIDE (grip) --> RELEASE --> RETREAT --> DONE
            above the  to the      grip      pull out to      grip       straight
            handle     head        closed    open_target      open       up
    close:  HOVER --> DESCEND --> SLIDE (push) --> RETREAT --> DONE
            in front of the head,           fingers on the head,
            fingers closed                  push to close_target

SLIDE aims at the handle led ``lead_m`` beyond its measured position every control step (closed
loop on the drawer, so a slipping grip never drags the hand away from the handle). Each phase ends
on its tolerance or its step budget. Works for any embodiment of
:mod:`awda_bench.envs.embodiments` (step size and grip sign come from there).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from awda_bench.experts.base import PhaseExpert, check_config, straight_line_action


class Phase(IntEnum):
    HOVER = 0
    DESCEND = 1
    CLOSE = 2
    SLIDE = 3
    RELEASE = 4
    RETREAT = 5
    DONE = 6


@dataclass(frozen=True)
class DrawerExpertConfig:
    """Targets, heights, tolerances and step budgets of the scripted drawer expert."""

    open_target_m: float = 0.16
    """Open: pull until the drawer is slid out this far [m] (success needs 0.12)."""
    close_target_m: float = 0.002
    """Close: push until the drawer is at most this far out [m] (success needs 0.005)."""
    lead_m: float = 0.012
    """SLIDE goal: this far ahead of the measured slide [m] (not clipped at the target; it also caps
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
    """Close: SLIDE aims the fingertips this far into the head (keeps them in contact) [m]."""
    retreat_m: float = 0.08
    """RETREAT: rise this far [m]."""
    close_steps: int = 6
    """Control steps the gripper is commanded closed before pulling."""
    release_steps: int = 5
    """Control steps the gripper is commanded open before retreating."""
    xy_tolerance_m: float = 0.005
    """Horizontal goal tolerance [m]."""
    z_tolerance_m: float = 0.006
    """Vertical goal tolerance [m]."""
    slide_tolerance_m: float = 0.005
    """Open: SLIDE ends within this of ``open_target_m`` [m]."""
    phase_budget_steps: int = 70
    """Most control steps any moving phase may take."""

    def __post_init__(self) -> None:
        check_config(
            self,
            positive=(
                "open_target_m",
                "lead_m",
                "hover_clearance_m",
                "retreat_m",
                "xy_tolerance_m",
                "z_tolerance_m",
                "slide_tolerance_m",
            ),
            at_least_one=(
                "close_steps",
                "release_steps",
                "phase_budget_steps",
            ),
        )


_GRIP_CLOSED_OPENING = {Phase.CLOSE, Phase.SLIDE}
"""Phases with the gripper closed when opening (closing keeps it closed until RETREAT)."""


class DrawerExpert(PhaseExpert):
    """Scripted expert of the ``drawer`` family (``AWDA-Drawer-v1``); batched over envs."""

    config: DrawerExpertConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE

    def __init__(self, config: DrawerExpertConfig | None = None, name: str = "scripted") -> None:
        super().__init__(config or DrawerExpertConfig(), name)
        self.pull = np.zeros(0, dtype=bool)
        """(n,) True: open by grasping and pulling; False: close by pushing."""
        self._retreat_z = np.zeros(0)
        self._grip_offset = np.zeros((0, 3))
        """(n, 3) TCP minus handle centre when the grip closed [m]."""

    # ------------------------------------------------------------------ Policy protocol
    def _reset_state(self, n: int) -> None:
        self.pull = self._env.wants_open.cpu().numpy().astype(bool)
        self._retreat_z = np.zeros(n)
        self._grip_offset = np.zeros((n, 3))

    def act(self, obs: Any) -> np.ndarray:
        """(n, 4) action for the loaded embodiment: straight-line step towards the phase goal."""
        if self._env is None:
            raise RuntimeError("act() before reset(ctx)")
        env, cfg = self._env, self.config
        n = env.num_envs
        tcp = env.agent.tcp_pose.p.cpu().numpy().astype(np.float64)
        slide = env.target_slide().cpu().numpy().astype(np.float64)
        handle = env.handle_position().cpu().numpy().astype(np.float64)
        axis = env.slide_axis().cpu().numpy().astype(np.float64)  # toward the robot
        head_half_x = np.array([env.target_spec(i).handle_head_size_m[0] / 2 for i in range(n)])
        hx, hy = cfg.closed_fingers_half_extent_m
        support = hx * np.abs(axis[:, 0]) + hy * np.abs(axis[:, 1])  # fingertips along the axis
        head_front = handle + axis * head_half_x[:, None]
        push_approach = head_front + axis * (support + cfg.approach_margin_m)[:, None]

        goal = tcp.copy()
        for i in range(n):
            self._advance(i, tcp[i], handle[i], push_approach[i], slide[i])
            phase = Phase(self.phase[i])
            hover_z = handle[i, 2] + cfg.hover_clearance_m
            if self.pull[i]:
                target_xy, work_z = handle[i, :2], handle[i, 2] + cfg.grasp_offset_m
            else:
                target_xy, work_z = push_approach[i, :2], handle[i, 2]
            if phase == Phase.HOVER:
                goal[i] = (target_xy[0], target_xy[1], hover_z)
                if tcp[i, 2] < hover_z - cfg.rise_first_m:  # climb over open drawers first
                    goal[i, :2] = tcp[i, :2]
            elif phase == Phase.DESCEND:
                goal[i] = (target_xy[0], target_xy[1], work_z)
            elif phase == Phase.SLIDE:
                if self.pull[i]:  # the grasp point on the handle, led out along the axis
                    goal[i] = handle[i] + self._grip_offset[i] + axis[i] * cfg.lead_m
                else:  # fingertips pressed on the head, led inward along the axis
                    led = head_front[i] - axis[i] * cfg.lead_m
                    goal[i] = led + axis[i] * (support[i] - cfg.press_in_m)
                goal[i, 2] = work_z
            elif phase == Phase.RETREAT:
                goal[i, 2] = self._retreat_z[i]
            # CLOSE, RELEASE, DONE: hold position
            self.phase_steps[i] += 1

        closed = np.where(
            self.pull,
            np.isin(self.phase, [int(p) for p in _GRIP_CLOSED_OPENING]),
            self.phase < Phase.RETREAT,
        )
        return straight_line_action(goal, tcp, closed, env)

    # ------------------------------------------------------------------ phase logic
    def _advance(
        self, i: int, tcp: np.ndarray, handle: np.ndarray, push_approach: np.ndarray, slide: float
    ) -> None:
        """Move env ``i`` to its next phase once the current one is finished (one per step)."""
        cfg = self.config
        phase = Phase(self.phase[i])
        steps = self.phase_steps[i]
        over_budget = steps >= cfg.phase_budget_steps
        target_xy = handle[:2] if self.pull[i] else push_approach[:2]
        xy_err = float(np.linalg.norm(tcp[:2] - target_xy))
        work_z = handle[2] + (cfg.grasp_offset_m if self.pull[i] else 0.0)
        nxt = phase
        if phase == Phase.HOVER:
            hover_z = handle[2] + cfg.hover_clearance_m
            near = xy_err <= cfg.xy_tolerance_m and abs(tcp[2] - hover_z) <= 2 * cfg.z_tolerance_m
            if near or over_budget:
                nxt = Phase.DESCEND
        elif phase == Phase.DESCEND:
            near = abs(tcp[2] - work_z) <= cfg.z_tolerance_m and xy_err <= 2 * cfg.xy_tolerance_m
            if near or over_budget:
                nxt = Phase.CLOSE if self.pull[i] else Phase.SLIDE
        elif phase == Phase.CLOSE:
            if steps >= cfg.close_steps:
                nxt = Phase.SLIDE
        elif phase == Phase.SLIDE:
            if self.pull[i]:
                arrived = slide >= cfg.open_target_m - cfg.slide_tolerance_m
            else:
                arrived = slide <= cfg.close_target_m
            if arrived or over_budget:
                nxt = Phase.RELEASE if self.pull[i] else Phase.RETREAT
        elif phase == Phase.RELEASE:
            if steps >= cfg.release_steps:
                nxt = Phase.RETREAT
        elif phase == Phase.RETREAT:
            if tcp[2] >= self._retreat_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.DONE
        if nxt != phase:
            if nxt == Phase.SLIDE:
                self._grip_offset[i] = tcp - handle
            if nxt == Phase.RETREAT:
                self._retreat_z[i] = tcp[2] + cfg.retreat_m
            self.phase[i] = int(nxt)
            self.phase_steps[i] = 0

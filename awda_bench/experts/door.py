"""Scripted door expert from privileged state (hinge geometry, angle), acting via the 4-D action.

Opening grasps the handle bar and carries it along the door's arc; closing pushes the panel's
front face with the closed fingers (the door swings toward the robot, so a push toward shut never
needs a grasp)::

    open:   HOVER --> DESCEND --> CLOSE --> SWING (grip) --> RELEASE --> RETREAT --> DONE
            above the  bar top     grip      along the arc    grip       straight
            handle     -2 cm       closed    to open_target   open       up
    close:  HOVER --> DESCEND --> SWING (push) --> RETREAT --> DONE
            in front of the panel,          fingers on the panel, angle
            fingers closed                  led toward close_target

SWING aims at the handle (or push point) placed with the hinge ``lead_rad`` ahead of the measured
angle, every control step (closed loop on the door, so a slipping grip or a lagging arm never
outruns it). Each phase ends on its tolerance or its step budget, so a stuck phase never stalls the
episode. Works for any embodiment of
:mod:`awda_bench.envs.embodiments` (step size and grip sign come from there).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
import torch

from awda_bench.experts.base import PhaseExpert, check_config, straight_line_action


class Phase(IntEnum):
    HOVER = 0
    DESCEND = 1
    CLOSE = 2
    SWING = 3
    RELEASE = 4
    RETREAT = 5
    DONE = 6


@dataclass(frozen=True)
class DoorExpertConfig:
    """Targets, heights, tolerances and step budgets of the scripted door expert."""

    open_target_rad: float = 0.62
    """Open: swing until the hinge reaches this angle [rad] (success needs 0.4)."""
    close_target_rad: float = 0.02
    """Close: push until the hinge is at most this angle [rad] (success needs 0.1)."""
    lead_rad: float = 0.10
    """SWING goal: this far ahead of the measured hinge angle [rad] (not clipped at the target, so
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
    """Close: SWING aims the fingers this far into the panel (keeps them in contact) [m]."""
    retreat_m: float = 0.08
    """RETREAT: rise this far [m]."""
    close_steps: int = 6
    """Control steps the gripper is commanded closed before swinging."""
    release_steps: int = 5
    """Control steps the gripper is commanded open before retreating."""
    xy_tolerance_m: float = 0.006
    """Horizontal goal tolerance [m]."""
    z_tolerance_m: float = 0.006
    """Vertical goal tolerance [m]."""
    angle_tolerance_rad: float = 0.02
    """SWING ends within this of its target angle [rad]."""
    phase_budget_steps: int = 70
    """Most control steps any moving phase may take."""

    def __post_init__(self) -> None:
        check_config(
            self,
            positive=(
                "open_target_rad",
                "lead_rad",
                "hover_clearance_m",
                "grasp_depth_m",
                "push_depth_m",
                "push_along_m",
                "retreat_m",
                "xy_tolerance_m",
                "z_tolerance_m",
                "angle_tolerance_rad",
            ),
            at_least_one=(
                "close_steps",
                "release_steps",
                "phase_budget_steps",
            ),
        )


_GRIP_CLOSED_OPENING = {Phase.CLOSE, Phase.SWING}
"""Phases with the gripper closed when opening (closing keeps it closed until RETREAT)."""


class DoorExpert(PhaseExpert):
    """Scripted expert of the ``door`` family (``AWDA-Door-v1``); batched over envs."""

    config: DoorExpertConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE

    def __init__(self, config: DoorExpertConfig | None = None, name: str = "scripted") -> None:
        super().__init__(config or DoorExpertConfig(), name)
        self.pull = np.zeros(0, dtype=bool)
        """(n,) True: open by grasping the handle; False: close by pushing the panel."""
        self._retreat_z = np.zeros(0)
        self._grip_offset = np.zeros((0, 3))
        """(n, 3) TCP minus handle top when the grip closed [m]."""

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
        dev = env.device
        tcp = env.agent.tcp_pose.p.cpu().numpy().astype(np.float64)
        angle_t = env.target_angle()
        angle = angle_t.cpu().numpy().astype(np.float64)
        pull = torch.as_tensor(self.pull, device=dev)

        # geometry at the current angle and at the SWING's led angle (batched on the env's device)
        lead = torch.where(pull, angle_t + cfg.lead_rad, angle_t - cfg.lead_rad)
        handle_now = env.handle_position().cpu().numpy().astype(np.float64)
        handle_led = env.handle_position(lead).cpu().numpy().astype(np.float64)
        top = np.array([env.target_spec(i).handle_top_z_m for i in range(n)])
        push_approach = self._push_point(env, angle_t, cfg.approach_margin_m)
        push_led = self._push_point(env, lead, -cfg.press_in_m)

        goal = tcp.copy()
        for i in range(n):
            self._advance(i, tcp[i], handle_now[i], top[i], push_approach[i], angle[i])
            phase = Phase(self.phase[i])
            hover_z = top[i] + cfg.hover_clearance_m
            rising = phase == Phase.HOVER and tcp[i, 2] < top[i] + cfg.rise_clearance_m
            if self.pull[i]:
                grasp_z = top[i] - cfg.grasp_depth_m
                if phase == Phase.HOVER:
                    goal[i] = (handle_now[i, 0], handle_now[i, 1], hover_z)
                elif phase == Phase.DESCEND:
                    goal[i] = (handle_now[i, 0], handle_now[i, 1], grasp_z)
                elif phase == Phase.SWING:
                    # the grasp point on the handle, carried to the led angle
                    goal[i] = handle_led[i] + self._grip_offset[i]
                    goal[i, 2] = grasp_z
            else:
                push_z = top[i] - cfg.push_depth_m
                if phase == Phase.HOVER:
                    goal[i] = (push_approach[i, 0], push_approach[i, 1], hover_z)
                elif phase == Phase.DESCEND:
                    goal[i] = (push_approach[i, 0], push_approach[i, 1], push_z)
                elif phase == Phase.SWING:
                    goal[i] = (push_led[i, 0], push_led[i, 1], push_z)
            if phase == Phase.RETREAT:
                goal[i, 2] = self._retreat_z[i]
            if rising:  # below the doors' tops: rise before moving across
                goal[i, :2] = tcp[i, :2]
            # CLOSE, RELEASE, DONE: hold position
            self.phase_steps[i] += 1

        closed = np.where(
            self.pull,
            np.isin(self.phase, [int(p) for p in _GRIP_CLOSED_OPENING]),
            self.phase < Phase.RETREAT,
        )
        return straight_line_action(goal, tcp, closed, env)

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

    # ------------------------------------------------------------------ phase logic
    def _advance(
        self,
        i: int,
        tcp: np.ndarray,
        handle: np.ndarray,
        top: float,
        push_approach: np.ndarray,
        angle: float,
    ) -> None:
        """Move env ``i`` to its next phase once the current one is finished (one per step)."""
        cfg = self.config
        phase = Phase(self.phase[i])
        steps = self.phase_steps[i]
        over_budget = steps >= cfg.phase_budget_steps
        target_xy = handle[:2] if self.pull[i] else push_approach[:2]
        xy_err = float(np.linalg.norm(tcp[:2] - target_xy))
        work_z = top - (cfg.grasp_depth_m if self.pull[i] else cfg.push_depth_m)
        nxt = phase
        if phase == Phase.HOVER:
            hover_z = top + cfg.hover_clearance_m
            if (
                xy_err <= cfg.xy_tolerance_m and abs(tcp[2] - hover_z) <= 2 * cfg.z_tolerance_m
            ) or over_budget:
                nxt = Phase.DESCEND
        elif phase == Phase.DESCEND:
            if (abs(tcp[2] - work_z) <= cfg.z_tolerance_m and xy_err <= 2 * cfg.xy_tolerance_m) or (
                over_budget
            ):
                nxt = Phase.CLOSE if self.pull[i] else Phase.SWING
        elif phase == Phase.CLOSE:
            if steps >= cfg.close_steps:
                nxt = Phase.SWING
        elif phase == Phase.SWING:
            if self.pull[i]:
                arrived = angle >= cfg.open_target_rad - cfg.angle_tolerance_rad
            else:
                arrived = angle <= cfg.close_target_rad
            if arrived or over_budget:
                nxt = Phase.RELEASE if self.pull[i] else Phase.RETREAT
        elif phase == Phase.RELEASE:
            if steps >= cfg.release_steps:
                nxt = Phase.RETREAT
        elif phase == Phase.RETREAT:
            if tcp[2] >= self._retreat_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.DONE
        if nxt != phase:
            if nxt == Phase.SWING and self.pull[i]:
                self._grip_offset[i] = tcp - handle
            if nxt == Phase.RETREAT:
                self._retreat_z[i] = tcp[2] + cfg.retreat_m
            self.phase[i] = int(nxt)
            self.phase_steps[i] = 0

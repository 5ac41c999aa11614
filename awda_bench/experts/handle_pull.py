"""The one handle expert core (door, drawer): open by grasping a handle and pulling it along the
articulation's path, close by pushing with the closed fingers.

Phases per env (straight-line TCP steps, at most ``max_step_m`` per axis per step)::

    open:   HOVER --> DESCEND --> CLOSE --> MOVE (grip) --> RELEASE --> RETREAT --> DONE
            above the  to the      grip      the grasped     grip       straight
            handle     handle      closed    handle led      open       up
                                             along its path
    close:  HOVER --> DESCEND --> MOVE (push) --> RETREAT --> DONE
            in front of the part,  fingers on it, led toward shut,
            fingers closed         fingers closed

A family says only *where* (its :meth:`HandleExpert.read_scene` returns a :class:`HandleScene`,
re-read every step): the approach point, heights, the handle now, where the handle or the push
point is *led* to (a fixed lead ahead of the measured hinge angle or slide, every step: closed
loop on the articulation, so a slipping grip or a lagging arm never outruns it), and whether the
articulation has arrived. The core says *how*: it keeps the grip offset measured when the grip
closed, rises before crossing sideways, and ends each phase on its tolerance or its step budget.
Works for any embodiment of :mod:`awda_bench.envs.embodiments`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from awda_bench.experts.base import PhaseExpert, check_config


class HandlePhase(IntEnum):
    HOVER = 0
    DESCEND = 1
    CLOSE = 2
    MOVE = 3
    RELEASE = 4
    RETREAT = 5
    DONE = 6


_GRIP_CLOSED_OPENING = frozenset({HandlePhase.CLOSE, HandlePhase.MOVE})
"""Phases with the gripper closed when opening (closing keeps it closed until RETREAT)."""


@dataclass(frozen=True)
class HandleScene:
    """Where things are, per env (arrays over the envs), as a family reads them from the state."""

    work_xy: np.ndarray
    """(n, 2) where the TCP descends: the handle (open) or in front of the push point (close) [m]."""
    hover_z: np.ndarray
    """(n,) TCP height of HOVER [m]."""
    work_z: np.ndarray
    """(n,) TCP height of DESCEND and MOVE [m]."""
    rise_below_z: np.ndarray
    """(n,) in HOVER, a TCP below this height first rises straight up [m]."""
    handle: np.ndarray
    """(n, 3) the handle's reference point now [m] (the grip offset is measured from it)."""
    pull_goal: np.ndarray
    """(n, 3) that reference point led along the opening path [m] (MOVE, open)."""
    push_goal: np.ndarray
    """(n, 2) TCP position that keeps the closed fingers pushing, led toward shut [m] (MOVE, close)."""
    arrived: np.ndarray
    """(n,) bool: the articulation reached the asked state (open or shut)."""


@dataclass(frozen=True)
class HandleConfig:
    """How the core moves; families subclass it."""

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
    phase_budget_steps: int = 70
    """Most control steps any moving phase may take."""

    def __post_init__(self) -> None:
        check_config(
            self,
            positive=("retreat_m", "xy_tolerance_m", "z_tolerance_m"),
            at_least_one=("close_steps", "release_steps", "phase_budget_steps"),
        )


class HandleExpert(PhaseExpert):
    """The core (batched over envs); a family overrides :meth:`read_scene`."""

    config: HandleConfig
    start_phase = HandlePhase.HOVER
    done_phase = HandlePhase.DONE
    config_type = HandleConfig

    def __init__(self, config: HandleConfig | None = None, name: str = "scripted") -> None:
        super().__init__(config, name)
        self.pull = np.zeros(0, dtype=bool)
        """(n,) True: open by grasping and pulling; False: close by pushing."""
        self._retreat_z = np.zeros(0)
        self._grip_offset = np.zeros((0, 3))
        """(n, 3) TCP minus the handle's reference point when the grip closed [m]."""

    def read_scene(self, env: Any, tcp: np.ndarray) -> HandleScene:
        """The family's :class:`HandleScene` for the current state (``tcp``: (n, 3) [m])."""
        raise NotImplementedError

    # ------------------------------------------------------------------ Policy protocol
    def _reset_state(self, n: int) -> None:
        self.pull = self._env.wants_open.cpu().numpy().astype(bool)
        self._retreat_z = np.zeros(n)
        self._grip_offset = np.zeros((n, 3))

    def _set_goal(self, i: int, tcp: np.ndarray, scene: HandleScene, goal: np.ndarray) -> None:
        phase = HandlePhase(self.phase[i])
        if phase == HandlePhase.HOVER:
            goal[:] = (scene.work_xy[i, 0], scene.work_xy[i, 1], scene.hover_z[i])
            if tcp[2] < scene.rise_below_z[i]:  # rise before crossing sideways
                goal[:2] = tcp[:2]
        elif phase == HandlePhase.DESCEND:
            goal[:] = (scene.work_xy[i, 0], scene.work_xy[i, 1], scene.work_z[i])
        elif phase == HandlePhase.MOVE:
            if self.pull[i]:  # the grasp point on the handle, led along the path
                goal[:] = scene.pull_goal[i] + self._grip_offset[i]
            else:
                goal[:2] = scene.push_goal[i]
            goal[2] = scene.work_z[i]
        elif phase == HandlePhase.RETREAT:
            goal[2] = self._retreat_z[i]
        # CLOSE, RELEASE, DONE: hold position

    def _grip_closed(self) -> np.ndarray:
        """Opening: closed in CLOSE and MOVE; closing: closed until RETREAT."""
        return np.where(
            self.pull,
            np.isin(self.phase, [int(p) for p in _GRIP_CLOSED_OPENING]),
            self.phase < HandlePhase.RETREAT,
        )

    # ------------------------------------------------------------------ phase logic
    def _advance(self, i: int, tcp: np.ndarray, scene: HandleScene) -> None:
        cfg = self.config
        phase = HandlePhase(self.phase[i])
        over_budget = self.phase_steps[i] >= cfg.phase_budget_steps
        xy_err = float(np.linalg.norm(tcp[:2] - scene.work_xy[i]))
        nxt = phase
        if phase == HandlePhase.HOVER:
            near = (
                xy_err <= cfg.xy_tolerance_m
                and abs(tcp[2] - scene.hover_z[i]) <= 2 * cfg.z_tolerance_m
            )
            if near or over_budget:
                nxt = HandlePhase.DESCEND
        elif phase == HandlePhase.DESCEND:
            near = (
                abs(tcp[2] - scene.work_z[i]) <= cfg.z_tolerance_m
                and xy_err <= 2 * cfg.xy_tolerance_m
            )
            if near or over_budget:
                nxt = HandlePhase.CLOSE if self.pull[i] else HandlePhase.MOVE
        elif phase == HandlePhase.CLOSE:
            if self.phase_steps[i] >= cfg.close_steps:
                nxt = HandlePhase.MOVE
        elif phase == HandlePhase.MOVE:
            if scene.arrived[i] or over_budget:
                nxt = HandlePhase.RELEASE if self.pull[i] else HandlePhase.RETREAT
        elif phase == HandlePhase.RELEASE:
            if self.phase_steps[i] >= cfg.release_steps:
                nxt = HandlePhase.RETREAT
        elif phase == HandlePhase.RETREAT:
            if tcp[2] >= self._retreat_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = HandlePhase.DONE
        if nxt != phase:
            if nxt == HandlePhase.MOVE:
                self._grip_offset[i] = tcp - scene.handle[i]
            if nxt == HandlePhase.RETREAT:
                self._retreat_z[i] = tcp[2] + cfg.retreat_m
            self.phase[i] = int(nxt)
            self.phase_steps[i] = 0

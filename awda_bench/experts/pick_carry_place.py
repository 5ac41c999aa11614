"""The one pick-carry-place expert core (pick_place, stack_block, basketball, nut_assembly).

Phases per env (each moves the TCP in a straight line, at most ``max_step_m`` per axis per step)::

    HOVER --> DESCEND --> CLOSE --> LIFT --> CARRY --> LOWER --> RELEASE --> RETREAT --> DONE
    above the  to the      grip      held      held       held        grip        straight
    grasp      grasp       closed    object    reference  object's    open        up
    point      point                 clears    over the   bottom at
                                     the tops  place      the release
                                                          height

A family says only *where*: its :meth:`PickCarryPlaceExpert.read_scene` returns a
:class:`PickScene` (grasp point, the held object's reference point and bottom, where the
reference must go, what the carried bottom must clear, where the bottom is released), re-read
every step. The core says *how*: after the grasp it aims the held object's reference point (not
the TCP) over the place point, so a grasp off-centre or a slip is compensated; the lift and
release heights are computed from the held object's actual bottom when the grip closes and when
the carry ends. A phase ends at its goal (within a tolerance) or when its step budget runs out,
so a stuck phase never stalls an episode. Works for any embodiment of
:mod:`awda_bench.envs.embodiments` (step size and grip sign come from the env).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.experts.base import PICK_GRIP_CLOSED, PhaseExpert, check_config
from awda_bench.experts.base import PickPhase as Phase


@dataclass(frozen=True)
class PickScene:
    """Where things are, per env (arrays over the envs), as a family reads them from the state."""

    grasp: np.ndarray
    """(n, 3) TCP position at which the fingers close [m]."""
    hover_z: np.ndarray
    """(n,) TCP height above the grasp point before descending [m]."""
    held: np.ndarray
    """(n, 3) reference point of the object to carry (its centre, a nut's hole) [m]."""
    bottom_z: np.ndarray
    """(n,) that object's lowest point [m]."""
    place_xy: np.ndarray
    """(n, 2) where the reference point must end up, horizontally [m]."""
    clear_z: np.ndarray
    """(n,) highest top the carried object's bottom must clear (bin walls, cubes, rims, pegs) [m]."""
    release_bottom_z: np.ndarray
    """(n,) height of the carried object's bottom at which the gripper opens [m]."""


@dataclass(frozen=True)
class PickCarryPlaceConfig:
    """How the core moves (tolerances, clearances, step budgets); families subclass it."""

    carry_clearance_m: float = 0.04
    """LIFT/CARRY: the held object's bottom this far above ``PickScene.clear_z`` [m]."""
    min_carry_z_m: float = 0.0
    """LIFT/CARRY TCP height never lower than this [m]."""
    retreat_m: float = 0.08
    """RETREAT: rise this far above the release height [m]."""
    close_steps: int = 6
    """Control steps the gripper is commanded closed before lifting."""
    release_steps: int = 5
    """Control steps the gripper is commanded open before retreating."""
    xy_tolerance_m: float = 0.005
    """Horizontal goal tolerance over the grasp point [m]."""
    carry_xy_tolerance_m: float = 0.005
    """Horizontal tolerance of the held reference over the place point before lowering [m]."""
    z_tolerance_m: float = 0.005
    """Vertical goal tolerance [m]."""
    phase_budget_steps: int = 60
    """Most control steps any moving phase may take (the TCP covers 2 cm per full step, so a
    60-step phase spans 1.2 m: only a blocked phase runs out)."""

    def __post_init__(self) -> None:
        check_config(
            self,
            positive=(
                "carry_clearance_m",
                "retreat_m",
                "xy_tolerance_m",
                "carry_xy_tolerance_m",
                "z_tolerance_m",
            ),
            at_least_one=("close_steps", "release_steps", "phase_budget_steps"),
        )


class PickCarryPlaceExpert(PhaseExpert):
    """The core (batched over envs); a family overrides :meth:`read_scene`."""

    config: PickCarryPlaceConfig
    start_phase = Phase.HOVER
    done_phase = Phase.DONE
    grip_closed_phases = PICK_GRIP_CLOSED
    config_type = PickCarryPlaceConfig

    def __init__(self, config: PickCarryPlaceConfig | None = None, name: str = "scripted") -> None:
        super().__init__(config, name)
        self._carry_z = np.zeros(0)
        self._release_z = np.zeros(0)

    def read_scene(self, env: Any, tcp: np.ndarray) -> PickScene:
        """The family's :class:`PickScene` for the current state (``tcp``: (n, 3) [m])."""
        raise NotImplementedError

    # ------------------------------------------------------------------ Policy protocol
    def _reset_state(self, n: int) -> None:
        self._carry_z = np.full(n, self.config.min_carry_z_m)
        self._release_z = np.zeros(n)

    def _set_goal(self, i: int, tcp: np.ndarray, scene: PickScene, goal: np.ndarray) -> None:
        phase = Phase(self.phase[i])
        # where the TCP must be for the *held reference* to be over the place point
        aim_xy = scene.place_xy[i] + (tcp[:2] - scene.held[i, :2])
        if phase == Phase.HOVER:
            goal[:] = (scene.grasp[i, 0], scene.grasp[i, 1], max(scene.hover_z[i], tcp[2]))
        elif phase == Phase.DESCEND:
            goal[:] = scene.grasp[i]
        elif phase == Phase.LIFT:
            goal[2] = self._carry_z[i]
        elif phase == Phase.CARRY:
            goal[:] = (aim_xy[0], aim_xy[1], self._carry_z[i])
        elif phase == Phase.LOWER:
            goal[:] = (aim_xy[0], aim_xy[1], self._release_z[i])
        elif phase == Phase.RETREAT:
            goal[2] = self._release_z[i] + self.config.retreat_m
        # CLOSE, RELEASE, DONE: hold position

    # ------------------------------------------------------------------ phase logic
    def _advance(self, i: int, tcp: np.ndarray, scene: PickScene) -> None:
        cfg = self.config
        phase = Phase(self.phase[i])
        over_budget = self.phase_steps[i] >= cfg.phase_budget_steps
        to_grasp = float(np.linalg.norm(tcp[:2] - scene.grasp[i, :2]))
        held_to_place = float(np.linalg.norm(scene.held[i, :2] - scene.place_xy[i]))
        bottom = scene.bottom_z[i]
        nxt = phase
        if phase == Phase.HOVER:
            if (
                to_grasp <= cfg.xy_tolerance_m
                and tcp[2] >= scene.hover_z[i] - 2 * cfg.z_tolerance_m
            ) or over_budget:
                nxt = Phase.DESCEND
        elif phase == Phase.DESCEND:
            if (
                abs(tcp[2] - scene.grasp[i, 2]) <= cfg.z_tolerance_m
                and to_grasp <= 2 * cfg.xy_tolerance_m
            ) or over_budget:
                nxt = Phase.CLOSE
        elif phase == Phase.CLOSE:
            if self.phase_steps[i] >= cfg.close_steps:
                nxt = Phase.LIFT
                # raise the TCP by as much as the held bottom must rise to clear the tops
                self._carry_z[i] = max(
                    cfg.min_carry_z_m, tcp[2] + (scene.clear_z[i] + cfg.carry_clearance_m - bottom)
                )
        elif phase == Phase.LIFT:
            if tcp[2] >= self._carry_z[i] - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.CARRY
        elif phase == Phase.CARRY:
            if held_to_place <= cfg.carry_xy_tolerance_m or over_budget:
                nxt = Phase.LOWER
                # lower the TCP by as much as the held bottom must drop to its release height
                self._release_z[i] = min(
                    tcp[2] - (bottom - scene.release_bottom_z[i]), self._carry_z[i]
                )
        elif phase == Phase.LOWER:
            if abs(tcp[2] - self._release_z[i]) <= cfg.z_tolerance_m or over_budget:
                nxt = Phase.RELEASE
        elif phase == Phase.RELEASE:
            if self.phase_steps[i] >= cfg.release_steps:
                nxt = Phase.RETREAT
        elif phase == Phase.RETREAT:
            if tcp[2] >= self._release_z[i] + cfg.retreat_m - 2 * cfg.z_tolerance_m or over_budget:
                nxt = Phase.DONE
        if nxt != phase:
            self.phase[i] = int(nxt)
            self.phase_steps[i] = 0

"""The grasp primitive (supplementary S1): localize, hover above, descend, close, lift.

Timeline in control steps (each phase ends on its tolerance or its step budget)::

    HOVER    re-localize every step; move to  top + (0, 0, hover_height_m)        gripper open
    DESCEND  move to (x, y, max(z_top - descent_offset_m, z_floor + clearance))  gripper open
             (within descend_tol_m, or blocked: the fingertips on the support)
    CLOSE    hold position, close command, close_steps steps
    LIFT     move to p_close + (0, 0, lift_m), the first lift_probe_m slowly;     gripper closed
             blocked there (fixed or articulated object) -> the lift ends early
             (skipped with ``lift=False``: the executor's choice when the next waypoint
             carries the grasped thing sideways, i.e. pulls a handle)
    DONE

``z_top`` is the localized (visible top) z of the object. The localizer is injected as a callable
returning :class:`~awda_bench.primitives.localization.Localization` or ``None`` (nothing seen), so
the primitive runs against a synthetic camera in tests and the wrist depth camera in the simulator.
If nothing has ever been localized, ``fallback_tcp_target`` (e.g. the grasp waypoint) is used as the
descent target; without a fallback the grasp ends immediately with ``failed = True``.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import Enum

import numpy as np

from awda_bench.primitives.base import GRIP_CLOSE, GRIP_OPEN, RobotState, hold_action, is_blocked
from awda_bench.primitives.config import GraspConfig
from awda_bench.primitives.free_space import straight_line_action
from awda_bench.primitives.localization import Localization

Locator = Callable[[], Localization | None]
"""Takes one wrist depth image of the current scene and localizes the object nearest its centre."""


class GraspPhase(Enum):
    HOVER = "hover"
    DESCEND = "descend"
    CLOSE = "close"
    LIFT = "lift"
    DONE = "done"


class Grasp:
    """Grasp the object nearest the wrist camera's image centre.

    Args:
        locate: one localization from a fresh wrist depth image (called once per HOVER step).
        config: heights, offsets, tolerances and budgets.
        max_step_m: TCP displacement per unit action [m] (the controller's step).
        fallback_tcp_target: (3,) TCP grasp position [m] used if localization never succeeds.
        lift: False ends the grasp once the gripper has closed (no LIFT phase).
    """

    def __init__(
        self,
        locate: Locator,
        config: GraspConfig = GraspConfig(),
        max_step_m: float = 0.02,
        fallback_tcp_target: np.ndarray | None = None,
        lift: bool = True,
    ) -> None:
        self.locate = locate
        self.lift = lift
        self.config = config
        self.max_step_m = max_step_m
        self.fallback = (
            None if fallback_tcp_target is None else np.asarray(fallback_tcp_target, float)
        )
        self.phase = GraspPhase.HOVER
        self.object_top: np.ndarray | None = None
        """(3,) latest localized object top [m], or None."""
        self.floor_z: float | None = None
        """Latest localized floor height [m], or None."""
        self.localizations = 0
        """Localizer calls (= wrist depth frames requested)."""
        self.localization_misses = 0
        """Localizer calls that found no object."""
        self.failed = False
        """True if the grasp ended without any target (no localization, no fallback)."""
        self.phase_steps = {p: 0 for p in GraspPhase}
        """Actions issued per phase."""
        self.hover_reached = False
        self._descent_target: np.ndarray | None = None
        self._lift_target: np.ndarray | None = None
        self._lift_last: tuple[np.ndarray, np.ndarray] | None = None
        """(TCP, commanded displacement [m]) of the last lift step."""
        self._lift_blocked_steps = 0
        self.lift_blocked = False
        self._descend_last: tuple[np.ndarray, np.ndarray] | None = None
        """(TCP, commanded displacement [m]) of the last descent step."""
        self._descend_blocked_steps = 0
        """True when the lift ended because the grasped thing did not rise (fixed/articulated)."""

    # -- helpers -------------------------------------------------------------------------------
    def _relocalize(self) -> None:
        self.localizations += 1
        loc = self.locate()
        if loc is None:
            self.localization_misses += 1
            return
        self.object_top = np.asarray(loc.position_world, dtype=np.float64)
        self.floor_z = float(loc.floor_world[2])

    def hover_target(self) -> np.ndarray | None:
        """TCP target of HOVER [m]: ``hover_height_m`` above the object top (or the fallback)."""
        base = self.object_top if self.object_top is not None else self.fallback
        return None if base is None else base + np.array([0.0, 0.0, self.config.hover_height_m])

    def descent_target(self) -> np.ndarray | None:
        """TCP target of DESCEND [m]: ``(x, y, max(z_top - offset, z_floor + clearance))``."""
        c = self.config
        if self.object_top is None:
            return None if self.fallback is None else self.fallback.copy()
        z = self.object_top[2] - c.descent_offset_m
        if self.floor_z is not None:
            z = max(z, self.floor_z + c.min_floor_clearance_m)
        return np.array([self.object_top[0], self.object_top[1], z])

    def _count_blocked(
        self, last: tuple[np.ndarray, np.ndarray] | None, tcp: np.ndarray, count: int
    ) -> int:
        """``count + 1`` if the last step's command (``last``: TCP, commanded displacement [m])
        was blocked (the pressing condition), else 0."""
        c = self.config
        if last is not None and is_blocked(
            last[0], tcp, last[1], c.lift_min_command_m, c.lift_progress_ratio
        ):
            return count + 1
        return 0

    def _move(self, state: RobotState, target: np.ndarray, grip: float) -> np.ndarray:
        self.phase_steps[self.phase] += 1
        return straight_line_action(state.tcp_pos, target, self.max_step_m, grip)

    # -- the state machine -----------------------------------------------------------------------
    def step(self, state: RobotState) -> np.ndarray | None:
        c = self.config
        while True:
            if self.phase is GraspPhase.HOVER:
                self._relocalize()
                hover = self.hover_target()
                if hover is None:
                    self.failed = True
                    self.phase = GraspPhase.DONE
                    continue
                if np.linalg.norm(hover - state.tcp_pos) < c.hover_tol_m:
                    self.hover_reached = True
                    self.phase = GraspPhase.DESCEND
                    continue
                if self.phase_steps[GraspPhase.HOVER] >= c.hover_step_budget:
                    self.phase = GraspPhase.DESCEND
                    continue
                return self._move(state, hover, GRIP_OPEN)
            if self.phase is GraspPhase.DESCEND:
                if self._descent_target is None:
                    self._descent_target = self.descent_target()
                    assert self._descent_target is not None  # HOVER ends only with a target
                tcp = np.asarray(state.tcp_pos, dtype=np.float64)
                self._descend_blocked_steps = self._count_blocked(
                    self._descend_last, tcp, self._descend_blocked_steps
                )
                if (
                    np.linalg.norm(self._descent_target - tcp) < c.descend_tol_m
                    or self._descend_blocked_steps >= c.lift_blocked_steps
                    or self.phase_steps[GraspPhase.DESCEND] >= c.descend_step_budget
                ):
                    self.phase = GraspPhase.CLOSE
                    continue
                action = self._move(state, self._descent_target, GRIP_OPEN)
                self._descend_last = (tcp, action[:3] * self.max_step_m)
                return action
            if self.phase is GraspPhase.CLOSE:
                if self.phase_steps[GraspPhase.CLOSE] >= c.close_steps and not self.lift:
                    self.phase = GraspPhase.DONE
                    continue
                if self.phase_steps[GraspPhase.CLOSE] >= c.close_steps:
                    self.phase = GraspPhase.LIFT
                    self._lift_target = np.asarray(state.tcp_pos, float) + np.array(
                        [0, 0, c.lift_m]
                    )
                    continue
                self.phase_steps[GraspPhase.CLOSE] += 1
                return hold_action(GRIP_CLOSE)
            if self.phase is GraspPhase.LIFT:
                assert self._lift_target is not None
                tcp = np.asarray(state.tcp_pos, dtype=np.float64)
                self._lift_blocked_steps = self._count_blocked(
                    self._lift_last, tcp, self._lift_blocked_steps
                )
                if self._lift_blocked_steps >= c.lift_blocked_steps:
                    self.lift_blocked = True
                    self.phase = GraspPhase.DONE
                    continue
                if (
                    np.linalg.norm(self._lift_target - tcp) < c.lift_tol_m
                    or self.phase_steps[GraspPhase.LIFT] >= c.lift_step_budget
                ):
                    self.phase = GraspPhase.DONE
                    continue
                lifted = tcp[2] - (self._lift_target[2] - c.lift_m)
                action = self._move(state, self._lift_target, GRIP_CLOSE)
                if lifted < c.lift_probe_m:
                    action[:3] *= min(1.0, c.lift_probe_speed / max(np.abs(action[:3]).max(), 1e-9))
                self._lift_last = (tcp, action[:3] * self.max_step_m)
                return action
            return None

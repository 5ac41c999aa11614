"""The press primitive: push toward a press-attributed waypoint until blocked, hold, retract.

A state machine over control steps (the fingers closed throughout: a blunt pusher)::

    APPROACH --(blocked for contact_steps)--> HOLD --(hold_steps)--> RETRACT --> done
        |  straight line from the start through the waypoint, at full speed until
        |  ``slow_distance_m`` before it, then at ``press_speed`` (a fraction of a full step),
        |  continuing up to ``overshoot_m`` past it
        '--(overshoot exhausted or step budget, never blocked)--> RETRACT, ``failed = True``

"Blocked" is the pressing condition of the attribute miner (:mod:`awda_bench.mining`): the command
asked for at least ``min_command_m`` and the TCP advanced less than ``progress_ratio`` of it along
the command. HOLD keeps commanding ``press_speed`` into the surface (with the tracking controller
the push is bounded: the target carries at most 1 cm past the measured TCP). RETRACT moves back
toward the start by ``retract_m``.
"""

from __future__ import annotations

from enum import Enum

import numpy as np

from awda_bench.primitives.base import GRIP_CLOSE, RobotState, is_blocked
from awda_bench.primitives.config import PressConfig


class PressPhase(Enum):
    APPROACH = "approach"
    HOLD = "hold"
    RETRACT = "retract"
    DONE = "done"


class Press:
    """Press at ``target`` (the waypoint, [m]), approaching along the direction start -> target."""

    def __init__(self, target: np.ndarray, config: PressConfig = PressConfig()) -> None:
        self.target = np.asarray(target, dtype=np.float64).reshape(3)
        self.config = config
        self.phase = PressPhase.APPROACH
        self.failed = False
        """True when the approach never met resistance (nothing was pressed)."""
        self.contact_pos: np.ndarray | None = None
        """TCP position where the press was first blocked [m]."""
        self.steps = 0
        self._phase_steps = 0
        self._blocked = 0
        self._start: np.ndarray | None = None
        self._direction = np.zeros(3)
        self._end = self.target.copy()
        self._last_pos: np.ndarray | None = None
        self._last_command = np.zeros(3)
        self._retract_to = self.target.copy()

    def _begin(self, tcp: np.ndarray) -> None:
        self._start = tcp.copy()
        offset = self.target - tcp
        distance = float(np.linalg.norm(offset))
        self._direction = offset / distance if distance > 1e-9 else np.array([0.0, 0.0, -1.0])
        self._end = self.target + self._direction * self.config.overshoot_m

    def _command(self, tcp: np.ndarray) -> np.ndarray:
        """Displacement [m] for this step: toward the approach line's end, slowed near the target."""
        cfg = self.config
        offset = self._end - tcp
        remaining = float(offset @ self._direction)
        to_target = float((self.target - tcp) @ self._direction)
        speed = (
            cfg.max_step_m if to_target > cfg.slow_distance_m else cfg.press_speed * cfg.max_step_m
        )
        # steer onto the approach line: the lateral error is corrected within the step
        lateral = offset - remaining * self._direction
        along = min(max(remaining, 0.0), speed)
        return self._direction * along + lateral

    def _action(self, displacement: np.ndarray) -> np.ndarray:
        a = displacement / self.config.max_step_m
        a = a / max(1.0, float(np.max(np.abs(a))))
        self._last_command = a * self.config.max_step_m
        return np.array([a[0], a[1], a[2], GRIP_CLOSE], dtype=np.float64)

    def _was_blocked(self, tcp: np.ndarray) -> bool:
        if self._last_pos is None:
            return False
        cfg = self.config
        return is_blocked(
            self._last_pos, tcp, self._last_command, cfg.min_command_m, cfg.progress_ratio
        )

    def step(self, state: RobotState) -> np.ndarray | None:
        cfg = self.config
        tcp = np.asarray(state.tcp_pos, dtype=np.float64)
        if self._start is None:
            self._begin(tcp)
        if self.phase == PressPhase.APPROACH:
            self._blocked = self._blocked + 1 if self._was_blocked(tcp) else 0
            beyond = float((tcp - self._end) @ self._direction) >= -cfg.end_tolerance_m
            if self._blocked >= cfg.contact_steps:
                self.contact_pos = tcp.copy()
                self._set_phase(PressPhase.HOLD)
            elif beyond or self._phase_steps >= cfg.step_budget:
                self.failed = True
                self._set_phase(PressPhase.RETRACT, tcp)
        if self.phase == PressPhase.HOLD and self._phase_steps >= cfg.hold_steps:
            self._set_phase(PressPhase.RETRACT, tcp)
        if self.phase == PressPhase.RETRACT:
            offset = self._retract_to - tcp
            if np.linalg.norm(offset) < cfg.retract_tol_m or self._phase_steps >= cfg.step_budget:
                self._set_phase(PressPhase.DONE)
        if self.phase == PressPhase.DONE:
            return None

        self._phase_steps += 1
        self.steps += 1
        self._last_pos = tcp.copy()
        if self.phase == PressPhase.APPROACH:
            return self._action(self._command(tcp))
        if self.phase == PressPhase.HOLD:
            return self._action(self._direction * cfg.press_speed * cfg.max_step_m)
        return self._action(self._retract_to - tcp)

    def _set_phase(self, phase: PressPhase, tcp: np.ndarray | None = None) -> None:
        if phase == PressPhase.RETRACT and tcp is not None:
            self._retract_to = tcp - self._direction * self.config.retract_m
        self.phase = phase
        self._phase_steps = 0


__all__ = ["Press", "PressPhase"]

"""Free-space motion: a straight line from the TCP to a destination, one control step at a time."""

from __future__ import annotations

import numpy as np

from awda_bench.primitives.base import GRIP_OPEN, RobotState
from awda_bench.primitives.config import FreeSpaceConfig


def straight_line_action(
    tcp_pos: np.ndarray,
    target: np.ndarray,
    max_step_m: float,
    grip: float,
    speed: float = 1.0,
) -> np.ndarray:
    """The action moving the TCP straight towards ``target``.

    With ``d = target - tcp_pos`` [m], ``s = max_step_m`` (displacement per unit action) and
    ``v = speed`` (fraction of a full step, in (0, 1])::

        a_xyz = (d / s) * v / max(v, ||d / s||_inf)

    so the commanded displacement is exactly ``d`` when it fits in ``v`` of a step, otherwise the
    largest step along ``d`` whose components all lie in [-v, v] (the direction is preserved).
    """
    a = (np.asarray(target, dtype=np.float64) - np.asarray(tcp_pos, dtype=np.float64)) / max_step_m
    a = a * (speed / max(speed, float(np.max(np.abs(a)))))
    return np.array([a[0], a[1], a[2], grip], dtype=np.float64)


class FreeSpace:
    """Move the TCP to ``target`` in a straight line with a fixed gripper command.

    Finishes when ``||p - target|| < reach_tol_m`` (then, with ``finish_exactly``, after one more
    step commanding the exact remaining displacement) or after ``step_budget`` actions. ``speed``
    (fraction of a full step, in (0, 1]) caps every command component.
    """

    def __init__(
        self,
        target: np.ndarray,
        config: FreeSpaceConfig = FreeSpaceConfig(),
        grip: float = GRIP_OPEN,
        speed: float = 1.0,
    ) -> None:
        if not 0.0 < speed <= 1.0:
            raise ValueError(f"speed must be in (0, 1], got {speed!r}")
        self.target = np.asarray(target, dtype=np.float64).reshape(3)
        self.config = config
        self.grip = float(grip)
        self.speed = float(speed)
        self.steps = 0
        """Actions issued so far."""
        self.reached = False
        """True if the motion ended within the tolerance (False if the budget ran out)."""

    def step(self, state: RobotState) -> np.ndarray | None:
        distance = float(np.linalg.norm(self.target - state.tcp_pos))
        if distance < self.config.reach_tol_m:
            finishing = (
                self.config.finish_exactly
                and not self.reached
                and distance > self.config.exact_tol_m
            )
            self.reached = True
            if not finishing:
                return None
            self.steps += 1
            return straight_line_action(
                state.tcp_pos, self.target, self.config.max_step_m, self.grip, self.speed
            )
        if self.steps >= self.config.step_budget:
            return None
        self.steps += 1
        return straight_line_action(
            state.tcp_pos, self.target, self.config.max_step_m, self.grip, self.speed
        )


__all__ = ["FreeSpace", "straight_line_action"]

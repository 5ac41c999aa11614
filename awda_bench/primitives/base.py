"""What every primitive sees (:class:`RobotState`) and the one method it implements.

A primitive is a small state machine over control steps::

    while (a := primitive.step(state)) is not None:
        state = env.step(a)          # a: (4,) float in [-1, 1] -- dx, dy, dz, grip (> 0 closes)

``step`` returns ``None`` once the primitive has finished *without* consuming a control step, so the
executor can start the next primitive in the same step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

GRIP_OPEN: float = -1.0
"""Gripper component of an action that opens (any value <= 0 opens)."""
GRIP_CLOSE: float = 1.0
"""Gripper component of an action that closes (any value > 0 closes)."""


@dataclass(frozen=True)
class RobotState:
    """The proprioceptive state of one env at one control step."""

    tcp_pos: np.ndarray
    """(3,) tool centre point in the world frame [m]."""
    gripper_opening_m: float
    """Distance between the finger pads [m]."""


class Primitive(Protocol):
    """One motor primitive acting through the 4-D action space."""

    def step(self, state: RobotState) -> np.ndarray | None:
        """Next action ``(4,)`` in [-1, 1], or ``None`` when finished (no step consumed)."""


def hold_action(grip: float) -> np.ndarray:
    """Zero motion with the given gripper command, shape ``(4,)``."""
    return np.array([0.0, 0.0, 0.0, grip], dtype=np.float64)


def is_blocked(
    previous_tcp: np.ndarray,
    tcp: np.ndarray,
    commanded_m: np.ndarray,
    min_command_m: float,
    progress_ratio: float,
) -> bool:
    """The pressing condition of :mod:`awda_bench.mining` for one step: the command asked for at
    least ``min_command_m`` [m] and the TCP advanced less than ``progress_ratio`` of it along it."""
    norm = float(np.linalg.norm(commanded_m))
    if norm < min_command_m:
        return False
    progress = float((np.asarray(tcp) - np.asarray(previous_tcp)) @ commanded_m) / norm
    return progress < progress_ratio * norm

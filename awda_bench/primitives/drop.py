"""Drop: come to rest, then open the gripper in place."""

from __future__ import annotations

import numpy as np

from awda_bench.primitives.base import GRIP_CLOSE, GRIP_OPEN, RobotState, hold_action
from awda_bench.primitives.config import DropConfig


class Drop:
    """Hold zero motion with the gripper still closed until the TCP has settled (it moved less
    than ``settled_m`` in a step, at most ``settle_steps`` steps), then hold the open command for
    ``open_steps`` control steps."""

    def __init__(self, config: DropConfig = DropConfig()) -> None:
        self.config = config
        self.steps = 0
        self._settling = 0
        self._settled = False
        self._last: np.ndarray | None = None

    def step(self, state: RobotState) -> np.ndarray | None:
        c = self.config
        tcp = np.asarray(state.tcp_pos, dtype=np.float64)
        if not self._settled:
            moved = np.inf if self._last is None else float(np.linalg.norm(tcp - self._last))
            self._last = tcp
            if moved < c.settled_m or self._settling >= c.settle_steps:
                self._settled = True
            else:
                self._settling += 1
                return hold_action(GRIP_CLOSE)
        if self.steps >= c.open_steps:
            return None
        self.steps += 1
        return hold_action(GRIP_OPEN)

"""Drop: open the gripper in place."""

from __future__ import annotations

import numpy as np

from awda_bench.primitives.base import GRIP_OPEN, RobotState, hold_action
from awda_bench.primitives.config import DropConfig


class Drop:
    """Hold zero motion with the open command for ``open_steps`` control steps."""

    def __init__(self, config: DropConfig = DropConfig()) -> None:
        self.config = config
        self.steps = 0

    def step(self, state: RobotState) -> np.ndarray | None:
        if self.steps >= self.config.open_steps:
            return None
        self.steps += 1
        return hold_action(GRIP_OPEN)

"""Free-space motion through a list of waypoints, then a few steps holding still: what trajectory
synthesis drives (SPEC §6 TS), on any robot the primitives drive (the ManiSkill recorder's Panda,
Meta-World's Sawyer)."""

from __future__ import annotations

import numpy as np

from awda_bench.primitives.base import GRIP_OPEN, RobotState, hold_action
from awda_bench.primitives.config import FreeSpaceConfig
from awda_bench.primitives.free_space import FreeSpace


class WaypointTour:
    """Move the TCP, gripper open, to each of ``waypoints`` in turn (a :class:`FreeSpace` motion
    each), then command zero motion for ``settle_steps`` steps; :meth:`step` returns ``None``
    once all that is done."""

    def __init__(self, waypoints: np.ndarray, config: FreeSpaceConfig, settle_steps: int) -> None:
        self.motions = [FreeSpace(w, config, grip=GRIP_OPEN) for w in waypoints]
        self.settle_steps = settle_steps
        self._current = 0
        self._settled = 0

    def step(self, state: RobotState) -> np.ndarray | None:
        """The next command ``(4,)``, or ``None`` when the tour is over."""
        while self._current < len(self.motions):
            command = self.motions[self._current].step(state)
            if command is not None:
                return command
            self._current += 1
        if self._settled >= self.settle_steps:
            return None
        self._settled += 1
        return hold_action(GRIP_OPEN)

    @property
    def reached(self) -> list[bool]:
        """Whether each waypoint's motion ended within its tolerance."""
        return [bool(m.reached) for m in self.motions]

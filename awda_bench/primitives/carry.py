"""Carry: free-space motion with the gripper kept closed."""

from __future__ import annotations

import numpy as np

from awda_bench.primitives.base import GRIP_CLOSE
from awda_bench.primitives.config import FreeSpaceConfig
from awda_bench.primitives.free_space import FreeSpace


class Carry(FreeSpace):
    """:class:`FreeSpace` towards ``target`` with the close command held every step (``speed``: a
    fraction of a full step, e.g. a slower pull of an articulated handle)."""

    def __init__(
        self, target: np.ndarray, config: FreeSpaceConfig = FreeSpaceConfig(), speed: float = 1.0
    ) -> None:
        super().__init__(target, config, grip=GRIP_CLOSE, speed=speed)

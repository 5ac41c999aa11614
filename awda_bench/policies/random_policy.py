"""``random``: uniform random actions in [-1, 1]^4 (the lower bound of every table)."""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import ClosedLoopPolicy, EpisodeContext


class RandomPolicy(ClosedLoopPolicy):
    """``a_t ~ U[-1, 1]^4`` per env, from a generator seeded with the episode's seed."""

    name = "random"
    observation_keys: tuple[str, ...] = ()
    """It reads no observation: served over openpi's protocol (``serve --protocol openpi``), the
    harness sends it the episode keys only (docs/serving.md)."""

    def __init__(self) -> None:
        self._rng = np.random.default_rng(0)
        self._num_envs = 1

    def reset(self, ctx: EpisodeContext) -> None:
        self._rng = np.random.default_rng(ctx.spec.seed)
        self._num_envs = 1 if ctx.observations is None else ctx.observations.num_envs

    def act(self, obs: Any) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, size=(self._num_envs, 4)).astype(np.float32)

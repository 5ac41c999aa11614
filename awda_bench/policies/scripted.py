"""``scripted``: the suite's privileged scripted expert (``awda_bench.experts``) as a method."""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import EpisodeContext, Policy


class ScriptedPolicy:
    """Thin wrapper: builds the agent-embodiment expert of the episode's suite at each reset."""

    name = "scripted"
    privileged = True
    """It reads the simulator (``ctx.env``): its rows are marked privileged."""

    def __init__(self) -> None:
        self._expert: Policy | None = None
        self._suite: str | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        from awda_bench.experts import make_expert

        if self._expert is None or self._suite != ctx.spec.suite:
            self._expert = make_expert(ctx.spec.suite, embodiment="agent")
            self._suite = ctx.spec.suite
        self._expert.reset(ctx)

    def act(self, obs: Any) -> np.ndarray:
        if self._expert is None:
            raise RuntimeError("ScriptedPolicy.act() before reset(ctx)")
        return np.asarray(self._expert.act(obs), dtype=np.float32)

    @property
    def done(self) -> bool:
        return self._expert is not None and bool(self._expert.done)

    @property
    def waypoints(self) -> np.ndarray | None:
        return None

"""``scripted``: the suite's privileged scripted expert (``awda_bench.experts``; on Meta-World the
package's own, :mod:`awda_bench.metaworld.expert`) as a method."""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import EpisodeContext, Policy


def _expert_for(ctx: EpisodeContext) -> Policy:
    """The agent-embodiment expert of ``ctx``'s suite: Meta-World's own scripted policies on a
    Meta-World env (imported only there: they need ``.venv-metaworld``), else ours."""
    if getattr(ctx.env, "simulator", None) == "metaworld":
        from awda_bench.metaworld.expert import MetaWorldExpert

        return MetaWorldExpert()
    from awda_bench.experts import make_expert

    return make_expert(ctx.spec.suite, embodiment="agent")


class ScriptedPolicy:
    """Thin wrapper: builds the agent-embodiment expert of the episode's suite at each reset."""

    name = "scripted"
    privileged = True
    """It reads the simulator (``ctx.env``): its rows are marked privileged."""

    def __init__(self) -> None:
        self._expert: Policy | None = None
        self._suite: str | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        if self._expert is None or self._suite != ctx.spec.suite:
            self._expert = _expert_for(ctx)
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

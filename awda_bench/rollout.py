"""The one rollout loop: an env stepped by a chooser until a stop rule says so.

Every episode the package plays runs through :func:`roll_out`: the evaluation's episodes
(:mod:`awda_bench.evaluation.episode_runner`), the collection's expert and synthesized episodes
(:mod:`awda_bench.data.recorder`), the demonstration videos (:mod:`awda_bench.demo_recording`) and
the Meta-World expert (:mod:`awda_bench.metaworld.rollout`, which collection and gt-waypoints
use). What differs between them is what chooses the action and what is written down, passed in as
hooks::

    t = 0, 1, ..., max_steps - 1:
        before_step(t)                     record state t (frames, TCP, simulator truth)
        a_t = choose(obs_t)                None ends the rollout (a policy done, a tour finished)
        obs_{t+1}, r, term, trunc, info_{t+1} = step(a_t)
        after_step(t + 1, a_t, info_{t+1}) True ends it (success reached, the expert settled)

``step`` is gymnasium's ``env.step`` or anything with its signature (a recorder that also
keeps the action). ``terminated`` and ``truncated`` do not stop a rollout: the suites' horizons
and the hooks do (the envs are built without a time limit).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

StepFn = Callable[[Any], tuple[Any, Any, Any, Any, dict[str, Any]]]
"""``action -> (obs, reward, terminated, truncated, info)``, as ``gymnasium.Env.step``."""
ChooseFn = Callable[[Any], Any]
"""``obs -> action``, or ``None`` to end the rollout before stepping."""
AfterStepFn = Callable[[int, Any, dict[str, Any]], bool]
"""``(steps taken, the action, info after it) -> stop?``"""


@dataclass
class RolloutEnd:
    """Where a rollout stopped."""

    obs: Any
    """The last observation (after the last step; the initial one if no step was taken)."""
    info: dict[str, Any]
    """The last step's info (the initial info if no step was taken)."""
    steps: int
    """Actions taken."""
    choose_s: float = 0.0
    """Seconds spent in ``choose``."""
    step_s: float = 0.0
    """Seconds spent in ``step``."""


def roll_out(
    step: StepFn,
    obs: Any,
    choose: ChooseFn,
    max_steps: int,
    *,
    info: dict[str, Any] | None = None,
    before_step: Callable[[int], None] | None = None,
    after_step: AfterStepFn | None = None,
) -> RolloutEnd:
    """Step from ``obs`` (and its ``info``) until ``choose`` returns ``None``, ``after_step``
    returns True, or ``max_steps`` actions were taken (module docstring)."""
    end = RolloutEnd(obs=obs, info={} if info is None else info, steps=0)
    while end.steps < max_steps:
        if before_step is not None:
            before_step(end.steps)
        t0 = time.perf_counter()
        action = choose(end.obs)
        t1 = time.perf_counter()
        end.choose_s += t1 - t0
        if action is None:
            break
        end.obs, _reward, _terminated, _truncated, end.info = step(action)
        end.step_s += time.perf_counter() - t1
        end.steps += 1
        if after_step is not None and after_step(end.steps, action, end.info):
            break
    return end


class Finishing(Protocol):
    """An actor that says when its work is done (an expert)."""

    @property
    def done(self) -> bool: ...


@dataclass
class SettleAfterDone:
    """An ``after_step`` rule: stop once the actor has been done for more than ``settle_steps``
    steps (the experts' episodes: the scene settles before the episode is judged)."""

    actor: Finishing
    settle_steps: int
    settled: int = field(default=0, init=False)

    def __call__(self, _steps: int, _action: Any, _info: dict[str, Any]) -> bool:
        if self.actor.done:
            self.settled += 1
            return self.settled > self.settle_steps
        return False

"""What the simulated task-env tests share: how they build an env, each task module's ``env``
fixture, and a scripted expert's rollout (``test_env_contract.py`` and the ``test_*_env.py``
modules)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from awda_bench.episode import EpisodeContext, EpisodeSpec, Policy

AGENT = "panda_awda"
"""The evaluated agent's embodiment (every env's default)."""
DEMONSTRATOR = "awda_demonstrator"
"""The demonstrator's embodiment."""


def make_task_env(env_id: str, robot_uids: str | None = None, **kwargs: Any) -> gym.Env:
    """``env_id`` with state observations and no reward, one env; ``robot_uids=None`` builds
    the env's default embodiment."""
    import awda_bench.envs  # noqa: F401  (registers the tasks, the robots and the empty table)

    if robot_uids is not None:
        kwargs["robot_uids"] = robot_uids
    return gym.make(env_id, obs_mode="state", reward_mode="none", **kwargs)


def task_env_fixture(env_id: str) -> Callable[..., Iterator[gym.Env]]:
    """A module-scoped ``env`` fixture: ``env_id`` with its default embodiment (the agent).
    In a test module: ``env = task_env_fixture("AWDA-Door-v1")``."""

    @pytest.fixture(scope="module")
    def env() -> Iterator[gym.Env]:
        e = make_task_env(env_id)
        yield e
        e.close()

    return env


@dataclass
class ExpertRun:
    """How a scripted expert's episode went."""

    steps: int
    """Steps taken (``horizon`` where the expert did not finish)."""
    done: bool
    """The expert said it was done within the horizon."""
    info: dict[str, Any]
    """The last step's ``info``."""
    signals: Counter[str] = field(default_factory=Counter)
    """Per truth signal (``env.truth_signals()``), the number of steps it was true after."""


def run_expert(
    env: gym.Env,
    expert: Policy,
    task: int,
    seed: int,
    horizon: int,
    on_step: Callable[[], None] | None = None,
) -> ExpertRun:
    """Reset ``env`` to variation ``task`` with ``seed`` and let ``expert`` act until it is done
    or ``horizon`` steps have passed; every action must be one (1, 4) row in [-1, 1].
    ``on_step`` is called after each step (to watch the scene)."""
    base = env.unwrapped
    obs, _ = env.reset(seed=seed, options={"task": task})
    spec = EpisodeSpec(suite="mosaic", task=task, episode=0, seed=seed, demo_seed=seed)
    expert.reset(EpisodeContext(env=base, spec=spec))
    signals: Counter[str] = Counter()
    info: dict[str, Any] = {}
    for t in range(horizon):
        action = expert.act(obs)
        assert action.shape == (1, 4) and np.abs(action).max() <= 1.0
        obs, _, _, _, info = env.step(action)
        signals.update(k for k, v in base.truth_signals().items() if bool(v[0]))
        if on_step is not None:
            on_step()
        if expert.done:
            return ExpertRun(t + 1, True, info, signals)
    return ExpertRun(horizon, False, info, signals)


def assert_spread_out(
    xy: np.ndarray,
    center_xy_m: Any,
    half_size_m: tuple[float, float],
    min_separation_m: float,
) -> None:
    """(k, 2) object positions [m]: pairwise at least ``min_separation_m`` apart, each within
    ``center_xy_m +- half_size_m`` (1 um of float slack)."""
    d = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.eye(len(xy))
    assert d.min() >= min_separation_m - 1e-6
    assert (np.abs(xy - np.asarray(center_xy_m)) <= np.array(half_size_m) + 1e-6).all()

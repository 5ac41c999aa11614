"""The single function that builds a suite's env; workers call it once and reuse the env.

Real suites name a ManiSkill env id registered by :mod:`awda_bench.envs`; a Meta-World suite
(``simulator = "metaworld"``) gets one :class:`awda_bench.metaworld.env.MetaWorldEnv` serving all
its tasks (built only inside a worker started from ``.venv-metaworld``). An id of the form
``"some.module:Env-v0"`` makes gymnasium import ``some.module`` first (how tests plug in a fake
env through the very same path).
"""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium as gym

from awda_bench.errors import UsageError
from awda_bench.render_device import render_backend
from awda_bench.suites import Suite

CONTROL_MODE = "pd_ee_delta_pos_mink"
"""Control mode of the ``panda_awda`` agent: 4-D normalized delta EE position + gripper via mink."""

ENV_PACKAGE = "awda_bench.envs"
"""Package whose import registers the suites' ManiSkill envs."""


def make_env(suite: Suite, *, env_id: str | None = None, render_mode: str | None = None) -> Any:
    """``gymnasium.make`` one of the suite's envs (default: its main ``env_id``): state
    observations, no reward, one env.

    ``render_mode="rgb_array"`` lets :func:`env.render` return frames (videos); rendering is only
    done when asked for.
    """
    if suite.simulator == "metaworld":
        from awda_bench.metaworld.env import MetaWorldEnv

        return MetaWorldEnv(suite, render_mode=render_mode)
    env_id = env_id or suite.env_id
    if ":" not in env_id:
        try:
            importlib.import_module(ENV_PACKAGE)
        except ModuleNotFoundError as exc:
            raise UsageError(
                f"suite {suite.name!r} needs {ENV_PACKAGE} ({exc}); is the package installed?"
            ) from exc
    try:
        return gym.make(
            env_id,
            obs_mode="state",
            control_mode=CONTROL_MODE,
            reward_mode="none",
            num_envs=1,
            render_mode=render_mode,
            render_backend=render_backend(),
            max_episode_steps=suite.horizon_steps,
            disable_env_checker=True,
        )
    except gym.error.Error as exc:
        raise UsageError(f"suite {suite.name!r}: cannot make env {env_id!r} ({exc})") from exc

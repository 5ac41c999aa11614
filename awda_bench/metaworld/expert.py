"""The ``metaworld`` package's scripted policies (``metaworld.policies.ENV_POLICY_MAP``, one per
task) as the ``scripted`` method on Meta-World suites, and as the demonstrator of the demo videos.

They read Meta-World's state observation (hand, gripper, object poses, goal): privileged. The
expert reports ``done`` once the env's per-step success flag was up (the episode's
``success_once`` is already decided; the harness stops early, as it does for the ManiSkill
experts).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from metaworld.policies import ENV_POLICY_MAP

from awda_bench.episode import EpisodeContext

# every policy's move() warns that its gain constants exceed the action range it then clips to
warnings.filterwarnings("ignore", message=r"Constant\(s\) may be too high", category=UserWarning)


def task_policy(task_name: str) -> Any:
    """A fresh scripted policy of task ``task_name``: ``get_action(obs) -> (4,)``."""
    return ENV_POLICY_MAP[task_name]()


def expert_action(policy: Any, obs: np.ndarray) -> np.ndarray:
    """``policy``'s action for Meta-World state ``obs``, ``(1, 4)`` float32 in [-1, 1]."""
    action = np.asarray(policy.get_action(np.asarray(obs, dtype=np.float64)), dtype=np.float32)
    return np.clip(action, -1.0, 1.0).reshape(1, 4)


def scripted_chooser(task_name: str) -> Callable[[np.ndarray], np.ndarray]:
    """A fresh scripted policy of ``task_name`` as a rollout's ``choose``
    (:func:`awda_bench.rollout.roll_out`): Meta-World state -> ``(4,)`` action of one env."""
    policy = task_policy(task_name)
    return lambda obs: expert_action(policy, obs)[0]


class MetaWorldExpert:
    """The scripted policy of the episode's task (``ctx.env`` is a
    :class:`~awda_bench.metaworld.env.MetaWorldEnv`)."""

    name = "scripted"
    privileged = True

    def __init__(self) -> None:
        self._env: Any = None
        self._policy: Any = None

    def reset(self, ctx: EpisodeContext) -> None:
        self._env = ctx.env
        self._policy = task_policy(self._env.task_name)

    def act(self, obs: Any) -> np.ndarray:
        if self._policy is None:
            raise RuntimeError("MetaWorldExpert.act() before reset(ctx)")
        return expert_action(self._policy, obs)

    @property
    def done(self) -> bool:
        return self._env is not None and bool(self._env.last_success)

    @property
    def waypoints(self) -> np.ndarray | None:
        return None

"""The episode protocol: what one episode is, what a policy is handed, the interface it implements.

:class:`EpisodeSpec`, :class:`EpisodeContext` and :class:`Policy` are shared by everything that
plays episodes (the scripted experts, demo recording, the primitives, the evaluated methods, the
harness and the collector), so they sit below all of them and import nothing of the package.

Timeline of one episode (``T = suite.horizon_steps`` control steps)::

    env.reset(seed, task) -> obs_0
    policy.reset(ctx)                       # ctx: env, spec, demo video (rendered lazily)
    for t in 0 .. T-1:
        a_t = policy.act(obs_t)             # (num_envs, 4) in [-1, 1]: dx, dy, dz, grip (>0 closes)
        obs_{t+1}, ... = env.step(a_t)
        stop early if policy.done

Privileged methods (``scripted``, ``gt-waypoints``) may read simulator state through ``ctx.env``;
learned methods must only use ``ctx.demo_frames()``, ``ctx.first_frame()`` and wrist depth.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class EpisodeSpec:
    """One evaluation episode, fixed before any scheduling (so results never depend on workers)."""

    suite: str
    """Suite name."""
    task: int
    """Suite-wide task index; its env receives ``suite.task(task).reset_task`` as
    ``options["task"]`` (the variation, for suites mixing families)."""
    episode: int
    """Episode index within the task (0-based)."""
    seed: int
    """Seed of the agent's scene (``env.reset(seed=seed)``)."""
    demo_seed: int
    """Seed of the demonstrator's scene (a different layout of the same task)."""


@dataclass
class EpisodeContext:
    """What a policy gets at the start of an episode."""

    env: Any
    """The unwrapped ManiSkill env, already reset to ``spec``."""
    spec: EpisodeSpec
    """Which episode this is."""
    extras: dict[str, Any] = field(default_factory=dict)
    """Lazily computed inputs (demo frames, first frame), filled by the harness."""


@runtime_checkable
class Policy(Protocol):
    """A method under evaluation."""

    name: str
    """Method name as used with ``--method``."""

    def reset(self, ctx: EpisodeContext) -> None:
        """Prepare for a new episode (plan, predict waypoints, ...)."""

    def act(self, obs: Any) -> np.ndarray:
        """Return the next action, shape ``(num_envs, 4)``, values in [-1, 1]."""

    @property
    def done(self) -> bool:
        """True once the policy has nothing more to do (the harness may stop the episode)."""

    @property
    def waypoints(self) -> np.ndarray | None:
        """Attributed waypoints ``(K, 3 + k)`` the policy predicted this episode, if any."""

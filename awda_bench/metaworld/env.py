"""A Meta-World suite's tasks behind the harness's env interface (what
:func:`awda_bench.harness.episode_runner.run_episode` calls).

::

    reset(seed=s, options={"task": i})   task i's Meta-World env (built once per process),
                                         layout of seed s (awda_bench.metaworld.layout)
    step(a)                              a: (4,) or (1, 4) in [-1, 1]; Meta-World's own action:
                                         hand (mocap) moves a[:3] x 1 cm, a[3] > 0 closes
    info["success"]                      Meta-World's per-step flag (not sticky: the harness's
                                         success_once is "any step")
    episode_observations(spec, extras)   what an observation-only policy sees

The obs ``reset`` and ``step`` return is Meta-World's 39-number state (with the goal): it reaches
privileged methods only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import EpisodeSpec
from awda_bench.errors import UsageError
from awda_bench.metaworld.layout import make_task_env, reset_to_layout
from awda_bench.metaworld.observations import MetaWorldObservations
from awda_bench.metaworld.renderer import FrameRenderer, process_renderer
from awda_bench.suites import Suite

MAX_PATH_LENGTH = 500
"""Steps after which a Meta-World env refuses to step without a reset (its ``max_path_length``)."""


class MetaWorldEnv:
    """Every task of ``suite``; one task env per task name, built on first use and reused."""

    simulator = "metaworld"
    num_envs = 1

    def __init__(self, suite: Suite, *, render_mode: str | None = None) -> None:
        if suite.horizon_steps > MAX_PATH_LENGTH:
            raise UsageError(
                f"suite {suite.name!r}: horizon {suite.horizon_steps} exceeds Meta-World's "
                f"{MAX_PATH_LENGTH} steps per episode"
            )
        if suite.camera.name is None:
            raise UsageError(f"suite {suite.name!r}: name the third-person camera ([camera] name)")
        self.suite = suite
        self.render_mode = render_mode
        self.renderer: FrameRenderer = process_renderer()
        self._task_envs: dict[str, Any] = {}
        self.task_name: str | None = None
        """The current task's Meta-World name (``None`` before the first reset)."""
        self.seed: int | None = None
        """The current episode's layout seed."""
        self.last_success = False
        """``info["success"]`` of the last step (False after a reset)."""

    @property
    def unwrapped(self) -> MetaWorldEnv:
        return self

    @property
    def task_env(self) -> Any:
        """The current task's ``SawyerXYZEnv`` (its ``model`` and ``data`` are the scene)."""
        if self.task_name is None:
            raise RuntimeError("MetaWorldEnv used before reset()")
        return self._task_envs[self.task_name]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Task ``options["task"]`` (a suite task index) in the layout of ``seed`` (required: an
        unseeded layout would not be reproducible)."""
        if seed is None or options is None or "task" not in options:
            raise UsageError("MetaWorldEnv.reset needs seed= and options={'task': index}")
        name = self.suite.task(int(options["task"])).name
        if name not in self._task_envs:
            self._task_envs[name] = make_task_env(name)
        self.task_name = name
        self.seed = int(seed)
        self.last_success = False
        return reset_to_layout(self._task_envs[name], seed), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = np.clip(np.asarray(action, dtype=np.float32).reshape(-1)[:4], -1.0, 1.0)
        obs, reward, terminated, truncated, info = self.task_env.step(a)
        self.last_success = bool(info.get("success", 0.0))
        return np.asarray(obs, dtype=np.float64), float(reward), terminated, truncated, info

    def episode_observations(
        self, spec: EpisodeSpec, extras: dict[str, Any]
    ) -> MetaWorldObservations:
        return MetaWorldObservations(self, spec, extras)

    def render(self) -> np.ndarray:
        """The third-person frame now, ``(H, W, 3)`` uint8 (videos)."""
        camera = self.suite.camera
        assert camera.name is not None
        env = self.task_env
        frame = self.renderer.capture(
            env.model, env.data, camera.name, height=camera.height, width=camera.width
        )
        assert frame.rgb is not None
        return frame.rgb

    def close(self) -> None:
        for env in self._task_envs.values():
            env.close()
        self._task_envs.clear()
        self.renderer.close()

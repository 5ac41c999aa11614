"""What an observation-only episode shows its policy: :class:`SimObservations`, the harness's
implementation of :class:`awda_bench.episode.Observations` over a live env.

Each call renders (or reads) exactly what it names, through the same functions the policies
called on the env before the boundary (:mod:`awda_bench.robot.cameras`,
:func:`awda_bench.demo_recording.demo_video_frames`), so an observation-only episode renders the
same frames in the same order as before and its record is unchanged. The demonstrator's envs are
built once per process (:data:`DEMO_ENVS`) and the demo videos cached there as before.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import EpisodeSpec, Proprioception, WristDepth
from awda_bench.suites import Suite

DEMO_ENVS: dict[tuple[str, str], Any] = {}
"""Demonstrator envs of this process, one per (env id, embodiment), built on first use."""


def _numpy(value: Any) -> np.ndarray:
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value)


class SimObservations:
    """The observations of one episode of ``spec`` played on ``env`` (an unwrapped ManiSkill env
    with the ``panda_awda`` agent); ``ctx.observations`` and ``act``'s ``obs``."""

    def __init__(self, env: Any, spec: EpisodeSpec, suite: Suite, extras: dict[str, Any]) -> None:
        self._env = env
        self._spec = spec
        self._suite = suite
        self._extras = extras
        self._stepped = False
        self.num_envs = int(getattr(env, "num_envs", 1))

    def mark_stepped(self) -> None:
        """Called by the harness after the first ``env.step``: the first frame is gone."""
        self._stepped = True

    def demo_frames(self, count: int = 10) -> np.ndarray:
        from awda_bench.demo_recording import demo_video_frames

        cached = self._extras.get("demo_frames")
        if cached is not None and len(cached) == count:
            return np.asarray(cached)
        video = demo_video_frames(
            self._suite, self._spec.task, self._spec.demo_seed, DEMO_ENVS, count
        )
        self._extras["demo_frames"] = list(video)
        return video

    def first_frame(self) -> np.ndarray:
        cached = self._extras.get("first_frame")
        if cached is not None:
            return np.asarray(cached)
        if self._stepped:
            raise RuntimeError(
                "first_frame() was first asked for after the episode's first step; "
                "call it in reset(ctx)"
            )
        frame = self.rgb()[0]
        self._extras["first_frame"] = frame
        return frame

    def rgb(self) -> np.ndarray:
        from awda_bench.robot.cameras import capture_rgb

        return capture_rgb(self._env)

    def wrist_depth(self) -> WristDepth:
        from awda_bench.robot.cameras import capture_wrist_depth

        frame = capture_wrist_depth(self._env)
        return WristDepth(frame.depth_m, frame.intrinsic_cv, frame.cam2world_cv)

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        from awda_bench.robot.cameras import camera_params

        return camera_params(self._env)

    def proprio(self) -> Proprioception:
        agent = self._env.agent
        pose = agent.tcp_pose
        return Proprioception(
            tcp_pos=_numpy(pose.p).astype(np.float64).reshape(self.num_envs, 3),
            tcp_quat=_numpy(pose.q).astype(np.float64).reshape(self.num_envs, 4),
            gripper_opening_m=_numpy(agent.gripper_opening_m)
            .astype(np.float64)
            .reshape(self.num_envs),
            qpos=_numpy(agent.robot.get_qpos()).astype(np.float64).reshape(self.num_envs, -1),
        )

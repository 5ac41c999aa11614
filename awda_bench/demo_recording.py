"""Record a scripted demonstration: third-person frames (optional) and the per-step Trajectory.

Used by ``python -m awda_bench demo`` (video + ``.npz``), by the harness (demo videos a one-shot
policy watches) and by ground-truth waypoint extraction (state only, ``frames=False``)::

    env.reset(seed, task)                  frame 0 rendered
    for t in 0 .. T-1:                     frames at t = k, 2k, ... (render_every = k) and the last
        record tcp_pos[t], gripper_opening_m[t], truth[k][t]   (state *before* a_t; k from the
                                                                env's truth_signals(), e.g. "grasp")
        a_t = expert.act(obs_t); env.step(a_t); record actions[t]
        stop once the expert is done (plus settle_steps) or at the suite's horizon

(the loop is the package's one rollout loop, :func:`awda_bench.rollout.roll_out`).
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from awda_bench.episode import EpisodeContext, EpisodeSpec, demo_frame_indices
from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.experts import EMBODIMENT_NAMES, make_expert
from awda_bench.render_device import render_backend
from awda_bench.rollout import SettleAfterDone, roll_out
from awda_bench.suites import Suite, load_suite
from awda_bench.trajectory import Trajectory

EMBODIMENT_UIDS: dict[str, str] = {"agent": "panda_awda", "demonstrator": "awda_demonstrator"}
"""ManiSkill agent uid of each embodiment name."""

THIRD_PERSON = "third_person"
"""Sensor uid of the third-person camera every task declares."""

SETTLE_STEPS = 5
"""Control steps recorded after the expert is done (the released object comes to rest)."""


def make_demo_env(
    suite: Suite | str, embodiment: str = "demonstrator", env_id: str | None = None
) -> Any:
    """One of the suite's envs (default its main ``env_id``) with ``embodiment``'s robot (state
    observations, no reward, one env).

    Build it once and pass it to :func:`record_demo` for every demo: a camera's first capture
    costs seconds (render pipeline build). Suites mixing families use :func:`demo_env_for`.
    """
    import awda_bench.envs  # noqa: F401  (registers the envs and robots)
    from awda_bench.envs.embodiments import embodiment as lookup

    if isinstance(suite, str):
        suite = load_suite(suite)
    if embodiment not in EMBODIMENT_UIDS:
        raise UnknownChoiceError("embodiment", embodiment, EMBODIMENT_NAMES)
    uid = EMBODIMENT_UIDS[embodiment]
    return gym.make(
        env_id or suite.env_id,
        robot_uids=uid,
        control_mode=lookup(uid).control_mode,
        obs_mode="state",
        reward_mode="none",
        num_envs=1,
        max_episode_steps=suite.horizon_steps,
        render_backend=render_backend(),
        sensor_configs={THIRD_PERSON: {"height": suite.camera.height, "width": suite.camera.width}},
    )


def demo_env_for(
    cache: dict[tuple[str, str], Any], suite: Suite, task: int, embodiment: str
) -> Any:
    """The env serving suite task ``task`` for ``embodiment``, built once per (env id, embodiment)
    and kept in ``cache``."""
    key = (suite.env_id_for(task), embodiment)
    if key not in cache:
        cache[key] = make_demo_env(suite, embodiment, env_id=key[0])
    return cache[key]


def _capture(env: Any) -> np.ndarray:
    from awda_bench.robot.cameras import capture_rgb

    return capture_rgb(env, THIRD_PERSON)[0]


def record_demo(
    suite: Suite | str,
    task: int,
    seed: int,
    embodiment: str = "demonstrator",
    render_every: int = 2,
    frames: bool = True,
    env: Any = None,
    fresh_scene: bool = False,
) -> tuple[np.ndarray | None, Trajectory]:
    """Run the scripted expert once; return ``(frames, trajectory)``.

    ``frames`` is ``(F, H, W, 3)`` uint8 (steps listed in ``trajectory.meta["frame_steps"]``) or
    None when ``frames=False``. ``env`` (from :func:`make_demo_env`, same suite and embodiment) is
    reused when given; ``fresh_scene`` rebuilds its scene first (``reconfigure``), so the demo does
    not depend on what the env played before (the evaluation's demos; a collection keeps its
    histories by replay instead, see :class:`awda_bench.data.plan.CollectJob`). The episode ends
    ``SETTLE_STEPS`` after the expert is done, or at the horizon.
    """
    if isinstance(suite, str):
        suite = load_suite(suite)
    suite.task(task)  # unknown task -> UnknownChoiceError
    if render_every < 1:
        raise UsageError(f"render_every must be >= 1, got {render_every}")
    env_id = suite.env_id_for(task)
    if env is None:
        env = make_demo_env(suite, embodiment, env_id=env_id)
    base = env.unwrapped
    if base.robot_uids != EMBODIMENT_UIDS.get(embodiment):
        raise UsageError(f"env has robot {base.robot_uids!r}, not the {embodiment!r} embodiment")
    if env.spec is not None and env.spec.id != env_id:
        raise UsageError(
            f"task {task} of suite {suite.name!r} runs in {env_id}, not in {env.spec.id}"
        )
    expert = make_expert(suite.name, embodiment)
    obs, info = env.reset(
        seed=seed, options={"task": suite.task(task).reset_task, "reconfigure": fresh_scene}
    )
    spec = EpisodeSpec(suite=suite.name, task=task, episode=0, seed=seed, demo_seed=seed)
    expert.reset(EpisodeContext(env=base, spec=spec))

    tcp, opening, actions = [], [], []
    truth: dict[str, list[bool]] = {}
    images: list[np.ndarray] = []
    frame_steps: list[int] = []

    def record_state(t: int) -> None:
        if frames and t % render_every == 0:
            images.append(_capture(env))
            frame_steps.append(t)
        tcp.append(base.agent.tcp_pose.p[0].cpu().numpy())
        opening.append(float(base.gripper_opening_m()[0]))
        for name, value in base.truth_signals().items():
            truth.setdefault(name, []).append(bool(value[0]))

    def record_action(steps_taken: int, action: Any, info_t: dict[str, Any]) -> bool:
        actions.append(np.asarray(action[0], dtype=np.float32))
        return settle(steps_taken, action, info_t)

    settle = SettleAfterDone(expert, SETTLE_STEPS)
    info = roll_out(
        env.step,
        obs,
        expert.act,
        suite.horizon_steps,
        info=info,
        before_step=record_state,
        after_step=record_action,
    ).info
    steps = len(actions)
    if frames and (not frame_steps or frame_steps[-1] != steps):
        images.append(_capture(env))
        frame_steps.append(steps)

    trajectory = Trajectory(
        tcp_pos=np.asarray(tcp, dtype=np.float64).reshape(steps, 3),
        gripper_opening_m=np.asarray(opening, dtype=np.float64),
        actions=np.asarray(actions, dtype=np.float32).reshape(steps, 4),
        truth={name: np.asarray(values, dtype=bool) for name, values in truth.items()},
        meta={
            "suite": suite.name,
            "task": task,
            "seed": seed,
            "embodiment": embodiment,
            "robot_uid": base.robot_uids,
            "control_freq_hz": suite.control_freq_hz,
            "max_step_m": base.embodiment.max_step_m,
            "steps": steps,
            "expert_done": expert.done,
            "success": bool(info["success"][0]),
            "success_once": bool(info["success_once"][0]),
            # tasks without a grasp target do not report the grasp analysis
            "reached": bool(info["reached"][0]) if "reached" in info else None,
            "grasped": bool(info["grasped"][0]) if "grasped" in info else None,
            "frame_steps": frame_steps,
        },
    )
    return (np.stack(images) if frames else None), trajectory


DEMO_FRAMES = 10
"""Frames of a demonstration video a one-shot policy watches (first and last included; SPEC §6)."""


def demo_video_frames(
    suite: Suite,
    task: int,
    demo_seed: int,
    envs: dict[tuple[str, str], Any],
    count: int = DEMO_FRAMES,
    render_every: int = 4,
) -> np.ndarray:
    """The demonstrator's video of ``(task, demo_seed)`` subsampled to ``count`` frames
    ``(count, H, W, 3)`` uint8, first and last included (:func:`demo_frame_indices`). ``envs`` caches the demo envs.

    Each demo is recorded in a rebuilt scene (``fresh_scene``), so it is the same whichever
    worker records it and whatever that worker recorded before. The last
    :data:`DEMO_VIDEO_CACHE_SIZE` videos are kept per process: a learned method's snapshots are
    evaluated on the same episodes, so the demonstrator runs once per episode instead of once
    per snapshot.
    """
    key = (suite.name, str(suite.path), task, demo_seed, count, render_every)
    cached = _DEMO_VIDEOS.get(key)
    if cached is not None:
        _DEMO_VIDEOS.move_to_end(key)
        return cached.copy()
    env = demo_env_for(envs, suite, task, "demonstrator")
    frames, _ = record_demo(
        suite, task, demo_seed, render_every=render_every, env=env, fresh_scene=True
    )
    assert frames is not None
    video = frames[demo_frame_indices(len(frames) - 1, count)]
    _DEMO_VIDEOS[key] = video
    while len(_DEMO_VIDEOS) > DEMO_VIDEO_CACHE_SIZE:
        _DEMO_VIDEOS.popitem(last=False)
    return video.copy()


DEMO_VIDEO_CACHE_SIZE = 64
"""Demo videos :func:`demo_video_frames` keeps per process (10 frames of 240x320: ~2.3 MB each)."""

_DEMO_VIDEOS: OrderedDict[tuple[object, ...], np.ndarray] = OrderedDict()


def clear_demo_video_cache() -> None:
    """Forget every cached demo video (benchmarks time the recording)."""
    _DEMO_VIDEOS.clear()


def save_video(frames: np.ndarray, path: str | Path, fps: float) -> Path:
    """Write RGB ``frames`` (F, H, W, 3) uint8 to an MP4 file (OpenCV, ``mp4v``)."""
    import cv2

    path = Path(path)
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0:
        raise UsageError(f"frames must be (F, H, W, 3) with F >= 1, got {frames.shape}")
    path.parent.mkdir(parents=True, exist_ok=True)
    height, width = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, (width, height))
    if not writer.isOpened():
        raise UsageError(f"cannot open {path} for writing an MP4 video")
    try:
        for frame in frames:
            writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    finally:
        writer.release()
    return path

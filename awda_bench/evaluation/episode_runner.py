"""Play one episode: reset the env to a spec, step it with ``policy.act`` through the package's one
rollout loop (:func:`awda_bench.rollout.roll_out`), judge it.

::

    env.reset(seed=spec.seed, options={"task": spec.task, "reconfigure": True})     t = 0
    policy.reset(ctx)       ctx.env only for a privileged policy; else ctx.observations
    a_t = policy.act(obs_t); obs_{t+1}, info_{t+1} = env.step(a_t)   t = 0 .. T-1
        obs_t: the env's state (privileged policy) or the episode's Observations
        stop after T = suite.horizon_steps steps, or once policy.done
    success_once   = any_t info_t["success"]      success_at_end = info_T["success"]
    reached/grasped = info_T["reached"/"grasped"] (the envs latch them), None if absent
    first_grip     = env.grip_outcome(a_t) at the first t whose a_t closes the gripper
                     (before that step), "never" if none does, None if the task does not tell
    carry, release_xy_m, release_dz_m = what became of a grasped target on a task with a place
                     goal (:mod:`awda_bench.evaluation.carry`), None elsewhere; place_goal
                     = that goal at the start

Every episode starts in a freshly built scene (``reconfigure``, ~0.2 s on pick-place): PhysX
carries contact caches and solver state from one episode of a scene into the next, and
resetting poses does not clear them all. Played second in a reused env, an episode ended
~3e-3 away (in the flat env state) from the same episode played first, and 4 of 400 Full-1
outcomes changed with the worker count. Rebuilt, the two are identical, so an episode's record
depends on its spec alone, not on the worker that played it or what that worker played before.

Exceptions are *not* caught here: the worker records them as errors with their traceback.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from awda_bench.episode import (
    GRIP_OUTCOMES,
    NEVER_GRIPPED,
    EpisodeContext,
    EpisodeSpec,
    Observations,
    Policy,
    is_privileged,
    seed_globals,
)
from awda_bench.evaluation.carry import CarryTally
from awda_bench.evaluation.episode_record import STATUS_OK, EpisodeRecord
from awda_bench.evaluation.observations import SimObservations
from awda_bench.rollout import roll_out
from awda_bench.suites import Suite

FrameHook = Callable[[Any], None]
"""Called with the env after reset and after every step (video capture); ``None`` for none."""


def info_flag(info: dict[str, Any], key: str) -> bool | None:
    """``info[key]`` of env 0 as a bool (tensors, arrays and scalars alike); ``None`` if absent."""
    if key not in info:
        return None
    value = info[key]
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return bool(np.asarray(value).reshape(-1)[0])


def fresh_scene_options(suite: Suite, task: int) -> dict[str, Any]:
    """``env.reset`` options that start suite task ``task`` in a rebuilt scene (no PhysX history)."""
    return {"task": suite.task(task).reset_task, "reconfigure": True}


class HarnessObservations(Observations, Protocol):
    """An episode's observations as the harness holds them: told when the first step is done
    (``first_frame`` is gone after it)."""

    def mark_stepped(self) -> None: ...


def episode_observations(
    env: Any, spec: EpisodeSpec, suite: Suite, extras: dict[str, Any]
) -> HarnessObservations:
    """What an observation-only policy sees of the episode on ``env`` (unwrapped): the env's own
    ``episode_observations(spec, extras)`` where it has one (Meta-World), else
    :class:`SimObservations` over the ManiSkill env."""
    own = getattr(env, "episode_observations", None)
    if own is not None:
        observations: HarnessObservations = own(spec, extras)
        return observations
    return SimObservations(env, spec, suite, extras)


@dataclass
class _Tally:
    """What an episode's steps add up to (module docstring)."""

    success_now: bool
    success_once: bool = False
    first_grip: str | None = None


def run_episode(
    env: Any,
    policy: Policy,
    spec: EpisodeSpec,
    suite: Suite,
    *,
    method: str,
    snapshot: str,
    on_frame: FrameHook | None = None,
    extras: dict[str, Any] | None = None,
) -> EpisodeRecord:
    """Play ``spec`` with ``policy`` on ``env`` and return its record (status ok).

    ``extras`` becomes ``ctx.extras`` (the caller keeps the dict to read what the policy left there,
    e.g. ``"demo_frames"``).
    """
    t_start = time.perf_counter()
    seed_globals(spec.seed)
    obs, info = env.reset(seed=spec.seed, options=fresh_scene_options(suite, spec.task))
    env_time = time.perf_counter() - t_start
    if on_frame is not None:
        on_frame(env)
    t0 = time.perf_counter()
    extras = {} if extras is None else extras
    observations = episode_observations(env.unwrapped, spec, suite, extras)
    privileged = is_privileged(policy)
    policy.reset(
        EpisodeContext(
            env=env.unwrapped if privileged else None,
            spec=spec,
            extras=extras,
            observations=observations,
            method=method,
        )
    )
    act_time = time.perf_counter() - t0

    grip_outcome = getattr(env.unwrapped, "grip_outcome", None)
    tells_grip = grip_outcome is not None and env.unwrapped.object_distances() is not None
    tally = _Tally(
        success_now=bool(info_flag(info, "success")),
        first_grip=NEVER_GRIPPED if tells_grip else None,
    )
    carry = CarryTally.for_env(env.unwrapped)

    def choose(obs_t: Any) -> Any:
        if policy.done:
            return None
        action = policy.act(obs_t if privileged else observations)
        if tally.first_grip == NEVER_GRIPPED and grip_outcome is not None:
            outcome = grip_outcome(action)
            if outcome is not None and int(outcome[0]) >= 0:
                tally.first_grip = GRIP_OUTCOMES[int(outcome[0])]
        return action

    def after_step(_steps: int, action: Any, info_t: dict[str, Any]) -> bool:
        observations.mark_stepped()
        tally.success_now = bool(info_flag(info_t, "success"))
        tally.success_once = tally.success_once or tally.success_now
        if carry is not None:
            carry.after_step(action, info_flag(info_t, "grasped"))
        if on_frame is not None:
            on_frame(env)
        return False

    end = roll_out(env.step, obs, choose, suite.horizon_steps, info=info, after_step=after_step)
    info = end.info

    grasped = info_flag(info, "grasped")
    release = None if carry is None else carry.release
    waypoints = policy.waypoints
    server_notes = getattr(policy, "server_notes", None)  # a served policy's (openpi)
    return EpisodeRecord(
        suite=spec.suite,
        task=spec.task,
        family=suite.task(spec.task).family,
        episode=spec.episode,
        seed=spec.seed,
        demo_seed=spec.demo_seed,
        method=method,
        snapshot=snapshot,
        status=STATUS_OK,
        success_once=tally.success_once,
        success_at_end=tally.success_now,
        reached=info_flag(info, "reached"),
        grasped=grasped,
        first_grip=tally.first_grip,
        carry=None if carry is None else carry.outcome(grasped, tally.success_once),
        release_xy_m=None if release is None else release.xy_m,
        release_dz_m=None if release is None else release.dz_m,
        place_goal=None if carry is None else carry.goal,
        steps=end.steps,
        wall_time_s=time.perf_counter() - t_start,
        act_time_s=act_time + end.choose_s,
        env_time_s=env_time + end.step_s,
        waypoints=None if waypoints is None else np.asarray(waypoints, dtype=float).tolist(),
        server=None if server_notes is None else dict(server_notes),
    )

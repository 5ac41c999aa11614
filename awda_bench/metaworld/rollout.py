"""The package's scripted policy played from a task env's current state, as a recorded
trajectory: what ``gt-waypoints`` plans with (:mod:`awda_bench.metaworld.gt_scene`, which then
restores the start) and what ``collect`` records (:mod:`awda_bench.data.metaworld_recorder`,
which renders a frame at every state through ``before_step``).

::

    t = 1, 2, ...:  before_step(t - 1)         the state before action t - 1 (hook: frames)
                    state t - 1: TCP, finger distance
                    a = expert(obs); env.step(a)
                    command t - 1 = tracking_command(TCP, mocap after the step, offset)
    stop AFTER_SUCCESS_STEPS past the first success, or after max_steps
    (the package's one rollout loop, :func:`awda_bench.rollout.roll_out`)

The env is left in its last state (state T, where T actions were taken).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.metaworld.expert import scripted_chooser
from awda_bench.metaworld.sawyer import robot_state, tracking_command
from awda_bench.rollout import roll_out
from awda_bench.trajectory import Trajectory

AFTER_SUCCESS_STEPS = 5
"""A rollout runs this many steps past the expert's first success (the reference truncated its
Meta-World demonstrations 5 frames after the first success): the last waypoint is then inside
the success region, not on its edge."""


@dataclass
class ExpertRollout:
    """One played rollout of the scripted expert."""

    trajectory: Trajectory
    """States 0..T-1 and the expert's commands in the primitives' action space:
    ``actions[:, :3]`` the expert's mocap targets as tracking commands
    (:func:`~awda_bench.metaworld.sawyer.tracking_command` with the hand's offset),
    ``actions[:, 3]`` its gripper commands. ``meta``: ``expert_done``, ``steps``,
    ``success_step`` (1-based step of the first success, 0 if none)."""
    env_actions: np.ndarray
    """``(T, 4)`` float32: the actions Meta-World was stepped with (its own action space: the
    mocap moves ``a[:3] x 1 cm``, ``a[3] > 0`` closes)."""
    success: np.ndarray
    """``(T,)`` bool: Meta-World's per-step ``info["success"]`` after each action."""
    success_step: int
    """The step (1-based) of the first success, 0 if none."""


def expert_rollout(
    task_env: Any,
    task_name: str,
    max_steps: int,
    offset: np.ndarray,
    before_step: Callable[[int], None] | None = None,
) -> ExpertRollout:
    """The package's scripted policy of ``task_name`` from ``task_env``'s current state (module
    docstring); ``offset`` is the hand's ``mocap - tcp`` at rest
    (:func:`~awda_bench.metaworld.sawyer.mocap_offset`)."""
    obs = np.asarray(
        task_env._last_stable_obs if task_env.curr_path_length else task_env._get_obs()
    )
    tcp, opening, actions, env_actions, success = [], [], [], [], []
    success_step = 0

    def record_state(t: int) -> None:
        if before_step is not None:
            before_step(t)
        state = robot_state(task_env)
        tcp.append(state.tcp_pos)
        opening.append(state.gripper_opening_m)

    def record_step(t: int, action: np.ndarray, info: dict[str, Any]) -> bool:
        nonlocal success_step
        command = tracking_command(tcp[-1], task_env.data.mocap_pos[0], offset)
        actions.append([*command, action[3]])
        env_actions.append(action)
        success.append(bool(info.get("success", 0.0)))
        if success[-1] and not success_step:
            success_step = t
        return bool(success_step) and t >= success_step + AFTER_SUCCESS_STEPS

    roll_out(
        task_env.step,
        obs,
        scripted_chooser(task_name),
        max_steps,
        before_step=record_state,
        after_step=record_step,
    )
    trajectory = Trajectory(
        tcp_pos=np.asarray(tcp, dtype=np.float64),
        gripper_opening_m=np.asarray(opening, dtype=np.float64),
        actions=np.asarray(actions, dtype=np.float32),
        truth={},
        meta={"expert_done": success_step > 0, "steps": len(actions), "success_step": success_step},
    )
    return ExpertRollout(
        trajectory=trajectory,
        env_actions=np.asarray(env_actions, dtype=np.float32).reshape(-1, 4),
        success=np.asarray(success, dtype=bool),
        success_step=success_step,
    )

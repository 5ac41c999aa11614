"""Trajectory synthesis on Meta-World (SPEC §6 TS, the method's §4.2): the Sawyer's hand driven
open through 1-3 random waypoints in a task's scene, what ``collect --synthesize N`` records on the
Meta-World suites (:mod:`awda_bench.data.metaworld_recorder`).

::

    waypoints      1-3 points drawn uniformly in the suite's box (SynthesisConfig.draw_waypoints,
                   data.config.METAWORLD_SYNTHESIS) with the attempt's seed (the layout's too)
    t = 0, 1, ...: before_step(t)                 the state before action t (hook: frames)
                   command = the free-space primitive toward the current waypoint (hand open;
                             SAWYER_EXECUTOR's motion: 1 cm steps, 2 mm tolerance, 120-step budget)
                   env.step(mocap_action(command))  (awda_bench.metaworld.sawyer: the mocap leads
                                                     the TCP by G x the command, as gt-waypoints
                                                     and awda drive the Sawyer)
    after the last waypoint: settle_steps zero-motion steps, then stop

The recorded commands are put in the primitives' action space exactly as the experts' are
(:func:`~awda_bench.metaworld.sawyer.tracking_command` of the mocap after each step), and the env's
own actions are kept for T-OSVI, so a synthesized file is read like an expert's. An episode is kept
when every waypoint was reached within the motion's budget (a fixture in the way, or a fixture the
hand moved, leaves it short: discarded).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from awda_bench.metaworld.rollout import ExpertRollout
from awda_bench.metaworld.sawyer import (
    SAWYER_EXECUTOR,
    mocap_action,
    mocap_offset,
    robot_state,
    tracking_command,
)
from awda_bench.primitives.waypoint_tour import WaypointTour
from awda_bench.rollout import roll_out
from awda_bench.trajectory import Trajectory


@dataclass
class SynthesizedRollout:
    """One played synthesized trajectory."""

    rollout: ExpertRollout
    """The recorded states, commands and env actions, as an expert's rollout holds them
    (``success``: Meta-World's flag, which a synthesized motion may raise by chance)."""
    waypoints: np.ndarray
    """``(K, 3)`` the drawn waypoints [m], K in 1..3."""
    reached: list[bool]
    """Whether each waypoint's motion ended within its tolerance."""


def synthesized_rollout(
    task_env: Any,
    waypoints: np.ndarray,
    max_steps: int,
    settle_steps: int,
    before_step: Callable[[int], None] | None = None,
) -> SynthesizedRollout:
    """Drive ``task_env``'s hand (at rest, just reset) open through ``waypoints`` (module
    docstring); stops after ``max_steps`` actions at most. The env is left in its last state."""
    offset = mocap_offset(task_env)
    tour = WaypointTour(waypoints, SAWYER_EXECUTOR.motion, settle_steps)
    tcp, opening, actions, success = [], [], [], []
    env_actions: list[np.ndarray] = []

    def choose(_obs: Any) -> np.ndarray | None:
        state = robot_state(task_env)
        command = tour.step(state)
        if command is None:
            return None
        if before_step is not None:
            before_step(len(env_actions))
        tcp.append(state.tcp_pos)
        opening.append(state.gripper_opening_m)
        return mocap_action(task_env, command, offset)

    def record_step(_t: int, action: np.ndarray, info: dict[str, Any]) -> bool:
        command = tracking_command(tcp[-1], task_env.data.mocap_pos[0], offset)
        actions.append([*command, action[3]])
        env_actions.append(action)
        success.append(bool(info.get("success", 0.0)))
        return False

    roll_out(task_env.step, None, choose, max_steps, after_step=record_step)
    flags = np.asarray(success, dtype=bool)
    first = int(np.argmax(flags)) + 1 if flags.any() else 0
    trajectory = Trajectory(
        tcp_pos=np.asarray(tcp, dtype=np.float64).reshape(-1, 3),
        gripper_opening_m=np.asarray(opening, dtype=np.float64),
        actions=np.asarray(actions, dtype=np.float32).reshape(-1, 4),
        truth={},
        meta={"expert_done": False, "steps": len(actions), "success_step": first},
    )
    rollout = ExpertRollout(
        trajectory=trajectory,
        env_actions=np.asarray(env_actions, dtype=np.float32).reshape(-1, 4),
        success=flags,
        success_step=first,
    )
    return SynthesizedRollout(rollout, np.asarray(waypoints), tour.reached)

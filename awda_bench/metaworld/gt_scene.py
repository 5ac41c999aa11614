"""What ``gt-waypoints`` (:class:`awda_bench.policies.gt_waypoints.GTWaypointsPolicy`) needs of a
Meta-World episode: the expert's plan from the real start, the Sawyer's state, its wrist
localizer, and its actions.

::

    plan:     S = save_state(task env)                      the real start (.state)
              the package's scripted policy from S, to its first success (or planning_steps),
              recording TCP, finger distance, actions       -> Trajectory
              restore_state(task env, S)                    bit-identical to S
    act:      primitives' (4,) command -> mocap action      (SawyerInterface, as for awda)
    grasp:    gripperPOV wrist depth (128 x 128) -> localize_object, as on ManiSkill

The planning rollout steps the task env itself, not :class:`~awda_bench.metaworld.env.MetaWorldEnv`
(whose ``last_success`` it must not set).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from awda_bench.episode import EpisodeContext
from awda_bench.metaworld.expert import expert_action, task_policy
from awda_bench.metaworld.sawyer import SAWYER_GRASP_MINING, robot_state, tracking_command
from awda_bench.metaworld.sawyer_interface import SawyerInterface
from awda_bench.metaworld.state import restore_state, save_state
from awda_bench.primitives.base import RobotState
from awda_bench.primitives.config import LocalizationConfig
from awda_bench.primitives.wrist_camera import WristLocator
from awda_bench.trajectory import Trajectory

AFTER_SUCCESS_STEPS = 5
"""The plan runs this many steps past the expert's first success (the reference truncated its
Meta-World demonstrations 5 frames after the first success): the last waypoint is then inside
the success region, not on its edge."""


def expert_trajectory(
    task_env: Any, task_name: str, max_steps: int, offset: np.ndarray
) -> Trajectory:
    """The package's scripted policy of ``task_name`` from ``task_env``'s current state, to
    :data:`AFTER_SUCCESS_STEPS` past its first success, or ``max_steps``; ``task_env`` is restored
    to that state afterwards.

    ``actions[:, :3]`` are the expert's mocap targets as the primitives' commands
    (:func:`~awda_bench.metaworld.sawyer.tracking_command` with the hand's ``offset``),
    ``actions[:, 3]`` its gripper commands. ``meta["success_step"]``: the step (1-based) of the
    first success, 0 if none."""
    start = save_state(task_env)
    policy = task_policy(task_name)
    obs = np.asarray(
        task_env._last_stable_obs if task_env.curr_path_length else task_env._get_obs()
    )
    tcp, opening, actions = [], [], []
    success_step = 0
    for t in range(1, max_steps + 1):
        state = robot_state(task_env)
        tcp.append(state.tcp_pos)
        opening.append(state.gripper_opening_m)
        action = expert_action(policy, obs)[0]
        obs, _reward, _terminated, _truncated, info = task_env.step(action)
        command = tracking_command(state.tcp_pos, task_env.data.mocap_pos[0], offset)
        actions.append([*command, action[3]])
        if info.get("success", 0.0) and not success_step:
            success_step = t
        if success_step and t >= success_step + AFTER_SUCCESS_STEPS:
            break
    restore_state(task_env, start)
    return Trajectory(
        tcp_pos=np.asarray(tcp, dtype=np.float64),
        gripper_opening_m=np.asarray(opening, dtype=np.float64),
        actions=np.asarray(actions, dtype=np.float32),
        truth={},
        meta={"expert_done": success_step > 0, "steps": len(actions), "success_step": success_step},
    )


class MetaWorldScene:
    """``gt-waypoints``' view of one Meta-World episode (``ctx.env`` a ``MetaWorldEnv``): the
    package's expert plans on the task env; executing is the Sawyer's
    :class:`~awda_bench.metaworld.sawyer_interface.SawyerInterface`, which ``awda`` drives too."""

    def __init__(self, ctx: EpisodeContext) -> None:
        self.env = ctx.env
        self.robot = SawyerInterface(self.env.episode_observations(ctx.spec, ctx.extras))
        """The Sawyer as the primitives drive it (its mocap offset measured now, at rest)."""

    def configure(self, config: Any) -> Any:
        """``config`` (a ``GTWaypointsConfig``) with the Sawyer's executor, mining and
        localization parameters (:mod:`awda_bench.metaworld.sawyer`) in place of the Panda's;
        the method's own choices (K, the planning budget, the grasp's component rule) kept.

        One attribute, grasp (the reference's on Meta-World): the pressing miner (with
        Meta-World's 1 cm step: ``PressMiningConfig(max_step_m=0.01, min_command_m=0.002)``)
        fires where the hand meets a
        lever it then pushes along (door-unlock, window-open), and the press primitive's retract
        there took the hand off it: 6 seeds each, door-unlock 4/6 with the press attribute,
        6/6 without; window-open 6/6 both; the other three unchanged (none has a press mined
        where it matters: button-press's button moves with the hand, so it never reads as
        blocked)."""
        return replace(
            config,
            executor=self.robot.executor_config(config.executor),
            mining=SAWYER_GRASP_MINING,
            press_mining=None,
            localization=self.robot.localization_config(config.localization),
            record_truth=False,
        )

    def plan(self, max_steps: int) -> list[Trajectory]:
        task_env = self.env.task_env
        return [expert_trajectory(task_env, self.env.task_name, max_steps, self.robot.offset)]

    def robot_states(self) -> list[RobotState]:
        return self.robot.robot_states()

    def locator(self, env_index: int, config: LocalizationConfig) -> WristLocator:
        return self.robot.locator(env_index, config)

    def env_actions(self, actions: np.ndarray) -> np.ndarray:
        """The primitives' ``(1, 4)`` commands as Meta-World's actions."""
        return self.robot.env_actions(actions)

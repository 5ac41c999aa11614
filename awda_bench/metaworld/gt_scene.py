"""What ``gt-waypoints`` (:class:`awda_bench.policies.gt_waypoints.GtWaypointsPolicy`) needs of a
Meta-World episode: the expert's plan from the real start, the Sawyer's state, its wrist
localizer, and its actions.

::

    plan:     S = save_state(task env)                      the real start (.state)
              the package's scripted policy from S, 5 steps past its first success (or
              planning_steps), recording TCP, finger distance, actions (.rollout) -> Trajectory
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
from awda_bench.metaworld.rollout import AFTER_SUCCESS_STEPS, expert_rollout
from awda_bench.metaworld.sawyer import SAWYER_GRASP_MINING
from awda_bench.metaworld.sawyer_interface import SawyerInterface
from awda_bench.metaworld.state import restore_state, save_state
from awda_bench.primitives.base import RobotState
from awda_bench.primitives.config import LocalizationConfig
from awda_bench.primitives.wrist_camera import WristLocator
from awda_bench.trajectory import Trajectory

__all__ = ["AFTER_SUCCESS_STEPS", "MetaWorldScene", "expert_trajectory"]


def expert_trajectory(
    task_env: Any, task_name: str, max_steps: int, offset: np.ndarray
) -> Trajectory:
    """The package's scripted policy of ``task_name`` from ``task_env``'s current state, to
    :data:`~awda_bench.metaworld.rollout.AFTER_SUCCESS_STEPS` past its first success, or
    ``max_steps`` (:func:`~awda_bench.metaworld.rollout.expert_rollout`, whose trajectory it
    returns); ``task_env`` is restored to that state afterwards."""
    start = save_state(task_env)
    rollout = expert_rollout(task_env, task_name, max_steps, offset)
    restore_state(task_env, start)
    return rollout.trajectory


class MetaWorldScene:
    """``gt-waypoints``' view of one Meta-World episode (``ctx.env`` a ``MetaWorldEnv``): the
    package's expert plans on the task env; executing is the Sawyer's
    :class:`~awda_bench.metaworld.sawyer_interface.SawyerInterface`, which ``awda`` drives too."""

    def __init__(self, ctx: EpisodeContext) -> None:
        self.env = ctx.env
        self.robot = SawyerInterface(self.env.episode_observations(ctx.spec, ctx.extras))
        """The Sawyer as the primitives drive it (its mocap offset measured now, at rest)."""

    def configure(self, config: Any) -> Any:
        """``config`` (a ``GtWaypointsConfig``) with the Sawyer's executor, mining and
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

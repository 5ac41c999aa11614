"""What a method that executes waypoints with the motor primitives needs of the robot it drives,
read through an observation-only episode's :class:`~awda_bench.episode.Observations`.

::

    executor_config(method's)      the executor parameters the episode runs with
    localization_config(method's)  the grasp's wrist-depth localization settings
    robot_states()                 per env, the primitives' view of the robot now
    locator(i, config)             the grasp primitive's wrist-depth localizer of env i
    env_actions(commands)          the primitives' (n, 4) commands as the env's actions

:func:`robot_interface_of` picks the robot: the observations' own ``robot_interface()`` where they
have one (Meta-World's Sawyer: :class:`awda_bench.metaworld.sawyer_interface.SawyerInterface`),
else :class:`ObservedPanda`, the ManiSkill suites' ``panda_awda``, whose parameters are the
executor's defaults and whose actions are the primitives' commands as they are.

``gt-waypoints`` reads the same through its privileged *scene*
(:class:`awda_bench.policies.gt_waypoints.Scene`), which on Meta-World delegates to the same
:class:`~awda_bench.metaworld.sawyer_interface.SawyerInterface`.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from awda_bench.episode import Observations
from awda_bench.primitives.base import RobotState
from awda_bench.primitives.config import ExecutorConfig, LocalizationConfig
from awda_bench.primitives.wrist_camera import WristLocator


class RobotInterface(Protocol):
    """The robot of one episode as the waypoint executor's caller drives it."""

    def executor_config(self, method: ExecutorConfig) -> ExecutorConfig:
        """The executor parameters to run with: this robot's own, or ``method``'s where the
        method's are this robot's (the Panda)."""

    def localization_config(self, method: LocalizationConfig) -> LocalizationConfig:
        """The wrist-depth localization to run with (this robot's camera; ``method.select``, the
        grasp's component rule, kept)."""

    def robot_states(self) -> list[RobotState]:
        """Per env, the primitives' view of the robot now."""

    def locator(self, env_index: int, config: LocalizationConfig) -> WristLocator:
        """The grasp primitive's wrist-depth localizer of env ``env_index``."""

    def env_actions(self, actions: np.ndarray) -> np.ndarray:
        """The primitives' ``(n, 4)`` commands as the env's ``(n, 4)`` actions."""


class ObservedPanda:
    """``panda_awda`` (the ManiSkill suites' agent) read through ``observations``: the TCP and
    opening from ``proprio()``, the grasp localizing in ``wrist_depth()``; its controller takes
    the primitives' commands as actions."""

    def __init__(self, observations: Observations) -> None:
        self._observations = observations

    def executor_config(self, method: ExecutorConfig) -> ExecutorConfig:
        return method

    def localization_config(self, method: LocalizationConfig) -> LocalizationConfig:
        return method

    def robot_states(self) -> list[RobotState]:
        proprio = self._observations.proprio()
        return [
            RobotState(tcp_pos=tcp, gripper_opening_m=float(opening))
            for tcp, opening in zip(proprio.tcp_pos, proprio.gripper_opening_m, strict=True)
        ]

    def locator(self, env_index: int, config: LocalizationConfig) -> WristLocator:
        observations = self._observations
        return WristLocator(
            None,
            env_index=env_index,
            config=config,
            capture=lambda _env: observations.wrist_depth(),
        )

    def env_actions(self, actions: np.ndarray) -> np.ndarray:
        return actions


def robot_interface_of(observations: Observations) -> RobotInterface:
    """The robot ``observations`` belong to: their own ``robot_interface()`` where they have one
    (Meta-World's Sawyer), else :class:`ObservedPanda`."""
    own = getattr(observations, "robot_interface", None)
    if own is not None:
        robot: RobotInterface = own()
        return robot
    return ObservedPanda(observations)

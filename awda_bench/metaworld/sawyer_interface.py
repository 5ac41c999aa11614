"""Meta-World's Sawyer as the motor primitives' robot in one episode
(:class:`awda_bench.primitives.robot_interface.RobotInterface`), read through the episode's
observations: what ``awda`` drives, and what ``gt-waypoints``' Meta-World scene
(:class:`awda_bench.metaworld.gt_scene.MetaWorldScene`) delegates its execution to.

::

    robot_states()      TCP and finger distance from proprio()        (sawyer.robot_state)
    env_actions(c)      lead_action(tcp, hand_target, c, offset)      (sawyer: the mocap leads the
                                                                       TCP by G x the command)
    locator(i, config)  gripperPOV wrist depth from wrist_depth()
    executor_config     SAWYER_EXECUTOR; localization_config: SAWYER_LOCALIZATION (the method's
                        component rule kept)

``offset`` (the mocap's place relative to the TCP at rest, :func:`~awda_bench.metaworld.sawyer.
mocap_offset`) is measured when the interface is built: build it with the hand at rest in the
episode's layout (after reset, and after the demo has been played and the layout restored).

Deviation from the ManiSkill suites' observation-only boundary: the conversion reads the mocap
target (``hand_target()``), the Sawyer's position set-point. It is the robot's own command
(the counterpart of the ``panda_awda`` controller's TCP target, which that agent keeps
internally), not the scene's state.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Protocol

import numpy as np

from awda_bench.episode import Proprioception, WristDepth
from awda_bench.metaworld.sawyer import SAWYER_EXECUTOR, SAWYER_LOCALIZATION, lead_action
from awda_bench.primitives.base import RobotState
from awda_bench.primitives.config import ExecutorConfig, LocalizationConfig
from awda_bench.primitives.wrist_camera import WristLocator


class HandView(Protocol):
    """What the interface reads of the Sawyer (:class:`~awda_bench.metaworld.observations.
    MetaWorldObservations`)."""

    def proprio(self) -> Proprioception: ...

    def hand_target(self) -> np.ndarray:
        """``(1, 3)`` the mocap target the hand is welded to [m]."""
        ...

    def wrist_depth(self) -> WristDepth: ...


class SawyerInterface:
    """The Sawyer of one Meta-World episode (one env) as the primitives drive it."""

    def __init__(self, view: HandView) -> None:
        self._view = view
        self.offset: np.ndarray = view.hand_target()[0] - view.proprio().tcp_pos[0]
        """``o = mocap - tcp`` [m] when built (the hand at rest)."""

    def executor_config(self, method: ExecutorConfig) -> ExecutorConfig:
        """:data:`~awda_bench.metaworld.sawyer.SAWYER_EXECUTOR` (1 cm steps at 80 Hz, budgets
        doubled, 2 mm reach tolerance, free motions with the hand open), whatever ``method``'s."""
        return SAWYER_EXECUTOR

    def localization_config(self, method: LocalizationConfig) -> LocalizationConfig:
        """:data:`~awda_bench.metaworld.sawyer.SAWYER_LOCALIZATION` (the hand masked by depth)
        with ``method``'s component rule (``select``)."""
        return replace(SAWYER_LOCALIZATION, select=method.select)

    def robot_states(self) -> list[RobotState]:
        proprio = self._view.proprio()
        return [
            RobotState(
                tcp_pos=proprio.tcp_pos[0], gripper_opening_m=float(proprio.gripper_opening_m[0])
            )
        ]

    def locator(self, env_index: int, config: LocalizationConfig) -> WristLocator:
        view = self._view
        return WristLocator(
            None, env_index=env_index, config=config, capture=lambda _env: view.wrist_depth()
        )

    def env_actions(self, actions: np.ndarray) -> np.ndarray:
        """The primitives' ``(1, 4)`` commands as Meta-World's ``(1, 4)`` actions."""
        tcp = self._view.proprio().tcp_pos[0]
        mocap = self._view.hand_target()[0]
        return lead_action(tcp, mocap, np.asarray(actions)[0], self.offset)[None]

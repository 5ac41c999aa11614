"""What a task needs to know about each robot acting in it, as data (no robot branches in tasks).

Every embodiment acts through the same 4-D action (dx, dy, dz, grip) in [-1, 1]; the table below
records, per ManiSkill agent uid, the control mode providing it, how far a unit action moves the
TCP,
which sign of ``action[3]`` closes the gripper, and where the robot starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from awda_bench.errors import UnknownChoiceError

AGENT_UID = "panda_awda"
"""The evaluated agent (Panda + mink IK), registered by :mod:`awda_bench.robot`."""


@dataclass(frozen=True)
class Embodiment:
    """Per-robot facts a task and the scripted experts rely on."""

    uid: str
    """ManiSkill agent uid."""
    control_mode: str
    """Control mode giving the 4-D action space."""
    max_step_m: float
    """TCP displacement of a unit action component in one control step [m]."""
    close_when_positive: bool
    """True: ``action[3] > 0`` closes the gripper; False: ``action[3] < 0`` closes it."""
    base_xyz_m: tuple[float, float, float]
    """Robot root position in the world at reset [m] (table top at z = 0)."""
    rest_keyframe: str = "rest"
    """Agent keyframe whose qpos the robot is reset to."""

    def grip_closed(self, action: torch.Tensor) -> torch.Tensor:
        """(n,) bool: does ``action`` (n, 4) command the gripper closed?"""
        return action[:, 3] > 0 if self.close_when_positive else action[:, 3] < 0

    def to_env_action(self, action: np.ndarray) -> np.ndarray:
        """Map the method's action (grip > 0 closes) to this robot's (same array if identical)."""
        if self.close_when_positive:
            return action
        out = np.array(action, dtype=np.float32, copy=True)
        out[:, 3] = -out[:, 3]
        return out


EMBODIMENTS: dict[str, Embodiment] = {
    e.uid: e
    for e in (
        Embodiment(
            uid=AGENT_UID,
            control_mode="pd_ee_delta_pos_mink",
            max_step_m=0.02,
            close_when_positive=True,
            base_xyz_m=(-0.615, 0.0, 0.0),
        ),
        Embodiment(
            uid="awda_demonstrator",
            control_mode="pd_ee_delta_pos",
            max_step_m=0.02,
            close_when_positive=True,
            base_xyz_m=(0.0, 0.0, 0.0),
        ),
        # ManiSkill's stock Panda (its own IK; -1 closes; 0.1 m per unit action): kept for
        # comparisons and for running the tasks without awda_bench.robot.
        Embodiment(
            uid="panda",
            control_mode="pd_ee_delta_pos",
            max_step_m=0.1,
            close_when_positive=False,
            base_xyz_m=(-0.615, 0.0, 0.0),
        ),
    )
}
"""Embodiments our tasks accept, by uid."""


def embodiment(uid: str) -> Embodiment:
    """Look up ``uid``; unknown ones list the valid choices."""
    try:
        return EMBODIMENTS[uid]
    except KeyError:
        raise UnknownChoiceError("robot uid", uid, EMBODIMENTS) from None

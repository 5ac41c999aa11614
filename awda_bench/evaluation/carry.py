"""The carry analysis: what became of a grasped target on a task that carries it to a place.

A policy can grasp the right object and still fail: MOSAIC's Full-1 lifts the block, the ball or
the nut in about half its held-out episodes and stacks, dunks or screws none. This says where the
carry broke. It runs on tasks whose env names a place goal
(:meth:`~awda_bench.envs.task_base.AwdaTaskEnv.place_goal`: pick-and-place, stack block,
basketball, nut assembly) and starts once the env latches ``grasped`` (reached, then lifted).
From then on the harness asks after every step whether the fingers still hold the target (a
contact query, asked only during the carry); the first step of :data:`RELEASE_STEPS` in a row
without a hold is the release, and the target's position then is compared with its goal::

    carry = "placed"      the episode succeeded
            "held"        never released: the target is still in the hand at the end
            "dropped"     released while the gripper was commanded closed (slipped, knocked out)
            "off_target"  released (gripper open) farther than the task's tolerance from over its
                          goal (carried to the wrong place, or let go on the way)
            "on_target"   released over its goal and still failed (released too high, bounced,
                          toppled: ``release_dz_m`` says how high)

    release_xy_m = |target_xy - goal_xy| at the release     release_dz_m = target_z - goal_z

``carry`` is ``None`` for an episode that never grasped (the grasp analysis covers those) and on
tasks without a place goal (doors, drawers, buttons, Meta-World's pushes). Meta-World's carries
(pick-place-wall, sweep-into and their siblings: ``awda_bench.metaworld.env.PLACE_TOLERANCE_M``)
answer the same questions in numpy: a hold there is a finger pad touching the object.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

CARRY_OUTCOMES: tuple[str, ...] = ("placed", "on_target", "off_target", "dropped", "held")
"""The values of an episode record's ``carry`` (module docstring)."""

RELEASE_STEPS = 3
"""Steps in a row without a hold that make a release (a contact query can miss a held object
for a step while the fingers settle)."""


@dataclass
class Release:
    """Where the target was when the fingers let it go."""

    xy_m: float
    """Horizontal distance from over its goal [m]."""
    dz_m: float
    """Height above its goal [m]."""
    over_goal: bool
    """``xy_m`` within the task's tolerance."""
    closed: bool
    """The gripper was commanded closed at that step (a drop, not a release)."""


def _first_row(value: Any) -> np.ndarray:
    """Env 0's row of a batched answer, as float64 numpy: ManiSkill answers in torch tensors,
    Meta-World in numpy arrays."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value, dtype=np.float64)[0]


class CarryTally:
    """Follows one episode's carry on ``env`` (the unwrapped task env); ask :meth:`for_env`."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.goal: list[float] = [float(v) for v in env.place_goal()[0][0]]
        """The place goal at the start (world xyz [m])."""
        self.release: Release | None = None
        self._free_steps = 0
        self._first_free: Release | None = None

    @classmethod
    def for_env(cls, env: Any) -> CarryTally | None:
        """A tally for a task with a place goal, ``None`` for any other."""
        place_goal = getattr(env, "place_goal", None)
        if place_goal is None or place_goal() is None:
            return None
        return cls(env)

    def after_step(self, action: Any, grasped: bool | None) -> None:
        """Called after each step with the action played and the env's latched ``grasped``."""
        if self.release is not None or not grasped:
            return
        if bool(self.env.is_grasping_target()[0]):
            self._free_steps, self._first_free = 0, None
            return
        if self._first_free is None:
            self._first_free = self._where_now(action)
        self._free_steps += 1
        if self._free_steps >= RELEASE_STEPS:
            self.release = self._first_free

    def _where_now(self, action: Any) -> Release:
        goal, tolerance = (_first_row(t) for t in self.env.place_goal())
        target = _first_row(self.env.target_position())
        xy = float(np.linalg.norm(target[:2] - goal[:2]))
        closing = self.env.grip_commanded(action)
        return Release(
            xy_m=xy,
            dz_m=float(target[2] - goal[2]),
            over_goal=xy <= float(tolerance),
            closed=closing is not None and bool(closing[0]),
        )

    def outcome(self, grasped: bool | None, success: bool) -> str | None:
        """The episode's ``carry`` (one of :data:`CARRY_OUTCOMES`), ``None`` if never grasped."""
        if not grasped:
            return None
        if success:
            return "placed"
        if self.release is None:
            return "held"
        if self.release.closed:
            return "dropped"
        return "on_target" if self.release.over_goal else "off_target"

"""What every scripted expert shares: a per-env phase machine acting by straight-line TCP steps.

An expert subclass names its phases (an ``IntEnum`` with ``start_phase``/``done_phase``), keeps
its per-env extras in :meth:`PhaseExpert._reset_state`, reads where things are
(:meth:`PhaseExpert.read_scene`), and per env advances the phase (:meth:`PhaseExpert._advance`)
and sets the phase's goal (:meth:`PhaseExpert._set_goal`); :meth:`PhaseExpert.act` runs them
every step and :func:`straight_line_action` turns the goals into the embodiment's 4-D actions.
"""

from __future__ import annotations

from collections.abc import Collection
from enum import IntEnum
from typing import Any, ClassVar

import numpy as np

from awda_bench.episode import EpisodeContext


class PickPhase(IntEnum):
    """Phases of the pick-carry-place experts (pick_place, stack_block, basketball, nut_assembly)::

    HOVER --> DESCEND --> CLOSE --> LIFT --> CARRY --> LOWER --> RELEASE --> RETREAT --> DONE
    """

    HOVER = 0
    DESCEND = 1
    CLOSE = 2
    LIFT = 3
    CARRY = 4
    LOWER = 5
    RELEASE = 6
    RETREAT = 7
    DONE = 8


PICK_GRIP_CLOSED = frozenset({PickPhase.CLOSE, PickPhase.LIFT, PickPhase.CARRY, PickPhase.LOWER})
"""Pick phases during which the gripper is commanded closed."""


def straight_line_action(
    goal: np.ndarray, tcp: np.ndarray, closed: np.ndarray, env: Any
) -> np.ndarray:
    """(n, 4) env action stepping the TCP straight toward ``goal`` (n, 3) [m], grip ``closed`` (n,).

    The whole step is scaled down when any axis would exceed the action bound (straight lines), and
    the grip sign is converted to the loaded embodiment's.
    """
    emb = env.embodiment
    action = np.zeros((len(tcp), 4), dtype=np.float32)
    step = (goal - tcp) / emb.max_step_m
    step /= np.maximum(np.abs(step).max(axis=1, keepdims=True), 1.0)
    action[:, :3] = step
    action[:, 3] = np.where(closed, 1.0, -1.0)
    return emb.to_env_action(action)


def check_config(
    config: object, positive: tuple[str, ...] = (), at_least_one: tuple[str, ...] = ()
) -> None:
    """``ValueError`` naming the field unless the ``positive`` fields are > 0 and the
    ``at_least_one`` fields >= 1 (an expert config's ``__post_init__``)."""
    for name in positive:
        if not getattr(config, name) > 0:
            raise ValueError(
                f"{type(config).__name__}.{name} must be > 0, got {getattr(config, name)}"
            )
    for name in at_least_one:
        if getattr(config, name) < 1:
            raise ValueError(
                f"{type(config).__name__}.{name} must be >= 1, got {getattr(config, name)}"
            )


class PhaseExpert:
    """Policy-protocol scaffolding of the scripted experts (batched over envs)."""

    start_phase: ClassVar[int] = 0
    """Phase every env starts an episode in."""
    done_phase: ClassVar[int]
    """Phase meaning "finished"; the expert is done when every env is in it."""
    grip_closed_phases: ClassVar[Collection[int]] = ()
    """Phases during which the gripper is commanded closed (see :meth:`_grip_closed`)."""
    config_type: ClassVar[type[Any]]
    """The config of an expert built without one (its defaults)."""

    def __init__(self, config: Any = None, name: str = "scripted") -> None:
        self.config = config or self.config_type()
        self.name = name
        self._env: Any = None
        self.phase = np.zeros(0, dtype=np.int64)
        """(n,) current phase per env."""
        self.phase_steps = np.zeros(0, dtype=np.int64)
        """(n,) control steps spent in the current phase."""

    def reset(self, ctx: EpisodeContext) -> None:
        self._env = ctx.env
        n = self._env.num_envs
        self.phase = np.full(n, int(self.start_phase), dtype=np.int64)
        self.phase_steps = np.zeros(n, dtype=np.int64)
        self._reset_state(n)

    def _reset_state(self, n: int) -> None:
        """Reset the subclass's per-env extras for ``n`` envs (``self._env`` is set)."""

    def read_scene(self, env: Any, tcp: np.ndarray) -> Any:
        """Where things are, per env, for the current state (``tcp``: (n, 3) [m])."""
        raise NotImplementedError

    def _advance(self, i: int, tcp: np.ndarray, scene: Any) -> None:
        """Move env ``i`` to its next phase once the current one is finished (one per step)."""
        raise NotImplementedError

    def _set_goal(self, i: int, tcp: np.ndarray, scene: Any, goal: np.ndarray) -> None:
        """Set env ``i``'s TCP goal (3,) [m] for its current phase in ``goal``, which holds the
        TCP (``tcp``) on entry: a phase that leaves it holds position."""
        raise NotImplementedError

    def _grip_closed(self) -> np.ndarray:
        """(n,) bool: the gripper is commanded closed (in :attr:`grip_closed_phases`)."""
        return np.isin(self.phase, [int(p) for p in self.grip_closed_phases])

    def act(self, obs: Any) -> np.ndarray:
        """(n, 4) action for the loaded embodiment: straight-line step towards the phase goal."""
        if self._env is None:
            raise RuntimeError("act() before reset(ctx)")
        env = self._env
        tcp = env.agent.tcp_pose.p.cpu().numpy().astype(np.float64)
        scene = self.read_scene(env, tcp)
        goal = tcp.copy()
        for i in range(len(tcp)):
            self._advance(i, tcp[i], scene)
            self._set_goal(i, tcp[i], scene, goal[i])
            self.phase_steps[i] += 1
        return straight_line_action(goal, tcp, self._grip_closed(), env)

    @property
    def done(self) -> bool:
        return bool(len(self.phase)) and bool((self.phase == self.done_phase).all())

    @property
    def waypoints(self) -> np.ndarray | None:
        return None

"""Save and restore a Meta-World task env exactly (a planning rollout from the real start, then
back to it).

What a step reads, and so what a snapshot holds:

- MuJoCo's integration state (``mj_getState(..., mjSTATE_INTEGRATION)``): time, ``qpos``,
  ``qvel``, actuator activations, the solver's warm start (``qacc_warmstart``: without it a
  restored rollout drifts from the first step by ~1e-9), ``ctrl``, applied forces, the mocap
  bodies' poses (the hand's target: the actions move it) and the equality constraints' switches;
- the env's Python attributes that are plain values (numbers, flags, NumPy arrays, and lists,
  tuples and dicts of them), deep-copied: ``curr_path_length`` (Meta-World refuses to step past
  ``max_path_length``), ``_prev_obs`` (the observation's second frame), ``_last_stable_obs``,
  ``_did_see_sim_exception``, and whatever a task keeps between steps (older reward versions set
  ``reachCompleted``, ``pickCompleted``).

Arrays that are views into MuJoCo's memory stay as they are: they follow the restored physics.
(sweep-into's ``obj_init_pos`` is such a view, of the puck's current position, so its reward reads
the puck's position twice; a frozen copy restored in its place changed the reward from the tenth
restored step.)
Objects (the model, the renderer, gymnasium spaces, random generators) are not copied: steps do
not change them. After the restore, ``mj_forward`` recomputes every derived quantity (then the
saved state is set once more: the forward pass overwrote the solver's warm start) and the goal
markers are put back (rendering only, as :func:`~awda_bench.metaworld.layout.reset_to_layout`). A
restored rollout is bit-identical to the original (checked on the five held-out tasks after 7
random steps; ``tests/test_metaworld_gt_waypoints.py`` keeps sweep-into and pick-place-wall).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION
"""The MuJoCo state components saved (everything ``mj_step`` reads)."""

_PLAIN = (bool, int, float, str, bytes, type(None), np.ndarray, np.generic)


def _is_plain(value: Any) -> bool:
    """Numbers, flags, strings, arrays that own their memory, and (nested) lists, tuples and
    dicts of them."""
    if isinstance(value, np.ndarray) and not value.flags.owndata:
        return False  # a view into MuJoCo's memory: it follows the restored physics
    if isinstance(value, _PLAIN):
        return True
    if isinstance(value, (list, tuple)):
        return all(_is_plain(v) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, str) and _is_plain(v) for k, v in value.items())
    return False


@dataclass(frozen=True)
class SimState:
    """A snapshot of one Meta-World task env."""

    physics: np.ndarray
    """MuJoCo's integration state (:data:`STATE_SPEC`), float64."""
    attributes: dict[str, Any]
    """Deep copies of the env's plain attributes, by name."""


def save_state(env: Any) -> SimState:
    """Snapshot ``env`` (a ``SawyerXYZEnv``)."""
    size = mujoco.mj_stateSize(env.model, STATE_SPEC)
    physics = np.empty(size, dtype=np.float64)
    mujoco.mj_getState(env.model, env.data, physics, STATE_SPEC)
    attributes = {k: copy.deepcopy(v) for k, v in vars(env).items() if _is_plain(v)}
    return SimState(physics=physics, attributes=attributes)


def restore_state(env: Any, state: SimState) -> None:
    """Put ``env`` back into ``state`` (taken from this env by :func:`save_state`)."""
    size = mujoco.mj_stateSize(env.model, STATE_SPEC)
    if state.physics.shape != (size,):
        raise ValueError(
            f"state of {state.physics.shape[0]} numbers does not fit this model ({size}): "
            "it was saved from another task's env"
        )
    mujoco.mj_setState(env.model, env.data, state.physics, STATE_SPEC)
    for name, value in state.attributes.items():
        setattr(env, name, copy.deepcopy(value))
    mujoco.mj_forward(env.model, env.data)
    # mj_forward's constraint solver leaves its result as the next warm start: put the saved one
    # back, or the first restored step starts from another solver guess (and differs by ~1e-16)
    mujoco.mj_setState(env.model, env.data, state.physics, STATE_SPEC)
    for site in env._target_site_config:
        env._set_pos_site(*site)

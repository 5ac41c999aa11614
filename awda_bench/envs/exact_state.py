"""``ExactStateEnv``: state round trips and episode starts that do not depend on history.

ManiSkill 3.0.1's ``BaseEnv`` leaves three gaps that a benchmark (planning on a restored copy,
replaying recorded trajectories, workers reusing one env for many episodes) falls into:

- the flat ``get_state()`` flattens the whole ``get_state_dict()`` (actors, articulations, the
  controller state, and whatever a task adds), casting float64 leaves to float32, but the flat
  ``set_state()`` reads back only the actors and articulations, so controller state and task
  flags are silently lost;
- ``set_state_dict()`` never restores the controller state (the gripper command, a controller's
  accumulated target), so after a restore the observation and the drives keep the last command;
  ``reset(options={"reset_to_env_states": ...})`` resets the controllers after restoring;
- an unseeded ``reset()`` draws its randomization from the global torch RNG (unless
  ``enhanced_determinism``), and PhysX keeps each colliding pair's contact cache across resets,
  so an episode's trajectory depends (by ~1e-6 here, then amplified) on the episodes run before
  it in the same process;
- a seeded ``reset(seed=s)`` without ``reconfigure`` keeps the PhysX scene, and with it what the
  scene remembers of earlier episodes that no state dict holds: contact pairs of the robot's
  links with static props (a finger that touched a hoop), solver ordering. Measured on
  ``AWDA-Basketball-v1`` (2 seeded episodes of 12 random full-scale actions, the sequence run
  twice in one process): the reset observations agreed, the first step after the second run's
  first reset differed by 0.066 (toggling every static body off and on, which drops their
  pairs, left 1.3e-3 from the second step on).

This base closes them: ``get_state`` flattens without loss and ``set_state`` is its exact
inverse (it unflattens the vector along the layout of the current ``get_state_dict()``);
``set_state_dict``, and ``reset`` to given env states, also restore the controller (from the state
dict's ``"controller"`` key, where ``BaseEnv.get_state_dict`` puts it); ``enhanced_determinism``
defaults to on; :meth:`ExactStateEnv._forget_contact_history` lets an episode start from a
clean contact state; and a seeded ``reset`` rebuilds the scene (``reconfigure``, as the harness
does for every episode) unless the caller passes ``options["reconfigure"]`` itself, so
``reset(seed=s)`` gives the same episode every time, whatever ran before (CPU sim; a partial
``env_idx`` reset cannot rebuild and is left as asked).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.utils import common


def flatten_state(state: Mapping[str, Any]) -> torch.Tensor:
    """A state dict's tensor leaves side by side, ``(n, D)``, in the dict's order.

    The same layout as ``mani_skill.utils.common.flatten_state_dict`` (a ``(n,)`` leaf is one
    column, empty dicts are skipped), but lossless: the columns take the promoted dtype of the
    leaves (float32 for float32, bool and int leaves; float64 if a leaf is float64, e.g. a
    controller target kept in double), where ManiSkill casts every float64 leaf to float32.
    """
    leaves = _leaves(state)
    if not leaves:
        return torch.empty(0)
    dtype = torch.float32
    for leaf in leaves:
        dtype = torch.promote_types(dtype, leaf.dtype)
    return torch.hstack([leaf.to(dtype) for leaf in leaves])


def _leaves(state: Mapping[str, Any]) -> list[torch.Tensor]:
    out: list[torch.Tensor] = []
    for key, leaf in state.items():
        if isinstance(leaf, Mapping):
            out += _leaves(leaf)
        elif isinstance(leaf, torch.Tensor):
            if leaf.ndim not in (1, 2):
                raise TypeError(
                    f"state leaf {key!r} must be (n,) or (n, k), got {tuple(leaf.shape)}"
                )
            out.append(leaf[:, None] if leaf.ndim == 1 else leaf)
        else:
            raise TypeError(f"state leaf {key!r} is a {type(leaf).__name__}; expected a tensor")
    return out


def unflatten_state(vector: torch.Tensor, layout: Mapping[str, Any]) -> dict[str, Any]:
    """Split a flat ``(b, D)`` state along ``layout`` (a state dict: nested dicts of tensors).

    The inverse of :func:`flatten_state` (and of ManiSkill's ``flatten_state_dict``): a ``(n,)``
    leaf takes one column, a ``(n, k)`` leaf ``k`` columns, in the dict's order; each piece gets
    the leaf's dtype back (flattening promotes bools and ints to the float dtype). ``b`` may differ
    from the layout's batch size ``n`` (a partial restore). Raises ``ValueError`` when the widths
    do not add up to ``D``.
    """
    if vector.ndim == 1:
        vector = vector[None, :]
    out, used = _unflatten(vector, layout)
    if used != vector.shape[1]:
        raise ValueError(
            f"flat state has {vector.shape[1]} columns; this env's state layout has {used} "
            "(was it saved from another env or embodiment?)"
        )
    return out


def _unflatten(vector: torch.Tensor, layout: Mapping[str, Any]) -> tuple[dict[str, Any], int]:
    out: dict[str, Any] = {}
    start = 0
    for key, leaf in layout.items():
        if isinstance(leaf, Mapping):
            sub, used = _unflatten(vector[:, start:], leaf)
            if used:
                out[key] = sub
            start += used
        elif isinstance(leaf, torch.Tensor):
            if leaf.ndim not in (1, 2):
                raise TypeError(
                    f"state leaf {key!r} must be (n,) or (n, k), got {tuple(leaf.shape)}"
                )
            width = 1 if leaf.ndim == 1 else int(leaf.shape[1])
            if start + width > vector.shape[1]:
                raise ValueError(f"flat state too short for state leaf {key!r}")
            piece = vector[:, start : start + width]
            out[key] = (piece[:, 0] if leaf.ndim == 1 else piece).to(leaf.dtype)
            start += width
        else:
            raise TypeError(f"state leaf {key!r} is a {type(leaf).__name__}; expected a tensor")
    return out, start


def env_rows(value: torch.Tensor, idx: torch.Tensor, num_envs: int) -> torch.Tensor:
    """The rows of ``value`` for the envs ``idx``: a full batch is indexed, a partial one is
    taken as given (ManiSkill passes either to ``set_state_dict(state, env_idx)``)."""
    return value[idx] if value.shape[0] == num_envs and len(idx) != num_envs else value


def _merge_rows(current: Any, saved: Any, idx: torch.Tensor, num_envs: int) -> Any:
    """``current`` with the rows ``idx`` of every tensor leaf replaced by ``saved``'s."""
    if isinstance(current, Mapping):
        return {
            k: _merge_rows(v, saved[k], idx, num_envs) if k in saved else v
            for k, v in current.items()
        }
    merged = current.clone()
    merged[idx] = env_rows(torch.as_tensor(saved, device=current.device), idx, num_envs).to(
        current.dtype
    )
    return merged


class ExactStateEnv(BaseEnv):
    """``BaseEnv`` whose state round trips are exact (see the module docstring)."""

    FIXED_ROOT_TOLERANCE_M: float = 1e-6
    """A fixed articulation root this close to its saved pose (position [m] and quaternion
    components) counts as unmoved: its pose is not written back on restore."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        # unseeded resets draw their episode seed from the main RNG (set by the last seeded
        # reset), so a seeded sequence of resets and steps repeats exactly
        kwargs.setdefault("enhanced_determinism", True)
        super().__init__(*args, **kwargs)

    def get_state(self) -> torch.Tensor:
        """``get_state_dict()`` flattened to ``(num_envs, D)`` without loss (:func:`flatten_state`;
        ``set_state`` reads it back)."""
        return flatten_state(self.get_state_dict())

    def set_state(self, state: Any, env_idx: torch.Tensor | None = None) -> None:
        """Restore a flat state from :meth:`get_state`: scene, controller and task state."""
        # not common.to_tensor: it casts float64 to float32
        vector = torch.as_tensor(state, device=self.device)
        self.set_state_dict(unflatten_state(vector, self.get_state_dict()), env_idx)

    def set_state_dict(self, state: dict, env_idx: torch.Tensor | None = None) -> None:
        """``BaseEnv.set_state_dict`` plus the controller state saved under ``"controller"``."""
        state = dict(state)
        controller = state.pop("controller", None)
        if not self.gpu_sim_enabled and "articulations" in state:
            state["articulations"] = self._restore_unmoved_articulations(state["articulations"])
        super().set_state_dict(state, env_idx)
        if controller is not None:
            self._set_controller_state(controller, env_idx)

    def reset(self, seed: Any = None, options: dict | None = None) -> tuple[Any, dict]:
        """``BaseEnv.reset``, rebuilding the scene on a seeded reset (:meth:`seeded_options`);
        with ``options["reset_to_env_states"]`` the saved controller state is put back after
        ``BaseEnv.reset`` has reset the controllers (which re-synchronizes them to the measured
        pose and opens the gripper), and the observation is taken after that."""
        options = self.seeded_options(seed, options)
        obs, info = super().reset(seed=seed, options=options)
        restore = (options or {}).get("reset_to_env_states")
        if restore is None:
            return obs, info
        states = restore["env_states"]
        if not isinstance(states, Mapping):
            states = unflatten_state(
                torch.as_tensor(states, device=self.device), self.get_state_dict()
            )
        controller = states.get("controller")
        if controller is None:
            return obs, info
        env_idx = (options or {}).get("env_idx")
        self._set_controller_state(
            controller, None if env_idx is None else torch.as_tensor(env_idx, device=self.device)
        )
        if restore.get("obs") is None:
            info = {**info, **self.get_info()}
            obs = self.get_obs(info)
            self._last_obs = obs
        return obs, info

    def seeded_options(self, seed: Any, options: dict | None) -> dict:
        """The reset options, with ``"reconfigure": True`` added to a seeded reset that does not
        say (``"reconfigure"`` absent; CPU sim; no partial ``env_idx``).

        Rebuilding is the one exact fix found: the scene's memory of earlier episodes is not all
        reachable (see the module docstring). It costs the scene build on every seeded reset
        (measured 0.21-0.34 s per reset against 3-17 ms, docs/numbers.md, "Seeded resets"); a caller who wants the
        cheap reset and accepts the history dependence passes ``options={"reconfigure": False}``.
        Handles to actors, the agent or its controllers taken before a rebuild refer to the old
        scene.
        Unseeded resets never rebuild: a seeded reset followed by steps and unseeded resets
        repeats exactly as a whole.
        """
        options = dict(options or {})
        if seed is None or "reconfigure" in options or "env_idx" in options:
            return options
        if not self.gpu_sim_enabled:
            options["reconfigure"] = True
        return options

    def _set_controller_state(
        self, controller: Mapping[str, Any], env_idx: torch.Tensor | None
    ) -> None:
        if env_idx is None or len(env_idx) == self.num_envs:
            self.agent.set_controller_state(controller)
        else:
            current = self.agent.get_controller_state()
            self.agent.set_controller_state(
                _merge_rows(current, controller, env_idx, self.num_envs)
            )

    def _restore_unmoved_articulations(self, saved: Mapping[str, Any]) -> dict[str, Any]:
        """Restore (CPU sim) the fixed-base articulations whose root is where ``saved`` has it
        (within :attr:`FIXED_ROOT_TOLERANCE_M`) without writing their root pose; return the other
        articulations' states for ``BaseEnv`` to restore.

        Writing a root pose back is not exact in PhysX: pose -> ``set_root_pose`` -> pose moves a
        fixed root by up to ~1e-7 (measured on the Panda and the procedural cabinets), a little
        more on every restore. A fixed root does not move within an episode, so restores no
        longer perturb it. (PhysX's read-back of some fixed roots alternates between two values
        one float32 ulp apart from one control step to the next, measured on a drawer cabinet
        and the button panel; that ulp is all a round trip can differ by.)
        """
        registry = self.scene.state_dict_registry.articulations
        rest: dict[str, Any] = {}
        for name, value in saved.items():
            row = common.to_tensor(value, device=self.device).reshape(-1).to(torch.float32)
            articulation = registry[name]
            root = articulation.root.pose.raw_pose[0]
            unmoved = bool((root - row[:7]).abs().max() <= self.FIXED_ROOT_TOLERANCE_M)
            if not (bool(articulation.fixed_root_link.all()) and unmoved):
                rest[name] = value
                continue
            dof = articulation.max_dof
            articulation.set_qpos(row[13 : 13 + dof][None])
            articulation.set_qvel(row[13 + dof : 13 + 2 * dof][None])
        return rest

    def _forget_contact_history(self, env_idx: torch.Tensor) -> None:
        """Drop PhysX's cached contacts of the dynamic (non-kinematic) bodies in the sub-scenes
        ``env_idx``.

        PhysX keeps a colliding pair's contact manifold while the pair's bounds overlap, across
        teleports: an object resting on the table at the end of one episode and teleported for
        the next starts from the old manifold, and the next episode differs (~1e-6 m after a few
        steps, measured on the nut-assembly and pick-place scenes) from the same episode run
        first. Toggling a body kinematic and back removes its pairs; it also zeroes the body's
        velocity and leaves it asleep, so objects start an episode at rest and asleep, and wake
        when something touches them (the gripper, another object) or moves them. They spawn
        resting: kept awake, they settle by <= 7.4e-6 m in 20 steps (measured on every task);
        woken here, the ~1e-6 history dependence comes back. Pairs of robot links with static or
        kinematic props keep their cache. CPU sim only (bodies cannot change type after the GPU
        sim is initialized).
        """
        if self.gpu_sim_enabled:
            return
        for i in env_idx.tolist():
            system = self.scene.sub_scenes[i].physx_system
            for body in system.get_rigid_dynamic_components():
                if not body.kinematic:
                    body.set_kinematic(True)
                    body.set_kinematic(False)

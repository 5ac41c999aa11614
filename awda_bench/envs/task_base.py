"""``AwdaTaskEnv``: what every benchmark task shares, so task files hold only their task.

A task subclass sets ``family`` and ``num_variations``, builds its objects in ``_load_task_scene``,
places them in ``_initialize_task(env_idx, variation)``, and judges them in
``_evaluate_task() -> dict`` (with ``"success"``). This base provides, for any embodiment of
:mod:`awda_bench.envs.embodiments` (no robot branches in tasks):

- the table, the robot at its embodiment's base pose and rest keyframe, 100 Hz physics / 20 Hz control;
- the third-person camera ``third_person`` (declared as a sensor, rendered only on demand);
- ``reset(options={"task": v})`` parsing (an int or one per env; ``0 <= v < num_variations``);
- latched episode flags: ``success_once``, ``grip_attempted``, and for tasks with a grasp target
  ``reached`` (TCP within ``reach_threshold_m`` of the target before the first grip command) and
  ``grasped`` (reached, then the target lifted ``lift_threshold_m``);
- ``gripper_opening_m()``, ``truth_signals()`` (simulator truths the demo recorder logs per step),
- exact state round trips including those flags and the controller state, flat
  (``get_state``/``set_state``) and as dicts (``get_state_dict``/``set_state_dict``), and episodes
  that do not depend on the ones run before them (see :mod:`awda_bench.envs.exact_state`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
import sapien
import torch
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.scene_builder.table import TableSceneBuilder
from mani_skill.utils.structs.actor import Actor
from mani_skill.utils.structs.link import Link
from mani_skill.utils.structs.types import SimConfig

from awda_bench.envs.embodiments import AGENT_UID, EMBODIMENTS, embodiment
from awda_bench.envs.exact_state import ExactStateEnv, env_rows
from awda_bench.errors import UsageError


class AwdaTaskEnv(ExactStateEnv):
    """Base of the benchmark's tasks (see the module docstring for the contract)."""

    SUPPORTED_ROBOTS = list(EMBODIMENTS)
    SUPPORTED_REWARD_MODES = ("sparse", "none")

    family: ClassVar[str] = ""
    """Task family name (``door``, ``drawer``, ...): the column of Table S4."""
    num_variations: ClassVar[int] = 1
    """Valid ``options["task"]`` values are ``0 .. num_variations - 1``."""
    has_grasp_target: ClassVar[bool] = False
    """True when the task's target is picked up (then ``reached``/``grasped`` are computed)."""

    third_person_eye_m: ClassVar[tuple[float, float, float]] = (0.32, 0.0, 0.68)
    """Third-person camera position [m]."""
    third_person_target_m: ClassVar[tuple[float, float, float]] = (-0.12, 0.0, 0.0)
    """Point the third-person camera looks at [m]."""
    third_person_fov_rad: ClassVar[float] = 1.0
    """Third-person camera vertical field of view [rad]."""
    camera_height_px: ClassVar[int] = 240
    """Third-person image height [px]."""
    camera_width_px: ClassVar[int] = 320
    """Third-person image width [px]."""
    reach_threshold_m: ClassVar[float] = 0.04
    """Reached: TCP within this distance of the target before any grasp attempt [m]."""
    lift_threshold_m: ClassVar[float] = 0.05
    """Grasped: after reaching, the target raised at least this much above its start height [m]."""

    _TASK_STATE: ClassVar[tuple[str, ...]] = (
        "task",
        "grip_attempted",
        "reached",
        "grasped",
        "success_once",
        "target_start_z",
    )
    """Per-env (n,) tensors saved beside the scene state; subclasses append their own."""

    def __init__(self, *args: Any, robot_uids: str = AGENT_UID, **kwargs: Any) -> None:
        self.embodiment = embodiment(robot_uids)
        kwargs.setdefault("control_mode", self.embodiment.control_mode)
        super().__init__(*args, robot_uids=robot_uids, **kwargs)

    # ------------------------------------------------------------------ hooks for subclasses
    def _load_task_scene(self, options: dict) -> None:
        """Build the task's actors and articulations (called once, after the table)."""
        raise NotImplementedError

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        """Place the task's objects for the envs ``env_idx`` (inside ``torch.device(self.device)``)."""
        raise NotImplementedError

    def _evaluate_task(self) -> dict[str, torch.Tensor]:
        """``{"success": (n,) bool, ...}`` for the current state."""
        raise NotImplementedError

    def target_position(self) -> torch.Tensor:
        """(n, 3) position of the grasp target [m] (tasks with ``has_grasp_target``)."""
        raise NotImplementedError

    def target_distance(self) -> torch.Tensor:
        """(n,) TCP distance to the grasp target [m]; override for a surface distance."""
        return torch.linalg.norm(self.agent.tcp_pose.p - self.target_position(), dim=1)

    def object_distances(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """``((n, k) TCP distance to each object a grip could take [m], (n,) the target's
        column)`` for the first-grip analysis (:meth:`grip_outcome`); ``None`` (this default):
        the task does not tell."""
        return None

    def is_grasping_target(self) -> torch.Tensor:
        """(n,) simulator truth: the fingers hold the target (contact forces)."""
        return torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)

    def place_goal(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """Where a carried target must go, for the carry analysis
        (:mod:`awda_bench.evaluation.carry`): ``((n, 3) the point :meth:`target_position` is at
        in a success [m], (n,) the horizontal distance from it within which the target is over
        the goal [m])``; ``None`` (this default): the task carries nothing to a place."""
        return None

    def _is_grasping_per_env(
        self, bodies: Sequence[Actor | Link], index: torch.Tensor
    ) -> torch.Tensor:
        """(n,) simulator truth: the fingers hold ``bodies[index[i]]`` in env ``i`` (the agent's
        contact-force test, asked only of the bodies some env's ``index`` names)."""
        out = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        for j in torch.unique(index).tolist():
            out = torch.where(index == j, self.agent.is_grasping(bodies[j]), out)
        return out

    def truth_signals(self) -> dict[str, torch.Tensor]:
        """(n,) bool simulator truths logged per step by the demo recorder (attribute mining)."""
        return {"grasp": self.is_grasping_target()}

    # ------------------------------------------------------------------ configuration
    @property
    def _default_sim_config(self) -> SimConfig:
        return SimConfig(sim_freq=100, control_freq=20)

    def _third_person_config(self, uid: str) -> CameraConfig:
        return CameraConfig(
            uid=uid,
            pose=sapien_utils.look_at(
                eye=list(self.third_person_eye_m), target=list(self.third_person_target_m)
            ),
            width=self.camera_width_px,
            height=self.camera_height_px,
            fov=self.third_person_fov_rad,
            near=0.01,
            far=10.0,
        )

    @property
    def _default_sensor_configs(self) -> list[CameraConfig]:
        return [self._third_person_config("third_person")]

    @property
    def _default_human_render_camera_configs(self) -> CameraConfig:
        return self._third_person_config("render_camera")

    # ------------------------------------------------------------------ scene
    def _load_agent(self, options: dict) -> None:
        super()._load_agent(options, sapien.Pose(p=list(self.embodiment.base_xyz_m)))

    def _load_scene(self, options: dict) -> None:
        self.table_scene = TableSceneBuilder(self, robot_init_qpos_noise=0.0)
        self.table_scene.build()
        self._load_task_scene(options)
        n = self.num_envs
        self.task = torch.zeros(n, dtype=torch.long, device=self.device)
        """(n,) variation index per env."""
        self.grip_attempted = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched: the gripper has been commanded closed this episode."""
        self.reached = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched grasp-analysis flag."""
        self.grasped = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched grasp-analysis flag."""
        self.success_once = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched: success was true at some step."""
        self.target_start_z = torch.zeros(n, dtype=torch.float32, device=self.device)
        """(n,) grasp target's height at reset [m] (0 for tasks without one)."""

    def _parse_task(self, options: dict, b: int) -> torch.Tensor:
        raw = options.get("task", 0)
        task = torch.as_tensor(raw, dtype=torch.long, device=self.device).reshape(-1)
        if task.numel() == 1:
            task = task.expand(b)
        if task.numel() != b:
            raise UsageError(f"options['task'] must be an int or {b} ints, got {raw!r}")
        if bool(((task < 0) | (task >= self.num_variations)).any()):
            raise UsageError(
                f"options['task'] must be in 0..{self.num_variations - 1} for {self.family}, got {raw!r}"
            )
        return task

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict) -> None:
        with torch.device(self.device):
            b = len(env_idx)
            self.table_scene.initialize(env_idx)
            keyframe = self.agent.keyframes[self.embodiment.rest_keyframe]
            qpos = torch.as_tensor(np.asarray(keyframe.qpos), dtype=torch.float32).expand(b, -1)
            self.agent.reset(qpos)
            self.agent.robot.set_pose(sapien.Pose(p=list(self.embodiment.base_xyz_m)))
            variation = self._parse_task(options, b)
            self.task[env_idx] = variation
            self._initialize_task(env_idx, variation)
            self.grip_attempted[env_idx] = False
            self.reached[env_idx] = False
            self.grasped[env_idx] = False
            self.success_once[env_idx] = False
            if self.has_grasp_target:
                self.target_start_z[env_idx] = self.target_position()[env_idx, 2]
            self._forget_contact_history(env_idx)

    # ------------------------------------------------------------------ robot signals
    def gripper_opening_m(self) -> torch.Tensor:
        """(n,) finger gap [m] of whichever robot is loaded."""
        if hasattr(self.agent, "gripper_opening_m"):
            return self.agent.gripper_opening_m
        qpos = self.agent.robot.get_qpos()
        return qpos[:, -2] + qpos[:, -1]

    # ------------------------------------------------------------------ step hooks
    def grip_commanded(self, action: Any) -> torch.Tensor | None:
        """(n,) bool: does ``action`` (as :meth:`step` takes it) command the gripper closed?
        ``None`` for an action that is not one (dx, dy, dz, grip) row per env."""
        if action is None or isinstance(action, dict):
            return None
        a = torch.as_tensor(np.asarray(action) if not isinstance(action, torch.Tensor) else action)
        if a.numel() != self.num_envs * 4:
            return None
        return self.embodiment.grip_closed(a.to(self.device).reshape(self.num_envs, 4).float())

    def grip_outcome(self, action: Any) -> torch.Tensor | None:
        """(n,) int: what ``action`` would close the gripper on from the current state, an index
        into :data:`~awda_bench.episode.GRIP_OUTCOMES` (the nearest object within
        ``reach_threshold_m`` of the TCP is the target or another one, or none is that near), -1
        where it does not close the gripper. ``None`` where the task does not tell
        (:meth:`object_distances`) or ``action`` is not one row per env. The harness asks this
        before each step until the first grip: what the policy went for."""
        closing = self.grip_commanded(action)
        if closing is None:
            return None
        if not bool(closing.any()):
            return torch.full_like(closing, -1, dtype=torch.long)
        measured = self.object_distances()
        if measured is None:
            return None
        distances, target = measured
        nearest, which = distances.min(dim=1)
        outcome = torch.where(which == target, 0, 1)  # GRIP_OUTCOMES: target, other
        outcome = torch.where(nearest <= self.reach_threshold_m, outcome, 2)  # nothing
        return torch.where(closing, outcome, -1)

    def _step_action(self, action: Any) -> Any:
        # latch the grasp attempt on the commanded action; "reached" is latched by evaluate() on
        # every state (reset and after each step), with the attempts commanded up to that state
        closing = self.grip_commanded(action)
        if closing is not None:
            self.grip_attempted |= closing
        return super()._step_action(action)

    def evaluate(self) -> dict:
        """``_evaluate_task()``'s dict plus the latched flags. A task may return
        ``"target_distance_m"`` and ``"target_pos"`` to spare their recomputation."""
        result = self._evaluate_task()
        if self.has_grasp_target:
            distance = result.get("target_distance_m")
            if distance is None:
                distance = self.target_distance()
            target_pos = result.get("target_pos")
            if target_pos is None:
                target_pos = self.target_position()
            self.reached |= (distance <= self.reach_threshold_m) & ~self.grip_attempted
            lifted = target_pos[:, 2] - self.target_start_z >= self.lift_threshold_m
            self.grasped |= self.reached & lifted
        self.success_once |= result["success"]
        flags = {
            "success_once": self.success_once.clone(),
            "grip_attempted": self.grip_attempted.clone(),
        }
        if self.has_grasp_target:  # tasks without one do not report the grasp analysis at all
            flags.update(reached=self.reached.clone(), grasped=self.grasped.clone())
        return {**result, **flags, "task": self.task.clone()}

    def _get_obs_extra(self, info: dict) -> dict:
        return dict(
            tcp_pos=self.agent.tcp_pose.p,
            gripper_opening_m=self.gripper_opening_m()[:, None],
            task_one_hot=torch.nn.functional.one_hot(self.task, self.num_variations).float(),
        )

    def compute_sparse_reward(self, obs: Any, action: torch.Tensor, info: dict) -> torch.Tensor:
        return info["success"].float()

    # ------------------------------------------------------------------ state
    def get_state_dict(self) -> dict:
        """Scene state plus the per-env task flags under ``"task_state"`` ((n, 1) floats)."""
        state = super().get_state_dict()
        state["task_state"] = {
            name: getattr(self, name).to(torch.float32)[:, None].clone()
            for name in self._TASK_STATE
        }
        return state

    def set_state_dict(self, state: dict, env_idx: torch.Tensor | None = None) -> None:
        """Scene and controller state (:class:`ExactStateEnv`), then the task flags."""
        state = dict(state)
        task_state = state.pop("task_state", None)
        super().set_state_dict(state, env_idx)
        if task_state is None:
            return
        idx = torch.arange(self.num_envs, device=self.device) if env_idx is None else env_idx
        for name in self._TASK_STATE:
            current = getattr(self, name)
            value = torch.as_tensor(task_state[name], device=self.device).reshape(-1)
            current[idx] = env_rows(value, idx, self.num_envs).to(current.dtype)

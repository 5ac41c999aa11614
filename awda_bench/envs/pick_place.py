"""AWDA-PickPlace-v1: one env serving all 16 pick-and-place tasks (SPEC §3.1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import sapien
import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.registration import register_env
from mani_skill.utils.scene_builder.table import TableSceneBuilder
from mani_skill.utils.structs.pose import Pose
from mani_skill.utils.structs.types import SimConfig

from awda_bench.envs.bins import BinSpec, build_bin
from awda_bench.envs.embodiments import AGENT_UID, EMBODIMENTS, embodiment
from awda_bench.envs.objects import (
    PICK_PLACE_OBJECTS,
    ObjectSpec,
    build_object,
    distance_to_objects,
)
from awda_bench.errors import UsageError

NUM_TASKS = 16
"""``task = 4 * object + compartment``."""


@dataclass(frozen=True)
class PickPlaceLayout:
    """Geometry of the pick-and-place scene (world: table top z = 0, robot base x = -0.615)."""

    source_bin: BinSpec = BinSpec(
        center_xy_m=(-0.08, -0.20), inner_half_size_m=(0.14, 0.17), wall_height_m=0.05
    )
    """The open bin the four objects start in."""
    target_bin: BinSpec = BinSpec(
        center_xy_m=(-0.08, 0.21),
        inner_half_size_m=(0.13, 0.13),
        wall_height_m=0.06,
        divided=True,
        color=(0.30, 0.50, 0.35, 1.0),
    )
    """The bin with 4 compartments (see :meth:`BinSpec.compartment_box` for the numbering)."""
    spawn_half_size_m: tuple[float, float] = (0.10, 0.11)
    """Object centres are drawn uniformly in source-bin centre +- this [m] (reference: 0.125 x
    0.155, shrunk so every layout stays in the Panda's top-down reach and the open fingers clear
    the walls)."""
    min_separation_m: float = 0.12
    """Minimum distance between any two object centres [m]."""
    layout_candidates: int = 4096
    """Whole layouts drawn per env at reset; the first one meeting ``min_separation_m`` is kept."""
    success_max_height_m: float = 0.10
    """Success: the target's centre at most this far above the compartment floor [m]."""
    reach_threshold_m: float = 0.04
    """Reached: TCP within this distance of the target's surface before any grasp attempt [m]."""
    lift_threshold_m: float = 0.05
    """Grasped: after reaching, the target raised at least this much above its start height [m]."""
    third_person_eye_m: tuple[float, float, float] = (0.32, 0.0, 0.68)
    """Third-person camera position [m]."""
    third_person_target_m: tuple[float, float, float] = (-0.12, 0.0, 0.0)
    """Point the third-person camera looks at [m]."""
    third_person_fov_rad: float = 1.0
    """Third-person camera vertical field of view [rad]."""
    camera_height_px: int = 240
    """Third-person image height [px]."""
    camera_width_px: int = 320
    """Third-person image width [px]."""


@register_env("AWDA-PickPlace-v1", max_episode_steps=300)
class PickPlaceEnv(BaseEnv):
    """
    **Task Description:**
    Pick the target object out of the source bin and put it into one of the 4 compartments of the
    target bin. Four objects are always present (milk carton, bread, cereal box, soda can); the
    three non-targets are distractors. ``reset(options={"task": i})`` selects object ``i // 4``
    and compartment ``i % 4`` (per env: an int or an (n,) sequence; default 0; kept until the
    next reset).

    **Randomizations:**
    - the four object centres are drawn uniformly in the source bin's spawn area
      (``PickPlaceLayout.spawn_half_size_m``), all pairwise at least ``min_separation_m`` apart
    - each object's yaw is uniform in [0, 2 pi); objects stand upright on the bin floor
    - the robot starts at its rest keyframe (no noise)

    **Success Conditions:**
    - the target object's centre is inside its compartment's inner x/y box and at most
      ``success_max_height_m`` above the compartment floor
    - grasp analysis (latched over the episode): ``reached`` = TCP within ``reach_threshold_m``
      of the target's surface before the gripper was first commanded closed; ``grasped`` =
      reached, then the target raised at least ``lift_threshold_m`` above its start height
    """

    SUPPORTED_ROBOTS = list(EMBODIMENTS)
    SUPPORTED_REWARD_MODES = ("sparse", "none")
    objects_spec: tuple[ObjectSpec, ...] = PICK_PLACE_OBJECTS

    def __init__(
        self,
        *args: Any,
        robot_uids: str = AGENT_UID,
        layout: PickPlaceLayout | None = None,
        **kwargs: Any,
    ) -> None:
        self.layout = layout or PickPlaceLayout()
        self.embodiment = embodiment(robot_uids)
        kwargs.setdefault("control_mode", self.embodiment.control_mode)
        super().__init__(*args, robot_uids=robot_uids, **kwargs)

    # ------------------------------------------------------------------ configuration
    @property
    def _default_sim_config(self) -> SimConfig:
        return SimConfig(sim_freq=100, control_freq=20)

    def _third_person_config(self, uid: str) -> CameraConfig:
        lay = self.layout
        return CameraConfig(
            uid=uid,
            pose=sapien_utils.look_at(
                eye=list(lay.third_person_eye_m), target=list(lay.third_person_target_m)
            ),
            width=lay.camera_width_px,
            height=lay.camera_height_px,
            fov=lay.third_person_fov_rad,
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
        self.source_bin = build_bin(self.scene, self.layout.source_bin, name="source_bin")
        self.target_bin = build_bin(self.scene, self.layout.target_bin, name="target_bin")
        floor = self.layout.source_bin.floor_z_m
        self.objects = [
            build_object(self.scene, s, floor + s.half_height_m) for s in self.objects_spec
        ]
        boxes = [self.layout.target_bin.compartment_box(c) for c in range(4)]
        self._compartment_lo = torch.tensor(
            [[b[0][0], b[1][0]] for b in boxes], dtype=torch.float32, device=self.device
        )
        self._compartment_hi = torch.tensor(
            [[b[0][1], b[1][1]] for b in boxes], dtype=torch.float32, device=self.device
        )
        self._half_heights = torch.tensor(
            [s.half_height_m for s in self.objects_spec], dtype=torch.float32, device=self.device
        )
        n = self.num_envs
        self.task = torch.zeros(n, dtype=torch.long, device=self.device)
        """(n,) task index per env."""
        self.grip_attempted = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched: the gripper has been commanded closed this episode."""
        self.reached = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched grasp-analysis flag (see the class docstring)."""
        self.grasped = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched grasp-analysis flag (see the class docstring)."""
        self.success_once = torch.zeros(n, dtype=torch.bool, device=self.device)
        """(n,) latched: success was true at some step."""
        self.target_start_z = torch.zeros(n, dtype=torch.float32, device=self.device)
        """(n,) target object's centre height at reset [m]."""

    def _parse_task(self, options: dict, b: int) -> torch.Tensor:
        raw = options.get("task", 0)
        task = torch.as_tensor(raw, dtype=torch.long, device=self.device).reshape(-1)
        if task.numel() == 1:
            task = task.expand(b)
        if task.numel() != b:
            raise UsageError(f"options['task'] must be an int or {b} ints, got {raw!r}")
        if bool(((task < 0) | (task >= NUM_TASKS)).any()):
            raise UsageError(f"options['task'] must be in 0..{NUM_TASKS - 1}, got {raw!r}")
        return task

    def _sample_layouts(self, b: int) -> torch.Tensor:
        """(b, 4, 2) object centres, pairwise >= ``min_separation_m`` (whole-layout rejection)."""
        lay = self.layout
        m, k = lay.layout_candidates, len(self.objects_spec)
        half = torch.tensor(lay.spawn_half_size_m, device=self.device)
        center = torch.tensor(lay.source_bin.center_xy_m, device=self.device)
        xy = (torch.rand((b, m, k, 2), device=self.device) * 2 - 1) * half + center
        d = torch.linalg.norm(xy[:, :, :, None, :] - xy[:, :, None, :, :], dim=-1)
        d = d + torch.eye(k, device=self.device) * 1e3
        ok = d.flatten(2).min(dim=2).values >= lay.min_separation_m
        if not bool(ok.any(dim=1).all()):
            raise RuntimeError(
                f"no layout with objects {lay.min_separation_m} m apart among {m} candidates; "
                "enlarge spawn_half_size_m or layout_candidates"
            )
        first = ok.to(torch.int8).argmax(dim=1)
        return xy[torch.arange(b, device=self.device), first]

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict) -> None:
        with torch.device(self.device):
            b = len(env_idx)
            self.table_scene.initialize(env_idx)
            keyframe = self.agent.keyframes[self.embodiment.rest_keyframe]
            qpos = torch.as_tensor(np.asarray(keyframe.qpos), dtype=torch.float32).expand(b, -1)
            self.agent.reset(qpos)
            self.agent.robot.set_pose(sapien.Pose(p=list(self.embodiment.base_xyz_m)))

            task = self._parse_task(options, b)
            xy = self._sample_layouts(b)
            yaw = torch.rand((b, len(self.objects)), device=self.device) * 2 * np.pi
            floor = self.layout.source_bin.floor_z_m
            for j, (actor, spec) in enumerate(zip(self.objects, self.objects_spec, strict=True)):
                p = torch.zeros((b, 3))
                p[:, :2] = xy[:, j]
                p[:, 2] = floor + spec.half_height_m
                q = torch.zeros((b, 4))
                q[:, 0] = torch.cos(yaw[:, j] / 2)
                q[:, 3] = torch.sin(yaw[:, j] / 2)
                actor.set_pose(Pose.create_from_pq(p, q))
                actor.set_linear_velocity(torch.zeros((b, 3)))
                actor.set_angular_velocity(torch.zeros((b, 3)))

            self.task[env_idx] = task
            self.grip_attempted[env_idx] = False
            self.reached[env_idx] = False
            self.grasped[env_idx] = False
            self.success_once[env_idx] = False
            self.target_start_z[env_idx] = floor + self._half_heights[task // 4]

    # ------------------------------------------------------------------ task state
    @property
    def target_object_index(self) -> torch.Tensor:
        """(n,) index into :attr:`objects` of each env's target."""
        return self.task // 4

    @property
    def target_compartment(self) -> torch.Tensor:
        """(n,) compartment index (0-3) of each env's task."""
        return self.task % 4

    def object_poses(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Positions (n, 4, 3) [m] and quaternions (n, 4, 4, wxyz) of the four objects."""
        raw = torch.stack([o.pose.raw_pose for o in self.objects], dim=1)
        return raw[..., :3], raw[..., 3:]

    def _select_target(self, values: torch.Tensor) -> torch.Tensor:
        """Pick each env's target row out of per-object ``values`` (n, 4, ...)."""
        return values[torch.arange(self.num_envs, device=self.device), self.target_object_index]

    def target_pose(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Position (n, 3) and quaternion (n, 4) of each env's target object."""
        pos, quat = self.object_poses()
        return self._select_target(pos), self._select_target(quat)

    def compartment_center(self) -> torch.Tensor:
        """(n, 3) centre of each env's goal compartment on its floor [m]."""
        c = self.target_compartment
        xy = (self._compartment_lo[c] + self._compartment_hi[c]) / 2
        z = torch.full((self.num_envs, 1), self.layout.target_bin.floor_z_m, device=self.device)
        return torch.cat([xy, z], dim=1)

    def gripper_opening_m(self) -> torch.Tensor:
        """(n,) finger gap [m] of whichever robot is loaded."""
        if hasattr(self.agent, "gripper_opening_m"):
            return self.agent.gripper_opening_m
        qpos = self.agent.robot.get_qpos()
        return qpos[:, -2] + qpos[:, -1]

    def is_grasping_target(self) -> torch.Tensor:
        """(n,) simulator truth: both fingers press on the target (Panda's contact-force test)."""
        idx = self.target_object_index
        out = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        for j in torch.unique(idx).tolist():
            out = torch.where(idx == j, self.agent.is_grasping(self.objects[j]), out)
        return out

    def truth_signals(self) -> dict[str, torch.Tensor]:
        """(n,) bool simulator truths the demo recorder logs per step (attribute mining)."""
        return {"grasp": self.is_grasping_target()}

    # ------------------------------------------------------------------ step hooks
    def _step_action(self, action: Any) -> Any:
        # latch the grasp attempt on the commanded action; "reached" is latched by evaluate() on
        # every state (reset and after each step), with the attempts commanded up to that state
        if action is not None and not isinstance(action, dict):
            a = torch.as_tensor(
                np.asarray(action) if not isinstance(action, torch.Tensor) else action
            )
            a = a.to(self.device).reshape(self.num_envs, -1)
            self.grip_attempted |= self.embodiment.grip_closed(a.float())
        return super()._step_action(action)

    def evaluate(self) -> dict:
        pos, quat = self.object_poses()
        target_pos = self._select_target(pos)
        c = self.target_compartment
        lo, hi = self._compartment_lo[c], self._compartment_hi[c]
        inside_xy = ((target_pos[:, :2] >= lo) & (target_pos[:, :2] <= hi)).all(dim=1)
        height = target_pos[:, 2] - self.layout.target_bin.floor_z_m
        success = inside_xy & (height >= 0) & (height <= self.layout.success_max_height_m)
        tcp_pos = self.agent.tcp_pose.p
        distance = self._select_target(distance_to_objects(tcp_pos, pos, quat, self.objects_spec))
        self.reached |= (distance <= self.layout.reach_threshold_m) & ~self.grip_attempted
        lifted = target_pos[:, 2] - self.target_start_z >= self.layout.lift_threshold_m
        self.grasped |= self.reached & lifted
        self.success_once |= success
        # the contact-force grasp test costs ~2 ms per step: call is_grasping_target() on demand;
        # tcp_pos and object_raw_poses (n, 4, 7: xyz + wxyz) are reused by _get_obs_extra
        return {
            "success": success,
            "success_once": self.success_once.clone(),
            "reached": self.reached.clone(),
            "grasped": self.grasped.clone(),
            "grip_attempted": self.grip_attempted.clone(),
            "target_distance_m": distance,
            "task": self.task.clone(),
            "tcp_pos": tcp_pos,
            "object_raw_poses": torch.cat([pos, quat], dim=2),
        }

    def _get_obs_extra(self, info: dict) -> dict:
        obs = dict(
            tcp_pos=info["tcp_pos"],
            gripper_opening_m=self.gripper_opening_m()[:, None],
            task_one_hot=torch.nn.functional.one_hot(self.task, NUM_TASKS).float(),
        )
        if "state" in self.obs_mode:
            raw = info["object_raw_poses"]
            pos, quat = raw[..., :3], raw[..., 3:]
            obs.update(
                object_poses=raw.flatten(1),
                target_pos=self._select_target(pos),
                target_quat=self._select_target(quat),
                goal_pos=self.compartment_center(),
            )
        return obs

    def compute_sparse_reward(self, obs: Any, action: torch.Tensor, info: dict) -> torch.Tensor:
        return info["success"].float()

    # ------------------------------------------------------------------ state
    _TASK_STATE = ("task", "grip_attempted", "reached", "grasped", "success_once", "target_start_z")
    """Per-env task attributes saved beside the scene state."""

    def get_state_dict(self) -> dict:
        """Scene state plus the per-env task and latched flags under ``"task_state"`` ((n, 1)
        floats,
        so :meth:`get_state` can flatten them; :meth:`set_state` restores the scene only)."""
        state = super().get_state_dict()
        state["task_state"] = {
            name: getattr(self, name).to(torch.float32)[:, None].clone()
            for name in self._TASK_STATE
        }
        return state

    def set_state_dict(self, state: dict, env_idx: torch.Tensor | None = None) -> None:
        state = dict(state)
        task_state = state.pop("task_state", None)
        super().set_state_dict(state, env_idx)
        if task_state is None:
            return
        idx = slice(None) if env_idx is None else env_idx
        for name in self._TASK_STATE:
            current = getattr(self, name)
            value = torch.as_tensor(task_state[name], device=self.device).reshape(self.num_envs)
            current[idx] = value[idx].to(current.dtype)

"""ManiSkill controllers for the 4-D action space: mink IK for the arm, a binary gripper.

Seated where ManiSkill seats its own IK controller: :class:`MinkEEPosController` subclasses
``PDJointPosController`` (joint PD drives do the tracking) and is chosen through its config's
``controller_cls``. Per control step and env::

    a[0:3] in [-1,1] --clip--> delta = a * max_step_m  (world axes, rotated into the base frame)
    p_now = FK(q_measured)                              (MuJoCo model of the same URDF)
    p*    = clip(p_now + delta, workspace_low_m, workspace_high_m)
    q*    = mink IK(q_measured -> p*, gripper pointing down, joint limits)   -> joint drive targets
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from gymnasium import spaces
from mani_skill.agents.controllers.pd_joint_pos import (
    PDJointPosController,
    PDJointPosControllerConfig,
    PDJointPosMimicController,
    PDJointPosMimicControllerConfig,
)

from awda_bench.robot.ik import IKConfig, PandaIK


class MinkEEPosController(PDJointPosController):
    """TCP position deltas in [-1, 1]^3 -> arm joint targets by mink differential IK."""

    config: MinkEEPosControllerConfig

    def _initialize_joints(self) -> None:
        super()._initialize_joints()
        n = self.scene.num_envs
        self.solvers = [PandaIK(self.config.ik) for _ in range(n)]
        """One IK instance (MuJoCo data + mink tasks) per env."""
        self._low = np.asarray(self.config.workspace_low_m, dtype=np.float64)
        self._high = np.asarray(self.config.workspace_high_m, dtype=np.float64)
        self._max_reach = float(self.config.max_reach_xy_m)
        self.last_target_pos = np.zeros((n, 3))
        """TCP targets of the last step, base frame [m] (after workspace clipping)."""
        self.last_ik_error = np.zeros(n)
        """Remaining model TCP error of the last IK solve per env [m]."""

    def _initialize_action_space(self) -> None:
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)

    _base_rotation_cache: np.ndarray | None = None

    def reset(self) -> None:
        super().reset()
        self._base_rotation_cache = None

    def set_state(self, state: dict) -> None:
        super().set_state(state)
        self._base_rotation_cache = None

    def _base_rotation(self) -> np.ndarray:
        """(n, 3, 3) rotation of the robot base in the world, read once per episode (fixed base)."""
        if self._base_rotation_cache is None:
            pose = self.articulation.root.pose
            matrix = pose.to_transformation_matrix()[:, :3, :3].cpu().numpy().astype(np.float64)
            self._base_rotation_cache = matrix
        return self._base_rotation_cache

    def set_action(self, action: torch.Tensor) -> None:
        self._step = 0
        qpos_all = self.articulation.get_qpos()
        self._start_qpos = qpos_all[:, self.active_joint_indices]
        commands = np.clip(action.detach().cpu().numpy().astype(np.float64), -1.0, 1.0)
        delta_world = commands * self.config.max_step_m
        rotation = self._base_rotation()
        qpos = qpos_all.cpu().numpy()
        targets = np.empty((len(qpos), len(self.solvers[0].arm_qpos_index)))
        for i, solver in enumerate(self.solvers):
            delta_base = rotation[i % len(rotation)].T @ delta_world[i]
            q_arm, target, error = solver.solve_delta(
                qpos[i], delta_base, self._low, self._high, self._max_reach
            )
            targets[i] = q_arm
            self.last_target_pos[i] = target
            self.last_ik_error[i] = error
        self._target_qpos = torch.as_tensor(
            targets, dtype=self._start_qpos.dtype, device=self.device
        )
        if self.scene.gpu_sim_enabled:
            self.set_drive_targets(self._target_qpos)
        else:
            # CPU sim: one SAPIEN call per joint and sub-scene, skipping ManiSkill's per-joint tensor
            # conversions (measured ~0.1 ms/step); same effect as set_drive_targets.
            for i, joint in enumerate(self.joints):
                for env_index, physx_joint in enumerate(joint._objs):
                    physx_joint.set_drive_target(float(targets[env_index, i]))


@dataclass
class MinkEEPosControllerConfig(PDJointPosControllerConfig):
    """Arm controller of ``panda_awda`` (``lower``/``upper`` are unused: the action is normalized)."""

    max_step_m: float = 0.02
    """TCP displacement commanded by a unit action component in one control step [m]
    (at 20 Hz control: 0.4 m/s per axis at most)."""
    workspace_low_m: tuple[float, float, float] = (0.25, -0.50, 0.01)
    """Lower corner of the box TCP targets are clipped to, robot base frame [m]."""
    workspace_high_m: tuple[float, float, float] = (0.78, 0.50, 0.55)
    """Upper corner of that box, robot base frame [m]."""
    max_reach_xy_m: float = 0.78
    """TCP targets are also clipped to this horizontal distance from the base axis [m]. Measured
    with the gripper pointing down: every target with radius <= 0.75 m and z <= 0.4 m is reached to
    < 1 mm; at 0.80 m the error grows to 3-5 cm (the arm is stretched)."""
    ik: IKConfig = field(default_factory=IKConfig)
    """mink solve settings."""
    normalize_action: bool = False
    controller_cls = MinkEEPosController

    def __post_init__(self) -> None:
        if not self.max_step_m > 0:
            raise ValueError(f"max_step_m must be > 0, got {self.max_step_m}")
        if any(
            lo >= hi for lo, hi in zip(self.workspace_low_m, self.workspace_high_m, strict=True)
        ):
            raise ValueError(
                f"workspace_low_m {self.workspace_low_m} must be below workspace_high_m {self.workspace_high_m}"
            )


class BinaryGripperController(PDJointPosMimicController):
    """One number per env: > 0 drives the fingers closed, <= 0 open.

    The drive targets are written only when the command changes (they persist in PhysX); the
    command is controller state, so ``get_state``/``set_state`` carry it and restoring re-applies it.
    """

    config: BinaryGripperControllerConfig
    _closed: torch.Tensor | None = None
    """(n, 1) commanded state: True = closed (set at every reset, so always present after one)."""

    def _initialize_action_space(self) -> None:
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def reset(self) -> None:
        super().reset()
        # envs being reset start open (the rest keyframe's fingers), and their drive targets must
        # say so: a drive target left closed by the previous episode would otherwise persist.
        if self._closed is None:
            closed = torch.zeros((self.scene.num_envs, 1), dtype=torch.bool, device=self.device)
        else:
            closed = self._closed.clone()
            closed[self.scene._reset_mask] = False
        self._apply(closed)

    def get_state(self) -> dict:
        assert self._closed is not None, "reset() sets the command"
        return {"closed": self._closed.clone()}

    def set_state(self, state: dict) -> None:
        if "closed" in state:
            self._apply(state["closed"].to(self.device).bool())

    def set_action(self, action: torch.Tensor) -> None:
        closed = action[:, :1] > 0
        if self._closed is not None and torch.equal(closed, self._closed):
            return
        self._apply(closed)

    def _apply(self, closed: torch.Tensor) -> None:
        self._closed = closed.clone()
        target = torch.where(
            closed,
            torch.full(closed.shape, self.config.closed_qpos_m, device=self.device),
            torch.full(closed.shape, self.config.open_qpos_m, device=self.device),
        )
        self._step = 0
        self._start_qpos = self.qpos
        self._target_qpos[:, self.control_joint_indices] = target.to(self._target_qpos.dtype)
        self._target_qpos[:, self.mimic_joint_indices] = (
            self._target_qpos[:, self.mimic_control_joint_indices] * self._multiplier[None, :]
            + self._offset[None, :]
        )
        self.set_drive_targets(self._target_qpos)


@dataclass
class BinaryGripperControllerConfig(PDJointPosMimicControllerConfig):
    """Finger targets for the two gripper states."""

    closed_qpos_m: float = -0.01
    """Finger joint target when closing [m] (below the 0 limit so thin objects feel force)."""
    open_qpos_m: float = 0.04
    """Finger joint target when open [m] (the joint's upper limit)."""
    normalize_action: bool = False
    controller_cls = BinaryGripperController

"""ManiSkill controllers for the 4-D action space: mink IK for the arm, a binary gripper.

Seated where ManiSkill seats its own IK controller: :class:`MinkEEPosController` subclasses
``PDJointPosController`` (joint PD drives do the tracking) and is chosen through its config's
``controller_cls``. Per control step and env::

    a[0:3] in [-1,1] --clip--> delta = a * max_step_m  (world axes, rotated into the base frame)
    p_meas = FK(q_measured)                             (MuJoCo model of the same URDF)
    p*     = advance_target(p*_prev, p_meas, delta)     (accumulated: p*_prev kept within
                                                         max_lag_m of p_meas, + delta; workspace
                                                         box and reach)
    q*     = mink IK(q*_prev -> p*, gripper pointing down, joint limits)
    drives : position target q*, velocity target (q* - q*_prev) * control_freq

Why each piece (``python -m awda_bench bench controller --fidelity``, pick-place scene, CPU sim):

- The first controller re-based every step on the *measured* TCP, and the joint PD drives
  (stiffness 1e3, damping 1e2, no velocity target) lag their targets by ~2 control steps, so the
  commanded lead was mostly eaten: achieved/commanded 0.39 at every magnitude from 1 mm/step up,
  0.00 at 0.4 mm/step (a dead band), top speed 7.9 mm/step. Accumulating the target from the
  previous target makes the steady-state gain 1.00 for every magnitude (0.99-1.00 measured).
- Accumulation alone leaves the lag, and a proportional law on the measured TCP then overshoots
  (k = 1: 9.7 mm). Stiffer drives (1e4 / 5e2, the agent's ``mink_arm_*``) and the velocity
  feed-forward bring that to 1.8 mm with 0.01-0.02 mm final error at k = 0.25 .. 1 (without
  feed-forward: 9 mm at k = 1, 2.9 mm at k = 0.5).
- The IK is warm-started from the previous joint targets and iterates to ``IKConfig.tolerance_m``
  = 0.01 mm (a 1 mm tolerance was a second dead band); one QP solve per step suffices because
  the residual is removed by the next step's solve toward the same absolute target.
- Blocked motion (pressing, pushing on the table, workspace clipping) cannot wind up: the target
  carries at most ``max_lag_m`` past the measured TCP into the next step; after 20 steps pressing
  on the table at full scale the TCP rises on the first step of an up command.

Whatever is carried from step to step (target, joint targets) is controller state: ``get_state``
saves it, ``set_state`` restores it (a restored scene continues as the original would), and
``reset`` re-synchronizes it to the measured pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from mani_skill.agents.controllers.pd_joint_pos import (
    PDJointPosController,
    PDJointPosControllerConfig,
    PDJointPosMimicController,
    PDJointPosMimicControllerConfig,
)
from mani_skill.utils import common

from awda_bench.robot.ik import IKConfig, PandaIK
from awda_bench.robot.tcp_target import advance_target, check_target_bounds


class MinkEEPosController(PDJointPosController):
    """TCP position deltas in [-1, 1]^3 -> arm joint targets by mink differential IK.

    Controller state (``get_state``/``set_state``, re-synchronized to the measured pose by
    ``reset``): the accumulated TCP target (base frame) and the arm's joint targets.
    """

    config: MinkEEPosControllerConfig

    def _initialize_joints(self) -> None:
        super()._initialize_joints()
        n = self.scene.num_envs
        self.solvers = [PandaIK(self.config.ik) for _ in range(n)]
        """One IK instance (MuJoCo data + mink tasks) per env."""
        self._low = np.asarray(self.config.workspace_low_m, dtype=np.float64)
        self._high = np.asarray(self.config.workspace_high_m, dtype=np.float64)
        self._max_reach = float(self.config.max_reach_xy_m)
        self.target_pos = np.zeros((n, 3))
        """Accumulated TCP target per env, base frame [m] (controller state)."""
        self.joint_target = np.zeros((n, len(self.joints)))
        """Arm joint targets of the last IK solve per env [rad] (controller state)."""
        self.last_ik_error = np.zeros(n)
        """Remaining model TCP error of the last IK solve per env [m]."""

    def _initialize_action_space(self) -> None:
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)

    _base_rotation_cache: np.ndarray | None = None

    @property
    def last_target_pos(self) -> np.ndarray:
        """(n, 3) TCP targets after the last step, base frame [m] (after workspace clipping)."""
        return self.target_pos

    def reset(self) -> None:
        super().reset()
        self._base_rotation_cache = None
        mask = self.scene._reset_mask.cpu().numpy()
        qpos = self.articulation.get_qpos().cpu().numpy().astype(np.float64)
        for i, solver in enumerate(self.solvers):
            if mask is not None and not mask[i]:
                continue
            self.target_pos[i] = solver.tcp_position(qpos[i])
            self.joint_target[i] = qpos[i, solver.arm_qpos_index]
        self._apply(self.joint_target, np.zeros_like(self.joint_target))

    def get_state(self) -> dict:
        return {
            "target_pos": torch.as_tensor(self.target_pos.copy(), dtype=torch.float64),
            "joint_target": torch.as_tensor(self.joint_target.copy(), dtype=torch.float64),
        }

    def set_state(self, state: dict | None) -> None:
        """Restore the target and re-apply the joint targets (velocity targets zero: a restored
        scene's joint velocities come with the articulation state)."""
        if not state:
            return
        # tensors from get_state_dict, or arrays from a trajectory file's env_states
        self.target_pos = common.to_numpy(state["target_pos"]).astype(np.float64).reshape(-1, 3)
        self.joint_target = (
            common.to_numpy(state["joint_target"])
            .astype(np.float64)
            .reshape(len(self.target_pos), -1)
        )
        self._base_rotation_cache = None
        self._apply(self.joint_target, np.zeros_like(self.joint_target))

    def _base_rotation(self) -> np.ndarray:
        """(n, 3, 3) rotation of the robot base in the world, read once per episode (fixed base)."""
        if self._base_rotation_cache is None:
            pose = self.articulation.root.pose
            matrix = pose.to_transformation_matrix()[:, :3, :3].cpu().numpy().astype(np.float64)
            self._base_rotation_cache = matrix
        return self._base_rotation_cache

    def set_action(self, action: torch.Tensor) -> None:
        cfg = self.config
        commands = np.clip(action.detach().cpu().numpy().astype(np.float64), -1.0, 1.0)
        rotation = self._base_rotation()
        # world-frame deltas into each env's base frame: delta_base = R^T delta_world
        delta_base = np.einsum("nji,nj->ni", rotation, commands * cfg.max_step_m)
        qpos = self.articulation.get_qpos().cpu().numpy().astype(np.float64)
        measured = np.stack([s.tcp_position(q) for s, q in zip(self.solvers, qpos, strict=True)])
        self.target_pos = advance_target(
            self.target_pos,
            measured,
            delta_base,
            self._low,
            self._high,
            cfg.max_lag_m,
            self._max_reach,
        )
        previous = self.joint_target.copy()
        for i, solver in enumerate(self.solvers):
            self.joint_target[i], self.last_ik_error[i] = solver.solve(
                self.joint_target[i], self.target_pos[i]
            )
        velocity = (self.joint_target - previous) * (self._control_freq * cfg.velocity_feedforward)
        self._apply(self.joint_target, velocity)

    @property  # type: ignore[override]
    def _target_qpos(self) -> torch.Tensor:
        """ManiSkill's view of the joint targets (built on demand, not every step)."""
        return torch.as_tensor(self.joint_target, dtype=torch.float32, device=self.device)

    @_target_qpos.setter
    def _target_qpos(self, value: torch.Tensor | None) -> None:
        if value is not None and hasattr(self, "joint_target"):
            self.joint_target = (
                value.detach().cpu().numpy().astype(np.float64).reshape(self.joint_target.shape)
            )

    def _apply(self, targets: np.ndarray, velocities: np.ndarray) -> None:
        """Write joint position and velocity drive targets."""
        self._step = 0
        if self.scene.gpu_sim_enabled:
            self.set_drive_targets(self._target_qpos)
            self.articulation.set_joint_drive_velocity_targets(
                torch.as_tensor(velocities, dtype=torch.float32, device=self.device),
                self.joints,
                self.active_joint_indices,
            )
            return
        # CPU sim: one SAPIEN call per joint and sub-scene, skipping ManiSkill's per-joint tensor
        # conversions (measured ~0.1 ms/step); same effect as set_drive_targets.
        for i, joint in enumerate(self.joints):
            for env_index, physx_joint in enumerate(joint._objs):
                physx_joint.set_drive_target(float(targets[env_index, i]))
                physx_joint.set_drive_velocity_target(float(velocities[env_index, i]))


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
    max_lag_m: float = 0.01
    """The target carries at most this far past the measured TCP into the next step [m]
    (blocked motion does not wind up; see :mod:`awda_bench.robot.tcp_target`)."""
    velocity_feedforward: float = 1.0
    """Joint velocity targets = this x (joint-target change per control step) / control period."""
    max_reach_xy_m: float = 0.78
    """TCP targets are also clipped to this horizontal distance from the base axis [m]. Measured
    with the gripper pointing down: every target with radius <= 0.75 m and z <= 0.4 m is reached to
    < 1 mm; at 0.80 m the error grows to 3-5 cm (the arm is stretched)."""
    ik: IKConfig = field(default_factory=IKConfig)
    """mink solve settings."""
    normalize_action: bool = False
    controller_cls = MinkEEPosController

    def __post_init__(self) -> None:
        check_target_bounds(self.max_step_m, self.workspace_low_m, self.workspace_high_m)


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

    @property
    def commanded_closed(self) -> torch.Tensor:
        """(n,) bool: the fingers are being driven closed (the last command)."""
        assert self._closed is not None, "reset() sets the command"
        return self._closed[:, 0].clone()

    def get_state(self) -> dict:
        assert self._closed is not None, "reset() sets the command"
        return {"closed": self._closed.clone()}

    def set_state(self, state: dict) -> None:
        if state and "closed" in state:
            # tensors from get_state_dict, or arrays from a trajectory file's env_states
            closed = common.to_tensor(state["closed"], device=self.device).bool()
            self._apply(closed.reshape(self.scene.num_envs, 1))

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


def gripper_commanded_closed(agent: Any) -> torch.Tensor:
    """(n,) bool: ``agent``'s gripper (either embodiment) was last commanded to close."""
    gripper = agent.controller.controllers["gripper"]
    assert isinstance(gripper, BinaryGripperController)
    return gripper.commanded_closed


@dataclass
class BinaryGripperControllerConfig(PDJointPosMimicControllerConfig):
    """Finger targets for the two gripper states."""

    closed_qpos_m: float = -0.01
    """Finger joint target when closing [m] (below the 0 limit so thin objects feel force)."""
    open_qpos_m: float = 0.04
    """Finger joint target when open [m] (the joint's upper limit)."""
    normalize_action: bool = False
    controller_cls = BinaryGripperController


def panda_gripper_config(agent: Any) -> BinaryGripperControllerConfig:
    """The binary gripper controller of a Panda hand, as both embodiments drive it: the second
    finger mimics the first, the drives take ``agent``'s gripper stiffness, damping and force
    limit (``agent``: a ManiSkill Panda or Panda-hand agent)."""
    return BinaryGripperControllerConfig(
        joint_names=agent.gripper_joint_names,
        lower=-0.01,
        upper=0.04,
        stiffness=agent.gripper_stiffness,
        damping=agent.gripper_damping,
        force_limit=agent.gripper_force_limit,
        mimic={"panda_finger_joint2": {"joint": "panda_finger_joint1"}},
    )

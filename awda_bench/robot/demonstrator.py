"""The demonstrator embodiment: a floating Panda hand, recoloured, with the agent's 4-D actions.

The demo videos a one-shot policy watches must come from an embodiment that *looks different* from
the agent (the references used a Sawyer demonstrator for a Panda agent). Only robot assets shipped
in
the ``mani-skill`` wheel may be used, so the demonstrator is ManiSkill's ``floating_panda_gripper``
(``panda_v2_gripper.urdf``: a Panda hand on six virtual root joints, no arm), painted a dark blue so
it is distinguishable from the white Panda arm at a glance, with gravity disabled on its links (it
floats like a mocap hand).

Its controller has the semantics of the agent's ``pd_ee_delta_pos_mink``::

    action[:, 0:3] in [-1, 1] -> target_xyz = previous target_xyz + action * max_step_m
                                  (world axes; no IK needed: the root's three prismatic joints
                                  *are* the TCP translation), clipped to
                                  [workspace_low_m, workspace_high_m] (root-joint coordinates)
                                  carrying at most max_lag_m past the measured root position
                                  (:mod:`awda_bench.robot.tcp_target`, as the agent's)
    rotation joints held at their reset values (pointing down)
    action[:, 3] > 0 closes the fingers, <= 0 opens them
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sapien
import torch
from gymnasium import spaces
from mani_skill.agents.base_agent import Keyframe
from mani_skill.agents.controllers.pd_joint_pos import (
    PDJointPosController,
    PDJointPosControllerConfig,
)
from mani_skill.agents.registration import register_agent
from mani_skill.agents.robots.floating_panda_gripper import FloatingPandaGripper
from mani_skill.utils import common
from mani_skill.utils.structs.actor import Actor

from awda_bench.robot.controller import panda_gripper_config
from awda_bench.robot.tcp_target import advance_target, check_target_bounds

DEMONSTRATOR_UID = "awda_demonstrator"
"""ManiSkill agent uid of the demonstrator."""

DEMONSTRATOR_CONTROL_MODE = "pd_ee_delta_pos"
"""Its only control mode: 4-D normalized TCP delta + binary gripper."""

DEMONSTRATOR_COLOR = (0.12, 0.20, 0.55, 1.0)
"""RGBA base colour painted over every visual part of the hand (the agent's Panda is white)."""

TCP_BELOW_ROOT_M = 0.1034
"""The TCP hangs this far below the root-joint origin when the hand points down [m]
(``panda_hand_tcp_joint`` offset of ``panda_v2_gripper.urdf``)."""


class FloatingDeltaPosController(PDJointPosController):
    """TCP position deltas in [-1, 1]^3 on a floating hand's six root joints (rotation held)."""

    config: FloatingDeltaPosControllerConfig
    _target_qpos: torch.Tensor

    def _initialize_action_space(self) -> None:
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)

    def set_action(self, action: torch.Tensor) -> None:
        cfg = self.config
        commands = np.clip(action.detach().cpu().numpy().astype(np.float64), -1.0, 1.0)
        measured = self.qpos[:, :3].detach().cpu().numpy().astype(np.float64)
        current = self._target_qpos[:, :3].detach().cpu().numpy().astype(np.float64)
        target = advance_target(
            current,
            measured,
            commands * cfg.max_step_m,
            np.asarray(cfg.workspace_low_m),
            np.asarray(cfg.workspace_high_m),
            cfg.max_lag_m,
        )
        self._step = 0
        self._target_qpos = self._target_qpos.clone()
        self._target_qpos[:, :3] = torch.as_tensor(
            target, dtype=self._target_qpos.dtype, device=self.device
        )
        self.set_drive_targets(self._target_qpos)

    def reset(self) -> None:
        """Targets re-synchronized to the measured pose (ManiSkill's reset does it for reset envs)."""
        super().reset()
        self.set_drive_targets(self._target_qpos)

    def get_state(self) -> dict:
        return {"target_qpos": self._target_qpos.clone()}

    def set_state(self, state: dict | None) -> None:
        if not state:
            return
        # tensors from get_state_dict, or arrays from a trajectory file's env_states
        # (unbatched when a replay hands over one step of a single env's trajectory)
        target = common.to_tensor(state["target_qpos"], device=self.device).clone()
        self._target_qpos = target.reshape(self.scene.num_envs, -1).to(torch.float32)
        self.set_drive_targets(self._target_qpos)


@dataclass
class FloatingDeltaPosControllerConfig(PDJointPosControllerConfig):
    """Root controller of the demonstrator (``lower``/``upper`` unused: the action is normalized).

    ``joint_names`` must list the three prismatic root joints first, then the three rotations.
    """

    max_step_m: float = 0.02
    """TCP displacement of a unit action component in one control step [m] (as the agent's)."""
    max_lag_m: float = 0.01
    """The target carries at most this far past the measured root position into the next step
    [m] (as the agent's; :mod:`awda_bench.robot.tcp_target`)."""
    workspace_low_m: tuple[float, float, float] = (-0.45, -0.55, 0.11)
    """Lower corner of the box root-joint targets are clipped to [m] (z: TCP 0.7 cm above table)."""
    workspace_high_m: tuple[float, float, float] = (0.30, 0.55, 0.80)
    """Upper corner of that box [m]."""
    normalize_action: bool = False
    controller_cls = FloatingDeltaPosController

    def __post_init__(self) -> None:
        check_target_bounds(self.max_step_m, self.workspace_low_m, self.workspace_high_m)


@register_agent()
class AwdaDemonstrator(FloatingPandaGripper):
    """Floating Panda hand, dark blue, 4-D action space (see the module docstring)."""

    uid = DEMONSTRATOR_UID
    keyframes = dict(
        rest=Keyframe(
            # root x, y, z [m]; root rotations x, y, z [rad] (y = pi: pointing down); fingers [m]
            qpos=np.array([-0.10, 0.0, 0.28 + TCP_BELOW_ROOT_M, 0.0, np.pi, 0.0, 0.04, 0.04]),
            pose=sapien.Pose(),
        )
    )
    root_stiffness = 1e5
    """Root joint drive stiffness [N/m, N m/rad]: tracks a 2 cm step within one control step."""
    root_damping = 1.5e3
    """Root joint drive damping."""
    root_force_limit = 500.0
    """Root joint force limit [N]."""

    @property
    def _controller_configs(self) -> dict:
        root = FloatingDeltaPosControllerConfig(
            joint_names=self.root_joint_names,
            lower=None,
            upper=None,
            stiffness=self.root_stiffness,
            damping=self.root_damping,
            force_limit=self.root_force_limit,
        )
        # the agent's gripper controller: action[3] > 0 closes, the command is controller state
        return {DEMONSTRATOR_CONTROL_MODE: dict(arm=root, gripper=panda_gripper_config(self))}

    def _after_init(self) -> None:
        super()._after_init()
        for link in self.robot.get_links():
            link.disable_gravity = True
        self._paint(DEMONSTRATOR_COLOR)

    def _paint(self, rgba: tuple[float, float, float, float]) -> None:
        """Set the base colour of every visual part of every link (all parallel scenes)."""
        for link in self.robot.get_links():
            for obj in link._objs:
                body = obj.entity.find_component_by_type(sapien.render.RenderBodyComponent)
                if body is None:
                    continue
                for shape in body.render_shapes:
                    for part in shape.parts:
                        part.material.set_base_color(list(rgba))

    @property
    def tcp_pos(self) -> torch.Tensor:
        """(n, 3) TCP position in the world [m]."""
        return self.tcp.pose.p

    @property
    def tcp_pose(self):
        return self.tcp.pose

    @property
    def gripper_opening_m(self) -> torch.Tensor:
        """(n,) distance between the two fingers [m] (sum of the two finger joints)."""
        qpos = self.robot.get_qpos()
        return qpos[:, -2] + qpos[:, -1]

    def is_grasping(
        self, object: Actor, min_force: float = 0.5, max_angle: float = 85
    ) -> torch.Tensor:
        """(n,) both fingers push on ``object`` with >= ``min_force`` [N] (Panda's test)."""
        l_contact_forces = self.scene.get_pairwise_contact_forces(self.finger1_link, object)
        r_contact_forces = self.scene.get_pairwise_contact_forces(self.finger2_link, object)
        lforce = torch.linalg.norm(l_contact_forces, axis=1)
        rforce = torch.linalg.norm(r_contact_forces, axis=1)
        ldirection = self.finger1_link.pose.to_transformation_matrix()[..., :3, 1]
        rdirection = -self.finger2_link.pose.to_transformation_matrix()[..., :3, 1]
        langle = common.compute_angle_between(ldirection, l_contact_forces)
        rangle = common.compute_angle_between(rdirection, r_contact_forces)
        lflag = torch.logical_and(lforce >= min_force, torch.rad2deg(langle) <= max_angle)
        rflag = torch.logical_and(rforce >= min_force, torch.rad2deg(rangle) <= max_angle)
        return torch.logical_and(lflag, rflag)

    def is_static(self, threshold: float = 0.2) -> torch.Tensor:
        qvel = self.robot.get_qvel()[..., :-2]
        return torch.max(torch.abs(qvel), 1)[0] <= threshold

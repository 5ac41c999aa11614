"""``panda_awda``: ManiSkill's Panda with a wrist depth camera and the method's 4-D action space.

Control mode ``pd_ee_delta_pos_mink`` (the default): ``action = (dx, dy, dz, grip)`` in [-1, 1],
see :mod:`awda_bench.robot.controller`. The Panda's own control modes stay available
(``pd_joint_pos``, ``pd_ee_delta_pos``, ...) for the controller benchmark.

The wrist depth camera ``wrist_depth`` sits on the hand 4 cm off the gripper axis and is tilted to
look at the point 15 cm below the TCP (the grasp primitive's hover height), field of view 90°.
Its size is set per env with ``gym.make(..., sensor_configs={"wrist_depth": {"width": W, "height": H}})``.
"""

from __future__ import annotations

import copy

import numpy as np
import sapien
import torch
from mani_skill.agents.registration import register_agent
from mani_skill.agents.robots.panda.panda import Panda
from mani_skill.sensors.camera import CameraConfig

from awda_bench.robot.action import ACTION_DIM, validate_action
from awda_bench.robot.controller import MinkEEPosControllerConfig, panda_gripper_config

CONTROL_MODE = "pd_ee_delta_pos_mink"
"""The 4-D action space of the method, driven by mink IK."""
WRIST_CAMERA = "wrist_depth"
"""Sensor uid of the eye-in-hand depth camera."""

TCP_OFFSET_IN_HAND_M = 0.1034
"""TCP position along the hand's z axis (from ``panda_v2.urdf``) [m]."""


def wrist_camera_pose(
    offset_m: float = 0.04, look_below_tcp_m: float = 0.15, height_m: float = 0.04
) -> sapien.Pose:
    """Camera pose in the ``panda_hand`` frame (SAPIEN camera convention: looks along +x, z up).

    The camera sits ``offset_m`` off the gripper axis along the hand's x axis, ``height_m`` along
    its z axis, and looks at the point ``look_below_tcp_m`` beyond the TCP on the gripper axis.
    """
    eye = np.array([offset_m, 0.0, height_m])
    target = np.array([0.0, 0.0, TCP_OFFSET_IN_HAND_M + look_below_tcp_m])
    forward = target - eye
    forward /= np.linalg.norm(forward)
    up_hint = np.array([-1.0, 0.0, 0.0])
    left = np.cross(up_hint, forward)
    left /= np.linalg.norm(left)
    up = np.cross(forward, left)
    matrix = np.eye(4)
    matrix[:3, :3] = np.stack([forward, left, up], axis=1)
    matrix[:3, 3] = eye
    return sapien.Pose(matrix)


@register_agent()
class PandaAwda(Panda):
    """Franka Panda, eye-in-hand depth camera, 4-D mink-IK action space."""

    uid = "panda_awda"

    wrist_camera_size: tuple[int, int] = (128, 128)
    """Default (height, width) of the wrist depth image [px]."""
    wrist_camera_fov_rad: float = np.pi / 2
    mink_arm_stiffness: float = 1e4
    """Arm joint drive stiffness under ``pd_ee_delta_pos_mink`` [N m/rad] (10x the Panda's
    default: with 1e3 the arm lagged its target ~2 control steps, and the proportional law
    ``a = k (goal - tcp)`` overshot by 10 mm at k = 1; ``bench controller --fidelity``)."""
    mink_arm_damping: float = 5e2
    """Arm joint drive damping under ``pd_ee_delta_pos_mink`` [N m s/rad] (2e2 and 3e2 overshot
    3-6 mm at k = 1; 5e2: 1.8 mm)."""
    mink_arm_drive_mode: str = "force"
    """PhysX drive mode (``acceleration`` drives oscillated, measured: 30 mm drift)."""
    """Wrist camera field of view [rad] (90°, as in the references)."""

    @property
    def _sensor_configs(self) -> list[CameraConfig]:
        height, width = self.wrist_camera_size
        return [
            CameraConfig(
                uid=WRIST_CAMERA,
                pose=wrist_camera_pose(),
                width=width,
                height=height,
                fov=self.wrist_camera_fov_rad,
                near=0.01,
                far=10.0,
                mount=self.robot.links_map["panda_hand"],
            )
        ]

    @property
    def _controller_configs(self) -> dict:
        arm = MinkEEPosControllerConfig(
            joint_names=self.arm_joint_names,
            lower=None,
            upper=None,
            stiffness=self.mink_arm_stiffness,
            damping=self.mink_arm_damping,
            force_limit=self.arm_force_limit,
            drive_mode=self.mink_arm_drive_mode,
        )
        configs = {CONTROL_MODE: {"arm": arm, "gripper": panda_gripper_config(self)}}
        configs.update(super()._controller_configs)
        return copy.deepcopy(configs)

    def set_action(self, action: object) -> None:
        """Validate the action (shape, finite) before the controller sees it; ``ValueError`` otherwise."""
        if self.control_mode == CONTROL_MODE:
            # validate_action already refused NaN/inf, so BaseAgent's own NaN check is skipped.
            self.controller.set_action(
                validate_action(action, self.scene.num_envs, ACTION_DIM).to(self.device)
            )
        else:
            super().set_action(action)

    @property
    def gripper_opening_m(self) -> torch.Tensor:
        """(n,) distance between the fingers [m]: the sum of the two finger joint positions."""
        return self.robot.get_qpos()[:, -2:].sum(dim=-1)

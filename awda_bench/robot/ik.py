"""Differential inverse kinematics for the Panda's TCP with mink.

Given the arm's joint positions ``q`` and a desired TCP position ``p*`` (robot base frame), find
joint targets ``q*`` whose TCP is at ``p*`` with the gripper pointing straight down. Each iteration
solves mink's QP

    min_v  ||e_frame(q) - J_frame v dt||²_W  +  ||e_posture(q) - v dt||²_{w_p}  +  damping ||v||²
    s.t.   q_min <= q + v dt <= q_max                       (ConfigurationLimit)

and integrates ``q <- q + v dt``. For the small per-step moves of the 4-D action space (<= 2 cm)
one to three iterations reach sub-millimetre error in the model.
"""

from __future__ import annotations

from dataclasses import dataclass

import mink
import mujoco
import numpy as np

from awda_bench.robot.panda_model import ARM_JOINTS, TCP_SITE, load_panda_model

REST_QPOS = np.array(
    [0.0, np.pi / 8, 0.0, -np.pi * 5 / 8, 0.0, np.pi * 3 / 4, np.pi / 4, 0.04, 0.04]
)
"""ManiSkill's Panda ``rest`` keyframe (arm + fingers); its TCP points straight down."""


@dataclass(frozen=True)
class IKConfig:
    """Weights and stopping rule of the mink IK solve."""

    position_cost: float = 1.0
    """Frame-task weight on TCP position error [1/m]."""
    orientation_cost: float = 0.5
    """Frame-task weight on TCP orientation error [1/rad] (keeps the gripper pointing down)."""
    posture_cost: float = 1e-3
    """Posture-task weight pulling the arm toward the rest keyframe (resolves the redundant DOF)."""
    damping: float = 1e-4
    """Levenberg-Marquardt damping of the QP (regularises near singularities)."""
    dt_s: float = 1.0
    """Integration step of the velocity the QP returns [s]; 1 makes ``v`` a position increment."""
    max_iterations: int = 1
    """QP solves per call at most. One solve leaves ~0.25 mm of a 2 cm step (measured), which the
    closed loop (every control step starts from the measured joints) removes on the next step."""
    limit_margin_rad: float = 0.2
    """Joint-limit constraints enter the QP only when a limited joint is within this of a limit
    [rad]: one control step moves a joint by < 0.05 rad, so farther away they cannot be active,
    and leaving them out saves ~1/4 of a solve (measured ~40 us of ~150 us)."""
    tolerance_m: float = 1e-5
    """Stop iterating once the TCP is this close to the target in the model [m]."""
    solver: str = "daqp"
    """qpsolvers backend."""

    def __post_init__(self) -> None:
        for name in ("position_cost", "orientation_cost", "dt_s", "tolerance_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"IKConfig.{name} must be > 0, got {getattr(self, name)}")
        if self.max_iterations < 1:
            raise ValueError(f"IKConfig.max_iterations must be >= 1, got {self.max_iterations}")


class PandaIK:
    """mink IK on the Panda model compiled from ManiSkill's URDF (one instance per env)."""

    def __init__(self, config: IKConfig = IKConfig()) -> None:
        self.config = config
        self.model: mujoco.MjModel = load_panda_model()
        self.configuration = mink.Configuration(self.model)
        self.arm_qpos_index = np.array(
            [self.model.jnt_qposadr[self.model.joint(name).id] for name in ARM_JOINTS]
        )
        self.configuration.update(REST_QPOS.copy())
        self.down_rotation = self.configuration.get_transform_frame_to_world(
            TCP_SITE, "site"
        ).rotation()
        """TCP orientation held fixed: the rest keyframe's (gripper pointing down, fingers along y)."""
        self.frame_task = mink.FrameTask(
            frame_name=TCP_SITE,
            frame_type="site",
            position_cost=config.position_cost,
            orientation_cost=config.orientation_cost,
        )
        self.posture_task = mink.PostureTask(self.model, cost=config.posture_cost)
        self.posture_task.set_target(REST_QPOS.copy())
        self.tasks = [self.frame_task, self.posture_task]
        self.limits = [mink.ConfigurationLimit(self.model)]
        arm_joints = [self.model.joint(name).id for name in ARM_JOINTS]
        self._lower = self.model.jnt_range[arm_joints, 0].copy()
        self._upper = self.model.jnt_range[arm_joints, 1].copy()
        self._limited = self.model.jnt_limited[arm_joints].astype(bool)
        self.failures = 0
        """How many solves raised ``mink.NoSolutionFound`` (the previous ``q`` was kept)."""

    def tcp_position(self, qpos: np.ndarray) -> np.ndarray:
        """TCP position (base frame) [m] for full ``qpos`` (9,) or arm ``q`` (7,)."""
        self.configuration.update(self._full_qpos(qpos))
        return self.configuration.data.site(TCP_SITE).xpos.copy()

    def tcp_rotation(self, qpos: np.ndarray) -> np.ndarray:
        """TCP rotation matrix (base frame) for ``qpos``."""
        self.configuration.update(self._full_qpos(qpos))
        return self.configuration.data.site(TCP_SITE).xmat.reshape(3, 3).copy()

    def _full_qpos(self, qpos: np.ndarray) -> np.ndarray:
        qpos = np.asarray(qpos, dtype=np.float64)
        if qpos.shape == (self.model.nq,):
            return qpos.copy()
        if qpos.shape == (len(ARM_JOINTS),):
            full = REST_QPOS.copy()
            full[self.arm_qpos_index] = qpos
            return full
        raise ValueError(
            f"qpos must have shape ({self.model.nq},) or ({len(ARM_JOINTS)},), got {qpos.shape}"
        )

    def solve(self, qpos: np.ndarray, target_pos: np.ndarray) -> tuple[np.ndarray, float]:
        """Arm joint targets (7,) reaching ``target_pos`` (3,) [m, base frame] from ``qpos``.

        Returns ``(q_arm, error_m)`` where ``error_m`` is the remaining TCP position error in the
        model. Never returns NaN: a failed QP keeps the last good ``q``.
        """
        self.configuration.update(self._full_qpos(qpos))
        return self._iterate(np.asarray(target_pos, dtype=np.float64))

    def solve_delta(
        self,
        qpos: np.ndarray,
        delta_m: np.ndarray,
        low_m: np.ndarray,
        high_m: np.ndarray,
        max_reach_xy_m: float = np.inf,
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Move the TCP by ``delta_m`` (3,) from where ``qpos`` puts it, clipped to ``[low_m, high_m]``
        and to ``max_reach_xy_m`` horizontal distance from the base axis.

        One forward-kinematics pass serves both the current TCP and the first IK iteration.
        Returns ``(q_arm, target_pos, error_m)``, all in the base frame.
        """
        self.configuration.update(self._full_qpos(qpos))
        current = self.configuration.data.site(TCP_SITE).xpos
        target = np.clip(current + delta_m, low_m, high_m)
        radius = float(np.hypot(target[0], target[1]))
        if radius > max_reach_xy_m:
            target[:2] *= max_reach_xy_m / radius
        q_arm, error = self._iterate(target)
        return q_arm, target, error

    def _near_limit(self) -> bool:
        """Is any limited arm joint within ``limit_margin_rad`` of a limit at the current ``q``?
        (The fingers sit on their limit, but no task moves them.)"""
        q = self.configuration.q[self.arm_qpos_index]
        margin = self.config.limit_margin_rad
        near = (q - self._lower < margin) | (self._upper - q < margin)
        return bool((near & self._limited).any())

    def _iterate(self, target_pos: np.ndarray) -> tuple[np.ndarray, float]:
        cfg = self.config
        self.frame_task.set_target(
            mink.SE3.from_rotation_and_translation(self.down_rotation, target_pos)
        )
        data = self.configuration.data
        error = float(np.linalg.norm(data.site(TCP_SITE).xpos - target_pos))
        for _ in range(cfg.max_iterations):
            if error < cfg.tolerance_m:
                break
            try:
                velocity = mink.solve_ik(
                    self.configuration,
                    self.tasks,
                    dt=cfg.dt_s,
                    solver=cfg.solver,
                    damping=cfg.damping,
                    limits=self.limits if self._near_limit() else [],
                )
            except mink.NoSolutionFound:
                self.failures += 1
                break
            self.configuration.integrate_inplace(velocity, cfg.dt_s)
            error = float(np.linalg.norm(data.site(TCP_SITE).xpos - target_pos))
        return self.configuration.q[self.arm_qpos_index].copy(), error

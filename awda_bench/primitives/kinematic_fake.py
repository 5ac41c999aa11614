"""A kinematic stand-in for the robot and its wrist depth camera (tests and benchmarks, no sim).

* The TCP is a point that moves by ``clip(a_xyz, -1, 1) * max_step_m`` per step.
* The gripper opening moves towards 0 (close, ``a_grip > 0``) or ``max_opening_m`` (open) by
  ``finger_speed_m`` per step, but stops at a box's width when the box is between the fingers
  (TCP inside the box's footprint, below its top, above its bottom); the box then moves with the
  TCP until the gripper opens, and falls back to the floor when released.
* The wrist camera looks straight down from ``camera_height_m`` above the TCP (OpenCV axes:
  ``x_c = +x``, ``y_c = -y``, ``z_c = -z``) and renders the floor (z = 0) and box tops.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from awda_bench.primitives.base import RobotState


@dataclass
class Box:
    """An axis-aligned box resting on (or carried above) the floor."""

    center_xy: np.ndarray
    """(2,) footprint centre [m]."""
    size: np.ndarray
    """(3,) extent along x, y, z [m]."""
    bottom_z: float = 0.0
    """Height of the bottom face [m]."""

    @property
    def top_z(self) -> float:
        return self.bottom_z + float(self.size[2])

    def contains_xy(self, xy: np.ndarray) -> np.ndarray:
        half = self.size[:2] / 2
        return np.all(np.abs(np.asarray(xy) - self.center_xy) <= half, axis=-1)


@dataclass
class TopDownDepthCamera:
    """Pinhole depth camera looking straight down."""

    width: int = 128
    height: int = 128
    fov_rad: float = np.pi / 2
    """Horizontal field of view [rad] (the wrist camera's 90 degrees)."""

    @property
    def K(self) -> np.ndarray:
        f = (self.width / 2) / np.tan(self.fov_rad / 2)
        return np.array([[f, 0, (self.width - 1) / 2], [0, f, (self.height - 1) / 2], [0, 0, 1.0]])

    @staticmethod
    def cam2world(position: np.ndarray) -> np.ndarray:
        T = np.diag([1.0, -1.0, -1.0, 1.0])
        T[:3, 3] = position
        return T

    def render(self, position: np.ndarray, boxes: list[Box], far_m: float = 10.0) -> np.ndarray:
        """(H, W) depth [m] looking straight down from ``position``; 0 beyond ``far_m``."""
        return self.render_pose(self.cam2world(np.asarray(position, float)), boxes, far_m)

    def render_pose(
        self, cam2world: np.ndarray, boxes: list[Box], far_m: float = 10.0
    ) -> np.ndarray:
        """(H, W) depth [m] (along the optical axis) from any camera pose (OpenCV axes).

        Ray of pixel ``(u, v)``: ``o + t R [(u - c_x)/f, (v - c_y)/f, 1]``; ``t`` is the depth.
        The floor (z = 0) and the box tops (horizontal rectangles) are intersected; no box sides.
        """
        K = self.K
        uu, vv = np.meshgrid(np.arange(self.width), np.arange(self.height))
        rays = np.stack(
            [(uu - K[0, 2]) / K[0, 0], (vv - K[1, 2]) / K[1, 1], np.ones_like(uu, float)]
        )
        R, o = cam2world[:3, :3], cam2world[:3, 3]
        d = np.einsum("ij,jhw->ihw", R, rays)  # world direction per unit depth
        with np.errstate(divide="ignore", invalid="ignore"):
            t_floor = np.where(d[2] < 0, -o[2] / d[2], np.inf)
            depth = t_floor.copy()
            for box in boxes:
                t = np.where(d[2] < 0, (box.top_z - o[2]) / d[2], np.inf)
                xy = np.stack([o[0] + t * d[0], o[1] + t * d[1]], axis=-1)
                hit = (t > 0) & box.contains_xy(xy) & (t < depth)
                depth[hit] = t[hit]
        depth[~np.isfinite(depth) | (depth > far_m)] = 0.0
        return depth.astype(np.float32)


@dataclass
class KinematicRobot:
    """Point TCP + two-finger gripper + boxes; ``step(action)`` advances one control step."""

    tcp_pos: np.ndarray
    boxes: list[Box] = field(default_factory=list)
    max_step_m: float = 0.02
    max_opening_m: float = 0.08
    finger_speed_m: float = 0.01
    gripper_opening_m: float = 0.08
    camera: TopDownDepthCamera = field(default_factory=TopDownDepthCamera)
    camera_height_m: float = 0.1
    held: Box | None = None
    frames: int = 0
    """Depth frames rendered so far."""
    _hold_offset_m: float = 0.0

    @property
    def state(self) -> RobotState:
        return RobotState(
            tcp_pos=self.tcp_pos.copy(), gripper_opening_m=float(self.gripper_opening_m)
        )

    def _between_fingers(self) -> Box | None:
        for box in self.boxes:
            if box.contains_xy(self.tcp_pos[:2]) and box.bottom_z <= self.tcp_pos[2] <= box.top_z:
                return box
        return None

    def step(self, action: np.ndarray) -> RobotState:
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        self.tcp_pos = self.tcp_pos + a[:3] * self.max_step_m
        self.tcp_pos[2] = max(self.tcp_pos[2], 0.0)
        if self.held is not None:
            self.held.center_xy = self.tcp_pos[:2].copy()
            self.held.bottom_z = max(0.0, self.tcp_pos[2] + self._hold_offset_m)
        if a[3] > 0:
            box = self.held or self._between_fingers()
            width = 0.0 if box is None else float(min(box.size[0], box.size[1]))
            self.gripper_opening_m = max(width, self.gripper_opening_m - self.finger_speed_m)
            if box is not None and self.held is None and self.gripper_opening_m <= width:
                self.held = box
                self._hold_offset_m = box.bottom_z - float(self.tcp_pos[2])
        else:
            self.gripper_opening_m = min(
                self.max_opening_m, self.gripper_opening_m + self.finger_speed_m
            )
            if self.held is not None:
                self.held.bottom_z = 0.0
                self.held = None
        return self.state

    def depth_frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(depth_m, K, cam2world)`` from the wrist camera (counts a rendered frame)."""
        self.frames += 1
        position = self.tcp_pos + np.array([0.0, 0.0, self.camera_height_m])
        return (
            self.camera.render(position, self.boxes),
            self.camera.K,
            self.camera.cam2world(position),
        )

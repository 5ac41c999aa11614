"""On-demand camera capture (the env runs with ``obs_mode="state"``; nothing renders per step).

A rendered frame costs ~60 ms on lavapipe and a camera's first capture ~4.6 s (pipeline build),
so policies ask for exactly the frames they need: the third-person first frame, demo frames, and
the wrist depth image while grasping. Sensors live in ``env.unwrapped.scene.sensors``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from awda_bench.errors import UnknownChoiceError
from awda_bench.robot.agent import WRIST_CAMERA

THIRD_PERSON_CAMERA = "third_person"
"""Sensor uid of the policy's third-person RGB camera (declared by each task)."""


@dataclass(frozen=True)
class DepthFrame:
    """One depth capture per env, with what back-projection needs."""

    depth_m: np.ndarray
    """(n, H, W) float32 depth along the optical axis [m]; 0 where nothing was hit."""
    intrinsic_cv: np.ndarray
    """(n, 3, 3) OpenCV intrinsics (fx, fy, cx, cy in pixels)."""
    cam2world_cv: np.ndarray
    """(n, 4, 4) camera-to-world transform, OpenCV axes (x right, y down, z forward)."""


class CaptureCounter:
    """Counts rendered camera frames (per env instance), for the per-episode frame budget."""

    def __init__(self) -> None:
        self.frames = 0

    def reset(self) -> None:
        self.frames = 0


def camera_sensor(env, uid: str):
    """Env ``env``'s sensor ``uid`` (a ManiSkill ``Camera``); unknown uids get the list."""
    sensors = env.unwrapped.scene.sensors
    if uid not in sensors:
        raise UnknownChoiceError("camera", uid, sorted(sensors))
    return sensors[uid]


def _count(env) -> None:
    counter = getattr(env.unwrapped, "capture_counter", None)
    if counter is None:
        counter = CaptureCounter()
        env.unwrapped.capture_counter = counter
    counter.frames += 1


def capture_rgb(env, uid: str = THIRD_PERSON_CAMERA) -> np.ndarray:
    """Render camera ``uid`` now: ``(n, H, W, 3)`` uint8 RGB."""
    sensor = camera_sensor(env, uid)
    env.unwrapped.scene.update_render()
    sensor.capture()
    _count(env)
    rgb = sensor.get_obs(rgb=True, depth=False, position=False, segmentation=False)["rgb"]
    return rgb.cpu().numpy().astype(np.uint8)


def camera_params(env, uid: str = THIRD_PERSON_CAMERA) -> tuple[np.ndarray, np.ndarray]:
    """Camera ``uid``'s ``intrinsic_cv`` (3, 3) and world-to-camera ``extrinsic_cv`` (3, 4) of env
    0 (OpenCV conventions), as float64."""
    params = camera_sensor(env, uid).get_params()
    out = []
    for key in ("intrinsic_cv", "extrinsic_cv"):
        value = params[key]
        if isinstance(value, torch.Tensor):
            value = value.cpu().numpy()
        out.append(np.asarray(value, dtype=np.float64).reshape(-1, *np.shape(value)[-2:])[0])
    return out[0], out[1]


def capture_wrist_depth(env, uid: str = WRIST_CAMERA) -> DepthFrame:
    """Render the wrist depth camera now."""
    sensor = camera_sensor(env, uid)
    env.unwrapped.scene.update_render()
    sensor.capture()
    _count(env)
    depth_mm = sensor.get_obs(rgb=False, depth=True, position=False, segmentation=False)["depth"]
    params = sensor.get_params()
    extrinsic = params["extrinsic_cv"]
    if isinstance(extrinsic, torch.Tensor):
        extrinsic = extrinsic.cpu().numpy()
    intrinsic = params["intrinsic_cv"]
    if isinstance(intrinsic, torch.Tensor):
        intrinsic = intrinsic.cpu().numpy()
    n = extrinsic.shape[0]
    world2cam = np.tile(np.eye(4), (n, 1, 1))
    world2cam[:, :3, :] = extrinsic
    return DepthFrame(
        depth_m=depth_mm.cpu().numpy()[..., 0].astype(np.float32) / 1000.0,
        intrinsic_cv=intrinsic.astype(np.float64),
        cam2world_cv=np.linalg.inv(world2cam),
    )


def third_person_camera_config(
    eye: tuple[float, float, float] = (0.75, 0.0, 0.85),
    target: tuple[float, float, float] = (-0.2, 0.0, 0.15),
    height: int = 240,
    width: int = 320,
    fov_rad: float = 1.0,
):
    """``CameraConfig`` of the policy's third-person RGB camera ``third_person``.

    Defaults: 240×320 (H×W) like the reference pick-and-place images, looking from the far side of
    the table back at the robot so the arm and the workspace are both in view. Tasks return it from
    ``_default_sensor_configs``; with ``obs_mode="state"`` it renders only through :func:`capture_rgb`.
    """
    from mani_skill.sensors.camera import CameraConfig
    from mani_skill.utils import sapien_utils

    return CameraConfig(
        uid=THIRD_PERSON_CAMERA,
        pose=sapien_utils.look_at(eye=list(eye), target=list(target)),
        width=width,
        height=height,
        fov=fov_rad,
        near=0.01,
        far=10.0,
    )

"""What an observation-only policy sees of a Meta-World episode
(:class:`awda_bench.episode.Observations`).

=====================  ===========================================================================
``rgb()``              ``(1, H, W, 3)`` uint8 from the suite's third-person camera, upright
``first_frame()``      the same at reset
``wrist_depth()``      ``gripperPOV`` (on the Sawyer's hand, looking down past the fingers),
                       :data:`WRIST_SIZE` px square, metres along the optical axis, with its
                       intrinsics and camera-to-world pose (OpenCV axes)
``camera()``           third-person intrinsics ``(3, 3)`` and world-to-camera ``(3, 4)``
``proprio()``          TCP (midpoint of the finger pads' end-effector sites) [m], hand quaternion
                       (w, x, y, z), finger-site distance [m], the 9 arm and finger joints
``demo_frames(n)``     the scripted expert in the demo layout (``spec.demo_seed``), ``n`` frames
                       evenly spaced from reset to its first success (or the horizon)
``hand_target()``      Meta-World only: the hand's mocap target [m] (the Sawyer's set-point)
``robot_interface()``  Meta-World only: the Sawyer as the motor primitives drive it
=====================  ===========================================================================

World frame: Meta-World's (metres, z up, the table top at z = 0). The demo is played in the
episode's own env, which is then reset to the episode's layout again (layouts are exact), so
``demo_frames`` and ``first_frame`` must be asked for before the first step (in ``reset(ctx)``).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from awda_bench.episode import EpisodeSpec, Proprioception, WristDepth
from awda_bench.metaworld.demo import demo_frames
from awda_bench.metaworld.layout import reset_to_layout
from awda_bench.metaworld.renderer import FrameRenderer, camera_pose
from awda_bench.metaworld.sawyer import robot_state
from awda_bench.metaworld.sawyer_interface import SawyerInterface
from awda_bench.suites import Suite

WRIST_CAMERA = "gripperPOV"
"""Meta-World's eye-in-hand camera."""

WRIST_SIZE = 128
"""Wrist depth images are this many pixels square (as the ManiSkill suites')."""


class Scene(Protocol):
    """What the observations read of the env playing the episode
    (:class:`awda_bench.metaworld.env.MetaWorldEnv`)."""

    suite: Suite
    renderer: FrameRenderer
    task_name: str | None

    @property
    def task_env(self) -> Any:
        """The current task's ``SawyerXYZEnv``."""


class MetaWorldObservations:
    """The observations of episode ``spec`` played on ``env``."""

    num_envs = 1

    def __init__(self, env: Scene, spec: EpisodeSpec, extras: dict[str, Any]) -> None:
        self._env = env
        self._spec = spec
        self._extras = extras
        self._stepped = False

    def mark_stepped(self) -> None:
        """Called by the harness after the first step: the first frame and the demo are gone."""
        self._stepped = True

    def _before_first_step(self, what: str) -> None:
        if self._stepped:
            raise RuntimeError(
                f"{what} was first asked for after the episode's first step; call it in reset(ctx)"
            )

    def rgb(self) -> np.ndarray:
        camera = self._env.suite.camera
        assert camera.name is not None
        env = self._env.task_env
        frame = self._env.renderer.capture(
            env.model, env.data, camera.name, height=camera.height, width=camera.width
        )
        assert frame.rgb is not None
        return frame.rgb[None]

    def first_frame(self) -> np.ndarray:
        cached = self._extras.get("first_frame")
        if cached is not None:
            return np.asarray(cached)
        self._before_first_step("first_frame()")
        frame = self.rgb()[0]
        self._extras["first_frame"] = frame
        return frame

    def wrist_depth(self) -> WristDepth:
        return wrist_capture(self._env)

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        camera = self._env.suite.camera
        assert camera.name is not None
        env = self._env.task_env
        intrinsic, cam2world, _ = camera_pose(
            env.model, env.data, camera.name, camera.height, camera.width
        )
        world2cam = np.linalg.inv(cam2world)[:3, :]
        return intrinsic, world2cam

    def proprio(self) -> Proprioception:
        env = self._env.task_env
        state = robot_state(env)
        return Proprioception(
            tcp_pos=state.tcp_pos.reshape(1, 3),
            tcp_quat=np.asarray(env.data.body("hand").xquat, dtype=np.float64).reshape(1, 4),
            gripper_opening_m=np.array([state.gripper_opening_m]),
            qpos=np.asarray(env.data.qpos[:9], dtype=np.float64).reshape(1, 9),
        )

    def hand_target(self) -> np.ndarray:
        """``(1, 3)`` float64: the mocap target the hand is welded to [m] (the Sawyer's position
        set-point, which Meta-World's action moves; not in the
        :class:`~awda_bench.episode.Observations` protocol: the primitives' action conversion
        reads it, :mod:`awda_bench.metaworld.sawyer_interface`)."""
        mocap = self._env.task_env.data.mocap_pos[0]
        return np.asarray(mocap, dtype=np.float64).reshape(1, 3)

    def robot_interface(self) -> SawyerInterface:
        """The Sawyer as the motor primitives drive it in this episode (``awda``; picked by
        :func:`awda_bench.primitives.robot_interface.robot_interface_of`). Its mocap offset is
        measured now: ask for it with the hand at rest, after :meth:`demo_frames`."""
        return SawyerInterface(self)

    def demo_frames(self, count: int = 10) -> np.ndarray:
        cached = self._extras.get("demo_frames")
        if cached is not None and len(cached) == count:
            return np.asarray(cached)
        self._before_first_step("demo_frames()")
        frames = demo_frames(
            self._env.task_env,
            self._env.task_name or "",
            self._spec.demo_seed,
            count=count,
            horizon=self._env.suite.horizon_steps,
            render=lambda: self.rgb()[0],
        )
        reset_to_layout(self._env.task_env, self._spec.seed)  # back to the episode's layout
        self._extras["demo_frames"] = list(frames)
        return frames


def wrist_capture(env: Any, height: int = WRIST_SIZE, width: int = WRIST_SIZE) -> WristDepth:
    """The ``gripperPOV`` depth image (``height`` x ``width`` px) of a
    :class:`~awda_bench.metaworld.env.MetaWorldEnv` now (what ``wrist_depth()`` returns; the
    gt-waypoints grasp primitive localizes with it too, and ``collect`` records it)."""
    task_env = env.task_env
    frame = env.renderer.capture(
        task_env.model,
        task_env.data,
        WRIST_CAMERA,
        height=height,
        width=width,
        rgb=False,
        depth=True,
    )
    assert frame.depth_m is not None
    return WristDepth(frame.depth_m[None], frame.intrinsic_cv[None], frame.cam2world_cv[None])

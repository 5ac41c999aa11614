"""``awda``: a learned waypoint network (one snapshot file) driving the motor primitives.

Per episode (SPEC §6, S1)::

    demo video (demonstrator, other layout) --10 frames--+
                                                        +--> AwdaNet --> 5 attributed waypoints
    agent's first third-person frame --------------------+                  |
                                                        WaypointExecutor (free space, grasp with
                                                        wrist depth, carry, drop) --> 4-D actions

The network sees only images: the demo frames and the agent's first frame, resized with OpenCV to
the snapshot's configured input size. Predicted attribute probabilities are thresholded at
``attribute_threshold`` into the flags the executor acts on.

The robot the executor drives comes from the episode's observations
(:func:`~awda_bench.primitives.robot_interface.robot_interface_of`): on the ManiSkill suites the
``panda_awda`` agent with :class:`AwdaPolicyConfig`'s executor and localization parameters, its
actions the primitives' commands; on Meta-World the Sawyer
(:class:`~awda_bench.metaworld.sawyer_interface.SawyerInterface`, the object ``gt-waypoints``
executes with there): its executor and localization parameters replace the configured ones (the
component rule, ``--grasp-select``, kept: ``awda-centre`` too), and each command becomes the mocap
action that leads the TCP toward it. Waypoints are in the suite's world frame (Meta-World's: z up,
the table top at 0), as the training trajectories were recorded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.data.trajectory_file import as_stored
from awda_bench.episode import EpisodeContext, observations_of
from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.models.agent_cameras import camera_index, config_cameras
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig
from awda_bench.policies.trained_model import load_trained
from awda_bench.primitives.config import (
    CENTRE_SUFFIX,
    GRASP_SELECTS,
    ExecutorConfig,
    LocalizationConfig,
)
from awda_bench.primitives.executor import WaypointExecutor
from awda_bench.primitives.robot_interface import RobotInterface, robot_interface_of
from awda_bench.primitives.wrist_camera import WRIST_LOCALIZATION


@dataclass(frozen=True)
class AwdaPolicyConfig:
    """Settings of the ``awda`` method around the network."""

    attribute_threshold: float = 0.5
    """A predicted attribute probability above this is a set flag."""
    head: str = "task"
    """Waypoint head used at evaluation (``task``; ``synthesized`` is for trajectory synthesis)."""
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)
    """Primitive and execution parameters (as for ``gt-waypoints``)."""
    localization: LocalizationConfig = WRIST_LOCALIZATION
    """Wrist-depth localization in the grasp primitive."""

    def __post_init__(self) -> None:
        if not 0.0 < self.attribute_threshold < 1.0:
            raise ValueError(
                f"AwdaPolicyConfig.attribute_threshold must be in (0, 1), got {self.attribute_threshold}"
            )


def _resize(frames: np.ndarray, height: int, width: int) -> np.ndarray:
    import cv2

    if frames.shape[-3:-1] == (height, width):
        return frames
    return np.stack([cv2.resize(f, (width, height), interpolation=cv2.INTER_AREA) for f in frames])


def check_camera(config: AwdaConfig, camera: tuple[np.ndarray, np.ndarray]) -> int:
    """The index of the scene's third-person ``camera`` (intrinsics, extrinsics) among the cameras
    a network votes waypoints on the rays of (a cell head with cameras; 0 for one without); a
    scene filmed by none of them is refused."""
    cameras = config_cameras(config)
    if not cameras:
        return 0
    index = camera_index(cameras, camera)
    if index is None:
        raise UsageError(
            "this AWDA snapshot votes waypoints on the rays of the cameras it was trained with, "
            "and the scene's third-person camera is none of them; evaluate it on the suite it was "
            "trained on (or retrain on data recorded with this camera)"
        )
    return index


class AwdaPolicy:
    """Predicts waypoints once per episode from images, then executes them."""

    name = "awda"

    def __init__(self, snapshot: str | Path, config: AwdaPolicyConfig | None = None) -> None:
        self.config = config or AwdaPolicyConfig()
        trained = load_trained(snapshot, ("awda",), AwdaNet, "pick an AWDA checkpoint directory")
        self.device = trained.device
        self.jpeg_quality = trained.jpeg_quality
        """Live frames are JPEG-compressed at this quality first, as the training frames were."""
        self.model: AwdaNet = trained.model
        trunk = self.model.config.trunk
        self.image_size = (trunk.image_height_px, trunk.image_width_px)
        self.demo_frames = trunk.demo_frames
        self.episode_config = self.config
        """The settings the current episode runs with (on Meta-World the Sawyer's executor and
        localization parameters in place of the Panda's, the method's component rule kept)."""
        self._robot: RobotInterface | None = None
        self._executor: WaypointExecutor | None = None
        self._waypoints: np.ndarray | None = None
        self.predict_s = 0.0
        """Wall time of the last forward pass [s]."""

    def reset(self, ctx: EpisodeContext) -> None:
        from awda_bench.models.predict import predict_waypoints

        observations = observations_of(ctx)
        demo = observations.demo_frames(self.demo_frames)
        camera = check_camera(self.model.config, observations.camera())
        first = observations.first_frame()
        h, w = self.image_size
        start = time.perf_counter()
        predicted = predict_waypoints(
            self.model,
            _resize(as_stored(np.asarray(demo), self.jpeg_quality), h, w),
            _resize(as_stored(first[None], self.jpeg_quality), h, w)[0],
            head=self.config.head,
            camera=camera,
        )
        self.predict_s = time.perf_counter() - start
        waypoints = predicted.copy()
        waypoints[:, 3:] = (predicted[:, 3:] > self.config.attribute_threshold).astype(np.float64)
        self._waypoints = waypoints
        robot = robot_interface_of(observations)  # after the demo: the hand at rest, in layout
        self._robot = robot
        config = self.config
        self.episode_config = replace(
            config,
            executor=robot.executor_config(config.executor),
            localization=robot.localization_config(config.localization),
        )
        locator = robot.locator(0, self.episode_config.localization)
        self._executor = WaypointExecutor(waypoints, locator, self.episode_config.executor)

    def act(self, obs: Any) -> np.ndarray:
        if self._executor is None or self._robot is None:
            raise RuntimeError("AwdaPolicy.act() before reset(ctx)")
        state = self._robot.robot_states()[0]
        command = self._executor.step(state)[None]
        return np.asarray(self._robot.env_actions(command), dtype=np.float32)

    @property
    def done(self) -> bool:
        return self._executor is not None and self._executor.done

    @property
    def waypoints(self) -> np.ndarray | None:
        """The (5, 3 + k) waypoints acted on (attributes thresholded)."""
        return self._waypoints


def awda(snapshot: str | Path, grasp_select: str = GRASP_SELECTS[0]) -> AwdaPolicy:
    """The awda family (one method per setting, :mod:`awda_bench.evaluation.methods`): grasps
    take the wrist depth component the predicted grasp waypoint points at (``waypoint``, ``awda``)
    or the one nearest the wrist image's centre (``centre``, the reference's rule:
    ``awda-centre``)."""
    if grasp_select not in GRASP_SELECTS:
        raise UnknownChoiceError("--grasp-select", grasp_select, GRASP_SELECTS)
    if grasp_select == GRASP_SELECTS[0]:
        return AwdaPolicy(snapshot)
    localization = replace(WRIST_LOCALIZATION, select=grasp_select)
    policy = AwdaPolicy(snapshot, AwdaPolicyConfig(localization=localization))
    policy.name = "awda" + CENTRE_SUFFIX
    return policy

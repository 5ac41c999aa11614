"""A learned method with its own checkpoint format: ``snapshot-<step>.npz`` files.

The model is linear: the demonstration's colour change (mean RGB of its last frame minus its
first, in [-1, 1]) maps to a TCP goal relative to where the TCP starts::

    goal = tcp_start + W @ colour_change + b          W (3, 3), b (3,) [m]
    a_t  = clip(gain * (goal - tcp_t) / 0.02, -1, 1)  gripper open; done within 5 mm of the goal

``list_snapshots`` and ``load_snapshot`` (static methods) make it a learned method for the
harness: ``--method awda_example_policies.demo_reacher:DemoReacherPolicy --checkpoints DIR``
evaluates each snapshot file, keyed by its content hash.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from awda_bench.episode import EpisodeContext, Observations

MAX_STEP_M = 0.02
"""What a full-scale action moves the TCP in one step [m]."""

DEMO_FRAMES = 10
"""Demonstration frames asked for."""


class DemoReacherPolicy:
    """One snapshot of the demo reacher (observation-only)."""

    name = "demo-reacher"

    @staticmethod
    def list_snapshots(directory: str | Path) -> list[Path]:
        """The snapshot files in ``directory``, oldest (lowest step) first."""
        files = Path(directory).glob("snapshot-*.npz")
        return sorted(files, key=lambda p: int(p.stem.split("-")[1]))

    @staticmethod
    def load_snapshot(path: str | Path) -> dict[str, np.ndarray]:
        """The weights of one snapshot; a file without them raises ``ValueError``."""
        with np.load(path) as data:
            weights = {key: np.asarray(data[key], np.float64) for key in data.files}
        shapes = {"W": (3, 3), "b": (3,), "gain": ()}
        for key, shape in shapes.items():
            if key not in weights or weights[key].shape != shape:
                raise ValueError(f"{path} needs {key} of shape {shape}")
        return weights

    def __init__(self, snapshot: str | Path) -> None:
        self.weights = self.load_snapshot(snapshot)
        self._goal: np.ndarray | None = None
        self._done = False

    def reset(self, ctx: EpisodeContext) -> None:
        obs = ctx.observations
        assert obs is not None
        demo = obs.demo_frames(DEMO_FRAMES).astype(np.float64) / 255.0
        change = demo[-1].mean(axis=(0, 1)) - demo[0].mean(axis=(0, 1))
        start = obs.proprio().tcp_pos[0]
        self._goal = start + self.weights["W"] @ change + self.weights["b"]
        self._done = False

    def act(self, obs: Observations) -> np.ndarray:
        if self._goal is None:
            raise RuntimeError("DemoReacherPolicy.act() before reset(ctx)")
        error = self._goal - obs.proprio().tcp_pos[0]
        self._done = bool(np.linalg.norm(error) < 0.005)
        action = np.zeros((obs.num_envs, 4), np.float32)
        action[:, :3] = np.clip(float(self.weights["gain"]) * error / MAX_STEP_M, -1.0, 1.0)
        action[:, 3] = -1.0
        return action

    @property
    def done(self) -> bool:
        return self._done

    @property
    def waypoints(self) -> np.ndarray | None:
        """The goal as one waypoint (x, y, z, grasp = 0), stored with the episode's record."""
        return None if self._goal is None else np.append(self._goal, 0.0)[None]

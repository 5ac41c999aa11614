"""A policy for the Meta-World suite tests: it records what it observed at reset as its
"waypoints" (the one array a record carries back from a worker), then acts at random.

Imported inside ``.venv-metaworld`` workers (the tests put this directory on ``PYTHONPATH``): NumPy
and ``awda_bench.episode`` only.

Row 0: TCP position [m], gripper opening [m], mean and checksum of the first frame.
Row 1: world point back-projected from the wrist depth image's median-depth pixels (x, y, z),
fraction of pixels with a depth, the first frame's height and width.
Row 2: the TCP projected into the first frame with ``camera()`` (u, v [px]), then zeros.
Row 3 (``DemoProbePolicy`` only): demo frame count, mean of its first and last frame, whether the
TCP and the current frame are unchanged after the demo was played, 0.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import EpisodeContext, observations_of


def backprojected_median(
    depth_m: np.ndarray, intrinsic: np.ndarray, cam2world: np.ndarray
) -> np.ndarray:
    """The median world point of every pixel with a depth (OpenCV pinhole model)."""
    v, u = np.nonzero(depth_m > 0)
    z = depth_m[v, u].astype(np.float64)
    x = (u + 0.5 - intrinsic[0, 2]) / intrinsic[0, 0] * z
    y = (v + 0.5 - intrinsic[1, 2]) / intrinsic[1, 1] * z
    points = np.stack([x, y, z, np.ones_like(z)], axis=1) @ cam2world.T
    return np.median(points[:, :3], axis=0)


class ProbePolicy:
    name = "probe"

    def __init__(self) -> None:
        self._rng = np.random.default_rng(0)
        self._waypoints: np.ndarray | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        obs = observations_of(ctx)
        frame = obs.first_frame()
        proprio = obs.proprio()
        wrist = obs.wrist_depth()
        depth = wrist.depth_m[0]
        point = backprojected_median(depth, wrist.intrinsic_cv[0], wrist.cam2world_cv[0])
        intrinsic, world2cam = obs.camera()
        cam = world2cam @ np.append(proprio.tcp_pos[0], 1.0)
        u, v = (intrinsic @ cam)[:2] / cam[2]
        checksum = float(
            np.sum(frame.astype(np.int64) * np.arange(frame.size).reshape(frame.shape) % 9973)
        )
        self._waypoints = np.array(
            [
                [*proprio.tcp_pos[0], proprio.gripper_opening_m[0], frame.mean(), checksum],
                [*point, float(np.mean(depth > 0)), frame.shape[0], frame.shape[1]],
                [u, v, 0, 0, 0, 0],
            ]
        )
        self._rng = np.random.default_rng(ctx.spec.seed)

    def act(self, obs: Any) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, size=(1, 4)).astype(np.float32)

    @property
    def done(self) -> bool:
        return True  # one step is enough

    @property
    def waypoints(self) -> np.ndarray | None:
        return self._waypoints


class DemoProbePolicy(ProbePolicy):
    """:class:`ProbePolicy` that also asks for the demo (played in the episode's own env)."""

    name = "demo-probe"

    def reset(self, ctx: EpisodeContext) -> None:
        super().reset(ctx)
        obs = observations_of(ctx)
        before = obs.proprio().tcp_pos.copy()
        demo = obs.demo_frames(10)
        same = np.array_equal(obs.proprio().tcp_pos, before) and np.array_equal(
            obs.rgb()[0], obs.first_frame()
        )
        assert self._waypoints is not None
        row = [len(demo), demo[0].mean(), demo[-1].mean(), float(same), 0.0, 0.0]
        self._waypoints = np.vstack([self._waypoints, row])


class CrashingPolicy(ProbePolicy):
    """Kills its worker process in the first episode's reset (episode 0 of any task)."""

    name = "crashing"

    def reset(self, ctx: EpisodeContext) -> None:
        if ctx.spec.episode == 0:
            import os

            os._exit(7)
        super().reset(ctx)

"""A non-learned method: go down on what the wrist camera sees, grasp it, lift.

Every step reads proprioception; while descending it also reads the wrist depth image (one render
per step) and stops 4 cm above whatever is under the camera's centre::

    descend  dz = -1 until the centre of the wrist depth image is < 0.13 m away (or 60 steps)
    close    gripper +1 for 10 steps
    lift     dz = +1 for 20 steps, then done
"""

from __future__ import annotations

import numpy as np

from awda_bench.episode import EpisodeContext, Observations

STOP_DEPTH_M = 0.13
"""Depth at the image centre that ends the descent [m] (the fingertips are ~9 cm below the lens)."""


class WristDescendPolicy:
    """Observation-only: ``privileged`` is not declared, so ``ctx.env`` is off limits."""

    name = "wrist-descend"

    def __init__(self) -> None:
        self._phase = "descend"
        self._steps = 0

    def reset(self, ctx: EpisodeContext) -> None:
        self._phase = "descend"
        self._steps = 0

    def _centre_depth_m(self, obs: Observations) -> float:
        depth = obs.wrist_depth().depth_m[0]
        h, w = depth.shape
        patch = depth[h // 2 - 4 : h // 2 + 4, w // 2 - 4 : w // 2 + 4]
        hit = patch[patch > 0]
        return float(np.median(hit)) if hit.size else float("inf")

    def act(self, obs: Observations) -> np.ndarray:
        self._steps += 1
        action = np.zeros((obs.num_envs, 4), np.float32)
        if self._phase == "descend":
            action[:, 2], action[:, 3] = -1.0, -1.0
            if self._steps >= 60 or self._centre_depth_m(obs) < STOP_DEPTH_M:
                self._phase, self._steps = "close", 0
        elif self._phase == "close":
            action[:, 3] = 1.0
            if self._steps >= 10:
                self._phase, self._steps = "lift", 0
        else:
            action[:, 2], action[:, 3] = 1.0, 1.0
            if self._steps >= 20 or obs.proprio().tcp_pos[0, 2] > 0.4:
                self._phase = "done"
        return action

    @property
    def done(self) -> bool:
        return self._phase == "done"

    @property
    def waypoints(self) -> np.ndarray | None:
        return None

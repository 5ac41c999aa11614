"""A learned method for the Meta-World tests: it plays a snapshot with the real ``awda`` or
``tosvi`` policy (whichever the snapshot holds) and reports, as its "waypoints" (the one array a
record carries back from a worker), what the worker saw of it.

Imported inside ``.venv-metaworld`` workers (the tests put this directory on ``PYTHONPATH``).

Row 0: actions returned, all finite, largest |component|, actions' rows, columns, float32.
Row 1: the executor runs the Sawyer's parameters (1/0; -1 for tosvi, which has none), its
localization is the Sawyer's with the method's rule (1/0; -1), the robot interface is the
Sawyer's (1/0; -1), mink / ManiSkill / SAPIEN imported in the worker (1/0), torch's threads, 0.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.episode import EpisodeContext
from awda_bench.models import snapshot as snapshots


class LearnedProbe:
    name = "learned-probe"

    list_snapshots = staticmethod(snapshots.list_snapshots)
    load_snapshot = staticmethod(snapshots.load_snapshot)

    def __init__(self, snapshot: str | Path) -> None:
        from awda_bench.policies.awda_policy import AwdaPolicy
        from awda_bench.policies.tosvi_policy import TosviPolicy

        arch = snapshots.load_snapshot(Path(snapshot)).arch
        self.inner: Any = (
            AwdaPolicy(snapshot) if arch == "awda" else TosviPolicy(snapshot, arch="tosvi")
        )
        self.actions: list[np.ndarray] = []

    def reset(self, ctx: EpisodeContext) -> None:
        self.actions = []
        self.inner.reset(ctx)

    def act(self, obs: Any) -> np.ndarray:
        action = self.inner.act(obs)
        self.actions.append(np.array(action))
        return action

    @property
    def done(self) -> bool:
        return bool(self.inner.done)

    @property
    def waypoints(self) -> np.ndarray:
        import torch

        from awda_bench.metaworld.sawyer import SAWYER_EXECUTOR, SAWYER_LOCALIZATION
        from awda_bench.metaworld.sawyer_interface import SawyerInterface

        a = np.stack(self.actions) if self.actions else np.zeros((0, 1, 4), np.float32)
        config = getattr(self.inner, "episode_config", None)
        if config is None:
            sawyer = localization = robot = -1.0
        else:
            select = self.inner.config.localization.select  # the method's rule
            sawyer = float(config.executor == SAWYER_EXECUTOR)
            localization = float(config.localization == replace(SAWYER_LOCALIZATION, select=select))
            robot = float(isinstance(self.inner._robot, SawyerInterface))
        foreign = float(any(m in sys.modules for m in ("mink", "mani_skill", "sapien")))
        return np.array(
            [
                [
                    len(a),
                    float(np.isfinite(a).all()),
                    float(np.abs(a).max(initial=0.0)),
                    a.shape[1],
                    a.shape[2],
                    float(a.dtype == np.float32),
                ],
                [sawyer, localization, robot, foreign, torch.get_num_threads(), 0.0],
            ]
        )

"""A recorded robot trajectory: per control step, the states and the commanded action.

This is what the demo recorder writes, what attribute mining reads and what ground-truth waypoints
are extracted from. Index ``t`` holds the state *before* action ``t`` is applied::

    state_0 --a_0--> state_1 --a_1--> ... --a_{T-1}--> state_T
    tcp_pos[0..T-1], gripper_opening_m[0..T-1], actions[0..T-1]   (final state not stored)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.errors import CorruptFileError


@dataclass
class Trajectory:
    """Per-step arrays of one episode of one env (no batch dimension)."""

    tcp_pos: np.ndarray
    """(T, 3) TCP position in the world frame [m]."""
    gripper_opening_m: np.ndarray
    """(T,) distance between the two fingers [m] (0 = closed on nothing)."""
    actions: np.ndarray
    """(T, 4) commanded action in [-1, 1]: dx, dy, dz (scaled by the controller's max step), grip (> 0 closes)."""
    truth: dict[str, np.ndarray] = field(default_factory=dict)
    """(T,) boolean simulator truths per step, e.g. ``"grasp"`` (fingers touch the target object while
    it moves with the gripper) or ``"press"``; used to score attribute mining."""
    meta: dict[str, object] = field(default_factory=dict)
    """Free-form episode description (suite, task, seed, embodiment, success, control_freq_hz ...)."""

    def __post_init__(self) -> None:
        T = len(self.actions)
        if self.tcp_pos.shape != (T, 3):
            raise ValueError(f"tcp_pos must be ({T}, 3), got {self.tcp_pos.shape}")
        if self.gripper_opening_m.shape != (T,):
            raise ValueError(
                f"gripper_opening_m must be ({T},), got {self.gripper_opening_m.shape}"
            )
        if self.actions.shape != (T, 4):
            raise ValueError(f"actions must be ({T}, 4), got {self.actions.shape}")
        for name, values in self.truth.items():
            if values.shape != (T,):
                raise ValueError(f"truth[{name!r}] must be ({T},), got {values.shape}")

    def __len__(self) -> int:
        return len(self.actions)

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` file (arrays plus ``meta`` as a JSON string)."""
        import json

        arrays: dict[str, Any] = {
            "meta": json.dumps(self.meta, default=str),
            "tcp_pos": self.tcp_pos,
            "gripper_opening_m": self.gripper_opening_m,
            "actions": self.actions,
            **{f"truth__{k}": v for k, v in self.truth.items()},
        }
        np.savez_compressed(path, **arrays)

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        """Read a file written by :meth:`save`."""
        import json
        import zipfile

        try:
            with np.load(path, allow_pickle=False) as data:
                truth = {
                    k[len("truth__") :]: data[k] for k in data.files if k.startswith("truth__")
                }
                return cls(
                    tcp_pos=data["tcp_pos"],
                    gripper_opening_m=data["gripper_opening_m"],
                    actions=data["actions"],
                    truth=truth,
                    meta=json.loads(str(data["meta"])),
                )
        except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
            raise CorruptFileError(
                f"{path} is not a trajectory file written by awda_bench ({exc})"
            ) from exc

"""Write two demo-reacher snapshots (``snapshot-100.npz``, ``snapshot-200.npz``) into a directory.

    python -m awda_example_policies.make_checkpoints DIR

A stand-in for a training run: fixed weights, so the files (and their hashes) are the same every
time.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def write_checkpoints(directory: Path) -> list[Path]:
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for step, down in ((100, 0.10), (200, 0.20)):
        path = directory / f"snapshot-{step}.npz"
        weights = {
            "W": np.diag([0.1, 0.1, 0.0]),
            "b": np.array([0.0, 0.0, -down]),
            "gain": np.array(0.5),
        }
        with path.open("wb") as f:
            np.savez(f, **weights)
        paths.append(path)
    return paths


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python -m awda_example_policies.make_checkpoints DIR")
    for written in write_checkpoints(Path(sys.argv[1])):
        print(written)

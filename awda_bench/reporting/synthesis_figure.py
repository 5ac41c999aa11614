"""Fig. S6: trajectory synthesis drawn over its scenes.

Each panel is one synthesized episode of a collection (SPEC §6 TS: free-space motion through 1-3
random waypoints, recorded by the agent): its first third-person frame, with the TCP's recorded
path projected through the episode's own camera (intrinsics and extrinsics from the file), coloured
from dark (start, a dot) to bright (end, a square). Panels are laid out in a grid, labelled with the
task and episode they come from, so several trajectories appear in one image as in the
supplementary's Fig. S6. Nothing is drawn from simulator state: the path is the recorded
``obs/extra/tcp_pose``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from awda_bench.data.config import ROLE_SYNTHESIZED
from awda_bench.data.datasets import CollectedData, EpisodeRef
from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.reporting.figures import draw_path, project_points, write_png


def synthesized_panel(data: CollectedData, ref: EpisodeRef) -> np.ndarray:
    """One episode: its first frame with its TCP path drawn, labelled ``task T traj_i``."""
    import cv2

    frame = data.frames(ref, [0])[0]
    intrinsic, extrinsic = data.camera(ref)
    pixels = project_points(data.tcp_pos(ref), intrinsic, extrinsic)
    panel = draw_path(frame, pixels)
    label = f"task {ref.task} {ref.traj} ({ref.steps} steps)"
    cv2.putText(panel, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 0), 1)
    return panel


def fig_s6(data: CollectedData, path: Path, episodes: int = 8, columns: int = 4) -> Path:
    """Write a grid of ``episodes`` synthesized episodes (spread over the collection's tasks, the
    first of each task first) to ``path`` (PNG) and return it."""
    if episodes < 1 or columns < 1:
        raise UsageError(f"--episodes and --columns must be >= 1, got {episodes} and {columns}")
    refs = data.select(ROLE_SYNTHESIZED)
    if not refs:
        raise CorruptFileError(
            f"{data.root} holds no synthesized episodes; collect with --synthesize N (N > 0)"
        )
    chosen: list[EpisodeRef] = []
    by_task: dict[int, list[EpisodeRef]] = {}
    for ref in refs:
        by_task.setdefault(ref.task, []).append(ref)
    depth = 0
    while len(chosen) < min(episodes, len(refs)):  # round-robin over tasks
        for task in sorted(by_task):
            if depth < len(by_task[task]) and len(chosen) < episodes:
                chosen.append(by_task[task][depth])
        depth += 1
    panels = [synthesized_panel(data, ref) for ref in chosen]
    h, w = panels[0].shape[:2]
    blank = np.zeros((h, w, 3), np.uint8)
    rows = []
    for start in range(0, len(panels), columns):
        row = panels[start : start + columns]
        row += [blank] * (columns - len(row)) if len(panels) > columns else []
        rows.append(np.concatenate(row, axis=1))
    return write_png(np.concatenate(rows, axis=0), path)

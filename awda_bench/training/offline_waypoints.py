"""Offline screening of an AWDA snapshot: its waypoints on collected pairs against the
ground-truth waypoints of the agent's own trajectory (the recipe studies' offline measure,
``reports/learned/recipe-study*.md``; not the evaluation protocol, which plays episodes).

For every (agent, demonstrator) pair of each task in a collection (a ``test`` split: the held-out
tasks' validation episodes; a ``train`` split: e.g. the held-out tasks' training siblings), the
snapshot's largest waypoint set against the gt-waypoints rule's K = 5 waypoints of the agent's
trajectory (:func:`awda_bench.waypoints.extract_waypoints`), per task::

    wp_err_cm        median over pairs of the mean distance between predicted and true waypoint i
    end_err_cm       median of the last predicted waypoint's distance to the trajectory's last TCP
    grasp_pred       fraction of pairs whose prediction has a grasp (probability > 0.5)
    grasp_true       fraction whose trajectory grasps
    grasp_err_cm     grasping tasks: median distance of the first grasp-attributed predicted
                     waypoint to the TCP at the first mined grasp step
    spread_pred_cm   mean distance of a pair's predicted waypoints to the task's mean prediction;
    spread_true_cm   the same of the true waypoints (a network that reads the scene spreads about
                     as much as the truth)
    demo_copy_cm     median of the mean distance between the predicted waypoints and the
                     *demonstrator's* true waypoints (its own scene's): below wp_err_cm, the
                     network copies the demo's positions instead of carrying them onto o_1's scene
    true_shift_cm    median of the mean distance between the demonstrator's and the agent's true
                     waypoints: how far the two layouts move the task's waypoints (a network that
                     copies the demo is off by about this much)
    demo_effect_cm   median over pairs of the mean distance between the waypoints predicted with
                     the pair's own demo and with another task's demo (the same o_1): how much
                     the demonstration moves the prediction (0: the network ignores the demo and
                     answers from the scene alone)
    bias_x_cm        mean over pairs and waypoints of predicted minus true waypoint, per world
    bias_y_cm        axis: a systematic offset, e.g. waypoints placed at a training sibling's
    bias_z_cm        height (Meta-World's held-out button-press: z +8 cm,
                     ``reports/learned/recipe-study-metaworld.md``)
    object_near      ``demo-pointer`` snapshots: fraction of pairs whose object softmax over o_1
    moved_near       (and what-moved softmax over the demo) peaks within one cell (Chebyshev) of
                     the identification label: the first grasp, or where the hand first moves the
                     object on a task without one (:mod:`awda_bench.data.contact_point`)
    target_near      ``place_target`` snapshots: the same of the target softmax over o_1 (and the
    put_near         put softmax over the demo) against where the trajectory lets go
    hand_height_cm   ``demo_heights`` snapshots: median over pairs of the mean distance between
                     the hand height read off each demo frame and the demonstrator's TCP z there

Frozen-trunk snapshots only (the features come from the collection's feature cache, built if
missing).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from awda_bench.data.datasets import AwdaPairDataset, CollectedData, Selection
from awda_bench.errors import UsageError
from awda_bench.models.agent_cameras import config_cameras
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig
from awda_bench.models.identification_loss import (
    grasp_cells_per_camera,
    height_errors_m,
    release_cells_per_camera,
)
from awda_bench.models.snapshot import load_snapshot
from awda_bench.training.feature_cache import load_or_build
from awda_bench.training.feature_datasets import CachedAwdaPairs, frames_needed
from awda_bench.waypoints import extract_waypoints

BATCH = 64
"""Pairs per forward pass."""

NEAR_COLUMNS = ("object_near", "moved_near", "target_near", "put_near")
"""The identification softmaxes' hit rates (module docstring); the place ones NaN without a place
target."""

POINTER_COLUMNS = (*NEAR_COLUMNS, "hand_height_cm")
"""What :func:`_pointer_measures` gives per pair."""


def _pointer_measures(
    model: AwdaNet, batch: dict[str, torch.Tensor], n: int
) -> dict[str, list[float]]:
    """Per pair, whether each of the pointer's identification softmaxes (:data:`NEAR_COLUMNS`)
    peaks within one cell of its label (NaN without a label, a pointer, or a place target), and
    its demo hand heights' error [cm] (NaN without ``demo_heights``)."""
    near = {key: [np.nan] * n for key in POINTER_COLUMNS}
    pointer = getattr(model.scene_head, "pointer", None)
    if pointer is None:
        return near
    camera = model.camera_indices(batch.get("camera"), n)
    demo, first = model.cached_maps(batch["demo_features"], batch["first_frame_features"])
    out = pointer(demo, first, torch.zeros_like(batch["head"]), camera)
    if out.demo_heights is not None:
        error = height_errors_m(out.demo_heights, batch["demo_trajectory"])
        near["hand_height_cm"] = (error.abs().mean(1) * 100).tolist()
    width = model.grid[1]
    cameras, grid = model.ray_cameras, model.grid
    labels = [
        ("object_near", out.object_logits,
         grasp_cells_per_camera(batch["trajectory"], cameras, camera, grid, batch["contact"])),
        ("moved_near", out.moved_logits, grasp_cells_per_camera(
            batch["demo_trajectory"], cameras, camera, grid, batch["demo_contact"])),
    ]  # fmt: skip
    if out.target_logits is not None and out.put_logits is not None:
        labels += [
            ("target_near", out.target_logits,
             release_cells_per_camera(batch["trajectory"], cameras, camera, grid)),
            ("put_near", out.put_logits,
             release_cells_per_camera(batch["demo_trajectory"], cameras, camera, grid)),
        ]  # fmt: skip
    for key, logits, (cells, ok) in labels:
        for j, (want, got) in enumerate(
            zip(cells.tolist(), logits.argmax(1).tolist(), strict=True)
        ):
            if ok[j]:
                apart = max(abs(want // width - got // width), abs(want % width - got % width))
                near[key][j] = float(apart <= 1)
    return near


def other_task_partners(tasks: Sequence[int]) -> np.ndarray:
    """For each sample of a batch, the index of a sample of another task whose demo it is shown
    instead (the nearest one after it, cyclically); -1 where the batch holds one task only."""
    partners = np.full(len(tasks), -1)
    for i in range(len(tasks)):
        for shift in range(1, len(tasks)):
            j = (i + shift) % len(tasks)
            if tasks[j] != tasks[i]:
                partners[i] = j
                break
    return partners


class _Truth:
    """Each episode's mined grasp flags, TCP path and the gt-waypoints rule's K = 5 waypoints,
    read once (an episode stands in many pairs)."""

    def __init__(self, data: CollectedData) -> None:
        self.data = data
        self._seen: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def __call__(self, episode: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(grasp (T,), tcp (T + 1, 3), waypoints (5, 3))`` of ``episode``."""
        key = id(episode)
        if key not in self._seen:
            grasp = self.data.attributes(episode, ("grasp",))[:, 0] > 0.5
            tcp = self.data.tcp_pos(episode)
            self._seen[key] = (grasp, tcp, extract_waypoints(tcp[:-1], grasp, K=5)[:, :3])
        return self._seen[key]


def _mean_distance_cm(a: np.ndarray, b: np.ndarray) -> float:
    """Mean distance between the rows of ``a`` and ``b`` [cm]."""
    return float(np.linalg.norm(a - b, axis=1).mean() * 100)


def _largest_set(model: AwdaNet, demo: torch.Tensor, batch: dict[str, Any], n: int) -> np.ndarray:
    """``(n, K, 3 + k)``: the largest waypoint set predicted from ``demo`` and the batch's o_1."""
    raw = model.forward_features(
        demo, batch["first_frame_features"], torch.zeros(n, dtype=torch.int64), batch.get("camera")
    )
    return model.waypoint_sets(raw)[-1].numpy()


def on_model_cameras(pairs: AwdaPairDataset, config: AwdaConfig) -> None:
    """Index every pair's camera among the snapshot's (the list its training saw), not among the
    pairs' own: a subset filmed by one of several cameras (MOSAIC's stack block: the second)
    would otherwise vote on, and project its labels through, the first camera's rays."""
    if config.num_cameras:
        pairs.index_cameras(config_cameras(config))


def pair_rows(
    snapshot: Path, data_dir: Path, tasks: Sequence[int] = (), threads: int | None = None
) -> list[dict[str, Any]]:
    """One row per pair: task, predicted and true waypoints, and the measures above."""
    if threads is not None:
        torch.set_num_threads(threads)
    loaded = load_snapshot(snapshot)
    model = loaded.build_model("cpu").eval()
    if not isinstance(model, AwdaNet):
        raise UsageError(
            f"{snapshot} holds a {loaded.arch!r} model; the offline study reads AWDA snapshots"
        )
    trunk = model.config.trunk
    if not trunk.freeze_backbone:
        raise UsageError(
            f"{snapshot} fine-tunes its backbone; the offline study reads frozen-trunk snapshots"
        )
    data = CollectedData(data_dir)
    pairs = AwdaPairDataset(
        data, image_size=(trunk.image_height_px, trunk.image_width_px), include_synthesized=False,
        allow_test=True, selection=Selection(tasks=tuple(tasks) or None), contact_points=True,
    )  # fmt: skip
    if len(pairs) == 0:
        raise UsageError(
            f"{data_dir} holds no (agent, demonstrator) pairs of tasks {list(tasks) or 'any'}"
        )
    on_model_cameras(pairs, model.config)
    samples = CachedAwdaPairs(
        pairs, load_or_build(data, trunk, frames_needed(pairs), progress=False)
    )
    rows: list[dict[str, Any]] = []
    truth = _Truth(data)  # the pairs' refs live as long as ``pairs``: their ids stay theirs
    with torch.no_grad():
        for start in range(0, len(samples), BATCH):
            chunk = range(start, min(len(samples), start + BATCH))
            batch = torch.utils.data.default_collate([samples[i] for i in chunk])
            largest = _largest_set(model, batch["demo_features"], batch, len(chunk))
            partners = other_task_partners([pairs.pairs[i][0].task for i in chunk])
            swapped = _largest_set(
                model, batch["demo_features"][np.maximum(partners, 0)], batch, len(chunk)
            )
            near = _pointer_measures(model, batch, len(chunk))
            for n, (i, predicted) in enumerate(zip(chunk, largest, strict=True)):
                agent, demo, _head = pairs.pairs[i]
                grasp, tcp, true = truth(agent)
                demo_true = truth(demo)[2]
                demo_effect = np.nan
                if partners[n] >= 0:
                    demo_effect = _mean_distance_cm(swapped[n, :, :3], predicted[:, :3])
                flags = 1 / (1 + np.exp(-predicted[:, 3])) > 0.5
                first_grasp = np.flatnonzero(grasp)
                grasp_err = np.nan
                if first_grasp.size and flags.any():
                    at = predicted[np.flatnonzero(flags)[0], :3]
                    grasp_err = float(np.linalg.norm(at - tcp[first_grasp[0]]) * 100)
                rows.append({
                    "task": agent.task,
                    "task_name": agent.meta.get("task_name", str(agent.task)),
                    "wp_err_cm": _mean_distance_cm(predicted[:, :3], true),
                    "end_err_cm": float(np.linalg.norm(predicted[-1, :3] - tcp[-1]) * 100),
                    "grasp_pred": bool(flags.any()),
                    "grasp_true": bool(first_grasp.size),
                    "grasp_err_cm": grasp_err,
                    "demo_copy_cm": _mean_distance_cm(predicted[:, :3], demo_true),
                    "true_shift_cm": _mean_distance_cm(true, demo_true),
                    "demo_effect_cm": demo_effect,
                    **{key: near[key][n] for key in POINTER_COLUMNS},
                    "predicted": predicted[:, :3],
                    "true": true,
                })  # fmt: skip
    return rows


def _spread(points: list[np.ndarray]) -> float:
    stack = np.stack(points)
    return float(np.linalg.norm(stack - stack.mean(0), axis=-1).mean() * 100)


def axis_bias_cm(rows: list[dict[str, Any]]) -> np.ndarray:
    """``(3,)``: the mean of predicted minus true waypoints over ``rows``' pairs and waypoints,
    per world axis [cm]."""
    predicted = np.stack([r["predicted"] for r in rows])
    true = np.stack([r["true"] for r in rows])
    return (predicted - true).reshape(-1, 3).mean(axis=0) * 100


def per_task_table(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """The per-task measures (module docstring), one row per task, plus ``all`` (medians over
    every pair's waypoint and end errors)."""
    by_task: dict[int, list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        by_task[row["task"]].append(row)
    table = []
    for _, group in sorted(by_task.items()):
        frame = pd.DataFrame(group)
        table.append({
            "task": group[0]["task_name"],
            "pairs": len(group),
            "wp_err_cm": frame["wp_err_cm"].median(),
            "end_err_cm": frame["end_err_cm"].median(),
            "grasp_pred": frame["grasp_pred"].mean(),
            "grasp_true": frame["grasp_true"].mean(),
            "grasp_err_cm": frame["grasp_err_cm"].median(),
            "spread_pred_cm": _spread([r["predicted"] for r in group]),
            "spread_true_cm": _spread([r["true"] for r in group]),
            "demo_copy_cm": frame["demo_copy_cm"].median(),
            "true_shift_cm": frame["true_shift_cm"].median(),
            "demo_effect_cm": frame["demo_effect_cm"].median(),
            **dict(zip(("bias_x_cm", "bias_y_cm", "bias_z_cm"), axis_bias_cm(group), strict=True)),
            **{key: frame[key].mean() for key in NEAR_COLUMNS},
            "hand_height_cm": frame["hand_height_cm"].median(),
        })  # fmt: skip
    every = pd.DataFrame(rows)
    table.append({
        "task": "all", "pairs": len(rows), "wp_err_cm": every["wp_err_cm"].median(),
        "end_err_cm": every["end_err_cm"].median(),
        "demo_copy_cm": every["demo_copy_cm"].median(),
        "true_shift_cm": every["true_shift_cm"].median(),
        "demo_effect_cm": every["demo_effect_cm"].median(),
    })  # fmt: skip
    return pd.DataFrame(table).set_index("task")

"""Where a run's AWDA waypoints land in MOSAIC: each evaluated episode's scene is rebuilt from its
seed (reset only, nothing rendered) and the stored predicted waypoints are measured against the
task's own objects. Per task (variation) of the held-out family, medians and hit rates:

    door, drawer   3-D distance of the first grasp-attributed waypoint (the pull's handle grasp)
                   and of the closest waypoint to the target handle (``handle_position``)
    press button   xy distance of the closest waypoint to the target button's cap and to any
                   button; how often the button nearest the waypoints is the target
    stack block    xy distance of the grasp point (first grasp-attributed waypoint) to cube A
                   and to cube B, and of the release point (last grasp-attributed) to B

Used for reports/learned/recipe-study.md (session 18); pick-and-place has ``which_object.py``::

    python scripts/screening/mosaic_waypoints.py runs/rp-door/runs/results.sqlite [METHOD]
"""

from __future__ import annotations

import collections
import json
import sqlite3
import sys
from typing import Any

import numpy as np

from awda_bench.evaluation.env_factory import make_env
from awda_bench.evaluation.episode_runner import fresh_scene_options
from awda_bench.suites import load_suite

HIT_M = 0.05
"""A waypoint "lands on" an object within this distance [m]."""


def _first_attributed(w: np.ndarray) -> int | None:
    marked = np.flatnonzero(w[:, 3] > 0.5)
    return int(marked[0]) if marked.size else None


def measure(scene: Any, w: np.ndarray) -> dict[str, float]:
    """The family's distances [m] for one episode's waypoints ``w`` (K, 4) in its scene."""
    first = _first_attributed(w)
    out: dict[str, float] = {}
    if hasattr(scene, "handle_position"):  # door, drawer
        handle = scene.handle_position()[0].cpu().numpy()
        out["closest waypoint to handle"] = float(np.linalg.norm(w[:, :3] - handle, axis=1).min())
        if first is not None:
            out["grasp waypoint to handle"] = float(np.linalg.norm(w[first, :3] - handle))
    elif hasattr(scene, "target_cap_top"):  # press button
        target = scene.target_cap_top()[0].cpu().numpy()
        caps = scene.button_cap_top()[0].cpu().numpy().reshape(-1, 3)
        to_caps = np.linalg.norm(w[:, None, :2] - caps[None, :, :2], axis=2)  # (K, buttons)
        nearest = int(to_caps.min(axis=0).argmin())
        out["closest waypoint to target button"] = float(
            np.linalg.norm(w[:, :2] - target[:2], axis=1).min()
        )
        out["closest waypoint to any button"] = float(to_caps.min())
        out["nearest button is the target"] = float(np.allclose(caps[nearest], target))
    elif hasattr(scene, "base_pose"):  # stack block
        a = scene.target_position()[0].cpu().numpy()
        b = scene.base_pose()[0][0].cpu().numpy()
        if first is not None:
            last = int(np.flatnonzero(w[:, 3] > 0.5)[-1])
            out["grasp point to A"] = float(np.linalg.norm(w[first, :2] - a[:2]))
            out["grasp point to B"] = float(np.linalg.norm(w[first, :2] - b[:2]))
            out["release point to B"] = float(np.linalg.norm(w[last, :2] - b[:2]))
    return out


def main(store: str, method: str) -> None:
    suite = load_suite("mosaic")
    rows = sqlite3.connect(store).execute(
        "SELECT seed, task, success_once, waypoints FROM episodes WHERE status='ok' "
        "AND suite='mosaic' AND method=? AND waypoints IS NOT NULL ORDER BY task",
        (method,),
    )
    envs: dict[str, Any] = {}
    per_task: dict[int, list[dict[str, float]]] = collections.defaultdict(list)
    for seed, task, success, waypoints in rows:
        env_id = suite.env_id_for(task)
        env = envs.setdefault(env_id, make_env(suite, env_id=env_id))
        env.reset(seed=seed, options=fresh_scene_options(suite, task))
        row = measure(env.unwrapped, np.asarray(json.loads(waypoints)))
        row["success"] = float(success)
        per_task[task].append(row)
    if not per_task:
        raise SystemExit(f"{store}: no ok mosaic episodes of method {method!r} with waypoints")
    for task, found in sorted(per_task.items()):
        print(f"task {task} ({suite.task(task).name}), {len(found)} episodes")
        for key in sorted({k for r in found for k in r}):
            values = np.array([r[key] for r in found if key in r])
            if key in ("success", "nearest button is the target"):
                print(f"  {key}: {values.mean():.2f}")
            else:
                hit = (values < HIT_M).mean()
                print(f"  {key}: median {100 * np.median(values):.1f} cm, < 5 cm {hit:.2f}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else "full-1")

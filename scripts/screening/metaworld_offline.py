"""Offline screening of an AWDA snapshot on Meta-World pairs (the Meta-World recipe study's offline
measure, issue 52; not the evaluation protocol).

usage: python scripts/screening/metaworld_offline.py SNAPSHOT DATA_DIR [TASK ...]
    (frozen-trunk snapshots; DATA_DIR a Meta-World collection; TASKs: only these, default all)

For every (agent, demonstrator) pair of a task in DATA_DIR (a test split: the held-out tasks; a
train split: e.g. the held-out tasks' training siblings), the 5-waypoint set the snapshot predicts
against the ground-truth waypoints extracted from the agent's own trajectory (the gt-waypoints
rule, awda_bench.waypoints.extract_waypoints, K = 5):

    wp err      mean distance between predicted and true waypoint i, over i (cm)
    end err     the last predicted waypoint vs the trajectory's last TCP (cm): where the task ends
    grasp       fraction of pairs whose prediction has a grasp (probability > 0.5) / true fraction
    grasp err   grasping tasks: the first grasp-attributed predicted waypoint vs the TCP at the
                first mined grasp step (cm)
    spread      mean distance of a pair's predicted waypoints to the task's mean prediction (cm),
                beside the true waypoints' own spread (layouts differ: a model that reads the
                scene must spread about as much as the truth)
    obj / moved ``demo-pointer`` snapshots: fraction of pairs whose object softmax (o_1) and
                what-moved softmax (the demo) peak within one cell (Chebyshev) of the
                identification label: the first grasp, or where the hand first moves the
                object on a task without one (awda_bench/data/contact_point.py)
"""

import sys
from collections import defaultdict

import numpy as np
import torch

from awda_bench.data.datasets import AwdaPairDataset, CollectedData, Selection
from awda_bench.models.identification_loss import grasp_cells_per_camera
from awda_bench.models.snapshot import load_snapshot
from awda_bench.training.feature_cache import load_or_build
from awda_bench.training.feature_datasets import CachedAwdaPairs, frames_needed
from awda_bench.waypoints import extract_waypoints

torch.set_num_threads(2)
snap = load_snapshot(sys.argv[1])
model = snap.build_model("cpu").eval()
trunk = model.config.trunk
data = CollectedData(sys.argv[2])
tasks = tuple(int(t) for t in sys.argv[3:]) or None
pairs = AwdaPairDataset(
    data,
    image_size=(trunk.image_height_px, trunk.image_width_px),
    include_synthesized=False,
    allow_test=True,
    selection=Selection(tasks=tasks),
    contact_points=True,
)
cache = load_or_build(data, trunk, frames_needed(pairs), progress=False)
ds = CachedAwdaPairs(pairs, cache)
rows: dict[int, list[dict]] = defaultdict(list)
names = {}
with torch.no_grad():
    for k in range(0, len(ds), 64):
        chunk = range(k, min(len(ds), k + 64))
        samples = [ds[i] for i in chunk]
        raw = model.forward_features(
            torch.stack([s["demo_features"] for s in samples]),
            torch.stack([s["first_frame_features"] for s in samples]),
            torch.zeros(len(samples), dtype=torch.int64),
            torch.stack([s["camera"] for s in samples]) if "camera" in samples[0] else None,
        )
        largest = model.waypoint_sets(raw)[-1].numpy()
        near = {"obj": [np.nan] * len(samples), "moved": [np.nan] * len(samples)}
        if hasattr(model.scene_head, "pointer"):  # demo-pointer: its identification softmaxes
            batch = torch.utils.data.default_collate(samples)
            camera = model.camera_indices(batch.get("camera"), len(samples))
            demo, first = model.cached_maps(batch["demo_features"], batch["first_frame_features"])
            out = model.scene_head.pointer(demo, first, torch.zeros_like(batch["head"]), camera)
            width = model.grid[1]
            for key, logits, traj, contact in (
                ("obj", out.object_logits, batch["trajectory"], batch["contact"]),
                ("moved", out.moved_logits, batch["demo_trajectory"], batch["demo_contact"]),
            ):
                cells, ok = grasp_cells_per_camera(
                    traj, model.ray_cameras, camera, model.grid, contact
                )
                for j, (want, got) in enumerate(
                    zip(cells.tolist(), logits.argmax(1).tolist(), strict=True)
                ):
                    if ok[j]:
                        apart = max(
                            abs(want // width - got // width), abs(want % width - got % width)
                        )
                        near[key][j] = float(apart <= 1)
        for n, (i, wps) in enumerate(zip(chunk, largest, strict=True)):
            agent = pairs.pairs[i][0]
            names[agent.task] = agent.meta.get("task_name", str(agent.task))
            grasp = data.attributes(agent, ("grasp",))[:, 0] > 0.5
            tcp = data.tcp_pos(agent)
            true = extract_waypoints(tcp[:-1], grasp, K=5)
            flags = 1 / (1 + np.exp(-wps[:, 3])) > 0.5
            on = np.flatnonzero(grasp)
            grasp_err = np.nan
            if on.size and flags.any():
                grasp_err = np.linalg.norm(wps[np.flatnonzero(flags)[0], :3] - tcp[on[0]]) * 100
            rows[agent.task].append(
                {
                    "wp_err": np.linalg.norm(wps[:, :3] - true[:, :3], axis=1).mean() * 100,
                    "end_err": np.linalg.norm(wps[-1, :3] - tcp[-1]) * 100,
                    "pred_grasp": bool(flags.any()),
                    "true_grasp": bool(on.size),
                    "grasp_err": grasp_err,
                    "obj": near["obj"][n],
                    "moved": near["moved"][n],
                    "pred": wps[:, :3],
                    "true": true[:, :3],
                }
            )


def spread(points: list[np.ndarray]) -> float:
    stack = np.stack(points)
    return float(np.linalg.norm(stack - stack.mean(0), axis=-1).mean() * 100)


print(f"snapshot {sys.argv[1]}  data {sys.argv[2]}  pairs {len(ds)}")
print(
    "task                      pairs  wp err  end err  grasp pred/true  grasp err  spread pred/true"
    "  obj/moved within 1 cell"
)
all_wp, all_end = [], []
for task in sorted(rows):
    r = rows[task]
    wp = np.array([x["wp_err"] for x in r])
    end = np.array([x["end_err"] for x in r])
    all_wp += list(wp)
    all_end += list(end)
    ge = np.array([x["grasp_err"] for x in r])
    print(
        f"{names[task][:24]:24s} {len(r):6d} {np.median(wp):6.1f}  {np.median(end):7.1f}  "
        f"{np.mean([x['pred_grasp'] for x in r]):6.2f}/{np.mean([x['true_grasp'] for x in r]):.2f}"
        f"  {np.nanmedian(ge) if np.isfinite(ge).any() else float('nan'):9.1f}"
        f"  {spread([x['pred'] for x in r]):6.1f}/{spread([x['true'] for x in r]):.1f}"
        f"  {np.nanmean([x['obj'] for x in r]):.2f}/{np.nanmean([x['moved'] for x in r]):.2f}"
    )
print(f"all: wp err median {np.median(all_wp):.1f} cm, end err median {np.median(all_end):.1f} cm")

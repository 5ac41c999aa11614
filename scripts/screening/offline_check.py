"""Offline check of an AWDA snapshot on collected pairs (the recipe study's screening measure; not
the evaluation protocol).

usage: python scripts/screening/offline_check.py SNAPSHOT DATA_DIR [PAIRS]   (frozen-trunk snapshots)
For every (agent, demonstrator) pair of a task: the predicted grasp point (first waypoint whose
grasp probability > 0.5) vs the agent's true grasp point (TCP at the first mined grasp step),
which object is nearest the predicted grasp point (target or a distractor), and the place point.
"""

import sys
from collections import Counter

import numpy as np
import torch

from awda_bench.data.datasets import AwdaPairDataset, CollectedData
from awda_bench.models.snapshot import load_snapshot
from awda_bench.training.feature_cache import load_or_build
from awda_bench.training.feature_datasets import CachedAwdaPairs, frames_needed

OBJ = ["milk", "bread", "cereal", "can"]
torch.set_num_threads(2)
snap = load_snapshot(sys.argv[1])
model = snap.build_model("cpu").eval()
trunk = model.config.trunk
data = CollectedData(sys.argv[2])
pairs = AwdaPairDataset(
    data,
    image_size=(trunk.image_height_px, trunk.image_width_px),
    include_synthesized=False,
    allow_test=True,
)
cache = load_or_build(data, trunk, frames_needed(pairs), progress=False)
ds = CachedAwdaPairs(pairs, cache)
rng = np.random.default_rng(0)
idx = rng.choice(
    len(ds), min(len(ds), int(sys.argv[3]) if len(sys.argv) > 3 else 400), replace=False
)
rows = []
with torch.no_grad():
    for k in range(0, len(idx), 64):
        chunk = idx[k : k + 64]
        samples = [ds[int(i)] for i in chunk]
        raw = model.forward_features(
            torch.stack([s["demo_features"] for s in samples]),
            torch.stack([s["first_frame_features"] for s in samples]),
            torch.zeros(len(samples), dtype=torch.int64),
        )
        largest = model.waypoint_sets(raw)[-1]
        for i, wps in zip(chunk, largest.numpy(), strict=True):
            agent = pairs.pairs[int(i)][0]
            grasp = data.attributes(agent, ("grasp",))[:, 0] > 0.5
            tcp = data.tcp_pos(agent)
            on = np.flatnonzero(grasp)
            flags = 1 / (1 + np.exp(-wps[:, 3])) > 0.5
            objs = np.stack([data._read(agent, f"env_states/actors/{o}", 0)[:3] for o in OBJ])
            target = agent.task // 4
            if flags.any():
                g = wps[np.flatnonzero(flags)[0], :3]
                p = wps[np.flatnonzero(flags)[-1], :3]
                near = int(np.argmin(np.linalg.norm(objs[:, :2] - g[:2], axis=1)))
            else:
                g = p = None
                near = -1
            rows.append(
                {
                    "task": agent.task,
                    "grasp_err": np.linalg.norm(g - tcp[on[0]]) * 100 if g is not None else np.nan,
                    "place_err": np.linalg.norm(p - tcp[on[-1]]) * 100 if p is not None else np.nan,
                    "near": "target" if near == target else ("none" if near < 0 else OBJ[near]),
                    "g": g,
                }
            )
ge = np.array([r["grasp_err"] for r in rows])
pe = np.array([r["place_err"] for r in rows])
print(
    f"pairs {len(rows)}  grasp err median {np.nanmedian(ge):.1f} cm  "
    f"<3cm {np.mean(ge < 3):.2f}  <5cm {np.mean(ge < 5):.2f}"
)
print(f"place err median {np.nanmedian(pe):.1f} cm  <5cm {np.mean(pe < 5):.2f}")
print("nearest object to the predicted grasp:", dict(Counter(r["near"] for r in rows)))
by_task = {}
for r in rows:
    if r["g"] is not None:
        by_task.setdefault(r["task"], []).append(r["g"])
spread = [
    np.mean(np.linalg.norm(np.array(v) - np.mean(v, 0), axis=1)) * 100 for v in by_task.values()
]
print(f"grasp point spread per task (mean distance to the task mean): {np.mean(spread):.1f} cm")

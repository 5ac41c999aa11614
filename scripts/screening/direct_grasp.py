"""Diagnostic for the recipe study: can the demo-to-scene head find the demonstrated object in
o_1 when told directly where it is? Waypoint 0 (the 1-waypoint set) is regressed onto the true
grasp point (smooth L1, cm) instead of the Soft-DTW loss; batch 16, Adam 5e-4, frozen Lite0
stride-16 features from the project's cache.

usage: [HEAD=demo-pointer] python scripts/screening/direct_grasp.py ref|noref|can STEPS TRAIN_DATA TEST_DATA

``can``: localization alone, without identification: the horizontal position of the soda can
(every scene has one) is the target, whatever the task.
"""

import os
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

from awda_bench.data.datasets import AwdaPairDataset, CollectedData
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig, TrunkConfig
from awda_bench.training.feature_cache import load_or_build
from awda_bench.training.feature_datasets import CachedAwdaPairs, frames_needed
from awda_bench.training.run import agent_camera

torch.set_num_threads(2)
torch.manual_seed(0)
ref = sys.argv[1] in ("ref", "can")
can_only = sys.argv[1] == "can"
steps = int(sys.argv[2])
T = TrunkConfig(
    image_height_px=240,
    image_width_px=320,
    backbone="efficientnet-lite0",
    backbone_stride=16,
    freeze_backbone=True,
    backbone_weights="imagenet",
    head=os.environ.get("HEAD", "demo-to-scene"),
    attention_head_dim=32,
)
OBJ = ["milk", "bread", "cereal", "can"]


def load(path):
    data = CollectedData(path)
    pairs = AwdaPairDataset(data, image_size=(240, 320), include_synthesized=False, allow_test=True)
    cache = load_or_build(data, T, frames_needed(pairs), progress=False)
    ds = CachedAwdaPairs(pairs, cache)
    info = {}
    for a, _, _ in pairs.pairs:
        k = (str(a.file), a.traj)
        if k not in info:
            g = data.attributes(a, ("grasp",))[:, 0] > 0.5
            info[k] = (
                data.tcp_pos(a)[np.flatnonzero(g)[0]],
                np.stack([data._read(a, f"env_states/actors/{o}", 0)[:3] for o in OBJ]),
                a.task,
            )
    return data, pairs, ds, info


data, tp, tr, tinfo = load(sys.argv[3])
_, hp, he, hinfo = load(sys.argv[4])
model = AwdaNet(
    AwdaConfig(trunk=T, head_hidden_dim=128, demo_reference_frame=ref, **agent_camera(data))
)
opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], 5e-4)


def batch(ds, pairs, info, idx):
    s = [ds[int(i)] for i in idx]
    keys = [(str(pairs.pairs[int(i)][0].file), pairs.pairs[int(i)][0].traj) for i in idx]
    if can_only:  # the can's xy, at the mean grasp height
        rows = [np.r_[info[k][1][3, :2], 0.15] for k in keys]
    else:
        rows = [info[k][0] for k in keys]
    g = torch.tensor(np.stack(rows), dtype=torch.float32)
    return (
        torch.stack([x["demo_features"] for x in s]),
        torch.stack([x["first_frame_features"] for x in s]),
        g,
    )


def evaluate(ds, pairs, info, n=300):
    model.eval()
    rng = np.random.default_rng(0)
    n = min(n, len(ds))
    idx = rng.choice(len(ds), n, replace=False)
    errs, hit = [], []
    with torch.no_grad():
        for k in range(0, n, 50):
            d, f, g = batch(ds, pairs, info, idx[k : k + 50])
            w = model.forward_features(d, f, torch.zeros(len(g), dtype=torch.long))[:, 0, :3]
            errs += ((w - g)[:, : 2 if can_only else 3].norm(dim=1) * 100).tolist()
            for i, q in zip(idx[k : k + 50], w.numpy(), strict=True):
                _, objs, task = info[
                    (str(pairs.pairs[int(i)][0].file), pairs.pairs[int(i)][0].traj)
                ]
                want = 3 if can_only else task // 4
                hit.append(int(np.argmin(np.linalg.norm(objs[:, :2] - q[:2], axis=1))) == want)
    model.train()
    return f"median {np.median(errs):.1f} cm, nearest=target {np.mean(hit):.2f}"


gen = torch.Generator().manual_seed(0)
t0 = time.time()
for step in range(1, steps + 1):
    d, f, g = batch(tr, tp, tinfo, torch.randint(len(tr), (16,), generator=gen))
    w = model.forward_features(d, f, torch.zeros(16, dtype=torch.long))[:, 0, :3]
    n = 2 if can_only else 3
    loss = F.smooth_l1_loss(w[:, :n] * 100, g[:, :n] * 100)
    opt.zero_grad()
    loss.backward()
    opt.step()
    if step % 100 == 0:
        print(
            step,
            f"{loss.item():.2f}",
            f"{time.time() - t0:.0f}s",
            "train:",
            evaluate(tr, tp, tinfo),
            "| held-out:",
            evaluate(he, hp, hinfo),
            flush=True,
        )

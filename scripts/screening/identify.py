"""Screening for the recipe study: identification supervised directly, on frozen Lite0 stride-16
features from the project's cache (session 11).

Two cell-wise softmaxes, each trained with a cross-entropy onto a cell read from the trajectories
themselves (the TCP at the first grasp, projected through the scene camera; no simulator state):

    moved(cell)  over the demo's cells: where the demonstrator grasps, in demo frame 0
    g            = sum over cells of softmax(moved) * e(demo frame 0, cell): what stood there
    score(cell)  over o_1's cells: MLP([e(o_1, cell), e(o_1, cell) * g])      (SCORE=mlp)
                 or <P e(o_1, cell), P g> / sqrt(d)                           (SCORE=cosine)

g only ever sees demo frame 0's appearance where the grasp is: where the object goes afterwards
cannot select it (the leak the session-10 study suspected).

usage: python scripts/screening/identify.py STEPS TRAIN_DATA TEST_DATA
env:   SCORE=mlp|cosine  MOVED_FRAMES=all|first|pre  MOVED_WEIGHT=1.0  SEED=0

Prints, every 100 steps, on training pairs and held-out pairs: the demo grasp cell found (argmax
within one cell), o_1's target cell found (within one cell), and o_1's argmax nearest the target
object (of the four; chance 0.25).
"""

import os
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from awda_bench.data.datasets import AwdaPairDataset, CollectedData
from awda_bench.models.config import TrunkConfig
from awda_bench.training.feature_cache import load_or_build
from awda_bench.training.feature_datasets import CachedAwdaPairs, frames_needed

torch.set_num_threads(2)
SEED = int(os.environ.get("SEED", "0"))
torch.manual_seed(SEED)
SCORE = os.environ.get("SCORE", "mlp")
MOVED_FRAMES = os.environ.get("MOVED_FRAMES", "all")
MOVED_WEIGHT = float(os.environ.get("MOVED_WEIGHT", "1.0"))
steps = int(sys.argv[1])
T = TrunkConfig(
    image_height_px=240,
    image_width_px=320,
    backbone="efficientnet-lite0",
    backbone_stride=16,
    freeze_backbone=True,
    backbone_weights="imagenet",
)
GRID = (15, 20)
OBJ = ["milk", "bread", "cereal", "can"]


def project(points: np.ndarray, intrinsic: np.ndarray, extrinsic: np.ndarray) -> np.ndarray:
    """World points (k, 3) -> (k, 2) (row, col) in cell units."""
    cam = points @ extrinsic[:, :3].T + extrinsic[:, 3]
    uv = cam @ intrinsic.T
    uv = uv[:, :2] / uv[:, 2:3]
    return np.stack((uv[:, 1] * GRID[0] / 240, uv[:, 0] * GRID[1] / 320), axis=1)


def cell_index(rc: np.ndarray) -> int:
    r = int(np.clip(np.floor(rc[0]), 0, GRID[0] - 1))
    c = int(np.clip(np.floor(rc[1]), 0, GRID[1] - 1))
    return r * GRID[1] + c


def load(path):
    data = CollectedData(path)
    pairs = AwdaPairDataset(data, image_size=(240, 320), include_synthesized=False, allow_test=True)
    cache = load_or_build(data, T, frames_needed(pairs), progress=False)
    ds = CachedAwdaPairs(pairs, cache)
    info = {}
    for agent, demo, _ in pairs.pairs:
        for ref in (agent, demo):
            k = (str(ref.file), ref.traj)
            if k in info:
                continue
            grasp = data.attributes(ref, ("grasp",))[:, 0] > 0.5
            intrinsic, extrinsic = data.camera(ref)
            tcp = data.tcp_pos(ref)[np.flatnonzero(grasp)[0]]
            objects = np.stack([data._read(ref, f"env_states/actors/{o}", 0)[:3] for o in OBJ])
            info[k] = {
                "cell": cell_index(project(tcp[None], intrinsic, extrinsic)[0]),
                "objects_rc": project(objects, intrinsic, extrinsic),
                "target": ref.task // 4,
            }
    keys = [((str(a.file), a.traj), (str(d.file), d.traj), int(d.steps)) for a, d, _ in pairs.pairs]
    return ds, info, keys


class Identify(nn.Module):
    def __init__(self, channels: int, frames: int, dim: int = 128, hidden: int = 128) -> None:
        super().__init__()
        self.embed = nn.Sequential(nn.Conv2d(channels, dim, 1), nn.GELU(), nn.Conv2d(dim, dim, 1))
        self.moved = nn.Sequential(
            nn.Conv2d(frames * dim, hidden, 1),
            nn.GELU(),
            nn.Conv2d(hidden, hidden, 3, padding=1),
            nn.GELU(),
            nn.Conv2d(hidden, 1, 1),
        )
        if SCORE == "mlp":
            self.score = nn.Sequential(nn.Linear(2 * dim, hidden), nn.GELU(), nn.Linear(hidden, 1))
        else:
            self.project = nn.Linear(dim, dim)
        self.dim = dim

    def forward(self, demo, first):
        b, t, c, h, w = demo.shape
        if MOVED_FRAMES == "first":
            demo = demo[:, :1]
        elif MOVED_FRAMES == "pre":
            demo = demo[:, :3]
        t = demo.shape[1]
        e_demo = self.embed(demo.reshape(b * t, c, h, w)).view(b, t * self.dim, h, w)
        moved = self.moved(e_demo).flatten(1)  # (B, L)
        start = e_demo[:, : self.dim].flatten(2).transpose(1, 2)  # (B, L, d): demo frame 0
        g = torch.einsum("bl,bld->bd", torch.softmax(moved, 1), start)
        scene = self.embed(first).flatten(2).transpose(1, 2)  # (B, L, d)
        if SCORE == "mlp":
            gg = g[:, None].expand_as(scene)
            score = self.score(torch.cat((scene, scene * gg), -1))[..., 0]
        else:
            score = torch.einsum("bld,bd->bl", self.project(scene), self.project(g))
            score = score / self.dim**0.5
        return moved, score


train_ds, train_info, train_keys = load(sys.argv[2])
test_ds, test_info, test_keys = load(sys.argv[3])
sample = train_ds[0]
used = {"first": 1, "pre": 3}.get(MOVED_FRAMES, sample["demo_features"].shape[0])
model = Identify(sample["first_frame_features"].shape[0], used)
opt = torch.optim.Adam(model.parameters(), 5e-4)


def batch(ds, info, keys, idx):
    s = [ds[int(i)] for i in idx]
    demo_cell = torch.tensor([info[keys[int(i)][1]]["cell"] for i in idx])
    agent_cell = torch.tensor([info[keys[int(i)][0]]["cell"] for i in idx])
    demo = torch.stack([x["demo_features"] for x in s])
    first = torch.stack([x["first_frame_features"] for x in s])
    return demo, first, demo_cell, agent_cell


def near(pred: int, label: int) -> bool:
    return (
        abs(pred // GRID[1] - label // GRID[1]) <= 1 and abs(pred % GRID[1] - label % GRID[1]) <= 1
    )


def evaluate(ds, info, keys, n=400):
    model.eval()
    idx = np.random.default_rng(0).choice(len(ds), min(n, len(ds)), replace=False)
    found_demo, found_agent, nearest = [], [], []
    with torch.no_grad():
        for k in range(0, len(idx), 50):
            part = idx[k : k + 50]
            demo, first, demo_cell, agent_cell = batch(ds, info, keys, part)
            moved, score = model(demo, first)
            for i, m, s, dc, ac in zip(
                part, moved.argmax(1), score.argmax(1), demo_cell, agent_cell, strict=True
            ):
                found_demo.append(near(int(m), int(dc)))
                found_agent.append(near(int(s), int(ac)))
                a = info[keys[int(i)][0]]
                rc = np.array([int(s) // GRID[1] + 0.5, int(s) % GRID[1] + 0.5])
                nearest.append(
                    int(np.argmin(np.linalg.norm(a["objects_rc"] - rc, axis=1))) == a["target"]
                )
    model.train()
    return (
        f"demo cell {np.mean(found_demo):.2f}, o_1 cell {np.mean(found_agent):.2f}, "
        f"nearest=target {np.mean(nearest):.2f} (n={len(idx)})"
    )


gen = torch.Generator().manual_seed(SEED)
t0 = time.time()
print(
    f"SCORE={SCORE} MOVED_FRAMES={MOVED_FRAMES} MOVED_WEIGHT={MOVED_WEIGHT} "
    f"train pairs {len(train_ds)}, held-out pairs {len(test_ds)}",
    flush=True,
)
for step in range(1, steps + 1):
    demo, first, demo_cell, agent_cell = batch(
        train_ds, train_info, train_keys, torch.randint(len(train_ds), (16,), generator=gen)
    )
    moved, score = model(demo, first)
    loss = MOVED_WEIGHT * F.cross_entropy(moved, demo_cell) + F.cross_entropy(score, agent_cell)
    opt.zero_grad()
    loss.backward()
    opt.step()
    if step % 100 == 0:
        print(
            step,
            f"loss {loss.item():.2f}",
            f"{time.time() - t0:.0f}s",
            "| train:",
            evaluate(train_ds, train_info, train_keys),
            "| held-out:",
            evaluate(test_ds, test_info, test_keys),
            flush=True,
        )

"""Probe for the recipe study: can a detector that scores each cell of the frozen EfficientNet-Lite0
map from that cell's features alone (no position) find one object in scenes it never saw?

usage: python scripts/screening/detector_probe.py TRAIN.npz TEST.npz OBJECT [STRIDE] [DATA_DIR]
(TRAIN/TEST from scripts/screening/render_scenes.py; OBJECT 0 milk, 1 bread, 2 cereal, 3 can;
DATA_DIR any pick-place collection, for its camera.) Three detectors, each a softmax over the
cells whose expected cell centre is regressed onto the object's projected pixel (smooth L1),
batch 16, Adam 1e-3, 400 steps: a 1x1 conv, two 1x1 convs (128 hidden), a 3x3 then a 1x1 conv.
Printed: median pixel error and how often the object nearest the prediction is the one asked for
(chance 0.25), on the training scenes and on the new ones.
"""

import sys
import time

import numpy as np
import torch
from torch import nn

from awda_bench.data.datasets import CollectedData
from awda_bench.models.config import TrunkConfig
from awda_bench.models.frame_encoder import build_frame_encoder
from awda_bench.training.run import agent_camera

torch.set_num_threads(2)
torch.manual_seed(0)
obj = int(sys.argv[3])
stride = int(sys.argv[4]) if len(sys.argv) > 4 else 16
trunk = TrunkConfig(
    image_height_px=240,
    image_width_px=320,
    backbone="efficientnet-lite0",
    backbone_stride=stride,
    freeze_backbone=True,
    backbone_weights="imagenet",
    head="demo-pointer",
)
normalize, backbone, channels = build_frame_encoder(trunk, True)
backbone.eval()
camera = agent_camera(CollectedData(sys.argv[5] if len(sys.argv) > 5 else "runs/probe"))
K = np.asarray(camera["camera_intrinsic"]).reshape(3, 3)
E = np.asarray(camera["camera_extrinsic"]).reshape(3, 4)


def load(path: str) -> tuple[torch.Tensor, torch.Tensor]:
    z = np.load(path)
    x = torch.from_numpy(z["imgs"]).permute(0, 3, 1, 2).float() / 255
    with torch.no_grad():
        f = torch.cat([backbone(normalize(x[i : i + 32])) for i in range(0, len(x), 32)])
    cam = np.einsum("ij,nkj->nki", E[:, :3], z["pos"]) + E[:, 3]
    uvw = np.einsum("ij,nkj->nki", K, cam)
    return f, torch.tensor(uvw[..., :2] / uvw[..., 2:], dtype=torch.float32)


t0 = time.time()
f_train, uv_train = load(sys.argv[1])
f_test, uv_test = load(sys.argv[2])
print(f"encoded in {time.time() - t0:.0f} s; feature map {tuple(f_train.shape[1:])}")
h, w = f_train.shape[-2:]
ys, xs = torch.meshgrid(
    (torch.arange(h) + 0.5) * 240 / h, (torch.arange(w) + 0.5) * 320 / w, indexing="ij"
)
centres = torch.stack((xs, ys), -1).reshape(-1, 2)
detectors = {
    "1x1 conv": nn.Conv2d(channels, 1, 1),
    "two 1x1 convs": nn.Sequential(nn.Conv2d(channels, 128, 1), nn.ReLU(), nn.Conv2d(128, 1, 1)),
    "3x3 + 1x1 conv": nn.Sequential(
        nn.Conv2d(channels, 128, 3, padding=1), nn.ReLU(), nn.Conv2d(128, 1, 1)
    ),
}
for name, net in detectors.items():
    opt = torch.optim.Adam(net.parameters(), 1e-3)

    def predict(f: torch.Tensor, net: nn.Module = net) -> torch.Tensor:
        return torch.softmax(net(f).flatten(1), 1) @ centres

    def score(f: torch.Tensor, uv: torch.Tensor) -> str:
        with torch.no_grad():
            q = predict(f)
        err = (q - uv[:, obj]).norm(dim=1)
        nearest = (q[:, None] - uv).norm(dim=2).argmin(1) == obj
        return f"{err.median():.1f} px, nearest {nearest.float().mean():.2f}"

    g = torch.Generator().manual_seed(0)
    for step in range(1, 401):
        i = torch.randint(len(f_train), (16,), generator=g)
        loss = nn.functional.smooth_l1_loss(predict(f_train[i]), uv_train[i, obj])
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step in (50, 100, 200, 400):
            print(
                f"{name:15s} {step:4d}  train {score(f_train, uv_train)}  new scenes {score(f_test, uv_test)}",
                flush=True,
            )

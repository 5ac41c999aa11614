"""Render N freshly reset pick-place scenes (o_1, the third-person frame) with the four objects'
world positions, for the detector probe (scripts/screening/detector_probe.py). No expert runs:
~0.06 s a scene.

usage: python scripts/screening/render_scenes.py N SEED0 OUT.npz
Scene i is task i % 16 reset with seed SEED0 + i.
"""

import sys
import time

import numpy as np

from awda_bench.evaluation.env_factory import make_env
from awda_bench.robot.cameras import capture_rgb
from awda_bench.suites import load_suite

OBJ = ["milk", "bread", "cereal", "can"]
n, seed0, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
env = make_env(load_suite("pick_place"))
images, positions = [], []
t0 = time.time()
for i in range(n):
    env.reset(seed=seed0 + i, options={"task": i % 16})
    actors = env.unwrapped.scene.actors
    images.append(capture_rgb(env)[0])
    positions.append(np.stack([actors[o].pose.p[0].cpu().numpy() for o in OBJ]))
print(f"rendered {n} scenes in {time.time() - t0:.1f} s")
np.savez_compressed(out, imgs=np.stack(images), pos=np.stack(positions))

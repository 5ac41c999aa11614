"""Where a run's AWDA grasp waypoints land: in each evaluated pick-place episode's own scene
(rebuilt from its seed), the object nearest (xy) to the waypoint before the first grasp-attributed
one, tallied by outcome. Used for reports/learned/recipe-study.md (session 12)::

    python scripts/screening/which_object.py runs/repro-small/runs/results.sqlite
"""

from __future__ import annotations

import collections
import json
import sqlite3
import sys

import numpy as np

from awda_bench.evaluation.env_factory import make_env
from awda_bench.evaluation.episode_runner import fresh_scene_options
from awda_bench.suites import load_suite

NEAR_M = 0.04
"""The grasp metric's "reached" distance [m]."""


def main(store: str) -> None:
    suite = load_suite("pick_place")
    env = make_env(suite)
    scene = env.unwrapped
    names = [s.name for s in scene.objects_spec]
    rows = sqlite3.connect(store).execute(
        "SELECT seed, task, reached, success_once, waypoints FROM episodes "
        "WHERE status='ok' AND suite='pick_place' AND waypoints IS NOT NULL"
    )
    tally: collections.Counter[tuple[str, str, str]] = collections.Counter()
    for seed, task, reached, success, waypoints in rows:
        env.reset(seed=seed, options=fresh_scene_options(suite, task))
        positions = scene.object_poses()[0][0].cpu().numpy()
        target = names[int(scene.target_object_index[0])]
        w = np.asarray(json.loads(waypoints))
        first_grasp = int(np.argmax(w[:, 3] > 0.5))
        point = w[max(first_grasp - 1, 0), :3]
        distance = np.linalg.norm(positions[:, :2] - point[:2], axis=1)
        nearest = names[int(distance.argmin())]
        outcome = "success" if success else "reached, grasp missed" if reached else "not reached"
        within = f"< {NEAR_M:.2f} m" if distance.min() < NEAR_M else f">= {NEAR_M:.2f} m"
        tally[(outcome, "the target" if nearest == target else nearest, within)] += 1
    for key, n in sorted(tally.items(), key=lambda item: -item[1]):
        print(n, *key, sep="\t")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "runs/repro-small/runs/results.sqlite")

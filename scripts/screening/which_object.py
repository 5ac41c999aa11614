"""Where a reproduce run's Full-1 grasp waypoints land (run from the project root: python scripts/screening/which_object.py): the nearest of the four objects (xy) in each held-out
episode's own scene (reset with the episode's seed), for successes and failures."""

import json, sqlite3, collections
import numpy as np
from awda_bench.suites import load_suite
from awda_bench.harness.env_factory import make_env
from awda_bench.harness.episode_runner import fresh_scene_options

suite = load_suite("pick_place")
env = make_env(suite)
u = env.unwrapped
names = [s.name for s in u.objects_spec]
c = sqlite3.connect("runs/repro-small/runs/results.sqlite")
rows = c.execute(
    "select seed, task, reached, grasped, success_once, waypoints from episodes where status='ok'"
).fetchall()
count = collections.Counter()
for seed, task, reached, grasped, success, wps in rows:
    env.reset(seed=seed, options=fresh_scene_options(suite, task))
    pos = u.object_poses()[0][0].cpu().numpy()
    target = names[int(u.target_object_index[0])]
    w = np.asarray(json.loads(wps))
    k = int(np.argmax(w[:, 3] > 0.5))
    point = w[max(k - 1, 0), :3]
    d = np.linalg.norm(pos[:, :2] - point[:2], axis=1)
    near = names[int(d.argmin())]
    outcome = "success" if success else ("reached, not grasped" if reached else "not reached")
    count[(outcome, "target" if near == target else near, d.min() < 0.04)] += 1
for key, n in sorted(count.items(), key=lambda kv: -kv[1]):
    print(n, key)

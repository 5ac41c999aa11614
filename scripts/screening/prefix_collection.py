"""Screening only: the collection `collect` would write with fewer episodes per task, cut from a
larger one instead of recorded again.

    python scripts/screening/prefix_collection.py SRC_DATA_DIR N OUT_DATA_DIR

Why it is exact: a unit's attempt ``i`` has a seed hashed from (suite, base seed, task, i, role)
and is recorded in an env that has played exactly attempts 0..i-1 (awda_bench/data/plan.py), so
the first N kept episodes of a unit of a complete collection with M >= N per task are, byte for
byte, what `collect --episodes-per-task N` keeps, as long as no attempt before them was discarded
(refused otherwise). Synthesized trajectories do not depend on N and are hard-linked. The
manifest is written by collect's own code for the N-per-task plan, so `reproduce --data OUT` and
`train` accept it as that collection (same fingerprint as a fresh one).

Used by the recipe study (issue 24, session 23) to measure Full-1 at 30 episodes per task from the
50-per-task collection without 40 more minutes of recording.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import h5py

from awda_bench.data.collect import MANIFEST, _write_final_manifest
from awda_bench.data.config import ROLE_SYNTHESIZED, CollectConfig
from awda_bench.data.plan import make_plan


def main(src: Path, n: int, out: Path) -> None:
    manifest = json.loads((src / MANIFEST).read_text())
    if not manifest.get("complete"):
        sys.exit(f"{src} is not a complete collection")
    d = manifest["definition"]
    if n > d["episodes_per_task"]:
        sys.exit(f"{src} holds {d['episodes_per_task']} per task, fewer than {n}")
    config = CollectConfig(
        suite=d["suite"], split=d["split"], embodiment="both", episodes_per_task=n,
        out=out, seed=d["seed"], synthesize=d["synthesize"],
        image_size=tuple(d["image_size"]), depth_size=tuple(d["depth_size"]),
        tasks=tuple(d["tasks"]),
    )  # fmt: skip
    plan = make_plan(config)
    if plan.definition != {**d, "episodes_per_task": n}:
        sys.exit("the N-per-task plan differs from the source in more than episodes_per_task")
    if out.exists():
        sys.exit(f"{out} exists; choose a new directory")
    for unit in manifest["units"]:
        h5_src = src / unit["file"]
        h5_dst = out / unit["file"]
        h5_dst.parent.mkdir(parents=True, exist_ok=True)
        json_src, json_dst = h5_src.with_suffix(".json"), h5_dst.with_suffix(".json")
        if unit["role"] == ROLE_SYNTHESIZED:
            os.link(h5_src, h5_dst)
            os.link(json_src, json_dst)
            continue
        payload = json.loads(json_src.read_text())
        episodes = payload["episodes"][:n]
        if payload.get("discarded") or [e["attempt"] for e in episodes] != list(range(n)):
            sys.exit(f"{unit['file']}: attempts before the {n}th kept one were discarded")
        with h5py.File(h5_src, "r") as fin, h5py.File(h5_dst, "w") as fout:
            for i in range(n):
                fin.copy(fin[f"traj_{i}"], fout, name=f"traj_{i}")
        json_dst.write_text(json.dumps({**payload, "episodes": episodes}, indent=1))
    if not _write_final_manifest(out, plan):
        sys.exit("the written collection is not complete (see its manifest)")
    print(f"{out}: {n} per task, fingerprint {plan.fingerprint}")


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3]))

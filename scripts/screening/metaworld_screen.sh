#!/usr/bin/env bash
# The Meta-World recipe study's screen of one trained directory (issue 52; reports/learned/
# recipe-study-metaworld.md): offline on the held-out tasks' validation pairs and the training
# siblings' pairs, then online: the last snapshot, 10 episodes per held-out task and per sibling.
# usage: bash scripts/screening/metaworld_screen.sh CKPT_DIR DATA_ROOT OUT
#   CKPT_DIR   a `train --method awda` directory (frozen trunk) on Meta-World
#   DATA_ROOT  the reproduce directory's data/ (train/ and test/ collections)
#   OUT        where the screen's stores go
set -euo pipefail
ckpt="$1"; data="$2"; out="$3"
last="$(ls "$ckpt"/snapshot-*.pt | sort | tail -n 1)"
siblings=(4 13 30 47 49)  # reproduce.config.fit_check_tasks(metaworld)
python scripts/screening/metaworld_offline.py "$last" "$data/test"
python scripts/screening/metaworld_offline.py "$last" "$data/train" "${siblings[@]}"
python -m awda_bench run --suite metaworld --method awda-centre --checkpoints "$ckpt" \
  --snapshots 1 --episodes 10 --workers 2 --no-progress --out "$out/held-out"
task_args=(); for t in "${siblings[@]}"; do task_args+=(--task "$t"); done
python -m awda_bench run --suite metaworld --method awda-centre --checkpoints "$ckpt" \
  --snapshots 1 --episodes 10 --workers 2 --no-progress --split train "${task_args[@]}" \
  --out "$out/siblings"
for store in "$out/held-out" "$out/siblings"; do
  python - "$store" <<'PY'
import sqlite3, sys
db = sqlite3.connect(f"{sys.argv[1]}/results.sqlite")
rows = db.execute("SELECT task, COUNT(*), SUM(success_once), SUM(reached), SUM(grasped) "
                  "FROM episodes GROUP BY task").fetchall()
print(sys.argv[1], " ".join(f"task {t}: {s}/{n} (reached {r}, grasped {g})" for t, n, s, r, g in rows),
      f"all {sum(r[2] for r in rows)}/{sum(r[1] for r in rows)}")
PY
done

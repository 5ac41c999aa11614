#!/usr/bin/env bash
# The recipe study's screening protocol (reports/learned/recipe-study.md), one variant:
#
#   bash scripts/screening/screen.sh RECIPE.toml OUT_DIR TRAIN_DATA TEST_DATA [train options...]
#
# trains Full-1 with RECIPE.toml on TRAIN_DATA (validation: TEST_DATA), then checks its last
# snapshot offline (scripts/screening/offline_check.py: predicted vs true grasp point, which object
# it lands nearest, on TEST_DATA's held-out pairs and on 400 training pairs), then plays 20 episodes
# of each held-out task with it (40 in all) and prints reached / grasped / success / spread.
# TEST_DATA: a `collect --split test` directory (the study used --episodes-per-task 20).
set -euo pipefail
cd "$(dirname "$0")/../.."
recipe=$1; out=$2; train=$3; test=$4; shift 4
PY=${PYTHON:-.venv/bin/python}
label=$(basename "$out")
start=$(date +%s)
$PY -m awda_bench train --method awda --data "$train" --val-data "$test" --out "$out/ckpt" \
  --recipe "$recipe" --threads 2 --no-progress "$@" 2>&1 | tail -3
echo "train wall $(( $(date +%s) - start )) s"
last=$(ls "$out"/ckpt/snapshot-*.pt | tail -1)
echo "== offline, held-out pairs"; $PY scripts/screening/offline_check.py "$last" "$test" 400
echo "== offline, training pairs"; $PY scripts/screening/offline_check.py "$last" "$train" 400
s2=$(date +%s)
$PY -m awda_bench run --suite pick_place --method awda --checkpoints "$out/ckpt" --snapshots 1 \
  --episodes 20 --out "$out/runs" --label "$label" --no-progress 2>&1 | tail -2
echo "eval wall $(( $(date +%s) - s2 )) s"
$PY -m awda_bench report --runs "$out/runs" --out "$out/report" > /dev/null
cat "$out/report/grasp.md"

#!/usr/bin/env bash
# The checks only a CUDA GPU can make, in one short run (~2 min on an H200, most of it Triton's
# first compile): the fused Triton Soft-DTW kernels compiled for the GPU against the torch
# reference (tests/test_soft_dtw.py's "cuda" cases: values and gradients in float64, gamma 1 and
# 0.001, ragged lengths), then `bench soft-dtw --device cuda --step` at the `paper` recipe's sizes
# (each implementation's loss time, their float64 agreement, a whole Full-1 step and the loss's
# share of it).
#
# Needs only torch (with CUDA), triton, tqdm, h5py, Pillow, torchvision and pytest: the soft-DTW
# modules, recipes and AwdaNet import no simulator (nor does this script import the CLI), so it
# runs from a plain checkout with PYTHONPATH set, on a GPU machine without the project's
# environment.
#
#   bash scripts/gpu_checks.sh [LOG_DIR]     # logs to LOG_DIR (default: runs/gpu-checks)
set -uo pipefail
cd "$(dirname "$0")/.."
log_dir="${1:-runs/gpu-checks}"
mkdir -p "$log_dir"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
python="${PYTHON:-python3}"

"$python" - <<'EOF' 2>&1 | tee "$log_dir/versions.txt"
import torch, triton
print(f"torch {torch.__version__}, triton {triton.__version__}, CUDA {torch.version.cuda}")
if not torch.cuda.is_available():
    raise SystemExit("no CUDA device: these checks need a GPU (run them where `nvidia-smi` works)")
print(f"GPU: {torch.cuda.get_device_name(0)}")
EOF
status=${PIPESTATUS[0]}
[ "$status" -eq 0 ] || exit "$status"

"$python" -m pytest tests/test_soft_dtw.py -q -p no:cacheprovider 2>&1 | tee "$log_dir/pytest_soft_dtw.txt"
tests=${PIPESTATUS[0]}
# `python -m awda_bench bench soft-dtw`, called without the CLI, whose other commands import the
# simulator and the serving stack
"$python" - --device cuda --step --repeats 20 <<'EOF' 2>&1 | tee "$log_dir/bench_soft_dtw_cuda.txt"
import argparse, sys
from awda_bench.benchmarks.soft_dtw import add_soft_dtw_args, run_soft_dtw_bench
parser = argparse.ArgumentParser(prog="bench soft-dtw")
add_soft_dtw_args(parser)
sys.exit(run_soft_dtw_bench(parser.parse_args(sys.argv[1:])))
EOF
bench=${PIPESTATUS[0]}
echo "pytest exit $tests, bench exit $bench"
[ "$tests" -eq 0 ] && [ "$bench" -eq 0 ]

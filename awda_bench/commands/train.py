"""``python -m awda_bench train``: train one Table S3 column from a collected DATA_DIR."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from awda_bench.errors import UnknownChoiceError
from awda_bench.models.config import DEVICE_CHOICES
from awda_bench.training.columns import ABLATIONS, METHODS, TRAINABLE
from awda_bench.training.recipe import available_recipes

_COLUMNS = "; ".join(
    f"{c.name} = --method {c.method}" + (f" --ablation {c.ablation}" if c.ablation else "")
    for c in TRAINABLE
)
HELP = "train one Table S3 column (method + ablation) from a collected DATA_DIR"
DESCRIPTION = (
    "Train a learned method from a `collect` directory into CKPT_DIR: snapshots "
    "every N steps (what `run --method awda --checkpoints CKPT_DIR` evaluates), "
    "metrics.csv, TensorBoard scalars, learning_curve.png. Re-running the same command "
    f"resumes from the latest snapshot. Columns: {_COLUMNS}."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", required=True, help=f"one of {', '.join(METHODS)}")
    parser.add_argument(
        "--ablation",
        default=None,
        help=f"an ablation of awda (or no-frame-stack, of tosvi): one of {', '.join(ABLATIONS)}",
    )
    parser.add_argument("--data", type=Path, required=True, help="DATA_DIR (a train collection)")
    parser.add_argument("--out", type=Path, required=True, help="CKPT_DIR (snapshots and logs)")
    parser.add_argument(
        "--recipe",
        default="small",
        help=f"one of {', '.join(available_recipes())} (recipes/*.toml), or a path to a .toml "
        "(default small)",
    )
    parser.add_argument("--steps", type=int, default=None, help="train until this step")
    parser.add_argument("--snapshot-every", type=int, default=None, help="steps between snapshots")
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        help="replace the recipe's [train] seed (a replicate training of the same recipe)",
    )
    parser.add_argument(
        "--device", default="auto", help=f"one of {', '.join(DEVICE_CHOICES)} (default auto)"
    )
    parser.add_argument(
        "--hold-out",
        default=None,
        metavar="FAMILY",
        help="leave this task family out of training and validate on it (MOSAIC)",
    )
    parser.add_argument(
        "--val-data",
        type=Path,
        default=None,
        help="a collection (e.g. --split test) whose pairs are the validation set",
    )
    parser.add_argument(
        "--threads", type=int, default=None, help="torch CPU threads (default: torch's)"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from awda_bench.training.run import TrainRequest, run_training

    if args.device not in DEVICE_CHOICES:
        raise UnknownChoiceError("device", args.device, DEVICE_CHOICES)
    request = TrainRequest(
        method=args.method,
        ablation=args.ablation,
        data=args.data,
        out=args.out,
        recipe=args.recipe,
        steps=args.steps,
        snapshot_every=args.snapshot_every,
        seed=args.seed,
        device=args.device,
        hold_out=args.hold_out,
        val_data=args.val_data,
        threads=args.threads,
        progress=not args.no_progress,
    )
    outcome = run_training(request)
    result = outcome.result
    taken = result.end_step - result.start_step
    line = f"{outcome.column.name} ({outcome.column.slug}), recipe {outcome.recipe.name}: "
    if result.resumed_from is not None:
        line += f"resumed from step {result.start_step}, "
    line += f"{taken} steps to step {result.end_step}, {len(result.snapshots)} snapshots"
    if outcome.step_s:
        mean = sum(outcome.step_s) / len(outcome.step_s)
        data = sum(outcome.data_s) / len(outcome.data_s)
        line += f", {mean:.3f} s/step (data {data:.3f} s)"
    if outcome.validation:
        first, last = outcome.validation[0], outcome.validation[-1]
        line += (
            f", validation loss {first[1]:.4g} (step {first[0]}) -> {last[1]:.4g} (step {last[0]})"
        )
    print(line)
    print(f"snapshots, metrics.csv, learning_curve.png in {outcome.out}", file=sys.stderr)
    return 0

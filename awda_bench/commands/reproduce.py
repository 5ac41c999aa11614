"""``python -m awda_bench reproduce``: collect -> train every requested column -> evaluate -> report."""

from __future__ import annotations

import argparse
from pathlib import Path

from awda_bench.primitives.config import GRASP_SELECTS
from awda_bench.reproduce.config import (
    COLUMN_KEYS,
    DEFAULT_COLUMNS,
    DEFAULT_EPISODES_PER_TASK,
    DEFAULT_GRASP_SELECT,
    EVAL_VARIANTS,
    SUITE_EPISODES_PER_TASK,
    SUITES,
    ReproduceConfig,
    parse_columns,
)
from awda_bench.reproduce.plan import format_plan, plan_stages
from awda_bench.reproduce.stages import run_stages
from awda_bench.reproduce.summary import write_summary

HELP = "from an empty directory to Table S3/S4 rows: collect, train, evaluate, report"
DESCRIPTION = (
    "Collect the suite's training (and validation) data, train every requested "
    "Table S3 column, evaluate each column's last N snapshots on the held-out tasks and write "
    "the report, printing the plan with estimated times first. Resumable: re-running the "
    "same command skips finished collections, training runs and evaluated episodes."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--suite", required=True, help=f"one of {', '.join(SUITES)}")
    parser.add_argument(
        "--recipe", default="small", help="training recipe: small, paper or a .toml path"
    )
    parser.add_argument(
        "--columns",
        default=None,
        help=f"comma-separated Table S3 columns among {', '.join(COLUMN_KEYS)} "
        f"(default {','.join(DEFAULT_COLUMNS)}; full-1 alone with a frozen-backbone recipe such "
        "as small: T-OSVI caches every agent frame and its steps cost seconds there, so name "
        "tosvi to add it); the supplementary's §S3 analysis adds tosvi-no-frame-stack (trained) "
        f"and {', '.join(EVAL_VARIANTS)} (tosvi's snapshots with the mean / mode action; they "
        "need tosvi in the list)",
    )
    parser.add_argument(
        "--hold-out", default=None, metavar="FAMILY", help="MOSAIC: the held-out family"
    )
    parser.add_argument("--workers", type=int, default=2, help="collect/run workers (default 2)")
    parser.add_argument(
        "--episodes-per-task",
        type=int,
        default=None,
        help="training demos per task and embodiment (default "
        + ", ".join(f"{n} on {suite}" for suite, n in SUITE_EPISODES_PER_TASK.items())
        + f", {DEFAULT_EPISODES_PER_TASK} elsewhere; the reference used 100)",
    )
    parser.add_argument(
        "--synthesize",
        type=int,
        default=None,
        help="synthesized trajectories (default 200; 450 on Meta-World, 10 per training env)",
    )
    parser.add_argument("--snapshots", type=int, default=10, help="last N snapshots (default 10)")
    parser.add_argument(
        "--episodes", type=int, default=None, help="episodes per held-out task (default: suite's)"
    )
    parser.add_argument("--steps", type=int, default=None, help="override the recipe's steps")
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        help="every trained column's [train] seed (a replicate of the recipe; default its own)",
    )
    parser.add_argument("--threads", type=int, default=None, help="torch threads for training")
    parser.add_argument("--no-fit-check", action="store_true", help="skip Full-1 on train tasks")
    parser.add_argument(
        "--grasp-select",
        default=DEFAULT_GRASP_SELECT,
        choices=GRASP_SELECTS,
        help="how AWDA columns pick the object to grasp from wrist depth: centre (default, the "
        "reference's rule: the component nearest the image centre) or waypoint (where the "
        "predicted waypoint points; run's awda default)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="directory (default runs/reproduce-SUITE-RECIPE)"
    )
    parser.add_argument(
        "--data",
        type=Path,
        default=None,
        metavar="DIR",
        help="the training collection (default OUT/data/train; collected there if incomplete). "
        "It holds every training task whatever --hold-out, so MOSAIC's leave-one-family-out runs "
        "can share one: --hold-out door --data runs/rp-drawer/data/train --out runs/rp-door",
    )
    parser.add_argument(
        "--val-data",
        type=Path,
        default=None,
        metavar="DIR",
        help="the validation collection (default OUT/data/test, collected there); variants on "
        "one --data can share one: --data runs/A/data/train --val-data runs/A/data/test",
    )
    parser.add_argument("--dry-run", action="store_true", help="print the plan and stop")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars in stages")


def config_from_args(args: argparse.Namespace) -> ReproduceConfig:
    """What the command line decides."""
    out = args.out or Path("runs") / f"reproduce-{args.suite}-{Path(args.recipe).stem}"
    columns = args.columns
    if columns is None:
        from awda_bench.training.recipe import load_recipe

        frozen = load_recipe(args.recipe).model.trunk.freeze_backbone
        columns = "full-1" if frozen else ",".join(DEFAULT_COLUMNS)
    return ReproduceConfig(
        suite=args.suite,
        out=out,
        recipe=args.recipe,
        columns=parse_columns(columns),
        hold_out=args.hold_out,
        workers=args.workers,
        episodes_per_task=args.episodes_per_task,
        synthesize=args.synthesize,
        snapshots=args.snapshots,
        episodes=args.episodes,
        steps=args.steps,
        seed=args.seed,
        threads=args.threads,
        fit_check=not args.no_fit_check,
        grasp_select=args.grasp_select,
        data=args.data,
        val_data=args.val_data,
        dry_run=args.dry_run,
        progress=not args.no_progress,
    )


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    stages = plan_stages(config)
    print(format_plan(config, stages), flush=True)
    if config.dry_run:
        return 0
    run_stages(config, stages)
    path = write_summary(config)
    print(f"[reproduce] done: {path}")
    return 0

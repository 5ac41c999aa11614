"""``python -m awda_bench study offline SNAPSHOT DATA_DIR [--task N ...]``: the recipe studies'
offline screening measure of a trained AWDA snapshot (:mod:`awda_bench.training.offline_waypoints`):
per task, how far its waypoints are from the ground-truth ones on collected pairs, and whether its
pointer finds the object. A screen, not the evaluation protocol (``run`` plays episodes)."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "offline screening of a trained snapshot (waypoint error per task on collected pairs)"
DESCRIPTION = (
    "The recipe studies' offline measure: a frozen-trunk AWDA snapshot's waypoints "
    "against the ground-truth waypoints of collected (agent, demonstrator) pairs, per task "
    "(reports/learned/recipe-study*.md). Not the evaluation protocol."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    studies = parser.add_subparsers(dest="study", required=True, metavar="STUDY")
    offline = studies.add_parser(
        "offline",
        help="waypoint and end errors, grasp flags, spread and identification per task",
        description="Per task of DATA_DIR (e.g. runs/rp-mw20/data/test, the held-out tasks' "
        "validation pairs): median waypoint error, end error, grasp flags, predicted vs true "
        "spread, and how often the pointer's softmaxes peak within one cell of the object.",
    )
    offline.add_argument("snapshot", type=Path, help="a frozen-trunk AWDA snapshot (.pt)")
    offline.add_argument("data", type=Path, help="a collection directory (train or test split)")
    offline.add_argument(
        "--task", type=int, action="append", default=[], help="only this task (repeatable)"
    )
    offline.add_argument("--threads", type=int, default=None, help="torch threads")
    offline.add_argument("--csv", type=Path, default=None, help="also write the table here")


def run(args: argparse.Namespace) -> int:
    from awda_bench.training.offline_waypoints import pair_rows, per_task_table

    table = per_task_table(pair_rows(args.snapshot, args.data, args.task, args.threads))
    print(f"snapshot {args.snapshot}  data {args.data}")
    print(table.to_string(float_format=lambda v: f"{v:.2f}", na_rep="-"))
    if args.csv is not None:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.csv)
        print(f"table: {args.csv}")
    return 0

"""``python -m awda_bench report``: tables, figures and summary.json from a run store."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from awda_bench.harness.aggregate import DEFAULT_METRIC, METRICS
from awda_bench.harness.report import write_report


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "report",
        help="write tables S3/S4, per-snapshot and grasp tables, figures and summary.json",
        description="Read RUN_DIR/results.sqlite and write Markdown, CSV and LaTeX tables, figures "
        "and "
        "summary.json into the report directory. Missing episodes and errors are flagged loudly.",
    )
    parser.add_argument(
        "--runs", type=Path, default=Path("runs"), help="run directory (default runs/)"
    )
    parser.add_argument(
        "--out", type=Path, default=Path("reports"), help="report directory (default reports/)"
    )
    parser.add_argument(
        "--metric",
        choices=METRICS,
        default=DEFAULT_METRIC,
        help=f"success metric (default {DEFAULT_METRIC})",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    result = write_report(args.runs, args.out, args.metric)
    for warning in result.warnings:
        print(f"WARNING: {warning}", file=sys.stderr)
    print(
        f"report: {len(result.files)} files in {result.out_dir} "
        f"(start with {result.out_dir / 'report.md'})"
    )
    return 0

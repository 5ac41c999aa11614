"""``python -m awda_bench report``: tables, figures and summary.json from a run store; with
``--results-page``, ``reports/RESULTS.md`` from the report directories its index names."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from awda_bench.reporting.aggregate import DEFAULT_METRIC, METRICS
from awda_bench.reporting.report import write_report
from awda_bench.reporting.results_page import DEFAULT_INDEX, write_results_page

HELP = "write tables S3/S4, per-snapshot and grasp tables, figures and summary.json"
DESCRIPTION = (
    "Read RUN_DIR/results.sqlite and write Markdown, CSV and LaTeX tables, figures "
    "and "
    "summary.json into the report directory. Missing episodes and errors are flagged loudly."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
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
    parser.add_argument(
        "--results-page",
        action="store_true",
        help="instead: write RESULTS.md beside the results index (Tables S3/S4 with the paper's "
        "values, reference rows, grasp failures) from the report directories it names",
    )
    parser.add_argument(
        "--index",
        type=Path,
        default=DEFAULT_INDEX,
        help=f"results index for --results-page (default {DEFAULT_INDEX})",
    )


def run(args: argparse.Namespace) -> int:
    if args.results_page:
        page = write_results_page(args.index)
        print(f"results page: {page} (from {args.index})")
        return 0
    result = write_report(args.runs, args.out, args.metric)
    for warning in result.warnings:
        print(f"WARNING: {warning}", file=sys.stderr)
    print(
        f"report: {len(result.files)} files in {result.out_dir} "
        f"(start with {result.out_dir / 'report.md'})"
    )
    return 0

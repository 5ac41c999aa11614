"""``report``: read a run directory's store, write tables (Markdown, CSV, LaTeX), figures and
``summary.json`` under the report directory.

Written files::

    report.md                   header (protocols, episode counts, metric, versions) + every table
    s3.{md,csv,tex}             rows = suites, columns = methods, mean ± SE
    s4.{md,csv,tex}             MOSAIC families + All (only when such families were evaluated)
    per_snapshot.{md,csv,tex}   success per snapshot, every method
    grasp.{md,csv,tex}          reached / grasped / success per (suite, method)
    carry.{md,csv,tex}          what became of the grasped targets (when any episode recorded it)
    per_task.{md,csv,tex}       success per (suite, method, task), pooled over snapshots
    counts.{md,csv,tex}         expected vs recorded episodes, errors
    errors.{md,csv,tex}         one line per error episode (when there are any)
    figures/success_vs_snapshot_<suite>_<method>.png   learned methods
    summary.json                every cell, for other tools
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from awda_bench.errors import UsageError
from awda_bench.evaluation.results_store import ResultsStore
from awda_bench.evaluation.sweep import software_versions
from awda_bench.reporting import aggregate, tables
from awda_bench.reporting.figures import plot_success_vs_snapshot

METRIC_TEXT = {
    "success_once": 'success_once: info["success"] was true at some step of the episode',
    "success_at_end": 'success_at_end: info["success"] was true at the last step played',
}


@dataclass
class ReportResult:
    """What ``write_report`` produced."""

    out_dir: Path
    """Report directory."""
    files: list[Path] = field(default_factory=list)
    """Every file written."""
    warnings: list[str] = field(default_factory=list)
    """Loud problems: missing episodes, errors."""


def count_table(per_snap: pd.DataFrame, protocols: pd.DataFrame) -> pd.DataFrame:
    """Expected vs recorded episodes per (suite, method)."""
    suites = protocols.set_index("fingerprint")["suite"]
    rows = []
    for (proto, method), g in per_snap.groupby(["protocol", "method"], sort=True):
        expected, ok, err = (
            int(g["episodes_expected"].sum()),
            int(g["ok"].sum()),
            int(g["errors"].sum()),
        )
        missing = expected - ok - err
        check = "OK" if missing == 0 and err == 0 else "MISMATCH" if missing else "ERRORS"
        rows.append(
            {
                "suite": suites[proto],
                "method": method,
                "protocol": proto,
                "snapshots": len(g),
                "expected": expected,
                "ok": ok,
                "errors": err,
                "missing": missing,
                "check": check,
            }
        )
    return pd.DataFrame(rows).set_index("suite")


def _header(
    store: ResultsStore,
    protocols: pd.DataFrame,
    counts: pd.DataFrame,
    metric: str,
    warnings: list[str],
) -> str:
    lines = [
        "# awda_bench report",
        "",
        f"Store: `{store.path}`  ",
        f"Generated: {time.strftime('%Y-%m-%d %H:%M:%S %z')}",
        "",
    ]
    lines += [
        f"**Success metric:** {METRIC_TEXT[metric]}.  ",
        "Both success_once and success_at_end are recorded; `report --metric` switches.  ",
        "**Cells:** mean over snapshots of each snapshot's success rate ± standard error "
        "across snapshots; "
        f"`{tables.BINOMIAL_MARK}` marks a single snapshot, whose SE is binomial over its "
        "episodes. "
        "Errors (`err`) are in no rate.",
        "",
    ]
    if warnings:
        lines += ["## ⚠ WARNINGS", ""] + [f"- **{w}**" for w in warnings] + [""]
    lines += [
        "## Protocols",
        "",
        "| suite | fingerprint | episodes | unit | base seed | horizon steps | evaluated tasks "
        "| suite file sha256 |",
        "|---|---|---:|---|---:|---:|---|---|",
    ]
    for _, p in protocols.iterrows():
        d = json.loads(p["definition"])
        lines.append(
            f"| {p['suite']} | `{p['fingerprint']}` | {d['episodes']} | {d['episode_unit']} "
            f"| {d['base_seed']} | "
            f"{d['horizon_steps']} | {d['eval_tasks']} | `{d['suite_sha256'][:12]}` |"
        )
    lines += ["", "## Episode counts (expected vs recorded)", "", tables.to_markdown(counts)]
    lines += ["## Software", ""]
    runs = store.runs()
    if len(runs):
        latest = runs.groupby(["protocol", "method"]).tail(1)
        suites = protocols.set_index("fingerprint")["suite"]
        for _, r in latest.iterrows():
            v = json.loads(r["versions"])
            listed = ", ".join(f"{k} {val}" for k, val in sorted(v.items()))
            lines.append(
                f"- run of {suites.get(r['protocol'], r['protocol'])}/{r['method']}: {listed}"
            )
    listed = ", ".join(f"{k} {val}" for k, val in sorted(software_versions().items()))
    lines += [f"- this report: {listed}", ""]
    return "\n".join(lines)


@dataclass(frozen=True)
class _StoreTables:
    """What a report reads from one results store (:func:`_read_store`)."""

    episodes: pd.DataFrame
    snapshots: pd.DataFrame
    protocols: pd.DataFrame
    per_snap: pd.DataFrame
    cells: list[aggregate.Cell]
    counts: pd.DataFrame
    header: str


def _read_store(run_dir: Path, metric: str, warnings: list[str]) -> _StoreTables:
    """``run_dir``'s episodes, aggregated; the counts' warnings appended to ``warnings``."""
    with ResultsStore(run_dir, create=False) as store:
        episodes, snapshots, protocols = store.episodes(), store.snapshots(), store.protocols()
        if episodes.empty:
            raise UsageError(
                f"{store.path} holds no episodes yet; run `python -m awda_bench run` first"
            )
        per_snap = aggregate.per_snapshot(episodes, snapshots, metric)
        cells = aggregate.all_cells(episodes, snapshots, protocols, metric)
        counts = count_table(per_snap, protocols)
        for suite, row in counts.iterrows():
            if row["missing"]:
                warnings.append(
                    f"{suite}/{row['method']}: expected {row['expected']} episodes, "
                    f"recorded {row['ok'] + row['errors']} "
                    f"({row['missing']} missing) — re-run the same command to finish"
                )
            if row["errors"]:
                warnings.append(
                    f"{suite}/{row['method']}: {row['errors']} episodes ended in errors "
                    "(see errors.md)"
                )
        header = _header(store, protocols, counts, metric, warnings)
    return _StoreTables(episodes, snapshots, protocols, per_snap, cells, counts, header)


def _sections(read: _StoreTables, metric: str) -> list[tuple[str, str, pd.DataFrame]]:
    """The report's tables in order: ``(file stem, title, table)``."""
    episodes, snapshots, protocols, per_snap = (
        read.episodes, read.snapshots, read.protocols, read.per_snap
    )  # fmt: skip
    suite_of = protocols.set_index("fingerprint")["suite"]
    display = dict(zip(protocols["suite"], protocols["display_name"], strict=True))
    privileged = set(snapshots.loc[snapshots["privileged"].fillna(0).astype(int) == 1, "method"])
    marked = tables.mark_privileged(read.cells, privileged)
    sections: list[tuple[str, str, pd.DataFrame]] = [
        ("s3", "Table S3: success per suite (held-out tasks)", tables.table_s3(marked, display)),
    ]
    s4 = tables.table_s4(marked)
    if s4 is not None:
        sections.append(("s4", "Table S4: success per family", s4))
    snap_table = per_snap.assign(suite=per_snap["protocol"].map(suite_of))[
        [
            "suite",
            "method",
            "ord",
            "name",
            "snapshot",
            "episodes_expected",
            "ok",
            "errors",
            "successes",
            "rate",
        ]
    ].set_index("suite")
    sections.append(("per_snapshot", "Success per snapshot", snap_table))
    grasp = aggregate.grasp_analysis(episodes, metric).set_index("suite")
    sections.append(
        (
            "grasp",
            "Grasp analysis (rates over ok episodes of tasks with a grasp target; – = none reports "
            "it; first_grip_*: what the gripper was first commanded closed on, the target, "
            "another object or nothing within reach, or never, over the episodes that recorded "
            "it; grasp_wp_spread_cm: how far the predicted grasp point moves across a task's "
            "episodes, near 0 for a network that ignores its images)",
            grasp,
        )
    )
    carry = aggregate.carry_analysis(episodes)
    if len(carry):
        sections.append(
            (
                "carry",
                "Carry analysis (ok episodes that grasped a target they must carry to a place: "
                "placed = success; held = never released; dropped = let go with the gripper "
                "commanded closed; off_target / on_target = released open farther than the "
                "task's tolerance from over its goal, or over it and still failed; release_*_cm: "
                "median distance from over the goal and height above it at the release; "
                "place_wp_xy_cm: median distance from over the goal of the last grasp-attributed "
                "waypoint, where the method meant to put it)",
                carry.set_index("suite"),
            )
        )
    sections.append(
        (
            "per_task",
            "Success per task (ok episodes pooled over snapshots)",
            aggregate.per_task(episodes, metric).set_index("suite"),
        )
    )
    sections.append(("counts", "Episode counts", read.counts))
    errors = episodes[episodes["status"] == "error"]
    if len(errors):
        err_table = errors.assign(
            last_line=errors["error"]
            .fillna("")
            .map(lambda e: (e.strip().splitlines() or [""])[-1][:160])
        )[
            ["suite", "method", "snapshot", "task", "episode", "seed", "attempts", "last_line"]
        ].set_index("suite")
        sections.append(("errors", "Errors (full tracebacks in the store)", err_table))
    return sections


def _snapshot_figures(read: _StoreTables, metric: str, out_dir: Path) -> list[Path]:
    """Success against snapshot, one figure per learned (suite, method)."""
    suite_of = read.protocols.set_index("fingerprint")["suite"]
    files = []
    for (proto, method), g in read.per_snap.groupby(["protocol", "method"]):
        if bool(g["learned"].any()):
            path = out_dir / "figures" / f"success_vs_snapshot_{suite_of[proto]}_{method}.png"
            files.append(
                plot_success_vs_snapshot(
                    g.sort_values("ord"), f"{suite_of[proto]} / {method} ({metric})", path
                )
            )
    return files


def _summary(read: _StoreTables, metric: str, warnings: list[str]) -> dict[str, Any]:
    """``summary.json``: the protocols, counts, cells and warnings."""
    return {
        "metric": metric,
        "protocols": {
            r["suite"]: {"fingerprint": r["fingerprint"], **json.loads(r["definition"])}
            for _, r in read.protocols.iterrows()
        },
        "counts": read.counts.reset_index().to_dict(orient="records"),
        "cells": [c.to_dict() for c in read.cells],
        "warnings": warnings,
    }


def write_report(
    run_dir: Path, out_dir: Path, metric: str = aggregate.DEFAULT_METRIC
) -> ReportResult:
    """Read ``run_dir``'s store and write every table and figure into ``out_dir``: the store
    aggregated, its tables (csv and markdown), the figures, ``summary.json`` and ``report.md``."""
    if metric not in aggregate.METRICS:
        raise UsageError(
            f"unknown metric {metric!r}; choose one of: {', '.join(aggregate.METRICS)}"
        )
    result = ReportResult(out_dir=out_dir)
    read = _read_store(run_dir, metric, result.warnings)
    body = [read.header]
    for stem, title, df in _sections(read, metric):
        result.files += tables.write_table(df, out_dir, stem)
        if stem != "counts":  # already in the header
            body += [f"## {title}", "", tables.to_markdown(df)]
    result.files += _snapshot_figures(read, metric, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = _summary(read, metric, result.warnings)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2, default=int) + "\n")
    (out_dir / "report.md").write_text("\n".join(body))
    result.files += [out_dir / "summary.json", out_dir / "report.md"]
    _remove_stale_outputs(out_dir, result.files)
    return result


_OUTPUT_STEMS = ("s3", "s4", "per_snapshot", "grasp", "carry", "per_task", "counts", "errors")
"""Table files a report may write (``<stem>.md/.csv/.tex``)."""


def _remove_stale_outputs(out_dir: Path, written: list[Path]) -> None:
    """Delete tables and snapshot plots an earlier report left in ``out_dir`` that this one did
    not write (e.g. an S4 table after the MOSAIC rows are gone), so the folder matches the store."""
    keep = {p.resolve() for p in written}
    candidates = [
        out_dir / f"{stem}{ext}" for stem in _OUTPUT_STEMS for ext in (".md", ".csv", ".tex")
    ]
    candidates += sorted((out_dir / "figures").glob("success_vs_snapshot_*.png"))
    for path in candidates:
        if path.is_file() and path.resolve() not in keep:
            path.unlink()

"""The results page (awda_bench/reporting/results_page.py) and what it is built from: the stratified
bootstrap CI (bootstrap_ci.py), the index (results_index.py) and the paper's values
(paper_values.py). Every source directory here is a tiny one the test writes itself."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from awda_bench.cli import main
from awda_bench.errors import UsageError
from awda_bench.reporting import paper_values
from awda_bench.reporting.aggregate import (
    ALL,
    FIRST_GRIP_COLUMNS,
    S4_FAMILIES,
    carry_analysis,
    mean_se,
)
from awda_bench.reporting.bootstrap_ci import outcomes, stratified_bootstrap_ci, stratified_mean
from awda_bench.reporting.results_index import (
    ANALYSIS_KEYS,
    LEARNED_KEYS,
    load_index,
    load_missing,
)
from awda_bench.reporting.results_page import (
    AFTER_THE_GRASP,
    CI,
    FIRST_GRIP,
    FULL1_GRIP,
    NO_RUN_YET,
    NOT_RECORDED,
    NOT_RUN,
    OURS,
    PAGE_NAME,
    build_results_page,
    failure_split,
    regenerate_command,
    write_results_page,
)

FAMILIES = [k for k, _ in S4_FAMILIES]


def _cell(suite: str, group: str, method: str, snaps: list[tuple[int, int]]) -> dict[str, object]:
    """A summary.json cell from (successes, ok) per snapshot, as aggregate computes it."""
    rates = [s / n for s, n in snaps if n]
    successes, episodes = sum(s for s, _ in snaps), sum(n for _, n in snaps)
    mean, se, kind = mean_se(rates, successes, episodes)
    return {
        "suite": suite,
        "group": group,
        "method": method,
        "metric": "success_once",
        "snapshots": len(rates),
        "snapshots_planned": len(snaps),
        "episodes": episodes,
        "successes": successes,
        "errors": 0,
        "mean": mean,
        "se": se,
        "se_kind": kind,
    }


def write_source(
    directory: Path,
    suite: str,
    method: str,
    snaps: list[tuple[int, int]],
    *,
    family: str | None = None,
    families: dict[str, tuple[int, int]] | None = None,
    grasp: tuple[float, float, float] | None = (1.0, 1.0, 1.0),
    readme: str | None = None,
) -> Path:
    """A report directory with one (suite, method): its per-snapshot (successes, ok), optionally
    one held-out ``family`` (all of its episodes) or one snapshot split into ``families``."""
    directory.mkdir(parents=True, exist_ok=True)
    cells = [_cell(suite, ALL, method, snaps)]
    if family is not None:
        cells.append(_cell(suite, family, method, snaps))
    for name, counts in (families or {}).items():
        cells.append(_cell(suite, name, method, [counts]))
    (directory / "summary.json").write_text(json.dumps({"metric": "success_once", "cells": cells}))
    pd.DataFrame(
        [
            {
                "suite": suite,
                "method": method,
                "ord": i,
                "name": f"snapshot-{i}.pt",
                "snapshot": f"h{i}",
                "episodes_expected": n,
                "ok": n,
                "errors": 0,
                "successes": s,
                "rate": s / n,
            }
            for i, (s, n) in enumerate(snaps)
        ]
    ).to_csv(directory / "per_snapshot.csv", index=False)
    reached, grasped, success = grasp if grasp is not None else (None, None, 0.0)
    pd.DataFrame(
        [
            {
                "suite": suite,
                "method": method,
                "episodes": sum(n for _, n in snaps),
                "reached": reached,
                "grasped": grasped,
                "success": success,
                "grasp_wp_spread_cm": None,
            }
        ]
    ).to_csv(directory / "grasp.csv", index=False)
    if readme is not None:
        (directory / "README.md").write_text(readme)
    return directory


def write_index(reports: Path, text: str) -> Path:
    reports.mkdir(parents=True, exist_ok=True)
    index = reports / "results_sources.toml"
    index.write_text(text)
    return index


def _paper_strings() -> set[str]:
    """The paper's cells that can be told apart from ours: a "mean ± SE" string (Table S4's bare
    "0" cells would match every number)."""
    values = {v for row in paper_values.PAPER_S3.values() for v in row.values()}
    values |= set(paper_values.PAPER_S4.values()) | set(paper_values.PAPER_S4_MOSAIC.values())
    return {v for v in values if "±" in v}


# --- the confidence interval -------------------------------------------------------------------


def _snapshots(rates: list[float], episodes: int) -> list[np.ndarray]:
    return [outcomes(round(r * episodes), episodes) for r in rates]


def test_ci_contains_the_mean_and_narrows_with_more_episodes() -> None:
    rates = [0.55, 0.7, 0.8, 0.6, 0.75]
    widths = []
    for episodes in (20, 80, 320):
        samples = _snapshots(rates, episodes)
        low, high = stratified_bootstrap_ci([samples])
        mean = stratified_mean([samples])
        assert mean == pytest.approx(np.mean(rates))
        assert low < mean < high
        widths.append(high - low)
    assert widths[0] > widths[1] > widths[2]
    # quadrupling the episodes roughly halves the width (binomial noise ~ 1/sqrt(n))
    assert widths[1] / widths[0] == pytest.approx(0.5, abs=0.1)


def test_ci_is_reproducible_and_stratified_by_snapshot() -> None:
    samples = _snapshots([0.2, 0.9], 20)
    assert stratified_bootstrap_ci([samples]) == stratified_bootstrap_ci([samples])
    # stratified: each snapshot keeps its own episodes, so two snapshots at 0 and 1 stay at 0.5
    assert stratified_bootstrap_ci([[outcomes(0, 20), outcomes(20, 20)]]) == (0.5, 0.5)
    # pooled, the same 40 outcomes would give an interval around 0.5 of width ~0.3
    pooled = stratified_bootstrap_ci([[outcomes(20, 40)]])
    assert pooled[1] - pooled[0] > 0.2


def test_degenerate_all_success_gives_a_point_interval() -> None:
    assert stratified_bootstrap_ci([[outcomes(40, 40)] * 10]) == (1.0, 1.0)
    assert stratified_bootstrap_ci([[outcomes(0, 20)] * 3]) == (0.0, 0.0)
    # a one-episode snapshot beside ordinary ones is resampled too (scipy needs two observations)
    low, high = stratified_bootstrap_ci([[outcomes(1, 1), outcomes(5, 10)]])
    assert 0.5 < low <= 0.75 <= high < 1.0


def test_mean_over_families_is_stratified_by_family() -> None:
    strata = [[outcomes(20, 20)], [outcomes(0, 20)], [outcomes(10, 20), outcomes(12, 20)]]
    assert stratified_mean(strata) == pytest.approx((1.0 + 0.0 + 0.55) / 3)
    low, high = stratified_bootstrap_ci(strata)
    assert low < (1.0 + 0.0 + 0.55) / 3 < high
    # only the third family varies: the interval is a third of that family's
    low3, high3 = stratified_bootstrap_ci([strata[2]])
    assert (high - low) == pytest.approx((high3 - low3) / 3, rel=0.15)


# --- the page ----------------------------------------------------------------------------------

INDEX = """
[pick_place]
full-1 = { source = "learned/pp", label = "full-1-centre", note = "centre rule" }
scripted = { source = "." }

[mosaic]
gt-waypoints = { source = "." }

[mosaic.drawer]
full-1 = { source = "learned/drawer", note = "older recipe" }
"""


@pytest.fixture()
def reports(tmp_path: Path) -> Path:
    """reports/ with a pick-place Full-1 source, a MOSAIC drawer source and oracle rows."""
    reports = tmp_path / "reports"
    write_source(
        reports / "learned" / "pp",
        "pick_place",
        "full-1-centre",
        [(30, 40), (34, 40), (26, 40)],
        grasp=(0.9, 0.8, 0.75),
    )
    write_source(
        reports / "learned" / "drawer",
        "mosaic",
        "full-1",
        [(2, 20), (4, 20)],
        family="drawer",
        grasp=None,
    )
    # the oracle rows: reports/ itself holds two suites, so write them and merge
    oracle_pp = write_source(tmp_path / "o1", "pick_place", "scripted", [(40, 40)])
    counts = [(20, 20), (20, 20), (20, 20), (20, 20), (18, 20), (17, 20)]
    families = dict(zip(FAMILIES, counts, strict=True))
    oracle_m = write_source(
        tmp_path / "o2", "mosaic", "gt-waypoints", [(115, 120)], families=families
    )
    summary = [json.loads((d / "summary.json").read_text()) for d in (oracle_pp, oracle_m)]
    merged = {"metric": "success_once", "cells": summary[0]["cells"] + summary[1]["cells"]}
    (reports / "summary.json").write_text(json.dumps(merged))
    for name in ("per_snapshot.csv", "grasp.csv"):
        frames = [pd.read_csv(d / name) for d in (oracle_pp, oracle_m)]
        pd.concat(frames).to_csv(reports / name, index=False)
    write_index(reports, INDEX)
    return reports


def test_the_page_reads_each_cell_from_its_source(reports: Path) -> None:
    page = build_results_page(reports / "results_sources.toml")
    full1 = page.s3_pick_place.loc["Full-1 (`full-1`)"]
    assert full1[OURS] == "0.75 ± 0.06"  # rates 0.75, 0.85, 0.65: SE 0.1 / sqrt(3)
    assert full1["snapshots × episodes"] == "3 × 40"
    low, high = (float(x) for x in full1[CI].strip("[]").split(","))
    assert low < 0.75 < high
    assert "[learned/pp/](learned/pp/) `full-1-centre`" in full1["source"]
    assert full1["note"] == "centre rule"
    tosvi = page.s3_pick_place.loc["T-OSVI [1] (`tosvi`)"]
    assert (tosvi[OURS], tosvi["note"]) == (NOT_RUN, NO_RUN_YET)
    assert "no counterpart" in page.s3_pick_place.loc["DAML [4] (`daml`)"]["note"]
    drawer = page.s4[(page.s4.index == "Drawer") & (page.s4["column"] == "Full-1 (`full-1`)")]
    assert drawer.iloc[0][OURS] == "0.15 ± 0.05"  # rates 0.10, 0.20
    assert drawer.iloc[0]["note"] == "older recipe"
    # All needs six families; the oracle row has them: the mean of the family means
    ref = page.reference[page.reference["method"] == "gt-waypoints"].set_index("family")
    assert ref.loc["All", OURS] == "0.96 ± 0.02"  # (4 + 0.90 + 0.85) / 6
    assert ref.loc["Basketball", OURS] == "0.90 ± 0.07†"
    # a mean's note points at its rows instead of repeating every family's note
    assert ref.loc["All", "note"].startswith("the mean of the 6 families above")
    assert ref.loc["Basketball", "note"] not in ref.loc["All", "note"].split("; ")[0]
    full1_all = page.s4[(page.s4.index == "All") & (page.s4["column"] == "Full-1 (`full-1`)")]
    assert full1_all.iloc[0][OURS] == NOT_RUN
    assert "needs all six families" in full1_all.iloc[0]["note"]


def test_paper_values_never_appear_in_our_columns(reports: Path) -> None:
    page = build_results_page(reports / "results_sources.toml")
    paper = _paper_strings()
    for table in (page.s3_pick_place, page.s3_metaworld, page.s4, page.reference):
        for column in (OURS, CI):
            if column in table:
                leaked = {v for v in table[column] if any(p in v for p in paper)}
                assert not leaked, f"paper values in our column {column!r}: {leaked}"
    # and they are where they belong, verbatim
    s3 = page.s3_pick_place
    for key, title in paper_values.S3_COLUMNS:
        assert s3.loc[f"{title} (`{key}`)", "paper"] == paper_values.PAPER_S3_PICK_PLACE[key]
    drawer = page.s4[(page.s4.index == "Drawer") & (page.s4["column"] == "Full-1 (`full-1`)")]
    assert drawer.iloc[0]["paper: Full-1"] == ".29 ± .033"
    assert drawer.iloc[0]["paper: MOSAIC [3]"] == ".15 ± .038"
    every = page.s4[page.s4["column"] == "Full-1 (`full-1`)"]  # Table S4 whole: six families, All
    assert list(every["paper: Full-1"]) == [".10 ± .02", ".29 ± .033", ".01 ± .005", "0", "0",
                                            ".02 ± .01", ".07 ± .007"]  # fmt: skip
    assert list(every["paper: MOSAIC [3]"]) == [".05 ± .018", ".15 ± .038", ".05 ± .018", "0",
                                                "0", "0", ".04 ± .008"]  # fmt: skip


def test_writing_the_page(reports: Path) -> None:
    path = write_results_page(reports / "results_sources.toml")
    assert path == reports / PAGE_NAME
    text = path.read_text()
    assert "Generated by `python -m awda_bench report --results-page`" in text
    assert "[`results_sources.toml`](results_sources.toml)" in text
    assert "| Full-1 (`full-1`) | 0.75 ± 0.06 |" in text
    assert not list(reports.glob(".*.tmp"))
    # the same rows give the same page (fixed random state, no timestamp)
    assert write_results_page(reports / "results_sources.toml").read_text() == text


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ('full-1 = { source = "learned/gone" }', ["[pick_place] full-1", "does not exist"]),
        (
            'full-1 = { source = "learned/pp" }',
            ["[pick_place] full-1", "'full-1'", "full-1-centre"],
        ),
    ],
)
def test_a_bad_source_is_one_line_and_leaves_the_page(
    reports: Path, capsys: pytest.CaptureFixture[str], line: str, expected: list[str]
) -> None:
    index = reports / "results_sources.toml"
    write_results_page(index)
    before = (reports / PAGE_NAME).read_text()
    good = 'full-1 = { source = "learned/pp", label = "full-1-centre", note = "centre rule" }'
    index.write_text(INDEX.replace(good, line))
    code = main(["report", "--results-page", "--index", str(index)])
    err = capsys.readouterr().err
    assert code != 0
    assert len(err.strip().splitlines()) == 1, err
    assert all(e in err for e in expected), err
    assert (reports / PAGE_NAME).read_text() == before


def test_a_summary_that_disagrees_with_its_snapshots_is_refused(reports: Path) -> None:
    per_snapshot = reports / "learned" / "pp" / "per_snapshot.csv"
    rows = pd.read_csv(per_snapshot)
    rows.loc[0, "successes"] = 31
    rows.to_csv(per_snapshot, index=False)
    with pytest.raises(UsageError, match=r"\[pick_place\] full-1: per_snapshot.csv .* disagrees"):
        build_results_page(reports / "results_sources.toml")


# --- failure analysis --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "rates", [(0.845, 0.8275, 0.8275), (0.9667, 0.9, 0.6667), (1.0, 1.0, 1.0), (0.3, 0.0, 0.0)]
)
def test_failure_fractions_sum_to_one_over_reached(rates: tuple[float, float, float]) -> None:
    split = failure_split(*rates)
    assert split is not None
    assert split.missed + split.dropped + split.placed == pytest.approx(1.0, abs=1e-12)
    reached, grasped, success = rates
    assert split.placed == pytest.approx(success / reached)
    assert split.missed == pytest.approx((reached - grasped) / reached)


def test_failure_split_refuses_rates_that_break_its_assumption() -> None:
    assert failure_split(0.0, 0.0, 0.0) is None
    with pytest.raises(ValueError, match="grasped <= reached"):
        failure_split(0.5, 0.6, 0.5)
    with pytest.raises(ValueError, match="success <= grasped"):
        failure_split(0.5, 0.4, 0.45)


def test_the_failure_table_counts_reached_episodes(reports: Path) -> None:
    page = build_results_page(reports / "results_sources.toml")
    row = page.failures.set_index("cell").loc["Full-1"]
    # 120 episodes: reached 108, grasped 96, success 90
    assert row["reached"] == "0.90 (108/120)"
    assert row["missed the grasp"] == "0.11 (12/108)"
    assert row["grasped, then dropped or misplaced"] == "0.06 (6/108)"
    assert row["placed (success)"] == "0.83 (90/108)"
    assert page.no_grasp == ["MOSAIC Full-1 (drawer)"]
    assert AFTER_THE_GRASP not in page.failures.columns  # no source has a carry.csv


def test_a_sources_carry_csv_says_what_became_of_the_grasped_targets(reports: Path) -> None:
    def episode(carry: str, xy: float | None) -> dict[str, object]:
        return {
            "suite": "pick_place", "method": "full-1-centre", "family": "pick_place",
            "status": "ok", "carry": carry, "release_xy_m": xy, "release_dz_m": 0.02,
            "waypoints": "[[0.1, 0.0, 0.1, 1.0], [0.4, 0.0, 0.2, 1.0]]",
            "place_goal": "[0.3, 0.0, 0.0]",
        }  # fmt: skip

    episodes = [episode("placed", 0.01), episode("off_target", 0.15), episode("held", None)]
    episodes.append(episode("off_target", 0.25))
    carry_analysis(pd.DataFrame(episodes)).to_csv(reports / "learned/pp/carry.csv", index=False)
    page = build_results_page(reports / "results_sources.toml")
    row = page.failures.set_index("cell").loc["Full-1"]
    assert row[AFTER_THE_GRASP] == (
        "4 grasped: placed 0.25, on target 0.00, off target 0.50, dropped 0.00, held 0.25; "
        "released 15.0 cm from over the goal, 2.0 cm above it; meant 10.0 cm from it"
    )
    assert AFTER_THE_GRASP in page.markdown()


# --- the index and the regenerate column -------------------------------------------------------


def test_the_index_defaults_the_label_and_refuses_overlaps(tmp_path: Path) -> None:
    index = write_index(tmp_path, '[pick_place]\nfull-1 = { source = "learned/v4" }\n')
    (entry,) = load_index(index)
    assert (entry.suite, entry.column, entry.family, entry.label) == (
        "pick_place",
        "full-1",
        None,
        "full-1",
    )
    both = '[mosaic]\nfull-1 = { source = "a" }\n[mosaic.drawer]\nfull-1 = { source = "b" }\n'
    with pytest.raises(UsageError, match="both fill the same cells"):
        load_index(write_index(tmp_path, both))
    with pytest.raises(UsageError, match="no counterpart"):
        load_index(write_index(tmp_path, '[pick_place]\nfull-2 = { source = "a" }\n'))
    with pytest.raises(UsageError, match="choose one of"):
        load_index(write_index(tmp_path, '[pick_place]\nfull-3 = { source = "a" }\n'))


def test_a_cell_with_no_run_says_why_and_how_to_fill_it(reports: Path) -> None:
    index = reports / "results_sources.toml"
    text = INDEX.replace(
        'scripted = { source = "." }',
        'scripted = { source = "." }\ntosvi-depth = { missing = "train ~80 min: reproduce X" }\n'
        'tosvi-mode = { missing = "evaluate ~54 min" }',
    ).replace("[mosaic]\n", '[mosaic]\ntosvi = { missing = "a run per family" }\n')
    index.write_text(text)
    missing = load_missing(index)
    assert missing[("pick_place", "tosvi-depth", None)] == "train ~80 min: reproduce X"
    assert [e.column for e in load_index(index)] == ["full-1", "scripted", "gt-waypoints", "full-1"]
    page = build_results_page(index)
    depth = page.s3_pick_place.loc["T-OSVI +depth (`tosvi-depth`)"]
    assert (depth[OURS], depth["note"]) == (NOT_RUN, f"{NO_RUN_YET}: train ~80 min: reproduce X")
    tosvi = page.s3_pick_place.loc["T-OSVI [1] (`tosvi`)"]
    assert tosvi["note"] == NO_RUN_YET  # no line: the bare reason
    mode = page.s3_analysis.loc["T-OSVI [1], mode action (`tosvi-mode`)"]
    assert mode["note"] == f"{NO_RUN_YET}: evaluate ~54 min"
    # a suite-wide line covers every family without a source of its own
    door = page.s4[(page.s4.index == "Door") & (page.s4["column"] == "T-OSVI [1] (`tosvi`)")]
    assert door.iloc[0]["note"] == f"{NO_RUN_YET}: a run per family"
    # a missing line is a text only, and it names a trainable column
    for bad, match in (
        ('no-ad = { missing = "x", note = "y" }', "a text only"),
        ('random = { missing = "x" }', "choose one of"),
    ):
        index.write_text(text.replace("[pick_place]\n", f"[pick_place]\n{bad}\n", 1))
        with pytest.raises(UsageError, match=match):
            load_missing(index)


def test_every_reproduce_column_is_a_page_column_and_shares_the_paper_values() -> None:
    from awda_bench.reproduce import config, summary

    trained_or_played = set(config.COLUMN_KEYS) | set(config.EVAL_VARIANTS)
    assert trained_or_played == set(LEARNED_KEYS) | set(ANALYSIS_KEYS)
    assert summary.PAPER_S3_PICK_PLACE is paper_values.PAPER_S3_PICK_PLACE
    assert summary.PAPER_S4 is paper_values.PAPER_S4


def test_regenerate_command_is_read_from_the_source_notes(tmp_path: Path) -> None:
    readme = (
        "Made with\n\n```bash\npython -m awda_bench reproduce --suite pick_place \\\n"
        "    --recipe small --columns full-1   # 40 min\n```\n"
    )
    source = write_source(tmp_path / "s", "pick_place", "full-1", [(1, 2)], readme=readme)
    assert regenerate_command(source) == (
        "python -m awda_bench reproduce --suite pick_place --recipe small --columns full-1"
    )
    # a command that left the demos per task to their default gets the collection's figure
    # (reproduce.md's row): the default changed, 20 -> 30 on pick-place
    row = "| demos per training task | 20 per embodiment; 200 synthesized | 100 per task |\n"
    (source / "reproduce.md").write_text(row)
    assert regenerate_command(source) == (
        "python -m awda_bench reproduce --suite pick_place --recipe small --columns full-1"
        " --episodes-per-task 20"
    )
    (source / "README.md").write_text(readme.replace("full-1", "full-1 --episodes-per-task 50"))
    assert regenerate_command(source).endswith("--episodes-per-task 50")  # type: ignore[union-attr]
    (source / "README.md").write_text("Generated by `python -m awda_bench reproduce`.\n")
    assert regenerate_command(source) is None


def test_rates_that_break_the_assumption_print_na_not_a_split(reports: Path) -> None:
    grasp = reports / "learned" / "pp" / "grasp.csv"
    rows = pd.read_csv(grasp)
    rows.loc[0, ["reached", "grasped"]] = [0.6, 0.7]
    rows.to_csv(grasp, index=False)
    row = build_results_page(reports / "results_sources.toml").failures.set_index("cell")
    assert row.loc["Full-1", "missed the grasp"].startswith("n/a: grasped 0.70")
    assert row.loc["Full-1", "placed (success)"].startswith("n/a")


def test_the_s3_analysis_rows_read_reached_and_grasped_beside_the_papers_reaching(
    reports: Path,
) -> None:
    write_source(
        reports / "learned" / "tv", "pick_place", "tosvi-mean", [(2, 40), (6, 40)],
        grasp=(0.4, 0.2, 0.1),
    )  # fmt: skip
    index = reports / "results_sources.toml"
    index.write_text(
        index.read_text().replace(
            "scripted = ", 'tosvi-mean = { source = "learned/tv" }\nscripted = ', 1
        )
    )
    page = build_results_page(index)
    row = page.s3_analysis.loc["T-OSVI [1], mean action (`tosvi-mean`)"]
    assert (row["reached"], row["grasped"], row[OURS]) == ("0.40", "0.20", "0.10 ± 0.05")
    assert row["paper: reached"] == "0.11" and row["paper: success"] == "not given"
    assert row[FIRST_GRIP] == NOT_RECORDED  # its grasp.csv predates the first-grip analysis
    grasp = reports / "learned" / "tv" / "grasp.csv"
    rows = pd.read_csv(grasp)
    rows[list(FIRST_GRIP_COLUMNS.values())] = [0.05, 0.6, 0.25, 0.1]
    rows.to_csv(grasp, index=False)
    again = build_results_page(index).s3_analysis.loc["T-OSVI [1], mean action (`tosvi-mean`)"]
    assert again[FIRST_GRIP] == "0.05 / 0.60 / 0.25 / 0.10"
    stack = page.s3_analysis.loc["T-OSVI [1], no frame-stack (`tosvi-no-frame-stack`)"]
    assert (stack[OURS], stack["note"]) == (NOT_RUN, NO_RUN_YET)
    assert stack["paper: reached"] == "0.12" and stack["paper: success"] == "0.01"
    assert "§S3 analysis" in page.markdown()
    # the analysis is pick-and-place's: an entry under another suite is refused in one line
    with pytest.raises(UsageError, match="pick-and-place analysis"):
        load_index(write_index(reports, '[mosaic]\ntosvi-mode = { source = "." }\n'))


def test_the_metaworld_rows_group_the_held_out_tasks_by_their_published_difficulty(
    reports: Path,
) -> None:
    # one snapshot of 4 episodes per held-out task: easy = button-press, door-unlock, window-open;
    # hard = sweep-into (medium) and pick-place-wall (very hard), as tasks/metaworld.toml says
    counts = {
        "button_press": (4, 4), "door_unlock": (3, 4), "window_open": (2, 4),
        "sweep_into": (1, 4), "pick_place_wall": (0, 4),
    }  # fmt: skip
    write_source(
        reports / "learned" / "mw", "metaworld", "full-1", [(10, 20)], families=counts, grasp=None
    )
    from awda_bench.suites import load_suite

    pick_place_wall = next(
        t.index for t in load_suite("metaworld").eval_tasks if t.family == "pick-place-wall"
    )
    pd.DataFrame(
        [
            {
                "suite": "metaworld", "method": "full-1", "task": pick_place_wall,
                "family": "pick-place-wall", "episodes": 4, "successes": 0, "rate": 0.0,
                "reached": 1.0, "grasped": 0.75, "first_grip_target": 0.75,
                "first_grip_other": 0.0, "first_grip_nothing": 0.25, "first_grip_never": 0.0,
            }
        ]
    ).to_csv(reports / "learned" / "mw" / "per_task.csv", index=False)  # fmt: skip
    index = reports / "results_sources.toml"
    index.write_text(index.read_text() + '\n[metaworld]\nfull-1 = { source = "learned/mw" }\n')
    page = build_results_page(index)
    row = page.s3_metaworld.loc["Full-1 (`full-1`)"]
    # [easy] (1 + 0.75 + 0.5) / 3; SE = sqrt(sum of the tasks' binomial SE^2) / 3
    se_easy = np.sqrt(sum(p * (1 - p) / 4 for p in (1.0, 0.75, 0.5))) / 3
    assert row["ours: Meta-World [easy]"] == f"0.75 ± {se_easy:.2f}"
    se_hard = np.sqrt(sum(p * (1 - p) / 4 for p in (0.25, 0.0))) / 2
    assert row["ours: Meta-World [hard]"] == f"0.12 ± {se_hard:.2f}"
    assert row["ours: Meta-World [all]"].startswith("0.50 ± ")
    assert row["paper: Meta-World [all]"] == ".48 ± .05"  # the paper's, in its own column
    assert "[learned/mw/](learned/mw/) `full-1`" in row["source"]
    tasks = page.s3_metaworld_tasks
    assert tasks.loc["pick-place-wall-v3", "difficulty"] == "very_hard"
    assert tasks.loc["window-open-v3", "Full-1 (`full-1`)"] == "0.50 ± 0.25†"
    # Full-1's episodes task by task: reached, grasped, then where the first grip landed
    grips = tasks[FULL1_GRIP]
    assert grips["pick-place-wall-v3"] == "1.00 / 0.75 / 0.75 / 0.00 / 0.25 / 0.00"
    assert grips["window-open-v3"] == NOT_RECORDED  # per_task.csv has no row for it
    tosvi = page.s3_metaworld.loc["T-OSVI [1] (`tosvi`)"]
    assert (tosvi["ours: Meta-World [all]"], tosvi["note"]) == (NOT_RUN, NO_RUN_YET)
    assert "[hard] = medium, hard, very_hard" in page.markdown()


def test_sources_say_whether_todays_code_makes_their_protocol(reports: Path) -> None:
    from awda_bench.evaluation.episode_specs import make_protocol
    from awda_bench.suites import load_suite

    today = make_protocol(load_suite("pick_place"), episodes=20, base_seed=0)
    older = dataclasses.replace(today, protocol_version=today.protocol_version - 1)
    for directory, protocol in ((reports / "learned" / "pp", today), (reports, older)):
        summary = json.loads((directory / "summary.json").read_text())
        recorded = {**json.loads(protocol.to_json()), "fingerprint": protocol.fingerprint}
        summary["protocols"] = {"pick_place": recorded}
        (directory / "summary.json").write_text(json.dumps(summary))
    sources = build_results_page(reports / "results_sources.toml").sources["protocol"]
    assert sources.iloc[0] == f"pick_place `{today.fingerprint}` (today's)"
    assert sources.iloc[1] == (
        f"mosaic: not recorded; pick_place `{older.fingerprint}` "
        f"(**differs: protocol v{older.protocol_version}, today v{today.protocol_version}**)"
    )
    assert sources.iloc[2] == "mosaic: not recorded"


def test_the_committed_page_is_what_its_index_and_sources_make() -> None:
    """reports/RESULTS.md is generated, never typed: regenerating it from the committed index and
    report directories (and today's suite files, which its protocol column checks) gives it back."""
    from awda_bench.reporting.results_page import DEFAULT_INDEX

    root = Path(__file__).resolve().parent.parent
    index = root / DEFAULT_INDEX
    committed = (index.parent / PAGE_NAME).read_text()
    assert build_results_page(index).markdown() == committed, (
        "reports/RESULTS.md is stale: run `python -m awda_bench report --results-page`"
    )

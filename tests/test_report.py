import json
import math
import sqlite3
from pathlib import Path

import pytest
from harness_fakes import fake_suites_dir, fake_sweep_config, learned_method, write_snapshots

from awda_bench.errors import UsageError
from awda_bench.evaluation.methods import MethodSpec, register_method, unregister_method
from awda_bench.evaluation.results_store import STORE_NAME
from awda_bench.evaluation.sweep import run_sweep
from awda_bench.reporting.aggregate import family_key, mean_se
from awda_bench.reporting.report import write_report
from awda_bench.reporting.tables import to_latex, to_markdown

FAKES = "harness_fakes"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("report")
    suites = fake_suites_dir(root / "tasks")
    specs = [
        MethodSpec("fake", f"{FAKES}:SkillPolicy"),
        MethodSpec("raising", f"{FAKES}:RaisingPolicy"),
        learned_method(),
    ]
    for spec in specs:
        register_method(spec)
    ckpt = write_snapshots(root / "ckpt", [0.1, 0.4, 0.6, 0.9])[0].parent
    out = root / "runs"
    run_sweep(fake_sweep_config(suites, out, "fake", episodes=6))
    run_sweep(fake_sweep_config(suites, out, "raising", episodes=6))
    run_sweep(fake_sweep_config(suites, out, "learned", episodes=6, checkpoints=ckpt, snapshots=3))
    for spec in specs:
        unregister_method(spec.name)
    return out


def _recompute(store: Path, metric: str) -> dict[tuple[str, str], tuple[float, float, str, int]]:
    """Mean ± SE per (method, group) straight from the rows, independently of aggregate.py."""
    db = sqlite3.connect(store)
    rows = db.execute(f"SELECT method, snapshot, family, status, {metric} FROM episodes").fetchall()
    planned = db.execute("SELECT method, snapshot FROM snapshots").fetchall()
    out = {}
    for group in ("all", "drawer", "press_button"):
        for method in {m for m, _ in planned}:
            rates, s_all, n_all, errors = [], 0, 0, 0
            for m, snap in planned:
                if m != method:
                    continue
                sel = [
                    r
                    for r in rows
                    if r[0] == m and r[1] == snap and (group == "all" or r[2] == group)
                ]
                errors += sum(r[3] == "error" for r in sel)
                ok = [r[4] for r in sel if r[3] == "ok"]
                if ok:
                    rates.append(sum(ok) / len(ok))
                    s_all += sum(ok)
                    n_all += len(ok)
            mean = sum(rates) / len(rates)
            if len(rates) == 1:
                se = math.sqrt(mean * (1 - mean) / n_all)
            else:
                se = math.sqrt(sum((r - mean) ** 2 for r in rates) / (len(rates) - 1) / len(rates))
            out[(method, group)] = (
                mean,
                se,
                "binomial" if len(rates) == 1 else "snapshots",
                errors,
            )
    return out


@pytest.mark.parametrize("metric", ["success_once", "success_at_end"])
def test_summary_equals_a_recomputation_from_the_rows(
    run_dir: Path, tmp_path: Path, metric: str
) -> None:
    write_report(run_dir, tmp_path, metric)
    summary = json.loads((tmp_path / "summary.json").read_text())
    expected = _recompute(run_dir / STORE_NAME, metric)
    got = {(c["method"], c["group"]): c for c in summary["cells"]}
    assert set(got) == set(expected)
    for key, (mean, se, kind, errors) in expected.items():
        cell = got[key]
        assert cell["mean"] == pytest.approx(mean) and cell["se"] == pytest.approx(se)
        assert (cell["se_kind"], cell["errors"], cell["metric"]) == (kind, errors, metric)
    # the learned method's snapshots differ in skill, so its mean is not any single rate
    assert got[("learned", "all")]["snapshots"] == 3


def test_tables_show_the_cells_and_flag_errors(run_dir: Path, tmp_path: Path) -> None:
    result = write_report(run_dir, tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    cell = next(c for c in summary["cells"] if c["method"] == "learned" and c["group"] == "all")
    s3 = (tmp_path / "s3.md").read_text()
    assert f"{cell['mean']:.2f} ± {cell['se']:.2f}" in s3
    assert "Fake suite" in s3 and "†" in s3  # one-snapshot methods are marked binomial
    assert "(2 err)" in s3  # raising: episode 1 of both tasks
    s4 = (tmp_path / "s4.csv").read_text().splitlines()
    assert s4[0] == "Method,Door,Drawer,Press Button,Stack Block,Basketball,Nut Assembly,All"
    assert (tmp_path / "figures" / "success_vs_snapshot_fake_learned.png").stat().st_size > 1000
    assert any("raising: 2 episodes ended in errors" in w for w in result.warnings)
    report = (tmp_path / "report.md").read_text()
    assert "## ⚠ WARNINGS" in report and summary["protocols"]["fake"]["fingerprint"] in report
    assert "success_once" in report and "mani-skill" in report
    assert "RuntimeError: boom in act" in (tmp_path / "errors.md").read_text()
    assert r"$\pm$" in (tmp_path / "s3.tex").read_text()
    grasp = (tmp_path / "grasp.csv").read_text()
    assert grasp.splitlines()[0] == (
        "suite,method,episodes,reached,grasped,success,first_grip_target,first_grip_other,"
        "first_grip_nothing,first_grip_never,grasp_wp_spread_cm"
    )


def test_per_task_table_counts_each_tasks_ok_episodes_and_successes(
    run_dir: Path, tmp_path: Path
) -> None:
    import pandas as pd

    write_report(run_dir, tmp_path, "success_at_end")
    table = pd.read_csv(tmp_path / "per_task.csv")
    rows = (
        sqlite3.connect(run_dir / STORE_NAME)
        .execute(
            "SELECT method, task, family, COUNT(*), SUM(success_at_end) FROM episodes "
            "WHERE status = 'ok' GROUP BY method, task"
        )
        .fetchall()
    )
    got = {
        (r.method, r.task): (r.family, r.episodes, r.successes, r.rate) for r in table.itertuples()
    }
    assert len(got) == len(rows) > 2
    for method, task, family, n, successes in rows:
        assert got[(method, task)] == (family, n, successes, pytest.approx(successes / n))
    # each task's reached / grasped over its ok episodes that report the flags (empty: none does)
    flags = (
        sqlite3.connect(run_dir / STORE_NAME)
        .execute(
            "SELECT method, task, AVG(reached), AVG(grasped) FROM episodes WHERE status = 'ok' "
            "AND reached IS NOT NULL AND grasped IS NOT NULL GROUP BY method, task"
        )
        .fetchall()
    )
    assert flags  # the fake env reports them
    rates = {(r.method, r.task): (r.reached, r.grasped) for r in table.itertuples()}
    for method, task, reached, grasped in flags:
        assert rates[(method, task)] == (pytest.approx(reached), pytest.approx(grasped))
    unflagged = set(rates) - {(m, t) for m, t, _, _ in flags}
    assert all(pd.isna(rates[k][0]) for k in unflagged)
    # raising fails episode 1 of each task: those rows are not episodes of the table
    assert all(got[("raising", t)][1] == 5 for m, t in got if m == "raising")
    assert "## Success per task" in (tmp_path / "report.md").read_text()


def test_grasp_waypoint_spread_follows_the_scene_not_a_constant() -> None:
    import pandas as pd

    from awda_bench.reporting.aggregate import grasp_waypoint_spread_cm

    def wps(x: float, y: float) -> str:  # free point, grasp point, release
        return json.dumps([[0, 0, 0.2, 0], [x, y, 0.05, 1], [0.1, 0.1, 0.1, 1]])

    rows = pd.DataFrame(
        {
            "snapshot": ["a"] * 4 + ["b"] * 4,
            "task": [0, 0, 1, 1] * 2,
            # snapshot a: the grasp point follows the scene (+-3 cm in x, +-4 cm in y)
            # snapshot b: the same point every episode; one episode stores no waypoints
            "waypoints": [wps(0.03, 0.0), wps(-0.03, 0.0), wps(0.0, 0.04), wps(0.0, -0.04)]
            + [wps(0.1, 0.1)] * 3
            + [None],
        }
    )
    # a: task 0 std 3 cm, task 1 std 4 cm; b: 0 cm for task 0 (task 1 has one point: skipped)
    assert grasp_waypoint_spread_cm(rows) == pytest.approx((3.0 + 4.0 + 0.0) / 3)
    assert grasp_waypoint_spread_cm(rows.assign(waypoints=None)) is None


def _fake_sweep(tmp_path: Path, **config: object) -> Path:
    """One ``fake`` sweep of the fake suite into ``tmp_path/runs``; returns that run directory."""
    suites = fake_suites_dir(tmp_path / "tasks")
    register_method(MethodSpec("fake", f"{FAKES}:SkillPolicy"))
    try:
        run_sweep(fake_sweep_config(suites, tmp_path / "runs", **config))
    finally:
        unregister_method("fake")
    return tmp_path / "runs"


def test_missing_episodes_are_flagged(tmp_path: Path) -> None:
    _fake_sweep(tmp_path, episodes=3)
    # a sweep cut short: task 3's episodes never arrived
    with sqlite3.connect(tmp_path / "runs" / STORE_NAME) as db:
        db.execute("DELETE FROM episodes WHERE task = 3")
    result = write_report(tmp_path / "runs", tmp_path / "rep")
    assert result.warnings == [
        "fake/fake: expected 6 episodes, recorded 3 (3 missing) — re-run the same command to finish"
    ]
    assert "MISMATCH" in (tmp_path / "rep" / "counts.md").read_text()


def test_a_held_out_family_alone_gets_its_s4_cell_and_no_all(tmp_path: Path) -> None:
    _fake_sweep(tmp_path, episodes=3, tasks=(2,))
    result = write_report(tmp_path / "runs", tmp_path / "rep")
    assert result.warnings == []  # the protocol is the drawer task alone: nothing missing
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    groups = {c["group"]: c for c in summary["cells"]}
    assert set(groups) == {"all", "drawer"} and groups["drawer"]["episodes"] == 3
    s4 = (tmp_path / "rep" / "s4.md").read_text().splitlines()
    row = next(line for line in s4 if line.startswith("| fake"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    header = [c.strip() for c in s4[0].strip("|").split("|")]
    assert cells[header.index("Drawer")] != "–" and cells[header.index("All")] == "–"
    assert cells[header.index("Door")] == "–"


def test_report_refuses_a_missing_store(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="no results store"):
        write_report(tmp_path / "nothing", tmp_path / "rep")
    with pytest.raises(UsageError, match="unknown metric"):
        write_report(tmp_path, tmp_path / "rep", "success_sometimes")


def test_mean_se_rules() -> None:
    assert mean_se([], 0, 0) == (None, None, "none")
    mean, se, kind = mean_se([0.5], 5, 10)
    assert (mean, kind) == (0.5, "binomial") and se == pytest.approx(math.sqrt(0.025))
    mean, se, kind = mean_se([0.2, 0.4, 0.6], 12, 30)
    assert (kind, mean) == ("snapshots", pytest.approx(0.4)) and se == pytest.approx(
        0.2 / math.sqrt(3)
    )
    assert family_key("Press Button") == family_key("press-button") == "press_button"


def test_markdown_and_latex_renderings() -> None:
    import pandas as pd

    df = pd.DataFrame(
        {"a_b": ["0.50 ± 0.10†"], "c": [float("nan")]}, index=pd.Index(["x&y"], name="Suite")
    )
    assert to_markdown(df).splitlines() == [
        "| Suite | a_b | c |",
        "|---|---:|---:|",
        "| x&y | 0.50 ± 0.10† | – |",
    ]
    tex = to_latex(df)
    assert r"x\&y & 0.50 $\pm$ 0.10$^\dagger$ & -- \\" in tex and r"a\_b" in tex


def test_stale_tables_from_an_earlier_report_are_removed(run_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "rep"
    out.mkdir()
    stale = [out / "s4.md", out / "errors.csv", out / "figures" / "success_vs_snapshot_x_y.png"]
    stale[2].parent.mkdir()
    for path in stale:
        path.write_text("from an older store")
    notes = out / "notes.txt"  # not a report output: left alone
    notes.write_text("mine")
    result = write_report(run_dir, out)
    written = {p.name for p in result.files}
    for path in stale:
        assert path.exists() == (path.name in written)
    assert notes.read_text() == "mine"

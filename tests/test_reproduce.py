"""``reproduce``: the plan (stages, commands, estimates), what counts as done, and one-line
refusals. The stages themselves are the tested ``collect``/``train``/``run``/``report`` commands."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from awda_bench.cli import main
from awda_bench.reproduce import ReproduceConfig, parse_columns, plan_stages


def _plan(out: Path, **kw) -> dict[str, object]:
    stages = plan_stages(ReproduceConfig(suite="pick_place", out=out, **kw))
    return {s.name: s for s in stages}


def test_dry_run_prints_the_plan_and_writes_nothing(tmp_path: Path, capsys) -> None:
    out = tmp_path / "rep"
    assert main(["reproduce", "--suite", "pick_place", "--out", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    for stage in (
        "collect train", "collect test", "train full-1", "evaluate full-1",
        "evaluate full-1 on training tasks", "train tosvi", "evaluate tosvi", "report",
    ):  # fmt: skip
        assert stage in text
    assert "760 episodes" in text and "estimated total for what is left" in text
    assert not out.exists()


def test_stage_commands_label_each_column_and_pass_the_options(tmp_path: Path) -> None:
    stages = _plan(tmp_path, columns=("no-adm", "no-waypoints"), workers=3, steps=40)
    train = stages["train no-adm"].argv  # type: ignore[attr-defined]
    assert train[:3] == ["train", "--method", "awda"] and "--ablation" in train
    assert train[train.index("--ablation") + 1] == "no-adm"
    assert train[train.index("--steps") + 1] == "40"
    assert train[train.index("--val-data") + 1] == str(tmp_path / "data" / "test")
    run = stages["evaluate no-waypoints"].argv  # type: ignore[attr-defined]
    # the no-waypoints ablation is T-OSVI's action head: evaluated closed loop, its own label
    assert run[run.index("--method") + 1] == "tosvi"
    assert run[run.index("--label") + 1] == "no-waypoints"
    assert run[run.index("--workers") + 1] == "3"
    assert "evaluate full-1 on training tasks" not in stages


def test_finished_stages_are_recognized(tmp_path: Path) -> None:
    data = tmp_path / "data" / "train"
    data.mkdir(parents=True)
    definition = {"split": "train", "episodes_per_task": 20, "synthesize": 200}
    (data / "manifest.json").write_text(json.dumps({"complete": True, "definition": definition}))
    ckpt = tmp_path / "checkpoints" / "full-1"
    ckpt.mkdir(parents=True)
    (ckpt / "snapshot-000000010.pt").write_bytes(b"")
    stages = _plan(tmp_path, columns=("full-1",), steps=10)
    assert stages["collect train"].done and not stages["collect test"].done  # type: ignore[attr-defined]
    assert stages["train full-1"].done  # type: ignore[attr-defined]
    # other data than asked for is not "done": collect then refuses or resumes it by itself
    assert not _plan(tmp_path, columns=("full-1",), episodes_per_task=5)["collect train"].done  # type: ignore[attr-defined]
    assert not _plan(tmp_path, columns=("full-1",), steps=20)["train full-1"].done  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--suite", "pick_place", "--columns", "full-1,daml"], "unknown column 'daml'"),
        (["--suite", "pick_place", "--columns", "tosvi,tosvi"], "names a column twice"),
        (["--suite", "mosaic"], "needs --hold-out FAMILY"),
        (["--suite", "mosaic", "--hold-out", "kitchen"], "unknown --hold-out family 'kitchen'"),
        (["--suite", "pick_place", "--hold-out", "drawer"], "is for --suite mosaic"),
        (["--suite", "metaworld"], "unknown suite 'metaworld'"),
        (["--suite", "pick_place", "--workers", "0"], "--workers must be at least 1"),
    ],
)
def test_bad_input_is_one_line_exit_2(
    tmp_path: Path, capsys, argv: list[str], message: str
) -> None:
    out = tmp_path / "rep"
    assert main(["reproduce", *argv, "--out", str(out), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_columns_parse_in_the_given_order() -> None:
    assert parse_columns("tosvi, full-1") == ("tosvi", "full-1")

"""``reproduce``: the plan (stages, commands, estimates), what counts as done, one-line refusals,
and how stages run (the stage-time log across invocations, stopping, one invocation per
directory). The stages themselves are the tested ``collect``/``train``/``run``/``report``
commands."""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from awda_bench.cli import build_parser, main
from awda_bench.errors import ProtocolMismatchError, UnknownChoiceError, UsageError
from awda_bench.evaluation.sweep import SweepConfig
from awda_bench.reproduce.config import ReproduceConfig, parse_columns
from awda_bench.reproduce.plan import Stage, plan_stages
from awda_bench.reproduce.stages import (
    LOCK_FILE,
    STAGE_TIMES,
    StageAttempt,
    pace_line,
    read_stage_times,
    run_stages,
    stage_totals,
    write_stage_times,
)
from awda_bench.training.recipe import load_recipe


def _plan(out: Path, **kw) -> dict[str, object]:
    stages = plan_stages(ReproduceConfig(suite="pick_place", out=out, **kw))
    return {s.name: s for s in stages}


def test_dry_run_prints_the_plan_and_writes_nothing(tmp_path: Path, capsys) -> None:
    out = tmp_path / "rep"
    argv = ["reproduce", "--suite", "pick_place", "--out", str(out), "--dry-run"]
    assert main([*argv, "--recipe", "small-scratch"]) == 0
    text = capsys.readouterr().out
    for stage in (
        "collect train", "collect test", "train full-1", "evaluate full-1",
        "evaluate full-1 on training tasks", "train tosvi", "evaluate tosvi", "report",
    ):  # fmt: skip
        assert stage in text
    # pick-place's default is 30 demos per task and embodiment: 14 tasks x 30 x 2 + 200
    assert "1040 episodes" in text and "estimated total for what is left" in text
    assert main([*argv, "--recipe", "small-scratch", "--episodes-per-task", "20"]) == 0
    assert "760 episodes" in capsys.readouterr().out
    # the default recipe (small) freezes its backbone: Full-1 alone unless T-OSVI is named
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "recipe small, columns full-1 ->" in text and "train tosvi" not in text
    assert main([*argv, "--columns", "full-1,tosvi"]) == 0
    assert "train tosvi" in capsys.readouterr().out
    assert not out.exists()


def test_stage_commands_label_each_column_and_pass_the_options(tmp_path: Path) -> None:
    stages = _plan(
        tmp_path, columns=("no-adm", "no-waypoints"), workers=3, steps=40, recipe="small-scratch"
    )
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


def test_the_summary_names_the_command_that_decides_the_same_config(tmp_path: Path) -> None:
    import shlex

    from awda_bench.commands import reproduce as command
    from awda_bench.reproduce.summary import command_line

    parser = build_parser()
    for kw in (
        {},
        {"columns": ("full-1", "tosvi"), "steps": 40, "grasp_select": "waypoint", "workers": 1},
        {"suite": "mosaic", "hold_out": "drawer", "fit_check": False, "episodes": 4},
        {"suite": "mosaic", "hold_out": "door", "data": tmp_path / "shared" / "train"},
        {"episodes_per_task": 20},
        {
            "seed": 2,
            "val_data": tmp_path / "shared" / "test",
            "data": tmp_path / "shared" / "train",
        },
    ):
        config = ReproduceConfig(
            **{"suite": "pick_place", "out": tmp_path / "rep", "recipe": "small", **kw}
        )
        words = shlex.split(command_line(config))
        assert words[:3] == ["python", "-m", "awda_bench"]
        # the demos per task are always spelled out (their default differs by suite, and changed)
        assert f"--episodes-per-task {config.demos_per_task}" in " ".join(words)
        again = command.config_from_args(parser.parse_args(words[3:]))
        assert again == replace(config, episodes_per_task=config.demos_per_task)
    assert ReproduceConfig(suite="pick_place", out=tmp_path).demos_per_task == 30
    assert ReproduceConfig(suite="mosaic", out=tmp_path).demos_per_task == 20


def test_awda_columns_grasp_by_the_references_centre_rule_unless_told_otherwise(
    tmp_path: Path,
) -> None:
    def methods(**kw) -> tuple[str, str, str]:
        stages = _plan(tmp_path, columns=("full-1", "tosvi"), recipe="small-scratch", **kw)
        return tuple(  # type: ignore[return-value]
            stages[name].argv[stages[name].argv.index("--method") + 1]  # type: ignore[attr-defined]
            for name in ("evaluate full-1", "evaluate full-1 on training tasks", "evaluate tosvi")
        )

    assert methods() == ("awda-centre", "awda-centre", "tosvi")
    assert methods(grasp_select="waypoint") == ("awda", "awda", "tosvi")
    with pytest.raises(UnknownChoiceError, match="waypoint"):
        _plan(tmp_path, grasp_select="middle")


def test_each_collect_and_run_stage_command_decides_the_config_its_progress_is_read_from(
    tmp_path: Path,
) -> None:
    """The plan reads a stage's progress from its config (the layer below the commands); the
    stage's command line, parsed by that command's own parser, decides the same config."""
    import dataclasses

    from awda_bench.commands import collect, run

    commands = {"collect": collect, "run": run}
    for kw in ({}, {"columns": ("full-1", "tosvi"), "episodes": 4, "progress": False}):
        stages = plan_stages(
            ReproduceConfig(
                suite="pick_place", out=tmp_path, workers=3, recipe="small-scratch", **kw
            )
        )
        checked = [s for s in stages if s.config is not None]
        assert {s.argv[0] for s in checked} == {"collect", "run"}
        assert len(checked) == len([s for s in stages if s.argv[0] in commands])
        for stage in checked:
            command = commands[stage.argv[0]]
            parser = build_parser()
            decided = command.config_from_args(parser.parse_args(stage.argv))
            if stage.argv[0] == "run":  # the command line recorded in the store
                decided = dataclasses.replace(decided, command=stage.config.command)
            assert decided == stage.config, stage.name


def _collection_manifest(
    data: Path, suite: str, episodes_per_task: int, complete: bool = True
) -> None:
    """The manifest ``collect`` writes for a training collection, finished or (``complete=False``)
    as it stands before the first episode; no episodes (planning reads the manifest)."""
    from awda_bench.data.collect import MANIFEST, _manifest
    from awda_bench.data.config import CollectConfig
    from awda_bench.data.plan import make_plan
    from awda_bench.reproduce.config import default_synthesize

    config = CollectConfig(
        suite=suite, split="train", embodiment="both", episodes_per_task=episodes_per_task,
        synthesize=default_synthesize(suite), out=data,
    )  # fmt: skip
    data.mkdir(parents=True)
    manifest = _manifest(make_plan(config), [], complete=complete, code=[])
    (data / MANIFEST).write_text(json.dumps(manifest))


def test_finished_stages_are_recognized(tmp_path: Path) -> None:
    data = tmp_path / "data" / "train"
    _collection_manifest(data, "pick_place", 30)
    ckpt = tmp_path / "checkpoints" / "full-1"
    ckpt.mkdir(parents=True)
    (ckpt / "snapshot-000000010.pt").write_bytes(b"")
    stages = _plan(tmp_path, columns=("full-1",), steps=10)
    assert stages["collect train"].done and not stages["collect test"].done  # type: ignore[attr-defined]
    assert stages["train full-1"].done  # type: ignore[attr-defined]
    # another collection than asked for is refused by the plan itself, in one line
    with pytest.raises(ProtocolMismatchError, match="holds another collection.*episodes_per_task"):
        _plan(tmp_path, columns=("full-1",), episodes_per_task=5)
    assert not _plan(tmp_path, columns=("full-1",), steps=20)["train full-1"].done  # type: ignore[attr-defined]


def test_a_finished_training_under_other_recipe_settings_is_refused(tmp_path: Path) -> None:
    """Its snapshots all there, the stage would count as done and ``train``'s own check never run:
    the old network would be evaluated under today's recipe. The name alone may differ."""
    from dataclasses import replace

    from awda_bench.training.recipe import load_recipe
    from awda_bench.training.run import TRAIN_JSON

    data = tmp_path / "data" / "train"
    _collection_manifest(data, "pick_place", 30)
    ckpt = tmp_path / "checkpoints" / "full-1"
    ckpt.mkdir(parents=True)
    (ckpt / "snapshot-000000010.pt").write_bytes(b"")
    today = load_recipe("small").for_suite("pick_place")

    def trained_with(recipe) -> None:
        record = {"column": {"arch": "awda"}, "recipe": recipe.to_dict(),
                  "data": {"fingerprint": "f"}, "hold_out": None}  # fmt: skip
        (ckpt / TRAIN_JSON).write_text(json.dumps(record))

    trained_with(replace(today, name="a-copy-of-small"))
    assert _plan(tmp_path, columns=("full-1",), steps=10)["train full-1"].done  # type: ignore[attr-defined]
    trained_with(replace(today, train=replace(today.train, learning_rate=1e-3)))
    with pytest.raises(ProtocolMismatchError, match="train.learning_rate"):
        _plan(tmp_path, columns=("full-1",), steps=10)
    # a replicate (--seed 1) resumes under its own seed and is refused under the recipe's
    trained_with(replace(today, train=replace(today.train, seed=1)))
    assert _plan(tmp_path, columns=("full-1",), steps=10, seed=1)["train full-1"].done  # type: ignore[attr-defined]
    with pytest.raises(ProtocolMismatchError, match="train.seed"):
        _plan(tmp_path, columns=("full-1",), steps=10)


def test_leave_one_family_out_runs_can_share_one_collection(tmp_path: Path) -> None:
    """--data: the collection (and its feature cache) of another run directory; every training
    task is in it whatever the hold-out, and train leaves the held-out family out."""
    shared = tmp_path / "rp-drawer" / "data" / "train"
    _collection_manifest(shared, "mosaic", 10)
    out = tmp_path / "rp-door"
    stages = {
        s.name: s
        for s in plan_stages(
            ReproduceConfig(
                suite="mosaic", hold_out="door", out=out, data=shared, episodes_per_task=10,
                columns=("full-1",),
            )
        )
    }  # fmt: skip
    assert stages["collect train"].done
    assert stages["collect train"].config.out == shared  # type: ignore[union-attr]
    train = stages["train full-1"].argv
    assert train[train.index("--data") + 1] == str(shared)
    assert train[train.index("--hold-out") + 1] == "door"
    assert train[train.index("--out") + 1] == str(out / "checkpoints" / "full-1")
    # without --data the run collects into its own directory: nothing there yet
    config = ReproduceConfig(
        suite="mosaic", hold_out="door", out=out, episodes_per_task=10, columns=("full-1",)
    )
    alone = {s.name: s for s in plan_stages(config)}
    assert not alone["collect train"].done
    assert alone["collect train"].config.out == out / "data" / "train"  # type: ignore[union-attr]


def test_a_replicate_shares_the_collections_and_passes_its_seed(tmp_path: Path) -> None:
    """--seed with --data and --val-data: a second training of a recipe collects nothing."""
    shared = tmp_path / "rp-a" / "data"
    _collection_manifest(shared / "train", "pick_place", 20)
    stages = _plan(
        tmp_path / "rp-a-seed1", columns=("full-1",), episodes_per_task=20, seed=1,
        data=shared / "train", val_data=shared / "test",
    )  # fmt: skip
    assert "collect test" not in stages and stages["collect train"].done  # type: ignore[attr-defined]
    train = stages["train full-1"].argv  # type: ignore[attr-defined]
    assert train[train.index("--seed") + 1] == "1"
    assert train[train.index("--val-data") + 1] == str(shared / "test")
    assert "--seed" not in _plan(tmp_path / "b", columns=("full-1",))["train full-1"].argv  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--suite", "pick_place", "--columns", "full-1,daml"], "unknown column 'daml'"),
        (["--suite", "pick_place", "--columns", "tosvi,tosvi"], "names a column twice"),
        (["--suite", "mosaic"], "needs --hold-out FAMILY"),
        (["--suite", "mosaic", "--hold-out", "kitchen"], "unknown --hold-out family 'kitchen'"),
        (["--suite", "pick_place", "--hold-out", "drawer"], "is for --suite mosaic"),
        (["--suite", "metaworld", "--hold-out", "drawer"], "is for --suite mosaic"),
        (["--suite", "metaworld_ml46"], "unknown suite 'metaworld_ml46'"),
        (["--suite", "pick_place", "--workers", "0"], "--workers must be at least 1"),
        (["--suite", "pick_place", "--seed", "-1"], "--seed must be >= 0"),
        (
            ["--suite", "mosaic", "--hold-out", "door", "--val-data", "x"],
            "--val-data and --hold-out both",
        ),
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


def test_metaworld_collects_with_synthesis_and_evaluates_the_five_held_out_tasks(
    tmp_path: Path, capsys
) -> None:
    from awda_bench.reproduce.summary import paper_cell

    out = tmp_path / "rep"
    argv = ["reproduce", "--suite", "metaworld", "--columns", "full-1,tosvi", "--out", str(out)]
    assert main([*argv, "--dry-run"]) == 0
    text = capsys.readouterr().out
    # 45 training tasks x 20 x 2 roles, and 450 synthesized (10 per env)
    assert "2250 episodes" in text and "50 validation episodes" in text
    assert "10 snapshots x 20 episodes x 5 tasks" in text
    assert not out.exists()
    stages = {s.name: s for s in plan_stages(ReproduceConfig(suite="metaworld", out=out))}
    collect = stages["collect train"].argv
    assert collect[collect.index("--synthesize") + 1] == "450"
    config = ReproduceConfig(suite="metaworld", out=out)
    assert paper_cell(config, "full-1") == ".48 ± .05"  # Table S3, Meta-World [all]
    assert paper_cell(ReproduceConfig(suite="pick_place", out=out), "full-1") == "1.0 ± .00"


def test_the_fit_check_plays_the_held_out_tasks_training_siblings(tmp_path: Path) -> None:
    from awda_bench.reproduce.config import fit_check_tasks
    from awda_bench.suites import load_suite

    metaworld = load_suite("metaworld")
    siblings = fit_check_tasks(metaworld)
    names = [metaworld.task(i).family for i in siblings]
    # one training sibling per held-out task, named like it
    assert names == ["button-press-topdown", "door-close", "pick-place", "sweep", "window-close"]
    assert all(metaworld.task(i) in metaworld.train_tasks for i in siblings)
    stages = {s.name: s for s in plan_stages(ReproduceConfig(suite="metaworld", out=tmp_path))}
    fit = stages["evaluate full-1 on training tasks"]
    assert isinstance(fit.config, SweepConfig)
    assert fit.config.tasks == siblings and fit.config.split == "train"
    # pick-and-place's held-out tasks are variations of the training family: its first two tasks
    assert fit_check_tasks(load_suite("pick_place")) == (0, 1)


def test_columns_parse_in_the_given_order() -> None:
    assert parse_columns("tosvi, full-1") == ("tosvi", "full-1")


def test_the_s3_analysis_columns_train_a_stack_of_one_and_replay_tosvis_snapshots(
    tmp_path: Path,
) -> None:
    # the mean / mode columns train nothing: they play tosvi's snapshots, so tosvi must be named
    with pytest.raises(UsageError, match="add tosvi to --columns"):
        parse_columns("full-1,tosvi-mean")
    columns = parse_columns("tosvi-mode,tosvi,tosvi-no-frame-stack")
    stages = plan_stages(
        ReproduceConfig(suite="pick_place", out=tmp_path, columns=columns, recipe="small")
    )
    names = [s.name for s in stages]
    assert "train tosvi-mode" not in names
    # played after everything trains, whatever order --columns gives
    assert names.index("evaluate tosvi-mode") > names.index("train tosvi")
    assert names.index("evaluate tosvi-mode") > names.index("train tosvi-no-frame-stack")
    by_name = {s.name: s.argv for s in stages}
    mode = by_name["evaluate tosvi-mode"]
    assert mode[mode.index("--method") + 1] == "tosvi-mode"
    assert mode[mode.index("--label") + 1] == "tosvi-mode"
    assert mode[mode.index("--checkpoints") + 1] == str(tmp_path / "checkpoints" / "tosvi")
    stack = by_name["train tosvi-no-frame-stack"]
    assert stack[:3] == ["train", "--method", "tosvi"]
    assert stack[stack.index("--ablation") + 1] == "no-frame-stack"
    played = by_name["evaluate tosvi-no-frame-stack"]
    assert played[played.index("--method") + 1] == "tosvi"


# --- running stages: the stage-time log, signals, one invocation per directory -----------------

PYTHON_C = (sys.executable, "-c")


def _stage(name: str, code: str, done: bool = False) -> Stage:
    return Stage(name=name, argv=[code], estimate_s=1.0, done=done)


def test_stage_times_add_up_over_invocations_and_name_the_failure(tmp_path: Path) -> None:
    config = ReproduceConfig(suite="pick_place", out=tmp_path)
    ok = _stage("collect train", "import time; time.sleep(0.2)")
    bad = _stage("train full-1", "import sys; sys.exit(3)")
    with pytest.raises(UsageError, match=r"stage 'train full-1' exited 3 after \d+ s"):
        run_stages(config, [ok, bad], command=PYTHON_C)
    first = read_stage_times(tmp_path)
    assert [(a.stage, a.outcome) for a in first] == [
        ("collect train", "finished"),
        ("train full-1", "failed (exit 3)"),
    ]
    assert first[0].wall_s >= 0.2
    # the re-run skips the finished stage and adds a second attempt at the failed one
    ok.done = True
    fixed = _stage("train full-1", "pass")
    mine = run_stages(config, [ok, fixed], command=PYTHON_C)
    assert [(a.stage, a.outcome) for a in mine] == [("train full-1", "finished")]
    totals = {name: (n, last) for name, _, n, last in stage_totals(read_stage_times(tmp_path))}
    assert totals == {"collect train": (1, "finished"), "train full-1": (2, "finished")}


def test_each_stage_reports_its_time_beside_the_plan_and_the_rest_at_this_runs_pace(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a stage that took twice its plan: the 2 h left read as ~4 h at this pace
    assert pace_line([(600.0, 1200.0)], 7200.0) == (
        "1200 s (planned ~10 min); left: ~2 h 00 min at the plan's figures, "
        "~4 h 00 min at this run's pace so far (2.00x the plan)"
    )
    # the pace is over every stage finished so far, not the last one alone
    assert "(1.50x the plan)" in pace_line([(600.0, 1200.0), (600.0, 600.0)], 60.0)
    assert pace_line([(60.0, 30.0)], 0.0) == "30 s (planned ~1 min)"  # nothing left
    assert "at the plan's figures" in pace_line([(0.0, 5.0)], 60.0)  # no pace from 0 planned
    assert "pace" not in pace_line([(0.0, 5.0)], 60.0)
    config = ReproduceConfig(suite="pick_place", out=tmp_path)
    first = Stage(name="collect train", argv=["pass"], estimate_s=600.0, done=False)
    skipped = Stage(name="collect test", argv=["pass"], estimate_s=60.0, done=True)
    last = Stage(name="train full-1", argv=["pass"], estimate_s=1200.0, done=False)
    run_stages(config, [first, skipped, last], command=PYTHON_C)
    out = capsys.readouterr().out
    # after the first stage: only the train stage is left (the finished one is not counted)
    assert "[reproduce] collect train: 0 s (planned ~10 min); left: ~20 min at the plan's" in out
    assert "[reproduce] train full-1: 0 s (planned ~20 min)\n" in out


def test_a_running_attempt_left_by_a_killed_invocation_is_marked_killed(tmp_path: Path) -> None:
    write_stage_times(
        tmp_path, [StageAttempt("train tosvi", "2026-11-26T09:00:00+00:00", 90.0, "running")]
    )
    run_stages(
        ReproduceConfig(suite="pick_place", out=tmp_path),
        [_stage("report", "pass")],
        command=PYTHON_C,
    )
    log = read_stage_times(tmp_path)
    assert [(a.stage, a.wall_s, a.outcome) for a in log][0] == ("train tosvi", 90.0, "killed")
    assert [a.outcome for a in log][1:] == ["finished"]


def test_a_second_invocation_in_the_same_directory_is_refused(tmp_path: Path) -> None:
    tmp_path.mkdir(exist_ok=True)
    with open(tmp_path / LOCK_FILE, "a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        held.write("4242")
        held.flush()
        with pytest.raises(UsageError, match=r"another reproduce \(pid 4242\) is running in"):
            run_stages(
                ReproduceConfig(suite="pick_place", out=tmp_path),
                [_stage("x", "pass")],
                command=PYTHON_C,
            )
    assert not (tmp_path / STAGE_TIMES).exists()


def test_corrupt_stage_time_log_is_one_line_naming_the_file(tmp_path: Path) -> None:
    (tmp_path / STAGE_TIMES).write_text("{not json")
    with pytest.raises(UsageError, match=r"stage_times.json is not a stage-time log .* delete it"):
        read_stage_times(tmp_path)


SLEEPER = """
import os, subprocess, sys, time
from pathlib import Path
grandchild = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
Path(sys.argv[1]).write_text(f"{os.getpid()} {grandchild.pid}")
time.sleep(60)
"""


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGINT])
def test_stopping_reproduce_stops_the_stage_and_its_workers_and_logs_it(
    tmp_path: Path, stop: signal.Signals
) -> None:
    pids = tmp_path / "pids"
    driver = (
        "import sys\n"
        "from pathlib import Path\n"
        "from awda_bench.errors import AwdaError\n"
        "from awda_bench.reproduce.config import ReproduceConfig\n"
        "from awda_bench.reproduce.plan import Stage\n"
        "from awda_bench.reproduce.stages import run_stages\n"
        f"stage = Stage('train full-1', [{SLEEPER!r}, {str(pids)!r}], 1.0, False)\n"
        f"config = ReproduceConfig(suite='pick_place', out=Path({str(tmp_path)!r}))\n"
        "try:\n"
        "    run_stages(config, [stage], command=(sys.executable, '-c'))\n"
        "except AwdaError as exc:\n"
        "    print(exc, file=sys.stderr); sys.exit(exc.exit_code)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", driver], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while not (pids.is_file() and len(pids.read_text().split()) == 2):
        assert time.monotonic() < deadline and parent.poll() is None, "stage never started"
        time.sleep(0.05)
    stage_pid, grandchild_pid = map(int, pids.read_text().split())
    start = time.monotonic()
    parent.send_signal(stop)
    _, err = parent.communicate(timeout=20)
    assert time.monotonic() - start < 10
    assert parent.returncode == 128 + stop, err
    assert "stopped stage 'train full-1'" in err and "re-run the same reproduce command" in err
    for pid in (stage_pid, grandchild_pid):  # the whole group went, not only the parent
        deadline = time.monotonic() + 5
        while _alive(pid):
            assert time.monotonic() < deadline, f"pid {pid} outlived reproduce"
            time.sleep(0.05)
    [attempt] = read_stage_times(tmp_path)
    assert attempt.outcome == f"interrupted ({stop.name})" and attempt.wall_s > 0


IDENTITY = """
import os, sys
from pathlib import Path
autogroup = Path("/proc/self/autogroup")
nice = autogroup.read_text().split()[-1] if autogroup.is_file() else "-"
Path(sys.argv[1]).write_text(f"{os.getpid()} {os.getpgid(0)} {os.getsid(0)} {nice}")
"""


def test_a_stage_runs_in_its_own_group_but_keeps_reproduces_priority(tmp_path: Path) -> None:
    """``nice python -m awda_bench reproduce`` must stay nice: the stage gets its own process group
    (for the stop signals) but stays in reproduce's session, so on Linux it shares reproduce's
    scheduler autogroup rather than starting a new one at nice 0."""
    seen = tmp_path / "seen"
    driver = (
        "import os, sys\n"
        "from pathlib import Path\n"
        "from awda_bench.reproduce.config import ReproduceConfig\n"
        "from awda_bench.reproduce.plan import Stage\n"
        "from awda_bench.reproduce.stages import run_stages\n"
        "autogroup = Path('/proc/self/autogroup')\n"
        "nice = '-'\n"
        "if autogroup.is_file():\n"
        "    try:\n"
        "        autogroup.write_text('5')\n"
        "    except OSError:  # a read-only /proc (some containers): its nice stays as it is\n"
        "        pass\n"
        "    nice = autogroup.read_text().split()[-1]\n"
        f"stage = Stage('train full-1', [{IDENTITY!r}, {str(seen)!r}], 1.0, False)\n"
        f"config = ReproduceConfig(suite='pick_place', out=Path({str(tmp_path)!r}))\n"
        "run_stages(config, [stage], command=(sys.executable, '-c'))\n"
        "print(os.getsid(0), nice)\n"
    )
    done = subprocess.run(  # its own session, so the autogroup it sets is not this test's
        [sys.executable, "-c", driver],
        capture_output=True,
        text=True,
        timeout=60,
        start_new_session=True,
    )
    assert done.returncode == 0, done.stderr
    pid, group, session, nice = seen.read_text().split()
    reproduce_session, reproduce_nice = done.stdout.split()[-2:]
    assert group == pid  # its own group: killpg stops it and its workers, nothing else
    assert session == reproduce_session
    assert nice == reproduce_nice  # with autogroups (5 where /proc is writable): as reproduce's


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie (exited, not yet reaped by its parent) counts as gone
    stat = Path(f"/proc/{pid}/stat")
    return stat.is_file() and stat.read_text().split()[2] != "Z"


def test_the_plan_encodes_each_feature_cache_once(tmp_path: Path) -> None:
    """T-OSVI-style columns share one cache of pooled maps: the plan counts its encoding for the
    first of them only, and not at all once the file is there; a one-frame T-OSVI steps faster."""
    from awda_bench.reproduce.costs import COSTS
    from awda_bench.training.recipe import load_recipe
    from awda_bench.training.run import cached_features_path

    columns = ("full-1", "tosvi", "tosvi-no-frame-stack")
    encode = COSTS.encode_frame_s * 420 * (COSTS.agent_episode_steps + 10)
    plan = _plan(tmp_path, columns=columns, steps=100)
    assert plan["train tosvi"].estimate_s == pytest.approx(  # type: ignore[attr-defined]
        100 * COSTS.frozen_tosvi_step_s["tosvi"] + encode
    )
    assert plan["train tosvi-no-frame-stack"].estimate_s == pytest.approx(  # type: ignore[attr-defined]
        100 * COSTS.frozen_tosvi_one_frame_step_s
    )
    # the collection is there and so is T-OSVI's cache (an earlier run's): nothing to encode
    data = tmp_path / "data" / "train"
    _collection_manifest(data, "pick_place", 30)
    fingerprint = json.loads((data / "manifest.json").read_text())["fingerprint"]
    path = cached_features_path(data, fingerprint, load_recipe("small"), "tosvi")
    path.parent.mkdir()
    path.write_bytes(b"")
    plan = _plan(tmp_path, columns=("full-1", "tosvi-no-frame-stack"), steps=100)
    assert plan["train tosvi-no-frame-stack"].estimate_s == pytest.approx(  # type: ignore[attr-defined]
        100 * COSTS.frozen_tosvi_one_frame_step_s
    )
    awda = COSTS.encode_frame_s * (420 * 11 + 200 * 10)  # AWDA's cache is another file
    assert plan["train full-1"].estimate_s == pytest.approx(100 * COSTS.frozen_step_s + awda)  # type: ignore[attr-defined]


def test_the_plan_counts_the_synthesized_frames_no_waypoints_adds_to_the_cache(
    tmp_path: Path,
) -> None:
    """``no-waypoints`` trains a T-OSVI-sized net on the synthesized episodes too: its cache holds
    T-OSVI's frames plus theirs, so after ``tosvi`` it still encodes the synthesized part, and a
    cache file that lacks them does not count as built for it."""
    import h5py

    from awda_bench.reproduce.costs import COSTS
    from awda_bench.training.recipe import load_recipe
    from awda_bench.training.run import cached_features_path

    agents = COSTS.encode_frame_s * 420 * (COSTS.agent_episode_steps + 10)
    synthesized = COSTS.encode_frame_s * 200 * COSTS.synthesized_episode_frames
    step = COSTS.frozen_tosvi_step_s["tosvi"]
    alone = _plan(tmp_path, columns=("no-waypoints",), steps=100)["train no-waypoints"]
    assert alone.estimate_s == pytest.approx(100 * step + agents + synthesized)  # type: ignore[attr-defined]
    after = _plan(tmp_path, columns=("tosvi", "no-waypoints"), steps=100)
    assert after["train tosvi"].estimate_s == pytest.approx(100 * step + agents)  # type: ignore[attr-defined]
    assert after["train no-waypoints"].estimate_s == pytest.approx(100 * step + synthesized)  # type: ignore[attr-defined]
    # an earlier run's T-OSVI cache, without synthesized episodes, then with them
    data = tmp_path / "data" / "train"
    _collection_manifest(data, "pick_place", 30)
    fingerprint = json.loads((data / "manifest.json").read_text())["fingerprint"]
    path = cached_features_path(data, fingerprint, load_recipe("small"), "tosvi")
    path.parent.mkdir()
    with h5py.File(path, "w") as f:
        f.create_group("agent/pick_place")
    plan = _plan(tmp_path, columns=("no-waypoints",), steps=100)
    assert plan["train no-waypoints"].estimate_s == pytest.approx(100 * step + synthesized)  # type: ignore[attr-defined]
    with h5py.File(path, "a") as f:
        f.create_group("synthesized/pick_place")
    plan = _plan(tmp_path, columns=("no-waypoints",), steps=100)
    assert plan["train no-waypoints"].estimate_s == pytest.approx(100 * step)  # type: ignore[attr-defined]


def test_a_resumed_plan_estimates_only_what_is_left(tmp_path: Path) -> None:
    from awda_bench.data.config import CollectConfig
    from awda_bench.data.plan import make_plan
    from awda_bench.data.trajectory_file import shard_dir
    from awda_bench.reproduce.costs import COSTS

    frozen = _plan(tmp_path, columns=("full-1",), steps=100)  # small: + encoding the cache once
    encode = COSTS.encode_frame_s * (420 * 11 + 200 * 10)
    assert frozen["train full-1"].estimate_s == pytest.approx(100 * COSTS.frozen_step_s + encode)  # type: ignore[attr-defined]
    fresh = _plan(tmp_path, columns=("full-1",), steps=100, recipe="small-scratch")
    assert fresh["train full-1"].estimate_s == pytest.approx(100 * COSTS.train_step_s["awda"])  # type: ignore[attr-defined]
    # 40 of 100 steps trained: train resumes from the last snapshot
    ckpt = tmp_path / "checkpoints" / "full-1"
    ckpt.mkdir(parents=True)
    (ckpt / "snapshot-000000040.pt").write_bytes(b"")
    resumed = _plan(tmp_path, columns=("full-1",), steps=100, recipe="small-scratch")
    assert resumed["train full-1"].estimate_s == pytest.approx(60 * COSTS.train_step_s["awda"])  # type: ignore[attr-defined]
    resumed = _plan(tmp_path, columns=("full-1",), steps=100)  # the cache is encoded by then
    assert resumed["train full-1"].estimate_s == pytest.approx(60 * COSTS.frozen_step_s)  # type: ignore[attr-defined]
    assert resumed["train full-1"].detail.endswith("100 steps, resumes at 40")  # type: ignore[attr-defined]
    # 3 kept shards (and a killed run's temporary file) in one unit of the train collection
    data = tmp_path / "data" / "train"
    config = CollectConfig(
        suite="pick_place", split="train", embodiment="both", episodes_per_task=30, out=data,
        synthesize=200,
    )  # fmt: skip
    unit = make_plan(config).units[0]
    _collection_manifest(data, "pick_place", 30, complete=False)
    shards = shard_dir(data, unit.name)
    shards.mkdir(parents=True)
    for attempt in range(3):
        (shards / f"a{attempt:05d}.h5").write_bytes(b"")
    (shards / ".a00003.h5.tmp").write_bytes(b"")
    before = fresh["collect train"].estimate_s  # type: ignore[attr-defined]
    again = _plan(tmp_path, columns=("full-1",), steps=100)["collect train"]
    assert again.estimate_s == pytest.approx(before * (1040 - 3) / 1040)  # type: ignore[attr-defined]
    assert again.detail == "1040 episodes, 1037 left"  # type: ignore[attr-defined]
    # planning only reads: the temporary file of a collection that may still be running stays
    assert (shards / ".a00003.h5.tmp").is_file()


def test_a_recipes_suite_train_table_sets_the_steps_reproduce_plans(tmp_path: Path) -> None:
    recipe = tmp_path / "steps.toml"
    base = Path(load_recipe("small-scratch").path or "")
    recipe.write_text(
        f'extends = "{base}"\nname = "steps"\n[suite.pick_place.train]\nmax_steps = 123\n'
    )
    train = _plan(tmp_path / "a", columns=("full-1",), recipe=str(recipe))["train full-1"]
    argv = train.argv  # type: ignore[attr-defined]
    assert "123 steps" in train.detail  # type: ignore[attr-defined]
    assert "--steps" not in argv  # train reads the same table
    assert load_recipe(str(recipe)).for_suite("pick_place").train.max_steps == 123
    forced = _plan(tmp_path / "b", columns=("full-1",), recipe=str(recipe), steps=40)
    assert "40 steps" in forced["train full-1"].detail  # type: ignore[attr-defined]

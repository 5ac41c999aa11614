import hashlib
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import pytest
from harness_fakes import (
    fake_suite_argv,
    learned_method,
    report_runs,
    run_fake_suite,
    slow_run_command,
    slow_run_env,
    write_snapshots,
)

from awda_bench.cli import main
from awda_bench.evaluation.methods import register_method, unregister_method
from awda_bench.evaluation.results_store import STORE_NAME

FAKES = "harness_fakes"


@pytest.fixture
def learned():
    register_method(learned_method())
    yield
    unregister_method("learned")


def _run(suites: Path, out: Path, *extra: str) -> int:
    return run_fake_suite(suites, out, "--workers", "0", *extra)


def test_run_then_report_end_to_end(tmp_path: Path, suites: Path, capsys) -> None:
    out = tmp_path / "runs"
    assert _run(suites, out, "--method", f"{FAKES}:SkillPolicy", "--quick") == 0
    assert "6 episodes planned, 0 already done, 6 played (0 errors)" in capsys.readouterr().out
    assert main(["report", "--runs", str(out), "--out", str(tmp_path / "rep")]) == 0
    s3 = (tmp_path / "rep" / "s3.md").read_text()
    assert "harness_fakes:SkillPolicy" in s3 and "Fake suite" in s3
    assert _run(suites, out, "--method", f"{FAKES}:SkillPolicy", "--quick") == 0
    assert "6 already done, 0 played" in capsys.readouterr().out


def test_errors_make_exit_code_1_and_are_kept(tmp_path: Path, suites: Path, capsys) -> None:
    assert (
        _run(suites, tmp_path / "runs", "--method", f"{FAKES}:RaisingPolicy", "--episodes", "2")
        == 1
    )
    assert "2 episodes ended in errors" in capsys.readouterr().err


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_bad_input_is_one_line_exit_2_and_leaves_the_store_alone(
    tmp_path: Path, suites: Path, learned, capsys
) -> None:
    out = tmp_path / "runs"
    assert _run(suites, out, "--method", f"{FAKES}:SkillPolicy", "--episodes", "2") == 0
    before = _digest(out / STORE_NAME)
    empty = tmp_path / "empty"
    empty.mkdir()
    corrupt = write_snapshots(tmp_path / "corrupt", [0.3, 0.4])[1]
    corrupt.write_bytes(b"\x00\x01 not json")
    cases = [
        (["--suite", "nope"], "unknown suite 'nope'"),
        (["--method", "nope"], "unknown method 'nope'"),
        (["--method", "no_such_module:Policy"], "cannot import no_such_module"),
        (["--task", "7"], "unknown task of suite 'fake' 7"),
        (["--method", "learned"], "pass --checkpoints DIR"),
        (["--method", "learned", "--checkpoints", str(empty)], "holds no snapshots"),
        (["--method", "learned", "--checkpoints", str(tmp_path / "missing")], "does not exist"),
        (
            ["--method", "learned", "--checkpoints", str(corrupt.parent)],
            "step_20000.json is not valid JSON",
        ),
        (["--method", f"{FAKES}:SkillPolicy", "--episodes", "3"], "under protocol"),
        (["--method", f"{FAKES}:SkillPolicy", "--seed", "1", "--episodes", "2"], "base_seed=0->1"),
    ]
    for extra, message in cases:
        argv = fake_suite_argv(suites, out, *extra)
        if "--suite" in extra:
            argv = argv[:1] + argv[3:]
        assert main(argv) == 2, extra
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and message in err, (extra, err)
    assert _digest(out / STORE_NAME) == before
    assert main(["report", "--runs", str(tmp_path / "none")]) == 2


def _outcomes(out: Path) -> list[tuple]:
    db = sqlite3.connect(out / STORE_NAME)
    return db.execute(
        "SELECT task, episode, seed, status, success_once, success_at_end, steps FROM episodes "
        "ORDER BY task, episode"
    ).fetchall()


def _recorded(store: Path) -> int:
    if not store.exists():
        return 0
    db = sqlite3.connect(store)
    if not db.execute("SELECT 1 FROM sqlite_master WHERE name='episodes'").fetchone():
        return 0  # the schema is being created
    return db.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]


@pytest.mark.slow
def test_sigkill_mid_sweep_then_resume_equals_an_uninterrupted_run(
    tmp_path: Path, suites: Path
) -> None:
    env = slow_run_env(0.1)
    killed = tmp_path / "killed"
    command = slow_run_command(suites, killed, "--episodes", "8", "--workers", "2")
    proc = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    store = killed / STORE_NAME
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:
            if _recorded(store) >= 4:
                break
            time.sleep(0.2)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    partial = len(_outcomes(killed))
    assert 4 <= partial < 16
    assert subprocess.run(command, env=env, timeout=300).returncode == 0
    whole = tmp_path / "whole"
    command = slow_run_command(suites, whole, "--episodes", "8", "--workers", "1")
    assert subprocess.run(command, env=env, timeout=300).returncode == 0
    assert _outcomes(killed) == _outcomes(whole) and len(_outcomes(whole)) == 16
    db = sqlite3.connect(killed / STORE_NAME)
    assert db.execute(
        "SELECT COUNT(*), COUNT(DISTINCT task || '/' || episode) FROM episodes"
    ).fetchone() == (16, 16)
    rep_killed, rep_whole = report_runs(tmp_path, "killed", "whole")
    assert (rep_killed / "s3.md").read_text() == (rep_whole / "s3.md").read_text()
    assert "⚠ WARNINGS" not in (rep_killed / "report.md").read_text()


def test_num_waypoints_selects_the_gt_waypoints_variant(tmp_path: Path, capsys) -> None:

    from awda_bench.cli import build_parser
    from awda_bench.commands.run import config_from_args
    from awda_bench.evaluation.methods import SnapshotRef, get_method, make_policy

    parser = build_parser()

    def method(*extra: str) -> str:
        args = parser.parse_args(["run", "--suite", "mosaic", "--out", str(tmp_path), *extra])
        return config_from_args(args).method

    assert method() == "gt-waypoints"
    assert method("--num-waypoints", "5") == "gt-waypoints"
    assert method("--num-waypoints", "3") == "gt-waypoints-k3"
    assert method("--num-waypoints", "8") == "gt-waypoints-k8"
    builtin = SnapshotRef("builtin", "builtin", None, 0)
    for k in (3, 8):  # one factory, the variant its parameter
        policy = make_policy(get_method(f"gt-waypoints-k{k}"), builtin)
        assert policy.config.num_waypoints == k and policy.name == f"gt-waypoints-k{k}"
    # only for gt-waypoints: one line, exit 2, nothing written
    code = main(
        [
            "run",
            "--suite",
            "mosaic",
            "--method",
            "scripted",
            "--num-waypoints",
            "3",
            "--out",
            str(tmp_path / "runs"),
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--num-waypoints" in err
    assert not (tmp_path / "runs").exists()


def test_labels_keep_checkpoint_dirs_apart_and_split_train_evaluates_training_tasks(
    tmp_path: Path, suites: Path, learned, capsys
) -> None:
    good = write_snapshots(tmp_path / "good", [0.99, 0.99])[0].parent
    bad = write_snapshots(tmp_path / "bad", [0.0, 0.0])[0].parent
    out = tmp_path / "runs"
    common = ("--method", "learned", "--snapshots", "2", "--episodes", "2")
    assert _run(suites, out, *common, "--checkpoints", str(good), "--label", "good") == 0
    assert _run(suites, out, *common, "--checkpoints", str(bad), "--label", "bad") == 0
    assert _run(suites, out, *common, "--checkpoints", str(good), "--label", "good") == 0
    assert "8 already done, 0 played" in capsys.readouterr().out
    # a store holds one protocol per suite: the training tasks go to a store of their own
    fit = (*common, "--checkpoints", str(good), "--label", "fit", "--split", "train")
    before = _digest(out / STORE_NAME)
    assert _run(suites, out, *fit) == 2
    assert "eval_tasks=[2, 3]->[0, 1]" in capsys.readouterr().err
    assert _digest(out / STORE_NAME) == before
    assert _run(suites, tmp_path / "fit", *fit) == 0
    with sqlite3.connect(tmp_path / "fit" / STORE_NAME) as db:
        fit_rows = db.execute("SELECT method, task FROM episodes").fetchall()
    assert len(fit_rows) == 8 and {t for _, t in fit_rows} == {0, 1}  # the training tasks
    assert {m for m, _ in fit_rows} == {"fit"}
    # with --task, the fit check's protocol is just those training tasks: nothing "missing"
    assert _run(suites, tmp_path / "fit1", *fit, "--task", "1") == 0
    assert main(["report", "--runs", str(tmp_path / "fit1"), "--out", str(tmp_path / "r1")]) == 0
    assert "⚠ WARNINGS" not in (tmp_path / "r1" / "report.md").read_text()
    with sqlite3.connect(out / STORE_NAME) as db:
        rows = db.execute(
            "SELECT method, COUNT(*), SUM(success_once), GROUP_CONCAT(DISTINCT task) "
            "FROM episodes GROUP BY method ORDER BY method"
        ).fetchall()
        protocols = db.execute("SELECT COUNT(*) FROM protocols").fetchone()[0]
    by_label = {m: (n, s, sorted(int(t) for t in tasks.split(","))) for m, n, s, tasks in rows}
    assert by_label["good"][:2] == (8, 8) and by_label["good"][2] == [2, 3]
    assert by_label["bad"][:2] == (8, 0)
    assert protocols == 1
    assert main(["report", "--runs", str(out), "--out", str(tmp_path / "rep")]) == 0
    s3 = (tmp_path / "rep" / "s3.md").read_text()
    assert "good" in s3 and "bad" in s3
    # the held-out split with --task (one held-out family): a protocol of just those tasks,
    # with the very episodes (seeds) the full protocol gives them
    held = (*common, "--checkpoints", str(good), "--label", "held")
    assert _run(suites, tmp_path / "held3", *held, "--task", "3") == 0
    assert main(["report", "--runs", str(tmp_path / "held3"), "--out", str(tmp_path / "r3")]) == 0
    assert "⚠ WARNINGS" not in (tmp_path / "r3" / "report.md").read_text()
    with sqlite3.connect(tmp_path / "held3" / STORE_NAME) as db:
        held_seeds = db.execute("SELECT task, episode, seed FROM episodes").fetchall()
    with sqlite3.connect(out / STORE_NAME) as db:
        full_seeds = db.execute(
            "SELECT task, episode, seed FROM episodes WHERE method = 'good'"
        ).fetchall()
    assert {t for t, _, _ in held_seeds} == {3}
    assert set(held_seeds) == {r for r in full_seeds if r[0] == 3}
    capsys.readouterr()
    # a label that is another method's name is refused before anything is written
    before = _digest(out / STORE_NAME)
    assert _run(suites, out, *common, "--checkpoints", str(bad), "--label", "scripted") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "another method's name" in err
    assert _digest(out / STORE_NAME) == before


def test_grasp_select_centre_folds_into_the_centre_methods(tmp_path: Path, capsys) -> None:

    from awda_bench.cli import build_parser
    from awda_bench.commands.run import config_from_args
    from awda_bench.evaluation.methods import SnapshotRef, get_method, make_policy
    from awda_bench.policies.gt_waypoints import GtWaypointsPolicy

    parser = build_parser()

    def method(*extra: str) -> str:
        args = parser.parse_args(["run", "--suite", "mosaic", "--out", str(tmp_path), *extra])
        return config_from_args(args).method

    # waypoint-guided selection is the default: the plain names
    assert method() == method("--grasp-select", "waypoint") == "gt-waypoints"
    assert GtWaypointsPolicy().config.localization.select == "waypoint"
    assert method("--num-waypoints", "3", "--grasp-select", "waypoint") == "gt-waypoints-k3"
    # the reference's centre rule is a method of its own
    assert method("--grasp-select", "centre") == "gt-waypoints-centre"
    assert method("--method", "awda", "--grasp-select", "centre") == "awda-centre"
    assert get_method("awda-centre").learned and not get_method("gt-waypoints-centre").learned
    policy = make_policy(
        get_method("gt-waypoints-centre"), SnapshotRef("builtin", "builtin", None, 0)
    )
    assert policy.config.localization.select == "centre" and policy.name == "gt-waypoints-centre"
    for bad, select in (
        (["--method", "scripted"], "waypoint"),
        (["--num-waypoints", "3"], "centre"),
    ):
        code = main(["run", "--suite", "mosaic", *bad, "--grasp-select", select,
                     "--out", str(tmp_path / "runs")])  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and "--grasp-select" in err
    assert not (tmp_path / "runs").exists()

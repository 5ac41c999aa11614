import hashlib
from pathlib import Path

import pytest
from harness_fakes import fake_sweep_config, learned_method, write_fake_suite, write_snapshots

from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.evaluation.methods import MethodSpec, register_method, unregister_method
from awda_bench.evaluation.results_store import STORE_NAME, ResultsStore
from awda_bench.evaluation.sweep import run_sweep
from awda_bench.execution.job_pool import WorkerStartError

FAKES = "harness_fakes"
METHODS = {
    "fake": MethodSpec("fake", f"{FAKES}:SkillPolicy"),
    "raising": MethodSpec("raising", f"{FAKES}:RaisingPolicy"),
    "hanging": MethodSpec("hanging", f"{FAKES}:HangingPolicy"),
    "crashing": MethodSpec("crashing", f"{FAKES}:CrashingPolicy"),
    "learned": learned_method(),
}


@pytest.fixture(autouse=True)
def fake_methods():
    for spec in METHODS.values():
        register_method(spec)
    yield
    for name in METHODS:
        unregister_method(name)


def _outcomes(out: Path) -> list[tuple]:
    with ResultsStore(out, create=False) as store:
        return store.raw(
            "SELECT method, snapshot, task, episode, seed, status, success_once, success_at_end, "
            "reached, grasped, steps FROM episodes ORDER BY method, snapshot, task, episode"
        )


def test_inline_sweep_records_every_episode_then_resume_skips_them(
    tmp_path: Path, suites: Path
) -> None:
    out = tmp_path / "run"
    first = run_sweep(fake_sweep_config(suites, out, episodes=5))
    assert (first.planned, first.skipped, first.ran, first.errors) == (10, 0, 10, 0)
    rows = _outcomes(out)
    assert len(rows) == 10 and {r[5] for r in rows} == {"ok"}
    # outcome rule of the fake env: success iff skill 0.5 > (seed % 1000) / 1000
    assert all(bool(r[6]) == (0.5 > (r[4] % 1000) / 1000) for r in rows)
    assert 0 < sum(r[6] for r in rows) < 10
    again = run_sweep(fake_sweep_config(suites, out, episodes=5))
    assert (again.skipped, again.ran) == (10, 0)
    assert _outcomes(out) == rows


def test_worker_count_does_not_change_outcomes(tmp_path: Path, suites: Path) -> None:
    run_sweep(fake_sweep_config(suites, tmp_path / "w0", episodes=3, workers=0))
    run_sweep(fake_sweep_config(suites, tmp_path / "w1", episodes=3, workers=1))
    run_sweep(fake_sweep_config(suites, tmp_path / "w2", episodes=3, workers=2))
    assert _outcomes(tmp_path / "w0") == _outcomes(tmp_path / "w1") == _outcomes(tmp_path / "w2")


def test_raising_episode_is_an_error_with_traceback_and_sweep_goes_on(
    tmp_path: Path, suites: Path
) -> None:
    out = tmp_path / "run"
    result = run_sweep(fake_sweep_config(suites, out, method="raising", episodes=3, workers=1))
    assert (result.ran, result.errors) == (6, 2)
    with ResultsStore(out, create=False) as store:
        errors = store.raw(
            "SELECT task, episode, error, success_once FROM episodes WHERE status='error'"
        )
    assert [(t, e) for t, e, _, _ in errors] == [(2, 1), (3, 1)]
    assert all("Traceback" in msg and "RuntimeError: boom in act" in msg for _, _, msg, _ in errors)
    assert all(s is None for *_, s in errors)
    rerun = run_sweep(fake_sweep_config(suites, out, method="raising", episodes=3, workers=1))
    assert (rerun.skipped, rerun.ran, rerun.errors) == (4, 2, 2)  # errors are retried
    with ResultsStore(out, create=False) as store:
        assert store.raw("SELECT DISTINCT attempts FROM episodes WHERE status='error'") == [(2,)]


@pytest.mark.slow
def test_watchdog_kills_a_hung_episode_and_respawns(tmp_path: Path, suites: Path) -> None:
    out = tmp_path / "run"
    result = run_sweep(
        fake_sweep_config(
            suites, out, method="hanging", episodes=3, workers=2, tasks=(2,), episode_timeout_s=3.0
        )
    )
    assert (result.ran, result.errors, result.respawns) == (3, 1, 1)
    with ResultsStore(out, create=False) as store:
        (msg,) = store.raw("SELECT error FROM episodes WHERE status='error'")[0]
    assert msg.startswith("watchdog: episode exceeded 3 s")


def test_a_crashed_worker_is_recorded_and_replaced(tmp_path: Path, suites: Path) -> None:
    result = run_sweep(
        fake_sweep_config(
            suites, tmp_path / "run", method="crashing", episodes=3, workers=1, tasks=(3,)
        )
    )
    assert (result.ran, result.errors, result.respawns) == (3, 1, 1)
    with ResultsStore(tmp_path / "run", create=False) as store:
        (msg,) = store.raw("SELECT error FROM episodes WHERE status='error'")[0]
    assert "worker died (exit code 7)" in msg


def test_learned_method_evaluates_the_last_snapshots(tmp_path: Path, suites: Path) -> None:
    ckpt = write_snapshots(tmp_path / "ckpt", [0.0, 0.2, 0.99, 0.01])[0].parent
    out = tmp_path / "run"
    run_sweep(
        fake_sweep_config(suites, out, method="learned", checkpoints=ckpt, snapshots=2, episodes=2)
    )
    with ResultsStore(out, create=False) as store:
        snaps = store.snapshots()
        assert snaps["name"].tolist() == ["step_30000.json", "step_40000.json"]
        assert snaps["ord"].tolist() == [2, 3]
        assert len(store.episodes()) == 8


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_bad_input_is_refused_before_the_store_is_touched(tmp_path: Path, suites: Path) -> None:
    out = tmp_path / "run"
    run_sweep(fake_sweep_config(suites, out, episodes=2))
    before = _digest(out / STORE_NAME)
    ckpt = tmp_path / "ckpt"
    cases = [
        (dict(method="nope"), UsageError, "unknown method 'nope'"),
        (dict(tasks=(9,)), UsageError, "unknown task of suite 'fake' 9"),
        (dict(tasks=(0,)), UsageError, "task 0 of suite 'fake' is not evaluated"),
        (dict(method="learned"), UsageError, "pass --checkpoints"),
        (dict(method="learned", checkpoints=tmp_path / "missing"), UsageError, "does not exist"),
        (dict(method="fake", checkpoints=ckpt), UsageError, "drop --checkpoints"),
        (dict(episodes=3), UsageError, "under protocol"),
    ]
    ckpt.mkdir()
    cases.append((dict(method="learned", checkpoints=ckpt), UsageError, "holds no snapshots"))
    for kw, exc, match in cases:
        kw.setdefault("episodes", 2)
        with pytest.raises(exc, match=match):
            run_sweep(fake_sweep_config(suites, out, **kw))
    write_snapshots(ckpt, [0.5, 0.5])
    (ckpt / "step_20000.json").write_text("{truncated")
    with pytest.raises(CorruptFileError, match="step_20000.json"):
        run_sweep(fake_sweep_config(suites, out, method="learned", checkpoints=ckpt, episodes=2))
    assert _digest(out / STORE_NAME) == before


def test_a_worker_that_cannot_build_its_env_stops_the_sweep(tmp_path: Path, suites: Path) -> None:
    write_fake_suite(suites, name="broken", env_id='"harness_fakes:AWDA-Missing-v0"')
    config = fake_sweep_config(suites, tmp_path / "run", suite="broken", workers=1, episodes=1)
    with pytest.raises(WorkerStartError, match="could not build the env"):
        run_sweep(config)

"""The Ray backend (awda_bench/execution/ray_pool.py, backends.py; the evaluation's pool in
awda_bench/evaluation/episode_pools.py) on the fake suite, on a private
local Ray instance: same outcomes and tables as the local pool, every planned episode recorded once
when an actor is killed, the watchdog, resume after the driver is killed, and the install hint
when Ray is missing. Every test starts (and stops) its own Ray instance: ~3-5 s each."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
from harness_fakes import (
    report_runs,
    run_fake_suite,
    slow_run_command,
    slow_run_env,
    write_fake_suite,
)
from test_collect import tiny_collect_argv, tree_digest

from awda_bench.cli import main
from awda_bench.evaluation.episode_record import STATUS_ERROR, STATUS_OK, EpisodeRecord
from awda_bench.evaluation.episode_specs import build_episode_specs, make_protocol
from awda_bench.evaluation.methods import BUILTIN_SNAPSHOT, MethodSpec, SnapshotRef
from awda_bench.evaluation.results_store import STORE_NAME
from awda_bench.evaluation.worker_pool import Job, WorkerConfig
from awda_bench.execution.job_pool import WorkerStartError
from awda_bench.suites import load_suite

if os.environ.get("CI"):
    import ray  # tox installs the extra: CI must exercise the Ray backend, never skip it
else:
    ray = pytest.importorskip("ray", reason="the 'ray' extra is not installed")

from awda_bench.evaluation.episode_pools import RayWorkerPool  # noqa: E402
from awda_bench.execution.ray_pool import LOST_WORKER_RETRIES  # noqa: E402

FAKES = "harness_fakes"
BUILTIN = SnapshotRef(sha256=BUILTIN_SNAPSHOT, name=BUILTIN_SNAPSHOT, path=None, order=0)


@pytest.fixture(autouse=True)
def no_ray_left_running():
    yield
    assert not ray.is_initialized(), "a test left Ray running"


def _outcomes(out: Path) -> list[tuple]:
    db = sqlite3.connect(out / STORE_NAME)
    try:
        return db.execute(
            "SELECT method, snapshot, task, episode, seed, demo_seed, status, success_once, "
            "success_at_end, reached, grasped, steps, waypoints, attempts FROM episodes "
            "ORDER BY task, episode"
        ).fetchall()
    finally:
        db.close()


def _jobs(suites: Path, method: str, episodes: int) -> tuple[list[Job], WorkerConfig]:
    suite = load_suite("fake", suites)
    specs = build_episode_specs(suite, make_protocol(suite, episodes=episodes, base_seed=0))
    spec = MethodSpec(method, f"{FAKES}:{method}")
    config = WorkerConfig(suite_name="fake", suites_dir=str(suites), episode_timeout_s=60.0)
    return [Job(spec=s, method=spec, snapshot=BUILTIN) for s in specs], config


def _keys(records: list[EpisodeRecord]) -> list[tuple[int, int]]:
    return sorted((r.task, r.episode) for r in records)


def _without_provenance(text: str) -> str:
    return "\n".join(
        line for line in text.splitlines() if not line.startswith(("Store:", "Generated:"))
    )


def test_ray_and_local_backends_give_identical_outcomes_and_tables(
    tmp_path: Path, suites: Path, capsys
) -> None:
    """The CI check of the Ray backend: 4 episodes (2 held-out tasks x 2) on 2 actors."""
    common = ("--method", f"{FAKES}:SkillPolicy", "--episodes", "2", "--workers", "2")
    assert run_fake_suite(suites, tmp_path / "local", *common, "--backend", "local") == 0
    assert run_fake_suite(suites, tmp_path / "ray", *common, "--backend", "ray") == 0
    assert "4 episodes planned, 0 already done, 4 played (0 errors)" in capsys.readouterr().out
    local, on_ray = _outcomes(tmp_path / "local"), _outcomes(tmp_path / "ray")
    assert len(local) == 4 and {r[6] for r in local} == {STATUS_OK}
    assert 0 < sum(r[7] for r in local) < 4  # outcomes differ by seed: a real comparison
    assert on_ray == local
    report_runs(tmp_path, "local", "ray")
    local_files = sorted(p.name for p in (tmp_path / "rep-local").iterdir())
    assert {"s3.md", "s4.csv", "per_snapshot.csv", "counts.csv", "summary.json"} <= set(local_files)
    assert sorted(p.name for p in (tmp_path / "rep-ray").iterdir()) == local_files
    for name in local_files:
        texts = [(tmp_path / rep / name).read_text() for rep in ("rep-local", "rep-ray")]
        if name == "report.md":  # its header names the store's path and the time
            texts = [_without_provenance(t) for t in texts]
        assert texts[0] == texts[1], name
    # resume keeps its meaning: nothing left to play
    assert run_fake_suite(suites, tmp_path / "ray", *common, "--backend", "ray") == 0
    assert "4 already done, 0 played" in capsys.readouterr().out


def test_an_actor_killed_by_pid_mid_sweep_loses_no_episode_and_repeats_none(
    suites: Path, monkeypatch
) -> None:
    monkeypatch.setenv("AWDA_FAKE_SLEEP_S", "0.05")  # 6 steps: ~0.3 s per episode
    jobs, config = _jobs(suites, "SlowPolicy", episodes=5)
    records: list[EpisodeRecord] = []
    killed: list[int] = []
    with RayWorkerPool(config, 2, load_suite("fake", suites)) as pool:

        def on_result(record: EpisodeRecord) -> None:
            records.append(record)
            if not killed:  # both actors hold a job now: the next one was sent before this call
                killed.append(pool.pids[0])
                os.kill(killed[0], signal.SIGKILL)

        pool.run(jobs, on_result)
    assert killed and killed[0] not in pool.pids
    assert _keys(records) == sorted((j.spec.task, j.spec.episode) for j in jobs)  # once each
    assert {r.status for r in records} == {STATUS_OK}
    assert (pool.requeued, pool.respawns) == (1, 1)


def test_an_actor_lost_while_starting_is_replaced_when_others_work(
    tmp_path: Path, suites: Path, monkeypatch
) -> None:
    monkeypatch.setenv("AWDA_FAKE_MARKERS", str(tmp_path))  # before Ray starts: actors inherit it
    monkeypatch.setenv("AWDA_FAKE_SLEEP_S", "0.3")  # ~2 s per episode: outlasts the 3 s wait
    jobs, config = _jobs(suites, "SlowPolicy", episodes=3)
    config = replace(config, env_factory="ray_fakes:make_env_second_dies_once")
    records: list[EpisodeRecord] = []
    with RayWorkerPool(config, 2, load_suite("fake", suites)) as pool:
        pool.run(jobs, records.append)
    assert (tmp_path / "died").exists()
    assert _keys(records) == sorted((j.spec.task, j.spec.episode) for j in jobs)
    assert {r.status for r in records} == {STATUS_OK}
    assert (pool.respawns, pool.requeued) == (1, 0)


def test_an_episode_that_kills_its_worker_every_time_ends_as_one_error(suites: Path) -> None:
    jobs, config = _jobs(suites, "CrashingPolicy", episodes=3)  # dies on episode 1 of each task
    jobs = [j for j in jobs if j.spec.task == 3]
    records: list[EpisodeRecord] = []
    with RayWorkerPool(config, 1, load_suite("fake", suites)) as pool:
        pool.run(jobs, records.append)
    assert _keys(records) == [(3, 0), (3, 1), (3, 2)]
    (error,) = [r for r in records if r.status == STATUS_ERROR]
    assert error.episode == 1
    assert error.error is not None
    assert error.error.startswith(f"worker lost {LOST_WORKER_RETRIES + 1} times")
    assert pool.requeued == LOST_WORKER_RETRIES
    assert pool.respawns == LOST_WORKER_RETRIES + 1


@pytest.mark.slow
def test_watchdog_ends_a_hung_episode_on_ray(tmp_path: Path, suites: Path) -> None:
    out = tmp_path / "run"
    extra = ("--method", f"{FAKES}:HangingPolicy", "--episodes", "3", "--task", "2")
    code = run_fake_suite(
        suites, out, *extra, "--workers", "2", "--backend", "ray", "--episode-timeout", "3"
    )
    assert code == 1  # the hung episode is an error, kept apart from failures
    rows = _outcomes(out)
    assert [(r[2], r[3], r[6]) for r in rows] == [
        (2, 0, STATUS_OK),
        (2, 1, STATUS_ERROR),
        (2, 2, STATUS_OK),
    ]
    db = sqlite3.connect(out / STORE_NAME)
    (message,) = db.execute("SELECT error FROM episodes WHERE status='error'").fetchone()
    db.close()
    assert message.startswith("watchdog: episode exceeded 3 s")


def test_an_actor_that_cannot_build_its_env_stops_the_sweep(tmp_path: Path, suites: Path) -> None:
    write_fake_suite(suites, name="broken", env_id='"harness_fakes:AWDA-Missing-v0"')
    suite = load_suite("broken", suites)
    config = WorkerConfig(suite_name="broken", suites_dir=str(suites))
    job = Job(
        spec=build_episode_specs(suite, make_protocol(suite, episodes=1, base_seed=0))[0],
        method=MethodSpec("fake", f"{FAKES}:SkillPolicy"),
        snapshot=BUILTIN,
    )
    with (
        RayWorkerPool(config, 1, suite) as pool,
        pytest.raises(WorkerStartError, match="could not build the env"),
    ):
        pool.run([job], lambda record: None)


def _recorded(store: Path) -> int:
    if not store.exists():
        return 0
    db = sqlite3.connect(store)
    try:
        if not db.execute("SELECT 1 FROM sqlite_master WHERE name='episodes'").fetchone():
            return 0
        return db.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
    finally:
        db.close()


@pytest.mark.slow
def test_driver_killed_mid_sweep_then_rerun_resumes(tmp_path: Path, suites: Path) -> None:
    out = tmp_path / "run"
    extra = ("--episodes", "6", "--workers", "2", "--backend", "ray")
    command = slow_run_command(suites, out, *extra)
    env = slow_run_env(0.1)
    proc = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 180
    try:
        while time.monotonic() < deadline and _recorded(out / STORE_NAME) < 3:
            time.sleep(0.2)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    partial = _recorded(out / STORE_NAME)
    assert 3 <= partial < 12
    rerun = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert f"12 episodes planned, {partial} already done, {12 - partial} played" in rerun.stdout
    rows = _outcomes(out)
    assert [(r[2], r[3]) for r in rows] == [(t, e) for t in (2, 3) for e in range(6)]
    assert {(r[6], r[13]) for r in rows} == {(STATUS_OK, 1)}  # each episode played once


def test_without_ray_the_ray_backend_is_refused_with_an_install_hint(
    tmp_path: Path, suites: Path, monkeypatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    out = tmp_path / "run"
    assert run_fake_suite(suites, out, "--method", f"{FAKES}:SkillPolicy", "--backend", "ray") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("error: --backend ray needs Ray") and "pip install -e '.[ray]'" in err
    assert not out.exists()


class _HangingRay:
    """A ``ray`` module whose ``init`` never returns (as when a raylet never reaches its GCS)."""

    __version__ = "0"

    def __init__(self) -> None:
        self.shutdowns = 0

    def is_initialized(self) -> bool:
        return False

    def init(self, **_kwargs) -> None:
        time.sleep(60)

    def shutdown(self) -> None:
        self.shutdowns += 1


def test_a_ray_init_that_hangs_is_a_one_line_error_after_the_limit(
    tmp_path: Path, suites: Path, monkeypatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "ray", _HangingRay())
    monkeypatch.setenv("AWDA_RAY_INIT_TIMEOUT_S", "0.5")
    previous = signal.getsignal(signal.SIGALRM)
    out = tmp_path / "run"
    t0 = time.perf_counter()
    assert run_fake_suite(suites, out, "--method", f"{FAKES}:SkillPolicy", "--backend", "ray") == 2
    assert time.perf_counter() - t0 < 20
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("error: Ray did not start within 0.5 s"), err
    assert "ray stop" in err and "AWDA_RAY_INIT_TIMEOUT_S" in err
    assert signal.getsignal(signal.SIGALRM) is previous  # the alarm is put back
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    assert not out.exists()


def test_bad_backend_options_are_one_line_errors(tmp_path: Path, suites: Path, capsys) -> None:
    out = tmp_path / "run"
    cases = [
        (["--ray-address", "127.0.0.1:6379"], "--ray-address needs --backend ray"),
        (["--backend", "ray", "--workers", "0"], "--backend ray needs --workers >= 1"),
        (
            ["--backend", "ray", "--ray-address", "127.0.0.1:1"],
            "cannot reach the Ray cluster at 127.0.0.1:1",
        ),
    ]
    for extra, message in cases:
        assert run_fake_suite(suites, out, "--method", f"{FAKES}:SkillPolicy", *extra) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err
    assert not out.exists()
    with pytest.raises(SystemExit):
        run_fake_suite(suites, out, "--backend", "dask")


@pytest.mark.slow
def test_bench_harness_times_ray_beside_local(tmp_path: Path, suites: Path, capsys) -> None:
    code = main(
        [
            "bench",
            "harness",
            "--suite",
            "fake",
            "--tasks-dir",
            str(suites),
            "--method",
            f"{FAKES}:SkillPolicy",
            "--episodes",
            "2",
            "--workers",
            "2",
            "--backends",
            "local",
            "ray",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "ray vs local, 2 workers:" in out
    assert "identical per-episode outcomes across backends and worker counts: yes" in out


@pytest.mark.slow
def test_collect_on_ray_writes_the_same_files_as_local(tmp_path: Path) -> None:
    args = tiny_collect_argv(embodiment="agent", episodes_per_task=1)
    assert main([*args, "--out", str(tmp_path / "local"), "--workers", "0"]) == 0
    assert main([*args, "--out", str(tmp_path / "ray"), "--workers", "2", "--backend", "ray"]) == 0
    digests = [tree_digest(tmp_path / "local"), tree_digest(tmp_path / "ray")]
    assert "manifest.json" in digests[0] and len(digests[0]) > 2
    assert digests[1] == digests[0]  # frame for frame, byte for byte

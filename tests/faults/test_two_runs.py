"""Two runs into one store at once (issue 53): two ``run`` commands started together on the same
directory, as two people (or a re-run and a forgotten first run) on a shared machine would. Every
episode is in the store once, with one attempt, and the report is the same as one run's."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

from awda_bench.cli import main
from awda_bench.evaluation.results_store import STORE_NAME

TESTS = Path(__file__).resolve().parent.parent


def test_two_runs_at_once_into_one_store_record_every_episode_once(
    tmp_path: Path, suites: Path
) -> None:
    env = {**os.environ, "PYTHONPATH": str(TESTS), "AWDA_FAKE_SLEEP_S": "0.01",
           "OMP_NUM_THREADS": "1"}  # fmt: skip

    def command(out: Path) -> list[str]:
        return [sys.executable, "-m", "awda_bench", "run", "--suite", "fake", "--tasks-dir",
                str(suites), "--method", "harness_fakes:SlowPolicy", "--episodes", "6",
                "--workers", "1", "--no-progress", "--out", str(out)]  # fmt: skip

    shared = tmp_path / "shared"
    both = [subprocess.Popen(command(shared), env=env, stderr=subprocess.PIPE, text=True)
            for _ in range(2)]  # fmt: skip
    errors = [p.communicate(timeout=300)[1] for p in both]
    assert [p.returncode for p in both] == [0, 0], errors
    db = sqlite3.connect(shared / STORE_NAME)
    rows = db.execute("SELECT task, episode, status, attempts FROM episodes").fetchall()
    db.close()
    assert len(rows) == len({(t, e) for t, e, _, _ in rows}) == 12  # 2 tasks x 6, once each
    assert all(status == "ok" and attempts == 1 for _, _, status, attempts in rows)
    alone = tmp_path / "alone"
    assert subprocess.run(command(alone), env=env, timeout=300).returncode == 0
    for name in ("shared", "alone"):
        assert (
            main(["report", "--runs", str(tmp_path / name), "--out", str(tmp_path / f"r-{name}")])
            == 0
        )
    assert (tmp_path / "r-shared" / "s3.md").read_text() == (
        tmp_path / "r-alone" / "s3.md"
    ).read_text()
    assert "⚠ WARNINGS" not in (tmp_path / "r-shared" / "report.md").read_text()

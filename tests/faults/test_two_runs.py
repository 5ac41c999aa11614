"""Two runs into one store at once (issue 53): two ``run`` commands started together on the same
directory, as two people (or a re-run and a forgotten first run) on a shared machine would. Every
episode is in the store once, with one attempt, and the report is the same as one run's."""

from __future__ import annotations

import sqlite3
import subprocess
from pathlib import Path

from harness_fakes import report_runs, slow_run_command, slow_run_env

from awda_bench.evaluation.results_store import STORE_NAME


def test_two_runs_at_once_into_one_store_record_every_episode_once(
    tmp_path: Path, suites: Path
) -> None:
    env = slow_run_env(0.01)

    def command(out: Path) -> list[str]:
        return slow_run_command(suites, out, "--episodes", "6", "--workers", "1")

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
    rep_shared, rep_alone = report_runs(tmp_path, "shared", "alone")
    assert (rep_shared / "s3.md").read_text() == (rep_alone / "s3.md").read_text()
    assert "⚠ WARNINGS" not in (rep_shared / "report.md").read_text()

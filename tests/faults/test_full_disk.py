"""A full disk (issue 53): ``run`` at store creation and mid-run, then the same command after the
space is back.

The disk is "full" for the run's process through ``RLIMIT_FSIZE`` (no file may grow past the limit;
SIGXFSZ ignored, so a write past it fails with EFBIG, which SQLite reports as "database or disk is
full", as it does ENOSPC): it needs no mount and no root, so CI runs it. Promised: one line naming
the file and the cause, exit code 4, the episodes committed before kept, no half-made store, and
the same command afterwards finishes with every episode exactly once.
"""

from __future__ import annotations

import os
import resource
import shutil
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from awda_bench.evaluation.results_store import STORE_NAME

TESTS = Path(__file__).resolve().parent.parent
EPISODES = 6
"""Per evaluated task of the fake suite."""
EVAL_TASKS = 2
"""The fake suite's held-out tasks: 12 episodes in all."""


def _command(suites: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "awda_bench", "run", "--suite", "fake", "--tasks-dir",
            str(suites), "--method", "harness_fakes:SkillPolicy", "--episodes", str(EPISODES),
            "--workers", "0", "--no-progress", "--out", str(out)]  # fmt: skip


def _run(command: list[str], file_limit_bytes: int | None) -> subprocess.CompletedProcess:
    def full_disk() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (file_limit_bytes, file_limit_bytes))

    # No bytecode from the child: under RLIMIT_FSIZE, CPython's .pyc writer keeps a short write
    # (it ignores write()'s count) and renames the truncated file into __pycache__, where every
    # later import of that module fails ("marshal data too short"). On a fresh clone (CI) the
    # first limited child compiled awda_bench's command modules and broke 30 later tests.
    env = {**os.environ, "PYTHONPATH": str(TESTS), "OMP_NUM_THREADS": "1",
           "PYTHONDONTWRITEBYTECODE": "1"}  # fmt: skip
    return subprocess.run(
        command, env=env, capture_output=True, text=True, timeout=300,
        preexec_fn=None if file_limit_bytes is None else full_disk,
    )  # fmt: skip


def _rows(out: Path) -> list[tuple]:
    db = sqlite3.connect(out / STORE_NAME)
    try:
        return db.execute(
            "SELECT task, episode, status, attempts FROM episodes ORDER BY task, episode"
        ).fetchall()
    finally:
        db.close()


def test_a_full_disk_at_store_creation_leaves_no_store_that_later_runs_refuse(
    tmp_path: Path, suites: Path
) -> None:
    out = tmp_path / "run"
    command = _command(suites, out)
    full = _run(command, file_limit_bytes=8 * 1024)  # the schema alone needs more
    err = full.stderr.strip()
    assert full.returncode == 4, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert str(out / STORE_NAME) in err and "full" in err
    assert not (out / STORE_NAME).exists()  # nothing half-made
    assert not list(out.glob(f"{STORE_NAME}.new*"))  # nor its partial file
    again = _run(command, file_limit_bytes=None)  # the space is back
    assert again.returncode == 0, again.stderr
    rows = _rows(out)
    assert len(rows) == EVAL_TASKS * EPISODES and all(r[2] == "ok" and r[3] == 1 for r in rows)


def test_a_disk_that_fills_mid_run_keeps_what_was_recorded_and_resumes_the_rest(
    tmp_path: Path, suites: Path
) -> None:
    out = tmp_path / "run"
    command = _command(suites, out)
    # the store's file and its WAL grow with every episode: room for some of the 12
    full = _run(command, file_limit_bytes=72 * 1024)
    err = full.stderr.strip()
    assert full.returncode == 4, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err and STORE_NAME in err
    kept = _rows(out)  # readable, and what was committed is there
    assert 0 < len(kept) < EVAL_TASKS * EPISODES
    again = _run(command, file_limit_bytes=None)
    assert again.returncode == 0, again.stderr
    rows = _rows(out)
    assert len(rows) == EVAL_TASKS * EPISODES and all(r[2] == "ok" for r in rows)
    assert all(r[3] == 1 for r in rows)  # every episode recorded exactly once
    assert set(kept) <= set(rows)


def test_a_report_on_a_full_disk_is_one_line_and_the_store_is_untouched(
    tmp_path: Path, suites: Path
) -> None:
    out = tmp_path / "run"
    assert _run(_command(suites, out), file_limit_bytes=None).returncode == 0
    before = (out / STORE_NAME).read_bytes()
    report = [sys.executable, "-m", "awda_bench", "report", "--runs", str(out), "--out",
              str(tmp_path / "reports")]  # fmt: skip
    # not even SQLite's shared-memory index of the store's log fits: reading it fails
    full = _run(report, file_limit_bytes=512)
    err = full.stderr.strip()
    assert full.returncode == 4, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert str(out / STORE_NAME) in err and "move it away" not in err  # the store is fine
    assert (out / STORE_NAME).read_bytes() == before
    assert _run(report, file_limit_bytes=None).returncode == 0


def _read_only_directory(directory: Path) -> bool:
    """Make ``directory`` unwritable to this process: chmod where that binds (not root), else
    a read-only tmpfs mounted on it (root); False where neither works."""
    directory.mkdir()
    directory.chmod(0o555)
    try:
        (directory / "probe").write_text("x")
    except PermissionError:
        return True
    (directory / "probe").unlink()
    if shutil.which("mount") is None:
        return False
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(directory)],
                             capture_output=True)  # fmt: skip
    return mounted.returncode == 0


def test_a_read_only_output_directory_is_one_line_and_writes_nothing(
    tmp_path: Path, suites: Path
) -> None:
    parent = tmp_path / "ro"
    if not _read_only_directory(parent):
        pytest.skip("cannot make a read-only directory here (root without mount rights)")
    try:
        out = parent / "run"
        full = _run(_command(suites, out), file_limit_bytes=None)
        err = full.stderr.strip()
        assert full.returncode == 4, err
        assert len(err.splitlines()) == 1 and "Traceback" not in err and str(out) in err
        assert not out.exists()
    finally:
        if shutil.which("umount"):
            subprocess.run(["umount", str(parent)], capture_output=True)
        parent.chmod(0o755)

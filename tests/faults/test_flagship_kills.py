"""The flagship run killed at random moments (issue 53): ``run --suite mosaic`` (gt-waypoints, the
suite's default 120 episodes, 2 workers) SIGKILLed five times in a row at a random moment of its
work, then re-run to the end. Promised: after each kill every worker is gone within 5 s; the
finished store holds every planned episode once; its outcomes and its Table S4 row equal those of
an uninterrupted run of the same command.

Opt-in (``AWDA_FLAGSHIP=1``): the five killed starts, the resumed run and an uninterrupted one took
12.5 min on 2 cores (2026-12-06, beside other jobs), more than CI's budget allows beside the rest
of the suite. Measured then (seed 0): kills 35-80 s after the workers appeared, with 25, 51, 60,
60 and 60 episodes recorded (the last three during set-up); workers outlived the parent by
0.26-0.52 s; the resume finished the remaining 60 in 147 s; 120 episodes once, none retried;
outcomes and S4 row equal to the uninterrupted run's (238 s). ``AWDA_FLAGSHIP_OUT=DIR`` keeps both run
directories (``DIR/uninterrupted``, ``DIR/killed``) and ``DIR/kills.json`` (each kill's moment,
episodes recorded by then, how long the workers outlived the parent); ``AWDA_FLAGSHIP_SEED``
draws other moments (default 0).
"""

from __future__ import annotations

import json
import os
import random
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from processes import descendants, kill_and_reap, outlived_s, wait_for

from awda_bench.evaluation.results_store import STORE_NAME

pytestmark = pytest.mark.skipif(
    os.environ.get("AWDA_FLAGSHIP") != "1",
    reason="two 120-episode MOSAIC runs: opt in with AWDA_FLAGSHIP=1 (tests/faults/test_flagship_kills.py)",
)

KILLS = 5
WINDOW_S = (15.0, 90.0)
"""Each kill lands this long after the run's workers appear (uniform): from environment
set-up to a few episodes in."""


def _command(out: Path) -> list[str]:
    return [sys.executable, "-m", "awda_bench", "run", "--suite", "mosaic", "--workers", "2",
            "--no-progress", "--out", str(out)]  # fmt: skip


def _episodes(out: Path) -> list[tuple]:
    store = out / STORE_NAME
    if not store.exists():
        return []
    db = sqlite3.connect(store)
    try:
        if not db.execute("SELECT 1 FROM sqlite_master WHERE name='episodes'").fetchone():
            return []
        return db.execute(
            "SELECT method, task, episode, seed, demo_seed, status, success_once, success_at_end, "
            "steps, attempts FROM episodes ORDER BY method, task, episode"
        ).fetchall()
    finally:
        db.close()


def _s4_row(out: Path, env: dict[str, str]) -> str:
    """The gt-waypoints row of ``report``'s Table S4 for the run directory ``out``."""
    reports = out / "report"
    subprocess.run([sys.executable, "-m", "awda_bench", "report", "--runs", str(out), "--out",
                    str(reports)], env=env, check=True, capture_output=True)  # fmt: skip
    rows = [r for r in (reports / "s4.md").read_text().splitlines() if r.startswith("| gt-wayp")]
    assert len(rows) == 1, rows
    return rows[0]


def _kill_once(out: Path, env: dict[str, str], moment: float) -> dict[str, float]:
    """Start the run on ``out``, SIGKILL it ``moment`` s after its workers appear; what happened."""
    parent = subprocess.Popen(_command(out), env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        assert wait_for(lambda: len(descendants(parent.pid)) >= 2, 300), "no workers started"
        started = time.monotonic()
        ended = wait_for(lambda: parent.poll() is not None, moment, 0.5)
        assert not ended, f"the run ended {moment:.0f} s in, before its kill (rc {parent.poll()})"
        workers = descendants(parent.pid)
        kill_and_reap(parent, signal.SIGKILL)
        lived = outlived_s(workers)
    finally:
        if parent.poll() is None:
            parent.kill()
    return {"after_s": round(time.monotonic() - started, 1), "workers": len(workers),
            "workers_outlived_s": round(lived, 2), "episodes_recorded": len(_episodes(out))}  # fmt: skip


def test_the_flagship_run_killed_five_times_then_finished_equals_an_uninterrupted_one(
    tmp_path: Path,
) -> None:
    root = Path(os.environ.get("AWDA_FLAGSHIP_OUT", tmp_path))
    rng = random.Random(int(os.environ.get("AWDA_FLAGSHIP_SEED", "0")))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    killed, whole = root / "killed", root / "uninterrupted"
    kills = []
    for _ in range(KILLS):
        kills.append(_kill_once(killed, env, rng.uniform(*WINDOW_S)))
        assert kills[-1]["workers_outlived_s"] <= 5.0, kills
    t0 = time.monotonic()
    subprocess.run(_command(killed), env=env, check=True, capture_output=True)
    resumed_s = time.monotonic() - t0
    t0 = time.monotonic()
    subprocess.run(_command(whole), env=env, check=True, capture_output=True)
    whole_s = time.monotonic() - t0
    got, want = _episodes(killed), _episodes(whole)
    summary = {"kills": kills, "resume_s": round(resumed_s, 1), "uninterrupted_s": round(whole_s, 1),
               "episodes": len(got), "attempts_above_1": sum(r[-1] > 1 for r in got)}  # fmt: skip
    root.mkdir(parents=True, exist_ok=True)
    (root / "kills.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary))
    assert len(got) == len({r[:3] for r in got}) == 120  # every planned episode, once
    assert all(r[5] == "ok" for r in got)
    assert [r[:9] for r in got] == [r[:9] for r in want]  # outcome by outcome (not attempts)
    assert _s4_row(killed, env) == _s4_row(whole, env)

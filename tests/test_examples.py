"""The example package (``examples/awda_example_policies``) as a method author runs it: a
non-learned and a learned method of one's own, named ``--method pkg.module:Factory``, each played
for 2 real pick-and-place episodes through ``python -m awda_bench run``; the learned one's own
snapshot hooks list, check and key its checkpoint files."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.evaluation.methods import get_method, select_snapshots

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
NON_LEARNED = "awda_example_policies.wrist_descend:WristDescendPolicy"
LEARNED = "awda_example_policies.demo_reacher:DemoReacherPolicy"


@pytest.fixture
def examples_on_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(EXAMPLES))


def _checkpoints(directory: Path) -> list[Path]:
    from awda_example_policies.make_checkpoints import write_checkpoints

    return write_checkpoints(directory)


@pytest.mark.usefixtures("examples_on_path")
def test_the_snapshot_hooks_make_an_imported_method_learned(tmp_path: Path) -> None:
    assert not get_method(NON_LEARNED).learned
    spec = get_method(LEARNED)
    assert spec.learned and spec.list_snapshots == f"{LEARNED}.list_snapshots"
    written = _checkpoints(tmp_path / "ckpt")
    refs = select_snapshots(spec, tmp_path / "ckpt", last_n=2)
    assert [r.path for r in refs] == [str(p) for p in written]  # oldest first, by step
    assert len({r.sha256 for r in refs}) == 2
    assert [r.sha256 for r in select_snapshots(spec, tmp_path / "ckpt", last_n=2)] == [
        r.sha256 for r in refs
    ]  # keyed by content: the same files, the same keys
    with pytest.raises(UsageError, match="is learned; pass --checkpoints"):
        select_snapshots(spec, None, last_n=2)


@pytest.mark.usefixtures("examples_on_path")
def test_a_snapshot_the_method_cannot_load_is_refused_in_one_line(tmp_path: Path) -> None:
    import numpy as np

    directory = tmp_path / "ckpt"
    _checkpoints(directory)
    with (directory / "snapshot-300.npz").open("wb") as f:
        np.savez(f, W=np.eye(2))
    with pytest.raises(CorruptFileError, match="snapshot-300.npz cannot be loaded") as caught:
        select_snapshots(get_method(LEARNED), directory, last_n=3)
    assert len(str(caught.value).splitlines()) == 1


def test_a_method_with_one_snapshot_hook_is_refused(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "half_learned.py").write_text(
        "class Factory:\n    @staticmethod\n    def list_snapshots(d):\n        return []\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(UsageError, match="only one of list_snapshots and load_snapshot"):
        get_method("half_learned:Factory")


def _run(out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(EXAMPLES), env.get("PYTHONPATH")]))
    command = [
        sys.executable, "-m", "awda_bench", "run", "--suite", "pick_place", "--workers", "1",
        "--out", str(out), "--no-progress", *args,
    ]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=900, env=env)


def _rows(out: Path) -> list[tuple]:
    with sqlite3.connect(out / "results.sqlite") as db:
        return db.execute("SELECT method, snapshot, task, status, steps FROM episodes").fetchall()


@pytest.mark.slow
def test_the_example_methods_play_two_real_episodes_each(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    result = _run(out, "--method", NON_LEARNED, "--episodes", "1")  # tasks 14 and 15
    assert result.returncode == 0, result.stderr[-2000:]
    rows = _rows(out)
    assert len(rows) == 2 and {r[3] for r in rows} == {"ok"}, rows
    assert all(0 < r[4] <= 180 for r in rows)

    checkpoints = tmp_path / "ckpt"
    env = dict(os.environ, PYTHONPATH=str(EXAMPLES))
    subprocess.run(
        [sys.executable, "-m", "awda_example_policies.make_checkpoints", str(checkpoints)],
        check=True,
        env=env,
    )
    result = _run(
        tmp_path / "learned", "--method", LEARNED, "--checkpoints", str(checkpoints), "--snapshots", "2",
        "--episodes", "1", "--task", "14",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    learned = _rows(tmp_path / "learned")
    assert len(learned) == 2 and len({r[1] for r in learned}) == 2, learned  # one per snapshot
    assert {r[0] for r in learned} == {LEARNED}
    assert {r[3] for r in learned} == {"ok"}, learned

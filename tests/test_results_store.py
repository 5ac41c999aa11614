import hashlib
import sqlite3
from dataclasses import replace
from pathlib import Path

import pytest
from harness_fakes import write_fake_suite

from awda_bench.errors import CorruptFileError, ProtocolMismatchError, UsageError
from awda_bench.evaluation.episode_record import EpisodeRecord
from awda_bench.evaluation.episode_specs import make_protocol
from awda_bench.evaluation.methods import BUILTIN_SNAPSHOT, SnapshotRef
from awda_bench.evaluation.results_store import STORE_NAME, ResultsStore
from awda_bench.suites import load_suite

SNAP = SnapshotRef(sha256=BUILTIN_SNAPSHOT, name=BUILTIN_SNAPSHOT, path=None, order=0)


def _record(episode: int, status: str = "ok", success: bool = True) -> EpisodeRecord:
    return EpisodeRecord(
        suite="fake",
        task=2,
        family="drawer",
        episode=episode,
        seed=episode,
        demo_seed=99,
        method="m",
        snapshot=BUILTIN_SNAPSHOT,
        status=status,
        success_once=success if status == "ok" else None,
        success_at_end=success if status == "ok" else None,
        error=None if status == "ok" else "Traceback ...\nRuntimeError: boom",
        waypoints=[[0.0, 1.0, 2.0, 1.0]],
    )


@pytest.fixture
def protocol(tmp_path: Path):
    write_fake_suite(tmp_path)
    return make_protocol(load_suite("fake", tmp_path), episodes=4, base_seed=0)


def _planned(run_dir: Path, protocol) -> ResultsStore:
    store = ResultsStore(run_dir, create=True)
    store.plan(protocol, "m", False, [SNAP], 8, "test", {"python": "3"})
    return store


def test_ok_rows_are_final_and_errors_are_replaced(tmp_path: Path, protocol) -> None:
    with _planned(tmp_path / "run", protocol) as store:
        fp = protocol.fingerprint
        store.record(fp, _record(0, success=True))
        store.record(fp, _record(1, status="error"))
        assert store.finished_keys(fp, "m", BUILTIN_SNAPSHOT) == {(2, 0)}
        store.record(fp, _record(1, success=False))  # retry of an error replaces it
        store.record(fp, _record(0, success=False))  # an ok row is never overwritten
        rows = store.raw(
            "SELECT episode, status, success_once, attempts FROM episodes ORDER BY episode"
        )
        assert rows == [(0, "ok", 1, 1), (1, "ok", 0, 2)]
        df = store.episodes()
        assert list(df["waypoints"]) == ["[[0.0, 1.0, 2.0, 1.0]]"] * 2


def test_store_is_wal_and_survives_reopen(tmp_path: Path, protocol) -> None:
    with _planned(tmp_path, protocol) as store:
        store.record(protocol.fingerprint, _record(0))
    assert (
        sqlite3.connect(tmp_path / STORE_NAME).execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    )
    with ResultsStore(tmp_path, create=False) as store:
        assert len(store.episodes()) == 1
        assert store.snapshots()["episodes_expected"].tolist() == [8]


def test_other_protocol_is_refused_without_touching_the_file(tmp_path: Path, protocol) -> None:
    with _planned(tmp_path, protocol) as store:
        store.record(protocol.fingerprint, _record(0))
    before = hashlib.sha256((tmp_path / STORE_NAME).read_bytes()).hexdigest()
    suite = load_suite("fake", tmp_path)
    other = make_protocol(suite, episodes=5, base_seed=0)
    with (
        ResultsStore(tmp_path, create=True) as store,
        pytest.raises(ProtocolMismatchError, match="episodes=4->5"),
    ):
        store.plan(other, "m", False, [SNAP], 10, "test", {})
    assert hashlib.sha256((tmp_path / STORE_NAME).read_bytes()).hexdigest() == before


def test_missing_and_foreign_files_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="no results store"):
        ResultsStore(tmp_path / "nowhere", create=False)
    (tmp_path / STORE_NAME).write_bytes(b"not a database at all" * 100)
    with pytest.raises(CorruptFileError, match="not a results store"):
        ResultsStore(tmp_path, create=True)
    other = tmp_path / "other"
    other.mkdir()
    sqlite3.connect(other / STORE_NAME).execute("CREATE TABLE x (y)").connection.commit()
    with pytest.raises(CorruptFileError, match="not an awda_bench results store"):
        ResultsStore(other, create=True)


def test_a_store_from_before_the_privileged_flag_and_first_grip_reads_and_gains_them(
    tmp_path: Path, protocol
) -> None:
    from awda_bench.evaluation import results_store

    run_dir = tmp_path / "old"
    run_dir.mkdir()
    old_schema = results_store._SCHEMA.replace("    privileged INTEGER,\n", "")
    old_schema = old_schema.replace("    first_grip TEXT,\n", "")
    assert "privileged" not in old_schema and "first_grip" not in old_schema
    with sqlite3.connect(run_dir / STORE_NAME) as db:
        db.executescript(old_schema)
        db.execute("INSERT INTO meta VALUES ('schema_version', ?)", (results_store.SCHEMA_VERSION,))
        db.execute(
            "INSERT INTO protocols VALUES (?, 'fake', 'Fake', ?)",
            (protocol.fingerprint, protocol.to_json()),
        )
        db.execute(
            "INSERT INTO snapshots VALUES (?, 'old', ?, ?, 0, 0, 8)",
            (protocol.fingerprint, BUILTIN_SNAPSHOT, BUILTIN_SNAPSHOT),
        )
    with ResultsStore(run_dir, create=False) as store:  # the report reads it as it is
        plan = store.snapshots()
        assert plan["privileged"].isna().all()
        assert "first_grip" in store.episodes().columns
    with ResultsStore(run_dir, create=True) as store:  # a run adds the columns
        store.plan(protocol, "new", False, [SNAP], 8, "test", {}, privileged=True)
        flags = dict(store.raw("SELECT method, privileged FROM snapshots"))
        store.record(protocol.fingerprint, replace(_record(0), first_grip="other"))
        grips = store.episodes()["first_grip"].tolist()
    assert flags == {"old": None, "new": 1}
    assert grips == ["other"]


def test_a_run_that_finds_the_store_made_meanwhile_uses_it(tmp_path: Path) -> None:
    # two runs started together: both saw no store; the first one's is in place when the second
    # finishes its own schema. The second must not replace it (the first may already write to
    # it) nor leave its partial file behind.
    first = ResultsStore(tmp_path, create=True)
    inode = first.path.stat().st_ino
    second = ResultsStore.__new__(ResultsStore)  # the second run, past its "no store yet" check
    second.path = first.path
    second._create_whole()
    assert first.path.stat().st_ino == inode
    assert not list(tmp_path.glob(f"{STORE_NAME}.new*"))
    ResultsStore(tmp_path, create=True)  # and it opens the first one's store


def test_the_carry_columns_round_trip_and_an_older_store_gains_them(
    tmp_path: Path, protocol
) -> None:
    carried = replace(
        _record(0), carry="off_target", release_xy_m=0.1, release_dz_m=0.2, place_goal=[0.1, 0, 0]
    )
    with _planned(tmp_path, protocol) as store:
        store.record(protocol.fingerprint, carried)
        row = store.episodes().iloc[0]
    assert (row["carry"], row["release_xy_m"], row["release_dz_m"]) == ("off_target", 0.1, 0.2)
    assert row["place_goal"] == "[0.1, 0, 0]"
    conn = sqlite3.connect(tmp_path / STORE_NAME)  # as written before the carry analysis
    for column in ("carry", "release_xy_m", "release_dz_m", "place_goal"):
        conn.execute(f"ALTER TABLE episodes DROP COLUMN {column}")
    conn.commit()
    conn.close()
    with ResultsStore(tmp_path, create=False) as store:  # read: unknown
        old = store.episodes()
    assert old["carry"].isna().all() and old["release_dz_m"].isna().all() and len(old) == 1
    with ResultsStore(tmp_path, create=True) as store:  # opened to write: gains the columns
        store.record(protocol.fingerprint, replace(carried, episode=1, seed=1))
        rows = store.episodes()
    assert rows["carry"].isna().tolist() == [True, False] and rows["carry"][1] == "off_target"

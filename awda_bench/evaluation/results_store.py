"""The results store: one SQLite file (WAL) per run directory, one row per episode.

Tables::

    meta(key, value)                       schema version
    protocols(fingerprint, suite, display_name, definition)   one protocol per suite per store
    snapshots(protocol, method, snapshot, name, ord, learned, episodes_expected, privileged)
                                                                                   the plan
    episodes(protocol, method, snapshot, task, episode, ...)   PRIMARY KEY of those five
    runs(id, started_at, command, versions)

Resume semantics: an episode whose row has status ``ok`` is finished and never re-run; a row with
status ``error`` is re-run and replaced (``attempts`` counts the tries); a missing row is pending.
Each record is committed as it arrives, so a killed run loses at most the episodes in flight.
Every check (schema, protocol) happens before the first write, so a refused run leaves the file
untouched.

A new store is created whole or not at all: the schema is written into
``results.sqlite.new.<pid>`` (one transaction), then hard-linked into place only if no store is
there yet (two runs started together into one directory: the first link wins and both use that
store; a rename would let the second replace a store the first already writes to), and the
partial file is removed; a store that could not be finished (no space left, an I/O error) is
removed, so the same command starts afresh once the cause is fixed (a half-made
file used to be refused for good: "store schema None"). Any write the store cannot make is a
:class:`~awda_bench.errors.StorageError` naming the file and the cause, never a traceback; the
episodes committed before it stay.
"""

from __future__ import annotations

import errno
import json
import os
import sqlite3
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pandas as pd

from awda_bench.errors import CorruptFileError, ProtocolMismatchError, StorageError, UsageError
from awda_bench.evaluation.episode_record import STATUS_OK, EpisodeRecord
from awda_bench.evaluation.episode_specs import EvalProtocol
from awda_bench.evaluation.methods import SnapshotRef

STORE_NAME = "results.sqlite"
"""File name of the store inside a run directory."""

NO_HARD_LINKS = frozenset({errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.ENOSYS})
"""``os.link`` errors of a file system without hard links (a new store is renamed into place)."""

SCHEMA_VERSION = "1"
"""Bumped on any incompatible schema change."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS protocols (
    fingerprint TEXT PRIMARY KEY,
    suite TEXT NOT NULL UNIQUE,
    display_name TEXT NOT NULL,
    definition TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS snapshots (
    protocol TEXT NOT NULL REFERENCES protocols(fingerprint),
    method TEXT NOT NULL,
    snapshot TEXT NOT NULL,
    name TEXT NOT NULL,
    ord INTEGER NOT NULL,
    learned INTEGER NOT NULL,
    episodes_expected INTEGER NOT NULL,
    privileged INTEGER,
    PRIMARY KEY (protocol, method, snapshot)
);
CREATE TABLE IF NOT EXISTS episodes (
    protocol TEXT NOT NULL REFERENCES protocols(fingerprint),
    method TEXT NOT NULL,
    snapshot TEXT NOT NULL,
    suite TEXT NOT NULL,
    task INTEGER NOT NULL,
    family TEXT NOT NULL,
    episode INTEGER NOT NULL,
    seed INTEGER NOT NULL,
    demo_seed INTEGER NOT NULL,
    success_once INTEGER,
    success_at_end INTEGER,
    reached INTEGER,
    grasped INTEGER,
    first_grip TEXT,
    carry TEXT,
    release_xy_m REAL,
    release_dz_m REAL,
    place_goal TEXT,
    steps INTEGER NOT NULL,
    wall_time_s REAL NOT NULL,
    act_time_s REAL NOT NULL,
    env_time_s REAL NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('ok', 'error')),
    error TEXT,
    waypoints TEXT,
    server TEXT,
    attempts INTEGER NOT NULL DEFAULT 1,
    finished_at REAL NOT NULL,
    PRIMARY KEY (protocol, method, snapshot, task, episode)
);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    started_at REAL NOT NULL,
    protocol TEXT NOT NULL,
    method TEXT NOT NULL,
    command TEXT NOT NULL,
    versions TEXT NOT NULL
);
"""

EPISODE_COLUMNS = (
    "protocol",
    "method",
    "snapshot",
    "suite",
    "task",
    "family",
    "episode",
    "seed",
    "demo_seed",
    "success_once",
    "success_at_end",
    "reached",
    "grasped",
    "first_grip",
    "carry",
    "release_xy_m",
    "release_dz_m",
    "place_goal",
    "steps",
    "wall_time_s",
    "act_time_s",
    "env_time_s",
    "status",
    "error",
    "waypoints",
    "server",
)

ADDED_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("snapshots", "privileged", "INTEGER"),
    ("episodes", "first_grip", "TEXT"),
    ("episodes", "server", "TEXT"),
    ("episodes", "carry", "TEXT"),
    ("episodes", "release_xy_m", "REAL"),
    ("episodes", "release_dz_m", "REAL"),
    ("episodes", "place_goal", "TEXT"),
)
"""(table, column, type) added since schema 1 without bumping it: an older store opened to
write gains them; one opened to read shows them as NULL."""


def _bool(value: bool | None) -> int | None:
    return None if value is None else int(value)


class ResultsStore:
    """Open (or create) ``run_dir/results.sqlite``. ``create=False`` refuses a missing store."""

    def __init__(self, run_dir: Path, *, create: bool) -> None:
        self.path = Path(run_dir) / STORE_NAME
        if create and self.path.is_file() and self.path.stat().st_size == 0:
            self.path.unlink()  # an empty file holds nothing: made whole below
        if not self.path.is_file():
            if not create:
                raise UsageError(
                    f"no results store at {self.path}; "
                    "run `python -m awda_bench run` first or pass --runs"
                )
            self._create_whole()
        self._conn = sqlite3.connect(self.path, timeout=30)
        try:
            self._check_or_init(create)
        except sqlite3.OperationalError as exc:
            self._conn.close()
            raise self._storage_error(exc) from exc
        except BaseException:
            self._conn.close()
            raise

    def _storage_error(self, exc: BaseException) -> StorageError:
        cause = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        return StorageError(
            f"cannot use the results store {self.path}: {cause}; free space or fix the "
            "directory's permissions, then re-run the same command (recorded episodes are kept)"
        )

    def _create_whole(self) -> None:
        """Write an empty store with its schema next to :attr:`path`, then rename it into place
        (module docstring); on failure nothing is left behind."""
        partial = self.path.with_name(f"{STORE_NAME}.new.{os.getpid()}")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            partial.unlink(missing_ok=True)
            conn = sqlite3.connect(partial)
            try:
                conn.executescript(f"BEGIN;\n{_SCHEMA}\nCOMMIT;")
                with conn:
                    conn.execute("INSERT INTO meta VALUES ('schema_version', ?)", (SCHEMA_VERSION,))
            finally:
                conn.close()
            try:
                os.link(partial, self.path)
            except FileExistsError:
                pass  # another run made the store first: this one uses it (module docstring)
            except OSError as exc:
                if exc.errno not in NO_HARD_LINKS:
                    raise
                partial.replace(self.path)  # a file system without hard links: a plain rename
            partial.unlink(missing_ok=True)
        except (OSError, sqlite3.OperationalError) as exc:
            try:
                partial.unlink(missing_ok=True)
            except OSError:
                pass  # the directory itself is unwritable: there is no partial file either
            raise self._storage_error(exc) from exc

    def _check_or_init(self, create: bool) -> None:
        try:
            tables = {
                r[0]
                for r in self._conn.execute("SELECT name FROM sqlite_master WHERE type='table'")
            }
        except sqlite3.OperationalError:
            raise  # the disk's (I/O, full, locked): a StorageError in __init__, the file is fine
        except sqlite3.DatabaseError as exc:
            raise CorruptFileError(
                f"{self.path} is not a results store ({exc}); move it away"
            ) from exc
        if tables:
            if "meta" not in tables:
                raise CorruptFileError(
                    f"{self.path} is not an awda_bench results store; move it away"
                )
            row = self._conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()
            if row is None or row[0] != SCHEMA_VERSION:
                found = None if row is None else row[0]
                raise CorruptFileError(
                    f"{self.path} has store schema {found}, this version reads {SCHEMA_VERSION}; "
                    "use another run directory"
                )
            if create:
                self._add_missing_columns()
                self._conn.execute("PRAGMA journal_mode=WAL")
                # WAL + NORMAL: a commit survives the process being killed (only an OS crash or
                # power loss can drop the last commits); no fsync per episode
                self._conn.execute("PRAGMA synchronous=NORMAL")
            return
        raise CorruptFileError(
            f"{self.path} is empty (not an awda_bench results store); move it away or re-run "
            "`python -m awda_bench run` into another directory"
        )

    def _add_missing_columns(self) -> None:
        """A store written before a column existed gains it (NULL: unknown): ``privileged``
        (before methods declared privilege), ``first_grip`` (before the first-grip analysis),
        ``server`` (before openpi-served policies), ``carry``, ``release_*`` and ``place_goal``
        (before the carry analysis)."""
        for table, column, kind in ADDED_COLUMNS:
            columns = {r[1] for r in self._conn.execute(f"PRAGMA table_info({table})")}
            if column not in columns:
                with self._conn:
                    self._conn.execute(f"ALTER TABLE {table} ADD COLUMN {column} {kind}")

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- protocol and plan -------------------------------------------------------------------

    def check_protocol(self, protocol: EvalProtocol) -> None:
        """Raise if the store holds ``protocol.suite`` under another protocol (writes nothing)."""
        row = self._conn.execute(
            "SELECT fingerprint, definition FROM protocols WHERE suite=?", (protocol.suite,)
        ).fetchone()
        if row is not None and row[0] != protocol.fingerprint:
            theirs = json.loads(row[1])
            ours = json.loads(protocol.to_json())
            diff = ", ".join(
                f"{k}={theirs.get(k)!r}->{ours[k]!r}"
                for k in sorted(ours)
                if theirs.get(k) != ours[k]
            )
            raise ProtocolMismatchError(
                f"{self.path} holds suite {protocol.suite!r} under protocol {row[0]}, this run is "
                f"{protocol.fingerprint} ({diff}); use another --out or the same settings"
            )

    def plan(
        self,
        protocol: EvalProtocol,
        method: str,
        learned: bool,
        snapshots: Iterable[SnapshotRef],
        episodes_expected: int,
        command: str,
        versions: dict[str, str],
        display_name: str = "",
        privileged: bool = False,
    ) -> None:
        """Record the protocol, the snapshots about to be evaluated and this run's invocation;
        ``privileged``: the method reads the simulator (its rows are marked in the tables)."""
        self.check_protocol(protocol)
        with self._conn:
            self._conn.execute(
                "INSERT OR IGNORE INTO protocols VALUES (?, ?, ?, ?)",
                (
                    protocol.fingerprint,
                    protocol.suite,
                    display_name or protocol.suite,
                    protocol.to_json(),
                ),
            )
            for snap in snapshots:
                self._conn.execute(
                    "INSERT OR REPLACE INTO snapshots (protocol, method, snapshot, name, ord, "
                    "learned, episodes_expected, privileged) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        protocol.fingerprint,
                        method,
                        snap.sha256,
                        snap.name,
                        snap.order,
                        int(learned),
                        episodes_expected,
                        int(privileged),
                    ),
                )
            self._conn.execute(
                "INSERT INTO runs (started_at, protocol, method, command, versions) "
                "VALUES (?, ?, ?, ?, ?)",
                (
                    time.time(),
                    protocol.fingerprint,
                    method,
                    command,
                    json.dumps(versions, sort_keys=True),
                ),
            )

    # --- episodes ------------------------------------------------------------------------------

    def finished_keys(self, protocol: str, method: str, snapshot: str) -> set[tuple[int, int]]:
        """``(task, episode)`` of the episodes already recorded with status ok."""
        rows = self._conn.execute(
            "SELECT task, episode FROM episodes "
            "WHERE protocol=? AND method=? AND snapshot=? AND status=?",
            (protocol, method, snapshot, STATUS_OK),
        )
        return {(int(t), int(e)) for t, e in rows}

    def record(self, protocol: str, rec: EpisodeRecord) -> None:
        """Insert or replace one episode's row and commit; an ok row is never overwritten."""
        values = (
            protocol,
            rec.method,
            rec.snapshot,
            rec.suite,
            rec.task,
            rec.family,
            rec.episode,
            rec.seed,
            rec.demo_seed,
            _bool(rec.success_once),
            _bool(rec.success_at_end),
            _bool(rec.reached),
            _bool(rec.grasped),
            rec.first_grip,
            rec.carry,
            rec.release_xy_m,
            rec.release_dz_m,
            None if rec.place_goal is None else json.dumps(rec.place_goal),
            rec.steps,
            rec.wall_time_s,
            rec.act_time_s,
            rec.env_time_s,
            rec.status,
            rec.error,
            None if rec.waypoints is None else json.dumps(rec.waypoints),
            None if rec.server is None else json.dumps(rec.server, sort_keys=True),
        )
        placeholders = ", ".join("?" * len(EPISODE_COLUMNS))
        columns = ", ".join(EPISODE_COLUMNS)
        updates = ", ".join(f"{c}=excluded.{c}" for c in EPISODE_COLUMNS[3:])
        try:
            self._insert(columns, placeholders, updates, (*values, time.time()))
        except sqlite3.OperationalError as exc:
            raise self._storage_error(exc) from exc

    def _insert(self, columns: str, placeholders: str, updates: str, values: tuple) -> None:
        with self._conn:
            self._conn.execute(
                f"INSERT INTO episodes ({columns}, attempts, finished_at) "
                f"VALUES ({placeholders}, 1, ?) "
                "ON CONFLICT (protocol, method, snapshot, task, episode) DO UPDATE SET "
                f"{updates}, attempts=episodes.attempts+1, finished_at=excluded.finished_at "
                "WHERE episodes.status != 'ok'",
                values,
            )

    # --- reading -------------------------------------------------------------------------------

    def episodes(self) -> pd.DataFrame:
        """Every episode row; a column added since schema 1 (:data:`ADDED_COLUMNS`) is NULL
        (unknown) in a store written before it."""
        rows = pd.read_sql_query(
            "SELECT * FROM episodes ORDER BY protocol, method, snapshot, task, episode", self._conn
        )
        for table, column, _ in ADDED_COLUMNS:
            if table == "episodes" and column not in rows.columns:
                rows[column] = None
        return rows

    def snapshots(self) -> pd.DataFrame:
        """The plan; ``privileged`` is NULL (unknown) in a store written before it existed."""
        plan = pd.read_sql_query(
            "SELECT * FROM snapshots ORDER BY protocol, method, ord", self._conn
        )
        if "privileged" not in plan.columns:
            plan["privileged"] = None
        return plan

    def protocols(self) -> pd.DataFrame:
        return pd.read_sql_query("SELECT * FROM protocols ORDER BY suite", self._conn)

    def runs(self) -> pd.DataFrame:
        return pd.read_sql_query("SELECT * FROM runs ORDER BY id", self._conn)

    def raw(self, sql: str, params: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        return list(self._conn.execute(sql, params))

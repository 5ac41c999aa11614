"""Running ``reproduce``'s stages: each one's command as a subprocess in its own process group,
one invocation per directory (a lock), every attempt's wall time in ``OUT/stage_times.json``, and
stop signals passed on to the running stage."""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from awda_bench.errors import AwdaError, CorruptFileError, UsageError
from awda_bench.execution.parent_death import PARENT_ENV
from awda_bench.reproduce.config import ReproduceConfig
from awda_bench.reproduce.costs import clock
from awda_bench.reproduce.plan import Stage


class RunInterrupted(AwdaError):
    """A signal stopped ``reproduce`` mid-stage; exit code 128 + the signal's number."""

    def __init__(self, message: str, exit_code: int) -> None:
        super().__init__(message)
        self.exit_code = exit_code


STAGE_TIMES = "stage_times.json"
"""``OUT/stage_times.json``: every attempt at every stage, across invocations (a killed run's
stages add up)."""

LOCK_FILE = ".reproduce.lock"
HEARTBEAT_S = 30.0
"""How often a running stage's wall time is written to :data:`STAGE_TIMES`."""


@dataclass
class StageAttempt:
    """One run of one stage's command: how long, and how it ended."""

    stage: str
    started_at: str
    wall_s: float
    outcome: str
    """``finished``, ``failed (exit N)``, ``interrupted (SIGTERM)``, ``running`` while it runs, or
    ``killed`` when a later invocation finds a ``running`` attempt whose process is gone."""


def read_stage_times(out: Path) -> list[StageAttempt]:
    path = out / STAGE_TIMES
    if not path.is_file():
        return []
    try:
        return [StageAttempt(**row) for row in json.loads(path.read_text())]
    except (ValueError, TypeError) as exc:
        raise CorruptFileError(
            f"{path} is not a stage-time log ({exc}); delete it to start a new log (only the "
            "reported stage wall times are lost)"
        ) from exc


def write_stage_times(out: Path, attempts: list[StageAttempt]) -> None:
    path = out / STAGE_TIMES
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps([asdict(a) for a in attempts], indent=1) + "\n")
    os.replace(tmp, path)


def stage_totals(attempts: list[StageAttempt]) -> list[tuple[str, float, int, str]]:
    """``(stage, wall s summed over attempts, attempts, last outcome)`` in first-run order."""
    totals: dict[str, list[Any]] = {}
    for a in attempts:
        row = totals.setdefault(a.stage, [0.0, 0, ""])
        row[0] += a.wall_s
        row[1] += 1
        row[2] = a.outcome
    return [(name, wall, n, last) for name, (wall, n, last) in totals.items()]


@contextmanager
def _exclusive(out: Path) -> Iterator[None]:
    """Hold ``OUT/.reproduce.lock`` so that two invocations never run stages in one directory."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / LOCK_FILE, "a+") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            owner = handle.read().strip() or "?"
            raise UsageError(
                f"another reproduce (pid {owner}) is running in {out}; wait for it to finish or "
                "stop it (Ctrl-C or kill PID), then re-run this command to resume"
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        yield


@contextmanager
def _forward_stop_signals(child: subprocess.Popen, received: list[int]) -> Iterator[None]:
    """While ``child`` runs in its own process group: SIGINT/SIGTERM/SIGHUP to this process stop
    the whole group (the stage and its workers) with SIGTERM, a second one with SIGKILL."""

    def handler(signum: int, _frame: object) -> None:
        received.append(signum)
        try:
            os.killpg(child.pid, signal.SIGTERM if len(received) == 1 else signal.SIGKILL)
        except ProcessLookupError:
            pass

    stops = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    saved = {s: signal.signal(s, handler) for s in stops}
    try:
        yield
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


def run_stages(
    config: ReproduceConfig,
    stages: list[Stage],
    command: tuple[str, ...] = (sys.executable, "-m", "awda_bench"),
) -> list[StageAttempt]:
    """Run every stage not done, in order, each as a subprocess in its own process group.

    Every attempt is logged to ``OUT/stage_times.json`` (its wall time rewritten every
    :data:`HEARTBEAT_S` while it runs), so the summary's stage times add up over a run that was
    killed and resumed. Stopping this process (Ctrl-C, SIGTERM, SIGHUP) stops the running stage
    and its workers too, records the attempt as interrupted and raises :class:`RunInterrupted`;
    a failing stage raises :class:`UsageError`. ``command`` prefixes each stage's ``argv``.
    After each stage it prints :func:`pace_line` (its time beside the plan's, and the rest re-timed
    at this run's pace). Returns this invocation's attempts."""
    with _exclusive(config.out):
        log = read_stage_times(config.out)
        for attempt in log:
            if attempt.outcome == "running":  # its invocation died without a word (SIGKILL)
                attempt.outcome = "killed"
        mine: list[StageAttempt] = []
        paced: list[tuple[float, float]] = []  # (planned, actual) of the stages finished here
        for index, stage in enumerate(stages):
            if stage.done:
                print(f"[reproduce] {stage.name}: done, skipped", flush=True)
                continue
            argv = [*command, *stage.argv]
            print(f"[reproduce] {stage.name}: {' '.join(argv[1:])}", flush=True)
            attempt = StageAttempt(
                stage.name, datetime.now(UTC).isoformat(timespec="seconds"), 0.0, "running"
            )
            log.append(attempt)
            mine.append(attempt)
            write_stage_times(config.out, log)
            start = time.perf_counter()
            received: list[int] = []
            # its own process group (stop signals reach its workers; Ctrl-C reaches this process
            # alone) in this session: a new session would be a new scheduler autogroup on Linux,
            # at nice 0 whatever ``nice`` this run was started under
            # the stage is SIGTERMed if reproduce dies (SIGKILL too): no orphaned stage or workers
            child = subprocess.Popen(
                argv, process_group=0, env={**os.environ, PARENT_ENV: str(os.getpid())}
            )
            with _forward_stop_signals(child, received):
                while True:
                    try:
                        code = child.wait(timeout=HEARTBEAT_S)
                        break
                    except subprocess.TimeoutExpired:
                        attempt.wall_s = round(time.perf_counter() - start, 3)
                        write_stage_times(config.out, log)
            attempt.wall_s = round(time.perf_counter() - start, 3)
            if received:
                name = signal.Signals(received[0]).name
                attempt.outcome = f"interrupted ({name})"
                write_stage_times(config.out, log)
                raise RunInterrupted(
                    f"{name}: stopped stage {stage.name!r} after {attempt.wall_s:.0f} s; re-run the "
                    "same reproduce command to resume (finished stages and episodes are kept)",
                    128 + received[0],
                )
            attempt.outcome = "finished" if code == 0 else f"failed (exit {code})"
            write_stage_times(config.out, log)
            if code != 0:
                raise UsageError(
                    f"stage {stage.name!r} exited {code} after {attempt.wall_s:.0f} s; fix what it "
                    "printed and re-run the same reproduce command (finished stages are skipped)"
                )
            paced.append((stage.estimate_s, attempt.wall_s))
            left = sum(s.estimate_s for s in stages[index + 1 :] if not s.done)
            print(f"[reproduce] {stage.name}: {pace_line(paced, left)}", flush=True)
        return mine


def pace_line(paced: list[tuple[float, float]], left_s: float) -> str:
    """The line ``reproduce`` prints after a stage: its wall time beside its plan, and what is left
    at the plan's figures and at this invocation's pace so far (actual / planned over the stages
    it finished: the plan's costs are one 2-core machine's, and machines differ). ``paced`` holds
    ``(planned_s, actual_s)`` of the finished stages, the last one being the stage just done."""
    planned, actual = paced[-1]
    line = f"{actual:.0f} s (planned ~{clock(planned)})"
    if left_s <= 0.0:
        return line
    line += f"; left: ~{clock(left_s)} at the plan's figures"
    plan_sum = sum(p for p, _ in paced)
    if plan_sum > 0.0:
        pace = sum(a for _, a in paced) / plan_sum
        line += f", ~{clock(left_s * pace)} at this run's pace so far ({pace:.2f}x the plan)"
    return line

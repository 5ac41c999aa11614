"""Collection workers: processes that each build their envs once and record jobs as they come.

The same shape as the evaluation pool (:mod:`awda_bench.harness.worker_pool`): jobs in, records
out, so another backend (Ray) can implement :class:`JobRunner` the same way::

    parent                                  worker k (spawned; OMP_NUM_THREADS=1)
      start ------------------------------>   recorder = EpisodeRecorder(config)
            <------------------------- ("ready", pid)
      CollectJob ------------------------->   fresh env; replay the unit's done attempts,
                                              record its next `chunk` successful ones
            <------------------- ("result", JobResult)   episodes, and/or error + traceback
      ... on_result(result) -> follow-up jobs (the unit's next chunk) join the queue
      ... watchdog: a job older than job_timeout_s -> kill worker, error result, respawn
      None ------------------------------->   close envs, exit

A worker that cannot build its recorder stops the collection (:class:`WorkerStartError`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import Any, Protocol

from awda_bench.data.config import CollectConfig
from awda_bench.data.plan import Attempt, CollectJob, make_attempt
from awda_bench.data.recorder import EpisodeData, EpisodeRecorder
from awda_bench.harness.worker_pool import WorkerStartError, _single_threaded_children


@dataclass
class JobResult:
    """What came back for one job: the attempts it recorded (kept and discarded), in order, and
    the error that stopped it, if any."""

    job: CollectJob
    episodes: list[EpisodeData] = field(default_factory=list)
    """Recorded attempts in attempt order (``data.success``: kept or discarded)."""
    error: str | None = None
    """Traceback or watchdog message; the unit is left unfinished (retried on re-run)."""
    gave_up: bool = False
    """The unit reached ``job.max_attempts`` without ``job.planned`` successes."""


OnResult = Callable[[JobResult], Iterable[CollectJob]]
"""Called in the parent per result; returns follow-up jobs to schedule (possibly none)."""


class JobRunner(Protocol):
    """A backend that records jobs and hands each result to ``on_result`` in the parent."""

    def run(self, jobs: Sequence[CollectJob], on_result: OnResult) -> None: ...


def run_unit_job(
    job: CollectJob,
    config: CollectConfig,
    record: Callable[[Attempt], EpisodeData],
    replay: Callable[[Attempt], None],
) -> JobResult:
    """The attempt sequence of one job (see :class:`~awda_bench.data.plan.CollectJob`)::

        for i = 0, 1, 2, ...  until the unit has `planned` successes or this job `chunk` new ones:
            i already kept or discarded  -> replay(i)   (the env's history, nothing recorded)
            otherwise                    -> record(i)  (kept if it succeeded, else discarded)
        i reaching max_attempts first -> gave_up

    An exception stops the job; what it recorded before is returned with the error.
    """
    result = JobResult(job=job)
    done = set(job.kept) | set(job.discarded)
    successes, new, i = 0, 0, 0
    try:
        while successes < job.planned and new < job.chunk and i < job.max_attempts:
            attempt = make_attempt(config, job.role, job.task, i)
            if i in done:
                replay(attempt)
                successes += i in job.kept
            else:
                data = record(attempt)
                result.episodes.append(data)
                successes += data.success
                new += data.success
            i += 1
        result.gave_up = successes < job.planned and new < job.chunk
    except Exception:  # reported with its traceback; the collection goes on
        result.error = traceback.format_exc()
    return result


def job_timeout_s(config: CollectConfig, job: CollectJob | None) -> float:
    """Watchdog limit of a job [s]: ``episode_timeout_s`` per episode it may play."""
    if job is None:
        return config.episode_timeout_s
    return config.episode_timeout_s * (job.chunk + len(job.kept) + len(job.discarded))


def play(recorder: EpisodeRecorder, job: CollectJob) -> JobResult:
    """Record ``job`` in a freshly built env (closed afterwards)."""
    try:
        env, env_info = recorder.build_env(job.task, job.role)
    except Exception:
        return JobResult(job=job, error=traceback.format_exc())
    try:
        return run_unit_job(
            job,
            recorder.config,
            record=lambda attempt: recorder.record(env, env_info, attempt),
            replay=lambda attempt: recorder.replay(env, attempt),
        )
    finally:
        env.close()


class InlineRunner:
    """Record jobs in this process, one after the other (``--workers 0``; no watchdog)."""

    def __init__(self, config: CollectConfig) -> None:
        self.config = config

    def run(self, jobs: Sequence[CollectJob], on_result: OnResult) -> None:
        recorder = EpisodeRecorder(self.config)
        queue = deque(jobs)
        try:
            while queue:
                queue.extend(on_result(play(recorder, queue.popleft())))
        finally:
            recorder.close()


def _worker_main(conn: Connection, config: CollectConfig) -> None:
    try:
        recorder = EpisodeRecorder(config)
        # build the first env now: a broken renderer stops the collection at start-up
        recorder.env_for(recorder.suite.tasks[0].index, "agent")
        recorder.close()  # jobs build their own envs
    except BaseException as exc:
        conn.send(("fatal", f"{type(exc).__name__}: {exc}"))
        conn.close()
        return
    conn.send(("ready", os.getpid()))
    try:
        while True:
            try:
                job = conn.recv()
            except EOFError:
                break  # the parent is gone
            if job is None:
                break
            result = play(recorder, job)
            try:
                conn.send(("result", result))
            except BrokenPipeError:
                break  # the parent was killed; the attempt is re-recorded on resume
    finally:
        recorder.close()
        conn.close()


class _Slot:
    def __init__(self, ctx: Any, config: CollectConfig) -> None:
        self.conn, child = ctx.Pipe(duplex=True)
        self.process = ctx.Process(target=_worker_main, args=(child, config), daemon=True)
        with _single_threaded_children():
            self.process.start()
        child.close()
        self.ready = False
        self.job: CollectJob | None = None
        self.since = time.monotonic()

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join(timeout=10)
        self.conn.close()


class ProcessRunner:
    """Record jobs on ``workers`` spawned processes (the local backend of ``collect``)."""

    def __init__(self, config: CollectConfig, workers: int, start_timeout_s: float = 600.0) -> None:
        if workers < 1:
            raise ValueError("workers must be >= 1")
        self.config = config
        self.workers = workers
        self.start_timeout_s = start_timeout_s
        self.respawns = 0
        self._ctx = mp.get_context("spawn")
        self._queue: deque[CollectJob] = deque()

    def run(self, jobs: Sequence[CollectJob], on_result: OnResult) -> None:
        self._queue = deque(jobs)
        if not self._queue:
            return
        slots = [_Slot(self._ctx, self.config) for _ in range(min(self.workers, len(jobs)))]
        try:
            while self._queue or any(s.job is not None for s in slots):
                for slot in slots:
                    self._dispatch(slot)
                for conn in wait([s.conn for s in slots], timeout=1.0):
                    i = next(k for k, s in enumerate(slots) if s.conn is conn)
                    slots[i] = self._receive(slots[i], on_result)
                now = time.monotonic()
                for i, slot in enumerate(slots):
                    if not slot.ready and now > slot.since + self.start_timeout_s:
                        raise WorkerStartError(
                            f"a collect worker did not build its env within "
                            f"{self.start_timeout_s:.0f} s; check `python -m awda_bench doctor`"
                        )
                    timeout_s = job_timeout_s(self.config, slot.job)
                    if slot.job is not None and now > slot.since + timeout_s:
                        message = f"watchdog: job exceeded {timeout_s:g} s; worker killed"
                        self._queue.extend(on_result(JobResult(job=slot.job, error=message)))
                        slots[i] = self._respawn(slot)
        finally:
            for slot in slots:
                if slot.process.is_alive():
                    try:
                        slot.conn.send(None)
                    except OSError:
                        pass  # already gone; kill() reaps it
            deadline = time.monotonic() + 30
            for slot in slots:
                slot.process.join(timeout=max(0.0, deadline - time.monotonic()))
                slot.kill()

    def _dispatch(self, slot: _Slot) -> None:
        if slot.ready and slot.job is None and self._queue:
            slot.job = self._queue.popleft()
            slot.since = time.monotonic()
            slot.conn.send(slot.job)

    def _respawn(self, slot: _Slot) -> _Slot:
        slot.kill()
        self.respawns += 1
        return _Slot(self._ctx, self.config)

    def _receive(self, slot: _Slot, on_result: OnResult) -> _Slot:
        try:
            message = slot.conn.recv()
        except (EOFError, OSError):
            slot.process.join(timeout=5)
            if slot.job is not None:
                error = f"worker died (exit code {slot.process.exitcode}) during the episode"
                self._queue.extend(on_result(JobResult(job=slot.job, error=error)))
                return self._respawn(slot)
            raise WorkerStartError(
                f"a collect worker exited (code {slot.process.exitcode}) before building its env"
            ) from None
        kind = message[0]
        if kind == "ready":
            slot.ready = True
            slot.since = time.monotonic()
        elif kind == "result":
            slot.job = None
            self._dispatch(slot)  # the worker records its next job while we write this one
            self._queue.extend(on_result(message[1]))
        elif kind == "fatal":
            raise WorkerStartError(f"a collect worker could not build its env: {message[1]}")
        return slot

"""Episode workers: processes that each build one env, reuse it, and stream records back.

::

    parent                                   worker k (spawned; OMP_NUM_THREADS=1)
      start ------------------------------->   env = make_env(suite)      (once per env id)
            <----------------------- ("ready", pid)
      ("job", Job) ------------------------>   policy cached per (method, snapshot)
            <--------------------- ("result", EpisodeRecord)   status ok, or error + traceback
      ... watchdog: a job older than episode_timeout_s -> kill worker, record an error, respawn
      None -------------------------------->   close env, exit

An exception inside an episode becomes an error record and the worker carries on; a worker that
dies or hangs is replaced and its episode recorded as an error; a worker that cannot even build
its env stops the sweep (:class:`WorkerStartError`), because every episode would fail the same way.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

from awda_bench.episode import EpisodeSpec, Policy
from awda_bench.errors import AwdaError
from awda_bench.harness.episode_record import STATUS_ERROR, EpisodeRecord
from awda_bench.harness.episode_runner import FrameHook, run_episode
from awda_bench.harness.methods import MethodSpec, SnapshotRef, make_policy, resolve
from awda_bench.suites import Suite, load_suite

DEFAULT_ENV_FACTORY = "awda_bench.harness.env_factory:make_env"
"""``"module:attribute"`` of ``make_env(suite, render_mode=...)``."""


class WorkerStartError(AwdaError):
    """A worker could not build its env (renderer, missing env package, ...)."""

    exit_code = 3


@dataclass(frozen=True)
class Job:
    """One episode to play with one (method, snapshot)."""

    spec: EpisodeSpec
    """The episode."""
    method: MethodSpec
    """The method (plain strings, rebuilt inside the worker)."""
    snapshot: SnapshotRef
    """The snapshot of the method."""


@dataclass(frozen=True)
class WorkerConfig:
    """What every worker of a sweep shares."""

    suite_name: str
    """Suite to load inside the worker."""
    suites_dir: str
    """Directory of the suite files."""
    env_factory: str = DEFAULT_ENV_FACTORY
    """``"module:attribute"`` of the env factory."""
    episode_timeout_s: float = 600.0
    """Watchdog: an episode running longer than this is killed and recorded as an error [s]."""
    start_timeout_s: float = 600.0
    """A worker that has not built its env after this long stops the sweep [s]."""
    render_mode: str | None = None
    """Passed to the env factory (``"rgb_array"`` to capture video frames)."""


def error_record(job: Job, family: str, message: str, wall_time_s: float = 0.0) -> EpisodeRecord:
    """The record of an episode that raised, hung or lost its worker."""
    s = job.spec
    return EpisodeRecord(
        suite=s.suite,
        task=s.task,
        family=family,
        episode=s.episode,
        seed=s.seed,
        demo_seed=s.demo_seed,
        method=job.method.name,
        snapshot=job.snapshot.sha256,
        status=STATUS_ERROR,
        error=message,
        wall_time_s=wall_time_s,
    )


class EpisodeExecutor:
    """Owns the suite's envs (one per env id, built on first use and reused) and the current
    policy; plays jobs, turning exceptions into error records."""

    def __init__(self, config: WorkerConfig) -> None:
        self.suite: Suite = load_suite(config.suite_name, Path(config.suites_dir))
        self._make_env = resolve(config.env_factory, what="env factory")
        self._render_mode = config.render_mode
        self.envs: dict[str, Any] = {}
        self.env_for(self.suite.env_id)  # fail at start-up, not in the first episode
        self._policy_key: tuple[str, str] | None = None
        self._policy: Policy | None = None

    def env_for(self, env_id: str) -> Any:
        """The env with id ``env_id``, built once."""
        if env_id not in self.envs:
            self.envs[env_id] = self._make_env(
                self.suite, env_id=env_id, render_mode=self._render_mode
            )
        return self.envs[env_id]

    @property
    def env(self) -> Any:
        """The suite's main env."""
        return self.envs[self.suite.env_id]

    def play(
        self, job: Job, on_frame: FrameHook | None = None, extras: dict[str, Any] | None = None
    ) -> EpisodeRecord:
        t0 = time.perf_counter()
        setup = 0.0
        try:
            key = (job.method.name, job.snapshot.sha256)
            if self._policy is None or self._policy_key != key:
                self._policy, self._policy_key = None, None
                self._policy = make_policy(job.method, job.snapshot)
                self._policy_key = key
                setup = time.perf_counter() - t0
            record = run_episode(
                self.env_for(self.suite.env_id_for(job.spec.task)),
                self._policy,
                job.spec,
                self.suite,
                method=job.method.name,
                snapshot=job.snapshot.sha256,
                on_frame=on_frame,
                extras=extras,
            )
            return replace(record, setup_time_s=setup)
        except Exception:  # recorded with its traceback; the sweep goes on
            family = self.suite.task(job.spec.task).family
            return error_record(job, family, traceback.format_exc(), time.perf_counter() - t0)

    def close(self) -> None:
        for env in self.envs.values():
            env.close()


def _worker_main(conn: Connection, config: WorkerConfig) -> None:
    try:
        executor = EpisodeExecutor(config)
    except BaseException as exc:
        conn.send(("fatal", f"{type(exc).__name__}: {exc}", traceback.format_exc()))
        conn.close()
        return
    conn.send(("ready", os.getpid()))
    try:
        while True:
            try:
                message = conn.recv()
            except EOFError:
                break  # the parent was killed: nobody to report to, exit quietly
            if message is None:
                break
            record = executor.play(message)
            try:
                conn.send(("result", record))
            except BrokenPipeError:
                break  # the parent was killed mid-episode; the episode re-runs on resume
    finally:
        executor.close()
        conn.close()


@contextmanager
def _single_threaded_children() -> Iterator[None]:
    """Spawned children inherit the environment: make their BLAS/OpenMP/torch single-threaded."""
    saved = {
        k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
    }
    os.environ.update({k: "1" for k in saved})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _Slot:
    def __init__(self, ctx: Any, config: WorkerConfig) -> None:
        self.conn, child = ctx.Pipe(duplex=True)
        self.process = ctx.Process(target=_worker_main, args=(child, config), daemon=True)
        with _single_threaded_children():
            self.process.start()
        child.close()
        self.ready = False
        self.job: Job | None = None
        self.since = time.monotonic()

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join(timeout=10)
        self.conn.close()


class WorkerPool:
    """Run jobs on ``workers`` processes, calling ``on_result`` in the parent as records arrive."""

    def __init__(self, config: WorkerConfig, workers: int, suite: Suite) -> None:
        if workers < 1:
            raise ValueError("workers must be >= 1")
        self.config = config
        self.workers = workers
        self.suite = suite
        self._ctx = mp.get_context("spawn")
        self.respawns = 0
        self._queue: deque[Job] = deque()
        self.startup_s = 0.0
        """Time from the start of :meth:`run` until every first-generation worker was ready [s]."""

    def _family(self, job: Job) -> str:
        return self.suite.task(job.spec.task).family

    def run(self, jobs: Sequence[Job], on_result: Callable[[EpisodeRecord], None]) -> None:
        queue = deque(jobs)
        self._queue = queue
        t_start = time.monotonic()
        slots = [_Slot(self._ctx, self.config) for _ in range(min(self.workers, len(jobs)))]
        waiting_first = len(slots)
        try:
            while queue or any(s.job is not None for s in slots):
                for slot in slots:
                    self._dispatch(slot)
                now = time.monotonic()
                deadlines = [
                    s.since
                    + (self.config.episode_timeout_s if s.ready else self.config.start_timeout_s)
                    for s in slots
                ]
                timeout = max(0.0, min(min(deadlines) - now, 1.0))
                for conn in wait([s.conn for s in slots], timeout=timeout):
                    index = next(i for i, s in enumerate(slots) if s.conn is conn)
                    was_ready = slots[index].ready
                    slots[index] = self._receive(slots[index], on_result)
                    if (
                        waiting_first
                        and not was_ready
                        and slots[index].ready
                        and self.respawns == 0
                    ):
                        waiting_first -= 1
                        if not waiting_first:
                            self.startup_s = time.monotonic() - t_start
                now = time.monotonic()
                for i, slot in enumerate(slots):
                    if not slot.ready and now > slot.since + self.config.start_timeout_s:
                        raise WorkerStartError(
                            f"a worker did not build its env within "
                            f"{self.config.start_timeout_s:.0f} s; "
                            "check `python -m awda_bench doctor`"
                        )
                    if slot.job is not None and now > slot.since + self.config.episode_timeout_s:
                        on_result(
                            self._lost(
                                slot,
                                f"watchdog: episode exceeded {self.config.episode_timeout_s:g} s; "
                                "worker killed",
                            )
                        )
                        slots[i] = self._respawn(slot)
        finally:
            for slot in slots:
                if slot.process.is_alive():
                    try:
                        slot.conn.send(None)
                    except OSError:
                        pass  # the worker is gone already; kill() below reaps it
            deadline = time.monotonic() + 30
            for slot in slots:
                slot.process.join(timeout=max(0.0, deadline - time.monotonic()))
                slot.kill()

    def _lost(self, slot: _Slot, message: str) -> EpisodeRecord:
        assert slot.job is not None
        return error_record(
            slot.job, self._family(slot.job), message, time.monotonic() - slot.since
        )

    def _dispatch(self, slot: _Slot) -> None:
        """Send the next queued job to ``slot`` if it is ready and idle."""
        if slot.ready and slot.job is None and self._queue:
            slot.job = self._queue.popleft()
            slot.since = time.monotonic()
            slot.conn.send(slot.job)

    def _respawn(self, slot: _Slot) -> _Slot:
        slot.kill()
        self.respawns += 1
        return _Slot(self._ctx, self.config)

    def _receive(self, slot: _Slot, on_result: Callable[[EpisodeRecord], None]) -> _Slot:
        try:
            message = slot.conn.recv()
        except (EOFError, OSError):
            slot.process.join(timeout=5)
            if slot.job is not None:
                on_result(
                    self._lost(
                        slot, f"worker died (exit code {slot.process.exitcode}) during the episode"
                    )
                )
                return self._respawn(slot)
            raise WorkerStartError(
                f"a worker exited (code {slot.process.exitcode}) before building its env"
            ) from None
        kind = message[0]
        if kind == "ready":
            slot.ready = True
            self._dispatch(slot)
        elif kind == "result":
            # hand the worker its next job before storing this result: it plays while we write
            slot.job = None
            self._dispatch(slot)
            on_result(message[1])
        elif kind == "fatal":
            raise WorkerStartError(f"a worker could not build the env: {message[1]}")
        return slot


def run_inline(
    jobs: Sequence[Job], config: WorkerConfig, on_result: Callable[[EpisodeRecord], None]
) -> None:
    """Play jobs in this process (``--workers 0``: debugging; no watchdog)."""
    executor = EpisodeExecutor(config)
    try:
        for job in jobs:
            on_result(executor.play(job))
    finally:
        executor.close()

"""Local workers: spawned processes that each build what they hold once, then play jobs one at a
time and stream results back. The one process pool behind ``run`` (episodes,
:class:`~awda_bench.evaluation.worker_pool.WorkerPool`) and ``collect`` (recording jobs,
:class:`~awda_bench.data.pool.ProcessRunner`); :class:`~awda_bench.execution.ray_pool.RayActorPool`
is the same :class:`~awda_bench.execution.job_pool.JobPool` on Ray actors.

::

    parent                                   worker k (spawned; OMP_NUM_THREADS=1)
      start ------------------------------->   executor = build(config)   (envs built once)
            <----------------------- ("ready", pid)     or ("fatal", message, traceback)
      job --------------------------------->   result = executor.play(job)
            <---------------------- ("result", result)  (the executor turns exceptions inside a
                                                         job into an error result)
      ... the next job is sent before on_result(result) runs: the worker plays while we write;
          on_result may return follow-up jobs (collect: a unit's next attempts)
      ... watchdog: a job older than job_timeout_s(job) -> kill worker, lost(job) result, respawn
      None -------------------------------->   executor.close(), exit

Workers are spawned from this interpreter, or, when :attr:`ProcessPool.python` names another
(a suite whose simulator needs an environment of its own, :mod:`awda_bench.runtimes`), started
from that one (:mod:`awda_bench.execution.interpreter_process`); the conversation
(:mod:`awda_bench.execution.worker_loop`) is the same.

A worker that dies mid-job is replaced and the job ends as ``lost(job, ...)``; a worker that
cannot build its executor, or does not within ``start_timeout_s``, stops the run
(:class:`~awda_bench.execution.job_pool.WorkerStartError`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from multiprocessing.connection import Connection, wait
from typing import Any, ClassVar

from awda_bench.execution.interpreter_process import start_in_interpreter
from awda_bench.execution.job_pool import THREAD_VARS, Executor, J, JobPool, R, WorkerStartError
from awda_bench.execution.worker_loop import serve_jobs


@contextmanager
def single_threaded_children() -> Iterator[None]:
    """Spawned children inherit the environment: make their BLAS/OpenMP/torch single-threaded."""
    saved = {k: os.environ.get(k) for k in THREAD_VARS}
    os.environ.update({k: "1" for k in saved})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def spawn_here(build: Callable[[Any], Executor], config: Any) -> tuple[Connection, Any]:
    """A worker spawned from this interpreter (``multiprocessing``'s spawn context): its end of
    the pipe and its process."""
    ctx = mp.get_context("spawn")
    conn, child = ctx.Pipe(duplex=True)
    process = ctx.Process(target=serve_jobs, args=(child, build, config), daemon=True)
    with single_threaded_children():
        process.start()
    child.close()
    return conn, process


class _Slot:
    """One worker process as the parent tracks it."""

    def __init__(self, conn: Connection, process: Any) -> None:
        self.conn = conn
        self.process: Any = process
        """A ``multiprocessing`` process, or an
        :class:`~awda_bench.execution.interpreter_process.InterpreterProcess` (the same methods)."""
        self.ready = False
        self.job: Any = None
        self.since = time.monotonic()

    def kill(self) -> None:
        if self.process.is_alive():
            self.process.kill()
        self.process.join(timeout=10)
        self.conn.close()


class ProcessPool(JobPool[J, R]):
    """Run jobs on ``workers`` spawned processes, each holding ``build(config)`` (a picklable
    executor class or factory); ``on_result`` gets one result per job in the parent, in arrival
    order, and may return follow-up jobs (see :class:`~awda_bench.execution.job_pool.JobPool`).
    :attr:`startup_s` runs from the start of :meth:`run`.
    """

    worker_noun: ClassVar[str] = "worker"
    """What messages call a worker (``a worker did not build its env``)."""
    job_noun: ClassVar[str] = "episode"
    """What messages call a job (``watchdog: episode exceeded 600 s``)."""

    _queue: deque[J]

    python: str | None = None
    """Interpreter the workers start from (another virtual environment's ``bin/python``, see
    :mod:`awda_bench.runtimes`); ``None``: spawned from this one."""

    def _spawn(self) -> _Slot:
        if self.python is None:
            return _Slot(*spawn_here(self.build, self.config))
        conn, process = start_in_interpreter(self.python, self.build, self.config)
        return _Slot(conn, process)

    def _deadline(self, slot: _Slot) -> float:
        """When the watchdog (a job) or the start-up limit (no job yet) ends ``slot``'s wait."""
        if not slot.ready:
            return slot.since + self.start_timeout_s
        if slot.job is not None:
            return slot.since + self.job_timeout_s(slot.job)
        return float("inf")

    def run(self, jobs: Sequence[J], on_result: Callable[[R], Iterable[J] | None]) -> None:
        """Play every job (and every follow-up job ``on_result`` returns) once."""
        self._queue = deque(jobs)
        t_start = time.monotonic()
        slots = [self._spawn() for _ in range(min(self.workers, len(jobs)))]
        waiting_first = len(slots)
        try:
            while self._queue or any(s.job is not None for s in slots):
                for slot in slots:
                    self._dispatch(slot)
                now = time.monotonic()
                next_deadline = min((self._deadline(s) for s in slots), default=now)
                timeout = max(0.0, min(next_deadline - now, 1.0))
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
                    if not slot.ready and now > slot.since + self.start_timeout_s:
                        raise WorkerStartError(
                            f"a {self.worker_noun} did not build its env within "
                            f"{self.start_timeout_s:.0f} s; check `python -m awda_bench doctor`"
                        )
                    if slot.job is not None and now > self._deadline(slot):
                        limit = self.job_timeout_s(slot.job)
                        message = f"watchdog: {self.job_noun} exceeded {limit:g} s; worker killed"
                        self._give_up(slot, message, self._queue, on_result)
                        slots[i] = self._respawn(slot)
        finally:
            for slot in slots:
                if slot.job is not None:  # leaving on an error or a signal mid-job: the result
                    slot.kill()  # has nowhere to go (the job is re-played on resume)
                elif slot.process.is_alive():
                    try:
                        slot.conn.send(None)
                    except OSError:
                        pass  # the worker is gone already; kill() below reaps it
            deadline = time.monotonic() + 30
            for slot in slots:
                slot.process.join(timeout=max(0.0, deadline - time.monotonic()))
                slot.kill()

    def _dispatch(self, slot: _Slot) -> None:
        """Send the next queued job to ``slot`` if it is ready and idle."""
        if slot.ready and slot.job is None and self._queue:
            slot.job = self._queue.popleft()
            slot.since = time.monotonic()
            slot.conn.send(slot.job)

    def _respawn(self, slot: _Slot) -> _Slot:
        slot.kill()
        self.respawns += 1
        return self._spawn()

    def _receive(self, slot: _Slot, on_result: Callable[[R], Iterable[J] | None]) -> _Slot:
        try:
            message = slot.conn.recv()
        except (EOFError, OSError):
            slot.process.join(timeout=5)
            if slot.job is not None:
                died = f"worker died (exit code {slot.process.exitcode}) during the episode"
                self._give_up(slot, died, self._queue, on_result)
                return self._respawn(slot)
            raise WorkerStartError(
                f"a {self.worker_noun} exited (code {slot.process.exitcode}) before building its "
                "env"
            ) from None
        kind = message[0]
        if kind == "ready":
            slot.ready = True
            self._dispatch(slot)
        elif kind == "result":
            # hand the worker its next job before handling this result: it plays while we write
            slot.job = None
            self._dispatch(slot)
            self._queue.extend(on_result(message[1]) or ())
        elif kind == "fatal":
            raise WorkerStartError(f"a {self.worker_noun} could not build the env: {message[1]}")
        return slot

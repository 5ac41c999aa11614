"""What every worker pool shares, local processes (:mod:`.process_pool`) or Ray actors
(:mod:`.ray_pool`): jobs in, one result per job handed to a callback on the calling side.

A pool runs ``workers`` workers, each holding ``build(config)`` (an :class:`Executor`: built
once, plays jobs, closes its envs). ``on_result(result)`` runs where the pool was started, in
arrival order, and may return follow-up jobs (collect: a unit's next attempts). A job the pool
gives up on (its watchdog, ``job_timeout_s(job)``, ended it, or its worker was lost) ends as
``lost(job, message, elapsed_s)``. A worker that cannot build its executor stops the run
(:class:`WorkerStartError`), because every job would fail the same way.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Generic, Protocol, TypeVar

from awda_bench.errors import AwdaError

THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
"""Environment variables set to 1 in every worker (one core each: BLAS, OpenMP, torch)."""

J = TypeVar("J")
"""A job type."""
R = TypeVar("R")
"""A result type."""
_J_in = TypeVar("_J_in", contravariant=True)
_R_out = TypeVar("_R_out", covariant=True)


class WorkerStartError(AwdaError):
    """A worker could not build its env (renderer, missing env package, ...)."""

    exit_code = 3


class Executor(Protocol[_J_in, _R_out]):
    """What a worker holds: built once from a config, plays jobs, closes its envs."""

    def play(self, job: _J_in) -> _R_out: ...

    def close(self) -> None: ...


class JobPool(Generic[J, R]):
    """The settings and counters of a pool; :meth:`run` is the backend's."""

    def __init__(
        self,
        build: Callable[[Any], Executor[J, R]],
        config: Any,
        workers: int,
        *,
        lost: Callable[[J, str, float], R],
        job_timeout_s: Callable[[J], float],
        start_timeout_s: float = 600.0,
    ) -> None:
        if workers < 1:
            raise ValueError("workers must be >= 1")
        self.build = build
        self.config = config
        self.workers = workers
        self.lost = lost
        self.job_timeout_s = job_timeout_s
        self.start_timeout_s = start_timeout_s
        self.respawns = 0
        """Workers replaced after a hang or a loss."""
        self.startup_s = 0.0
        """Time until every first-generation worker had built its executor [s]."""

    def run(self, jobs: Sequence[J], on_result: Callable[[R], Iterable[J] | None]) -> None:
        """Play every job (and every follow-up job ``on_result`` returns) once."""
        raise NotImplementedError

    def _give_up(
        self, slot: Any, message: str, queue: deque[J], on_result: Callable[[R], Iterable[J] | None]
    ) -> None:
        """Hand on the ``lost`` result of ``slot.job`` (played since ``slot.since``, monotonic
        clock) and queue what follows it."""
        result = self.lost(slot.job, message, time.monotonic() - slot.since)
        queue.extend(on_result(result) or ())

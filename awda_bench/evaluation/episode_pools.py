"""Where a sweep's episodes are played: the evaluation's pool on each execution backend
(:mod:`awda_bench.execution.backends`).

========  ==============================================  =====================================
backend   workers                                         pool
========  ==============================================  =====================================
local     ``--workers`` processes on this machine         :class:`~.worker_pool.WorkerPool`
ray       ``--workers`` Ray actors: a private local Ray   :class:`RayWorkerPool`
          instance, or a cluster (``--ray-address``)
========  ==============================================  =====================================

Both take the same pre-seeded jobs and call ``on_result`` on the driver once per job, so the
single store writer, resume, de-duplication, error records and the watchdog mean the same.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Protocol

from awda_bench.evaluation.episode_record import EpisodeRecord
from awda_bench.evaluation.worker_pool import (
    EpisodeExecutor,
    Job,
    WorkerConfig,
    WorkerPool,
    pool_settings,
)
from awda_bench.execution.backends import check_backend
from awda_bench.execution.ray_pool import RayActorPool
from awda_bench.runtimes import worker_python
from awda_bench.suites import Suite


class EpisodePool(Protocol):
    """What a backend's pool offers a sweep."""

    respawns: int
    """Workers replaced after a hang or crash."""
    startup_s: float
    """Time until every first worker had built its env [s]."""

    def run(self, jobs: Sequence[Job], on_result: Callable[[EpisodeRecord], None]) -> None:
        """Play every job; call ``on_result`` once per job on the calling thread."""
        ...


class RayWorkerPool(RayActorPool[Job, EpisodeRecord]):
    """The evaluation pool on Ray: actors hold an :class:`EpisodeExecutor` (one env per env id,
    the policy cached per snapshot), exactly like a local worker; same interface as
    :class:`~awda_bench.evaluation.worker_pool.WorkerPool`."""

    def __init__(
        self, config: WorkerConfig, workers: int, suite: Suite, *, address: str | None = None
    ) -> None:
        self.suite = suite
        settings = pool_settings(config, suite)
        python = worker_python(suite.simulator)  # Meta-World: its own environment's interpreter
        super().__init__(
            EpisodeExecutor, config, workers, address=address, python=python, **settings
        )


@contextmanager
def open_pool(
    backend: str,
    config: WorkerConfig,
    workers: int,
    suite: Suite,
    *,
    ray_address: str | None = None,
) -> Iterator[EpisodePool]:
    """The pool of ``backend``, ready to :meth:`~EpisodePool.run`; the Ray backend starts (or
    joins) Ray here and shuts a Ray instance it started down on exit."""
    check_backend(backend, workers, ray_address)
    if backend == "local":
        yield WorkerPool(config, workers, suite)
        return
    with RayWorkerPool(config, workers, suite, address=ray_address) as pool:
        yield pool

"""Execution backends: where a sweep's episodes are played. One place to pick one, for every
command that schedules episodes.

========  ==============================================  =====================================
backend   workers                                         pool
========  ==============================================  =====================================
local     ``--workers`` processes on this machine         :class:`~.worker_pool.WorkerPool`
ray       ``--workers`` Ray actors: a private local Ray   :class:`~.ray_pool.RayWorkerPool`
          instance, or a cluster (``--ray-address``)
========  ==============================================  =====================================

Both take the same pre-seeded jobs and call ``on_result`` on the driver once per job, so the
single store writer, resume, de-duplication, error records and the watchdog mean the same.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Protocol

from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.harness.episode_record import EpisodeRecord
from awda_bench.harness.worker_pool import Job, WorkerConfig, WorkerPool
from awda_bench.suites import Suite

BACKENDS = ("local", "ray")
"""Valid ``--backend`` values; the first is the default."""


DEFAULT_WORKERS = max(1, min(os.cpu_count() or 1, 4))
"""Worker processes (or Ray actors) when ``--workers`` is not given."""


def add_backend_args(parser: argparse.ArgumentParser) -> None:
    """``--workers``, ``--backend``, ``--ray-address``: the same for every scheduling command."""
    parser.add_argument(
        "--workers",
        type=int,
        default=DEFAULT_WORKERS,
        help=f"worker processes (or Ray actors), 0 = in this process (default {DEFAULT_WORKERS})",
    )
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default=BACKENDS[0],
        help="where --workers run: local processes, or Ray actors (a private local Ray instance, "
        "or the cluster at --ray-address; needs the 'ray' extra); default local",
    )
    parser.add_argument(
        "--ray-address",
        metavar="ADDRESS",
        help="join this Ray cluster (HOST:6379, 'auto', ray://HOST:10001) with --backend ray",
    )


class EpisodePool(Protocol):
    """What a backend's pool offers a sweep."""

    respawns: int
    """Workers replaced after a hang or crash."""
    startup_s: float
    """Time until every first worker had built its env [s]."""

    def run(self, jobs: Sequence[Job], on_result: Callable[[EpisodeRecord], None]) -> None:
        """Play every job; call ``on_result`` once per job on the calling thread."""
        ...


def check_backend(backend: str, workers: int, ray_address: str | None) -> None:
    """Refuse a bad backend choice with one line (before anything is started or written)."""
    if backend not in BACKENDS:
        raise UnknownChoiceError("backend", backend, BACKENDS)
    if ray_address is not None and backend != "ray":
        raise UsageError("--ray-address needs --backend ray")
    if backend == "ray":
        from awda_bench.harness.ray_pool import require_ray

        if workers < 1:
            raise UsageError(f"--backend ray needs --workers >= 1 (got {workers})")
        require_ray()


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
    from awda_bench.harness.ray_pool import RayWorkerPool

    with RayWorkerPool(config, workers, suite, address=ray_address) as pool:
        yield pool

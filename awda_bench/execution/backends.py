"""Execution backends: where a command's jobs are played (``run``: episodes, ``collect``:
recordings). One place to pick one, for every command that schedules jobs.

========  ==============================================  =========================================
backend   workers                                         pool
========  ==============================================  =========================================
local     ``--workers`` processes on this machine         :class:`~.process_pool.ProcessPool`
ray       ``--workers`` Ray actors: a private local Ray   :class:`~.ray_pool.RayActorPool`
          instance, or a cluster (``--ray-address``)
========  ==============================================  =========================================

Both take the same pre-seeded jobs and call ``on_result`` on the driver once per job, so the
single store writer, resume, de-duplication, error records and the watchdog mean the same. The
evaluation's pools on each: :mod:`awda_bench.evaluation.episode_pools`; the collection's:
:mod:`awda_bench.data.pool`, :mod:`awda_bench.data.ray_runner`.
"""

from __future__ import annotations

import argparse
import os

from awda_bench.errors import UnknownChoiceError, UsageError

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


def check_backend(backend: str, workers: int, ray_address: str | None) -> None:
    """Refuse a bad backend choice with one line (before anything is started or written)."""
    if backend not in BACKENDS:
        raise UnknownChoiceError("backend", backend, BACKENDS)
    if ray_address is not None and backend != "ray":
        raise UsageError("--ray-address needs --backend ray")
    if backend == "ray":
        from awda_bench.execution.ray_pool import require_ray

        if workers < 1:
            raise UsageError(f"--backend ray needs --workers >= 1 (got {workers})")
        require_ray()

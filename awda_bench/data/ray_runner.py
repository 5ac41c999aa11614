"""``collect --backend ray``: the collection's :class:`~awda_bench.data.pool.JobRunner` on Ray
actors (:class:`~awda_bench.execution.ray_pool.RayActorPool`), each holding a
:class:`~awda_bench.data.pool.RecorderExecutor` exactly like a local collect worker.

Meta-World's actors start from ``.venv-metaworld``'s interpreter (:mod:`awda_bench.runtimes`).
Results (the recorded episode's frames and arrays) travel back to the driver, the only writer of
DATA_DIR, so shards, discards, retries of failed attempts and resume mean what they mean locally.
"""

from __future__ import annotations

from awda_bench.data.config import CollectConfig
from awda_bench.data.plan import CollectJob
from awda_bench.data.pool import JobResult, RecorderExecutor, lost_job_result
from awda_bench.execution.ray_pool import RayActorPool
from awda_bench.runtimes import worker_python


class RayJobRunner(RayActorPool[CollectJob, JobResult]):
    """Record jobs on ``workers`` Ray actors (a private local instance, or ``address``)."""

    def __init__(
        self, config: CollectConfig, simulator: str, workers: int, *, address: str | None = None
    ) -> None:
        """``simulator``: the suite's (its workers' interpreter follows from it)."""
        super().__init__(
            RecorderExecutor,
            config,
            workers,
            lost=lost_job_result,
            job_timeout_s=lambda _job: config.episode_timeout_s,
            address=address,
            python=worker_python(simulator),
        )

"""``collect --backend ray``: the collection's :class:`~awda_bench.data.pool.JobRunner` on Ray
actors (:class:`~awda_bench.harness.ray_pool.RayActorPool`), each holding an
:class:`~awda_bench.data.recorder.EpisodeRecorder` exactly like a local collect worker.

Results (the recorded episode's frames and arrays) travel back to the driver, the only writer of
DATA_DIR, so shards, discards, retries of failed attempts and resume mean what they mean locally.
"""

from __future__ import annotations

from awda_bench.data.config import CollectConfig
from awda_bench.data.plan import CollectJob
from awda_bench.data.pool import JobResult, play
from awda_bench.data.recorder import EpisodeRecorder
from awda_bench.harness.ray_pool import RayActorPool


class RecorderExecutor:
    """What a collect actor holds: a recorder, as a local collect worker holds it. One env is
    built at start-up (a broken renderer stops the collection before any job) and closed: each
    job builds its own fresh env (:func:`awda_bench.data.pool.play`)."""

    def __init__(self, config: CollectConfig) -> None:
        self.recorder = EpisodeRecorder(config)
        self.recorder.env_for(self.recorder.suite.tasks[0].index, "agent")
        self.recorder.close()

    def play(self, job: CollectJob) -> JobResult:
        return play(self.recorder, job)

    def close(self) -> None:
        self.recorder.close()


def _lost(job: CollectJob, message: str, elapsed_s: float) -> JobResult:
    return JobResult(job=job, error=message)


class RayJobRunner(RayActorPool[CollectJob, JobResult]):
    """Record jobs on ``workers`` Ray actors (a private local instance, or ``address``)."""

    def __init__(self, config: CollectConfig, workers: int, *, address: str | None = None) -> None:
        super().__init__(
            RecorderExecutor,
            config,
            workers,
            lost=_lost,
            job_timeout_s=config.episode_timeout_s,
            address=address,
        )

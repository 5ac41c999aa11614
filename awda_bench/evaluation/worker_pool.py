"""Episode workers: processes that each build one env, reuse it, and stream records back.

What a worker holds is an :class:`EpisodeExecutor`; :class:`WorkerPool` runs it on the local
process pool (:mod:`awda_bench.execution.process_pool`, shared with ``collect``)::

    parent                                   worker k (spawned, or started from the suite's own
                                             environment, see awda_bench.runtimes; OMP_NUM_THREADS=1)
      start ------------------------------->   env = make_env(suite)      (once per env id)
            <----------------------- ("ready", pid)
      Job --------------------------------->   policy cached per (method, snapshot)
            <--------------------- ("result", EpisodeRecord)   status ok, or error + traceback
      ... watchdog: a job older than episode_timeout_s -> kill worker, record an error, respawn
      None -------------------------------->   close env, exit

An exception inside an episode becomes an error record and the worker carries on; a worker that
dies or hangs is replaced and its episode recorded as an error; a worker that cannot even build
its env stops the sweep (:class:`~awda_bench.execution.job_pool.WorkerStartError`), because
every episode would fail the same way.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

from awda_bench.episode import EpisodeSpec, Policy
from awda_bench.evaluation.episode_record import STATUS_ERROR, EpisodeRecord
from awda_bench.evaluation.episode_runner import FrameHook, run_episode
from awda_bench.evaluation.methods import MethodSpec, SnapshotRef, make_policy, resolve
from awda_bench.execution.process_pool import ProcessPool
from awda_bench.runtimes import worker_python
from awda_bench.suites import Suite, load_suite

DEFAULT_ENV_FACTORY = "awda_bench.evaluation.env_factory:make_env"
"""``"module:attribute"`` of ``make_env(suite, render_mode=...)``."""


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
                self._close_policy()
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

    def _close_policy(self) -> None:
        """Let go of the current policy, closing it if it has a ``close`` (a served policy's
        connection)."""
        policy, self._policy, self._policy_key = self._policy, None, None
        close = getattr(policy, "close", None)
        if close is not None:
            close()

    def close(self) -> None:
        self._close_policy()
        for env in self.envs.values():
            env.close()


def lost_job_record(suite: Suite, job: Job, message: str, elapsed_s: float) -> EpisodeRecord:
    """The error record of a job a pool gave up on (hung, or its worker lost)."""
    return error_record(job, suite.task(job.spec.task).family, message, elapsed_s)


def pool_settings(config: WorkerConfig, suite: Suite) -> dict[str, Any]:
    """What an evaluation pool (local or Ray) is given besides its :class:`EpisodeExecutor`: the
    record of a lost job, the watchdog's and the start-up limit."""
    return {
        "lost": partial(lost_job_record, suite),
        "job_timeout_s": lambda _job: config.episode_timeout_s,
        "start_timeout_s": config.start_timeout_s,
    }


class WorkerPool(ProcessPool[Job, EpisodeRecord]):
    """Run jobs on ``workers`` processes, each holding an :class:`EpisodeExecutor`, calling
    ``on_result`` in the parent as records arrive."""

    def __init__(self, config: WorkerConfig, workers: int, suite: Suite) -> None:
        self.suite = suite
        super().__init__(EpisodeExecutor, config, workers, **pool_settings(config, suite))
        self.python = worker_python(suite.simulator)


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

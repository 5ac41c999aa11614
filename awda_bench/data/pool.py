"""Collection workers: processes that each build their recorder once and record jobs as they come.

What a worker holds is a :class:`RecorderExecutor`; :class:`ProcessRunner` runs it on the local
process pool the evaluation uses too (:mod:`awda_bench.execution.process_pool`): jobs in, results
out, so another backend (Ray, :mod:`awda_bench.data.ray_runner`) implements :class:`JobRunner` the
same way::

    parent                                  worker k (spawned; OMP_NUM_THREADS=1)
      start ------------------------------>   recorder = make_recorder(config)
            <------------------------- ("ready", pid)
      CollectJob ------------------------->   fresh env; replay the unit's done attempts,
                                              record its next `chunk` successful ones
            <------------------- ("result", JobResult)   episodes, and/or error + traceback
      ... on_result(result) -> follow-up jobs (the unit's next chunk) join the queue
      ... watchdog: a job older than job_timeout_s -> kill worker, error result, respawn
      None ------------------------------->   close envs, exit

Workers of a Meta-World suite start from ``.venv-metaworld``'s interpreter
(:mod:`awda_bench.execution.interpreter_process`) and hold a
:class:`~awda_bench.data.metaworld_recorder.MetaWorldRecorder`; the conversation is the same.
A worker that cannot build its recorder stops the collection
(:class:`~awda_bench.execution.job_pool.WorkerStartError`).
"""

from __future__ import annotations

import traceback
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Protocol

from awda_bench.data.config import CollectConfig
from awda_bench.data.plan import Attempt, CollectJob, make_attempt
from awda_bench.data.recorder import EpisodeData, EpisodeRecorder
from awda_bench.execution.process_pool import ProcessPool
from awda_bench.runtimes import worker_python
from awda_bench.suites import Suite, load_suite


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


class Recorder(Protocol):
    """What a worker records jobs with: :class:`~awda_bench.data.recorder.EpisodeRecorder`
    (ManiSkill) or :class:`~awda_bench.data.metaworld_recorder.MetaWorldRecorder`."""

    config: CollectConfig
    suite: Suite

    def build_env(self, task: int, role: str) -> tuple[Any, dict[str, Any]]: ...

    def env_for(self, task: int, role: str) -> tuple[Any, dict[str, Any]]: ...

    def record(self, env: Any, env_info: dict[str, Any], job: Attempt) -> EpisodeData: ...

    def replay(self, env: Any, job: Attempt) -> None: ...

    def close(self) -> None: ...


def make_recorder(config: CollectConfig) -> Recorder:
    """The recorder of ``config``'s suite's simulator (Meta-World's is imported only here: it
    runs in ``.venv-metaworld`` workers)."""
    if load_suite(config.suite, config.suites_dir).simulator == "metaworld":
        from awda_bench.data.metaworld_recorder import MetaWorldRecorder

        return MetaWorldRecorder(config)
    return EpisodeRecorder(config)


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


def play(recorder: Recorder, job: CollectJob) -> JobResult:
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
        recorder = make_recorder(self.config)
        queue = deque(jobs)
        try:
            while queue:
                queue.extend(on_result(play(recorder, queue.popleft())))
        finally:
            recorder.close()


class RecorderExecutor:
    """What a collect worker (process or Ray actor) holds: a recorder. One env is built at
    start-up (a broken renderer stops the collection before any job) and closed: each job builds
    its own fresh env (:func:`play`)."""

    def __init__(self, config: CollectConfig) -> None:
        self.recorder = make_recorder(config)
        self.recorder.env_for(self.recorder.suite.tasks[0].index, "agent")
        self.recorder.close()

    def play(self, job: CollectJob) -> JobResult:
        return play(self.recorder, job)

    def close(self) -> None:
        self.recorder.close()


def lost_job_result(job: CollectJob, message: str, elapsed_s: float) -> JobResult:
    """The result of a job a pool gave up on (hung, or its worker lost): the unit is left
    unfinished and retried on re-run."""
    return JobResult(job=job, error=message)


class ProcessRunner(ProcessPool[CollectJob, JobResult]):
    """Record jobs on ``workers`` spawned processes (the local backend of ``collect``); a suite
    whose simulator has an environment of its own (Meta-World) gets workers started from that
    environment's interpreter (:mod:`awda_bench.runtimes`)."""

    worker_noun = "collect worker"
    job_noun = "job"

    def __init__(
        self, config: CollectConfig, simulator: str, workers: int, start_timeout_s: float = 600.0
    ) -> None:
        """``simulator``: the suite's (its workers' interpreter follows from it)."""
        super().__init__(
            RecorderExecutor,
            config,
            workers,
            lost=lost_job_result,
            job_timeout_s=partial(job_timeout_s, config),
            start_timeout_s=start_timeout_s,
        )
        self.python = worker_python(simulator)

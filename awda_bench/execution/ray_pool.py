"""Workers as Ray actors: the local pool's interface (:mod:`awda_bench.execution.process_pool`:
jobs in, results streamed to a callback on the driver) on one machine or a cluster.
:class:`RayActorPool` schedules any job type;
:class:`~awda_bench.evaluation.episode_pools.RayWorkerPool` is the evaluation pool
(``run --backend ray``), and :mod:`awda_bench.data.ray_runner` the collection one
(``collect --backend ray``).

::

    driver (the only writer)                       actor k (num_cpus=1, OMP_NUM_THREADS=1)
      ray.init(address) --- a private local instance, or a cluster (`ray start --head`)
      PoolActor.remote(build, config) ---------->   holds nothing yet
      start() --------------------------------->   executor = build(config): what a local
            <------------- ("ready", pid, host)      worker holds (run: one env per env id, reused)
      play(job) ------------------------------->   result = executor.play(job)
            <-------------------------------- result  (an exception inside is the executor's to
                                                       turn into an error result)
      ... the next job is sent before on_result(result) runs: the actor plays while we write;
          on_result may return follow-up jobs (collect: a unit's next attempts)
      watchdog: a job older than job_timeout_s -> ray.kill(actor), lost(job) result, new actor
      actor or its node lost mid-job -> the job is queued again (at most LOST_WORKER_RETRIES
                                        times, then a lost(job) result), a new actor is started

Differences from the local pool, and why:

- A worker lost mid-job (killed process, lost node) re-queues the job instead of recording an
  error: on a cluster losing a node is not the episode's fault. A job that takes its worker down
  :data:`LOST_WORKER_RETRIES` + 1 times (a simulator that segfaults on that scene) ends as an
  error result, so a run always ends. Each job gets exactly one result per invocation: from the
  actor that finished it or from the driver (watchdog, retries spent), never both, because an
  actor is killed before its job is queued again or given up.
- An actor that Ray cannot place (a cluster with fewer free CPUs than ``workers``) waits, and one
  that dies while starting is replaced if another actor has started; the run stops with
  :class:`~awda_bench.execution.job_pool.WorkerStartError` when an actor reports that it cannot
  build its envs, or when *no* actor has started (within ``start_timeout_s``, or at all).

Ray is an optional extra (``pip install -e '.[ray]'``); without it :func:`require_ray` raises a
one-line :class:`~awda_bench.errors.MissingExtraError`.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import sys
import threading
import time
import traceback
from collections import Counter, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from awda_bench.errors import MissingExtraError, UsageError
from awda_bench.execution.interpreter_process import CODE_ROOT, child_pythonpath
from awda_bench.execution.job_pool import THREAD_VARS, Executor, J, JobPool, R, WorkerStartError
from awda_bench.runtimes import check_worker_ray

RAY_INSTALL_HINT = "pip install -e '.[ray]'"
"""How to install the extra (printed when Ray is missing)."""

LOST_WORKER_RETRIES = 2
"""A job whose worker is lost is queued again at most this many times, then ends as an error
(the local pools record the error at once)."""

LOCAL_OBJECT_STORE_BYTES = 128 * 1024**2
"""Object store of a private local Ray instance [bytes]: results are small (a record: a few kB;
a collected episode: a few MB, passed on at once); Ray's default (30 % of memory) would reserve
shared memory for nothing."""

REACH_TIMEOUT_S = 10.0
"""A ``HOST:PORT`` cluster address that accepts no TCP connection within this long is refused at
once (Ray itself would retry for minutes) [s]."""

AUTH_HINT = (
    "a cluster with token authentication (on by default in recent Ray) also needs RAY_AUTH_MODE=token "
    "and its token (RAY_AUTH_TOKEN, or ~/.ray/auth_token from `ray get-auth-token`)"
)
"""Printed when joining a cluster fails."""

CLOSE_TIMEOUT_S = 30.0
"""Time actors get to close their envs at the end of a run before they are killed [s]."""

INIT_TIMEOUT_S = 300.0
"""``ray.init`` that has not returned within this long is given up with a one-line error
(``AWDA_RAY_INIT_TIMEOUT_S`` overrides it) [s]. A private instance starts in ~6 s on the 2-core
machine under load; once, under a CI run and a collection together, its raylet never reached its
GCS and ``ray.init`` waited without end (a test hung 15+ minutes)."""


class _InitTimeout(Exception):
    """Raised in the main thread by :func:`init_within`'s alarm."""


def init_within(ray: ModuleType, kwargs: dict[str, Any], timeout_s: float) -> None:
    """``ray.init(**kwargs)``, interrupted by ``SIGALRM`` after ``timeout_s`` (a one-line
    :class:`UsageError`). Only the main thread can take the alarm; elsewhere (a caller's thread)
    the call is not bounded. Not done in a helper thread: Ray started from a thread that is not
    the main one loses its GCS connection after 60 s (measured with Ray 2.60)."""
    if threading.current_thread() is not threading.main_thread() or timeout_s <= 0:
        ray.init(**kwargs)
        return

    def alarm(_signum: int, _frame: Any) -> None:
        raise _InitTimeout

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        ray.init(**kwargs)
    except _InitTimeout:
        if ray.is_initialized():
            ray.shutdown()
        raise UsageError(
            f"Ray did not start within {timeout_s:g} s (its processes may be stuck: run "
            "`ray stop`, then try again; AWDA_RAY_INIT_TIMEOUT_S sets the limit)"
        ) from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def check_reachable(address: str) -> None:
    """Refuse a ``[ray://]HOST:PORT`` address that accepts no TCP connection (``"auto"`` and
    other forms are left to Ray)."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=REACH_TIMEOUT_S).close()
    except OSError as exc:
        raise UsageError(
            f"cannot reach the Ray cluster at {address} ({exc.strerror or exc}); start its head "
            "with `ray start --head` or fix --ray-address"
        ) from exc


def require_ray() -> ModuleType:
    """The ``ray`` module; a one-line :class:`MissingExtraError` with the install hint if absent."""
    try:
        import ray
    except ImportError as exc:
        raise MissingExtraError(
            f"--backend ray needs Ray, which is not installed: {RAY_INSTALL_HINT} "
            "(or use --backend local)"
        ) from exc
    return ray


def interpreter_runtime_env(python: str) -> dict[str, Any]:
    """Ray's per-actor runtime environment for actors started from ``python`` (another virtual
    environment's interpreter): that executable, this checkout first on ``PYTHONPATH`` and one
    thread per BLAS/OpenMP pool, as :func:`~awda_bench.execution.interpreter_process.child_environment`
    gives a local worker started from it."""
    env_vars = {name: "1" for name in THREAD_VARS}
    env_vars["PYTHONPATH"] = child_pythonpath()
    return {"py_executable": python, "env_vars": env_vars}


class PoolActor:
    """One Ray actor: ``build(config)`` (an executor class or factory, importable by the actor).

    Made with the driver's ``sys.path`` so it imports what the driver can (as a spawned local
    worker does); on a cluster every node needs the project at the same path.
    """

    def __init__(self, build: Callable[[Any], Executor], config: Any, sys_path: Sequence[str]):
        missing = [p for p in sys_path if p and p not in sys.path and os.path.isdir(p)]
        sys.path[:0] = missing
        for name in THREAD_VARS:
            os.environ[name] = "1"  # before torch/numpy are imported by the env or the policy
        self._build = build
        self._config = config
        self._executor: Executor | None = None

    def start(self) -> tuple[str, Any, str]:
        """Build the executor: ``("ready", pid, host)``, or ``("fatal", message, traceback)``."""
        try:
            self._executor = self._build(self._config)
        except BaseException as exc:  # reported to the driver, which stops the run
            return ("fatal", f"{type(exc).__name__}: {exc}", traceback.format_exc())
        return ("ready", os.getpid(), socket.gethostname())

    def play(self, job: Any) -> Any:
        assert self._executor is not None, "start() first"
        return self._executor.play(job)

    def close(self) -> None:
        if self._executor is not None:
            self._executor.close()
            self._executor = None


@dataclass
class _Slot:
    """One actor as the driver tracks it."""

    handle: Any
    """The actor handle."""
    ref: Any
    """The call in flight (``start`` or ``play``), an ``ObjectRef``; ``None`` when idle."""
    since: float
    """When the call in flight was made (``time.monotonic()``) [s]."""
    first_generation: bool
    """Started with the run (counts towards :attr:`RayActorPool.startup_s`)."""
    ready: bool = False
    """``start`` returned: the actor holds its envs."""
    job: Any = None
    """The job being played."""
    pid: int | None = None
    """The actor's process id (once ready)."""


class RayActorPool(JobPool[J, R]):
    """Run jobs on ``workers`` Ray actors, each holding ``build(config)``; ``on_result`` gets one
    result per job on the driver, in arrival order (see :class:`~awda_bench.execution.job_pool.JobPool`).

    ``lost(job, message, elapsed_s)`` makes the error result of a job the watchdog ended or whose
    workers kept dying. ``address=None`` starts a private local Ray instance
    (``ray.init(address="local")``, ``max(workers, cpu_count)`` CPUs); otherwise the pool joins the
    cluster at ``address`` (``"auto"``, ``"HOST:6379"``, ``"ray://HOST:10001"``). If Ray is
    already initialized in this process it is used as it is. A Ray instance the pool started is
    shut down by :meth:`close`. ``settings``: :class:`~awda_bench.execution.job_pool.JobPool`'s
    (``lost``, ``job_timeout_s``, ``start_timeout_s``).
    """

    def __init__(
        self,
        build: Callable[[Any], Executor[J, R]],
        config: Any,
        workers: int,
        *,
        address: str | None = None,
        python: str | None = None,
        **settings: Any,
    ) -> None:
        super().__init__(build, config, workers, **settings)
        self._ray = require_ray()
        self.address = address
        self.python = python
        """Another environment's interpreter the actors start from (Ray's per-actor
        ``py_executable``: Meta-World's ``.venv-metaworld``), or ``None`` for the driver's."""
        if python is not None:
            check_worker_ray(python, self._ray.__version__)
        self.requeued = 0
        """Jobs queued again because their actor was lost."""
        self.connect_s = 0.0
        """Time to start or join Ray [s] (part of :attr:`startup_s`, which here counts connecting
        too)."""
        self._owns_ray = False
        self._actor_cls: Any = None
        self._slots: list[_Slot] = []
        self._connect()

    # --- Ray instance --------------------------------------------------------------------------

    def _connect(self) -> None:
        ray = self._ray
        t0 = time.perf_counter()
        if not ray.is_initialized():
            kwargs: dict[str, Any] = dict(logging_level=logging.WARNING, log_to_driver=True)
            if self.address is None:
                kwargs.update(
                    address="local",
                    num_cpus=max(self.workers, os.cpu_count() or 1),
                    include_dashboard=False,
                    object_store_memory=LOCAL_OBJECT_STORE_BYTES,
                )
            else:
                check_reachable(self.address)
                kwargs.update(address=self.address)
            try:
                init_within(
                    ray, kwargs, float(os.environ.get("AWDA_RAY_INIT_TIMEOUT_S", INIT_TIMEOUT_S))
                )
            except (ConnectionError, ValueError, RuntimeError) as exc:
                where = "a private local instance" if self.address is None else self.address
                first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
                hint = "" if self.address is None else f"; {AUTH_HINT}"
                raise UsageError(f"cannot start or join Ray at {where}: {first}{hint}") from exc
            self._owns_ray = True
        self._actor_cls = ray.remote(num_cpus=1, max_restarts=0)(PoolActor)
        self.connect_s = time.perf_counter() - t0

    def close(self) -> None:
        """Shut down the Ray instance this pool started (a joined cluster stays up)."""
        if self._owns_ray and self._ray.is_initialized():
            self._ray.shutdown()
        self._owns_ray = False

    def __enter__(self) -> RayActorPool[J, R]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def pids(self) -> list[int]:
        """Process ids of the ready actors of the current :meth:`run` (tests, fault drills)."""
        return [s.pid for s in self._slots if s.ready and s.pid is not None]

    # --- scheduling ----------------------------------------------------------------------------

    def _spawn(self, first_generation: bool) -> _Slot:
        if self.python is None:
            handle = self._actor_cls.remote(self.build, self.config, list(sys.path))
        else:  # the driver's sys.path would import this environment's packages: the code alone
            actor = self._actor_cls.options(runtime_env=interpreter_runtime_env(self.python))
            handle = actor.remote(self.build, self.config, [CODE_ROOT])
        return _Slot(handle, handle.start.remote(), time.monotonic(), first_generation)

    def _respawn(self, slot: _Slot) -> _Slot:
        self._ray.kill(slot.handle, no_restart=True)
        self.respawns += 1
        return self._spawn(first_generation=False)

    def _dispatch(self, slot: _Slot, queue: deque[J]) -> None:
        """Hand ``slot`` the next queued job if it is ready and idle."""
        if slot.ready and slot.job is None and queue:
            slot.job = queue.popleft()
            slot.since = time.monotonic()
            slot.ref = slot.handle.play.remote(slot.job)

    def run(self, jobs: Sequence[J], on_result: Callable[[R], Iterable[J] | None]) -> None:
        """Play every job (and every follow-up job ``on_result`` returns) once."""
        ray = self._ray
        t_start = time.monotonic() - self.connect_s
        queue: deque[J] = deque(jobs)
        losses: Counter[int] = Counter()  # by id(job): a lost job is queued again as is
        slots = [self._spawn(first_generation=True) for _ in range(min(self.workers, len(jobs)))]
        self._slots = slots
        waiting_first = len(slots)
        try:
            while queue or any(s.job is not None for s in slots):
                for slot in slots:
                    self._dispatch(slot, queue)
                now = time.monotonic()
                deadlines = [
                    s.since + (self.job_timeout_s(s.job) if s.ready else self.start_timeout_s)
                    for s in slots
                    if s.ref is not None
                ]
                timeout = max(0.0, min(min(deadlines, default=now + 1.0) - now, 1.0))
                in_flight = [s.ref for s in slots if s.ref is not None]
                done, _ = ray.wait(in_flight, num_returns=1, timeout=timeout)
                for ref in done:
                    index = next(i for i, s in enumerate(slots) if s.ref is ref)
                    slot = slots[index]
                    slot.ref = None
                    was_ready = slot.ready
                    slots[index] = self._receive(slot, ref, queue, losses, on_result)
                    if waiting_first and slot.first_generation and not was_ready and slot.ready:
                        waiting_first -= 1
                        if not waiting_first:
                            self.startup_s = time.monotonic() - t_start
                now = time.monotonic()
                starting = [s for s in slots if not s.ready]
                if starting and len(starting) == len(slots):
                    if now > min(s.since for s in starting) + self.start_timeout_s:
                        raise WorkerStartError(
                            f"no Ray actor started within {self.start_timeout_s:.0f} s "
                            f"(free resources: {ray.available_resources()}); check "
                            "`python -m awda_bench doctor` on the nodes"
                        )
                for i, slot in enumerate(slots):
                    limit = None if slot.job is None else self.job_timeout_s(slot.job)
                    if limit is not None and now > slot.since + limit:
                        message = f"watchdog: episode exceeded {limit:g} s; worker killed"
                        self._give_up(slot, message, queue, on_result)
                        slots[i] = self._respawn(slot)
        finally:
            if waiting_first:
                self.startup_s = time.monotonic() - t_start
            self._stop(slots)

    def _receive(
        self,
        slot: _Slot,
        ref: Any,
        queue: deque[J],
        losses: Counter[int],
        on_result: Callable[[R], Iterable[J] | None],
    ) -> _Slot:
        exceptions = self._ray.exceptions
        try:
            value = self._ray.get(ref)
        except exceptions.RayTaskError as exc:
            # raised past the executor's own handler (SystemExit, ...): an error, kept
            if slot.job is None:
                raise WorkerStartError(f"a Ray actor failed while starting: {exc}") from exc
            self._give_up(slot, f"worker raised outside the episode:\n{exc}", queue, on_result)
            return self._respawn(slot)
        except exceptions.RayError as exc:  # the actor's process or node is gone
            if slot.job is None:
                if not any(s.ready for s in self._slots):  # nothing works: stop the run
                    raise WorkerStartError(
                        f"a Ray actor died before building its env ({type(exc).__name__})"
                    ) from exc
                print(  # others built theirs: a lost node, not a broken set-up
                    f"warning: a Ray actor died while starting ({type(exc).__name__}); "
                    "starting another",
                    file=sys.stderr,
                )
                return self._respawn(slot)
            losses[id(slot.job)] += 1
            lost = losses[id(slot.job)]
            if lost > LOST_WORKER_RETRIES:
                message = (
                    f"worker lost {lost} times during this episode (last: {type(exc).__name__})"
                )
                self._give_up(slot, message, queue, on_result)
            else:
                print(
                    f"warning: a Ray worker was lost ({type(exc).__name__}); its episode is "
                    "queued again",
                    file=sys.stderr,
                )
                queue.appendleft(slot.job)
                self.requeued += 1
            return self._respawn(slot)
        if not slot.ready:
            if value[0] == "fatal":
                raise WorkerStartError(f"a worker could not build the env: {value[1]}")
            slot.ready, slot.pid = True, int(value[1])
            self._dispatch(slot, queue)
            return slot
        # hand the actor its next job before this result is handled: it plays while we write
        slot.job = None
        self._dispatch(slot, queue)
        queue.extend(on_result(value) or ())
        return slot

    def _stop(self, slots: list[_Slot]) -> None:
        """Let ready, idle actors close their envs; kill them all."""
        ray = self._ray
        closing = [s.handle.close.remote() for s in slots if s.ready and s.job is None]
        if closing:
            ray.wait(closing, num_returns=len(closing), timeout=CLOSE_TIMEOUT_S)
        for slot in slots:
            ray.kill(slot.handle, no_restart=True)

"""A sweep: every pending episode of (suite, method, snapshots) played and stored.

Order of work, so that bad input never touches the store::

    load suite -> protocol + episode specs -> method -> snapshots (each loaded once)
    -> open store, check protocol            (all of the above may refuse; nothing written yet)
    -> plan (protocol, snapshots, run row) -> skip finished (status ok) -> workers -> record each
"""

from __future__ import annotations

import sys
import time
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path

from tqdm import tqdm

from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.evaluation.episode_pools import EpisodePool, open_pool
from awda_bench.evaluation.episode_record import STATUS_OK, EpisodeRecord
from awda_bench.evaluation.episode_specs import EvalProtocol, build_episode_specs, make_protocol
from awda_bench.evaluation.methods import (
    REMOTE_METHOD,
    MethodSpec,
    SnapshotRef,
    get_method,
    method_names,
    select_snapshots,
    served_method,
)
from awda_bench.evaluation.results_store import ResultsStore
from awda_bench.evaluation.worker_pool import (
    DEFAULT_ENV_FACTORY,
    Job,
    WorkerConfig,
    run_inline,
)
from awda_bench.execution.backends import BACKENDS, check_backend
from awda_bench.metaworld_tasks import check_task_names
from awda_bench.runtimes import (
    check_local_workers,
    software_versions,
    worker_python,
    worker_versions,
)
from awda_bench.serving.protocol import NATIVE, PROTOCOLS
from awda_bench.serving.remote_policy import DEFAULT_TIMEOUT_S
from awda_bench.suites import SIMULATORS, SUITES_DIR, Suite, load_suite


@dataclass(frozen=True)
class SweepConfig:
    """Everything ``python -m awda_bench run`` decides."""

    suite: str
    """Suite name."""
    method: str
    """Method name."""
    out: Path
    """Run directory (holds ``results.sqlite``)."""
    checkpoints: Path | None = None
    """Snapshot directory of a learned method."""
    snapshots: int = 10
    """Evaluate the last this-many snapshots of a learned method."""
    episodes: int | None = None
    """Episodes per evaluation unit; ``None``: the suite's default (paper protocol: 20)."""
    seed: int = 0
    """Base seed of the episode seeds."""
    workers: int = 1
    """Worker processes or Ray actors (0: play in this process, no watchdog; local backend only)."""
    backend: str = BACKENDS[0]
    """Where workers run: ``"local"`` processes or ``"ray"`` actors (see :mod:`awda_bench.execution.backends`)."""
    ray_address: str | None = None
    """Ray cluster to join (``--backend ray``); ``None`` starts a private local Ray instance."""
    tasks: tuple[int, ...] = ()
    """Restrict this invocation to these evaluated tasks (the protocol still covers all)."""
    episode_timeout_s: float = 600.0
    """Watchdog limit per episode [s]."""
    suites_dir: Path = SUITES_DIR
    """Where suite files live."""
    env_factory: str = DEFAULT_ENV_FACTORY
    """``"module:attribute"`` of the env factory."""
    progress: bool = True
    """Show a progress bar on stderr."""
    command: str = field(default_factory=lambda: " ".join(sys.argv))
    """The command line, recorded in the store."""
    label: str | None = None
    """Name of the method's rows in the store and tables (``None``: the method's name); tells
    apart checkpoint directories evaluated with the same method (Table S3's columns)."""
    split: str = "test"
    """``test``: the held-out tasks (the protocol); ``train``: the training tasks (fit check)."""
    policy_url: str | None = None
    """``method="remote"``: the policy server's ``ws://HOST:PORT``."""
    policy_timeout_s: float = DEFAULT_TIMEOUT_S
    """``method="remote"``: longest wait for one message from the server [s]."""
    policy_protocol: str = NATIVE
    """``method="remote"``: what the server speaks, ``"awda"`` (``python -m awda_bench serve``)
    or ``"openpi"`` (openpi's websocket policy protocol)."""


@dataclass(frozen=True)
class SweepPlan:
    """A validated sweep, ready to run."""

    suite: Suite
    protocol: EvalProtocol
    method: MethodSpec
    snapshots: tuple[SnapshotRef, ...]
    jobs: tuple[Job, ...]
    """Every episode of the protocol restricted to ``config.tasks``, for every snapshot."""
    expected_per_snapshot: int
    """Episodes the protocol expects per snapshot."""


@dataclass(frozen=True)
class SweepResult:
    planned: int
    """Episodes in the sweep."""
    skipped: int
    """Already finished (status ok) before this invocation."""
    ran: int
    """Played by this invocation."""
    errors: int
    """Of those, recorded as errors."""
    successes: int
    """Of those, successes (success_once)."""
    wall_time_s: float
    """Wall time of the worker phase [s]."""
    episode_time_s: float
    """Sum of the played episodes' own wall times [s]."""
    respawns: int
    """Workers replaced after a hang or crash."""
    startup_s: float = 0.0
    """Part of ``wall_time_s`` until every worker had built its env [s] (0 in-process)."""
    act_time_s: float = 0.0
    """Sum over played episodes of time in ``policy.reset``/``policy.act`` [s]."""
    env_time_s: float = 0.0
    """Sum over played episodes of time in ``env.reset``/``env.step`` [s]."""
    setup_time_s: float = 0.0
    """Sum of policy construction times in the workers [s] (not part of episode time)."""


def sweep_method(config: SweepConfig) -> MethodSpec:
    """``config.method``'s spec (for ``remote``: what the server at ``config.policy_url``
    serves), named ``config.label`` when one is given."""
    if config.policy_protocol not in PROTOCOLS:
        raise UnknownChoiceError("--protocol", config.policy_protocol, PROTOCOLS)
    if config.method == REMOTE_METHOD and config.policy_url is not None:
        if config.policy_timeout_s <= 0:
            raise UsageError(f"--policy-timeout must be positive (got {config.policy_timeout_s})")
        method = served_method(config.policy_url, config.policy_timeout_s, config.policy_protocol)
    elif config.policy_url is not None:
        raise UsageError(
            f"--policy-url applies to --method {REMOTE_METHOD}, not {config.method!r}; "
            "drop --policy-url or use --method remote"
        )
    elif config.policy_protocol != NATIVE and config.method != REMOTE_METHOD:
        raise UsageError(
            f"--protocol {config.policy_protocol} applies to --method {REMOTE_METHOD} "
            f"--policy-url ws://HOST:PORT, not --method {config.method!r}"
        )
    else:
        method = get_method(config.method)
    if config.label is None or config.label == method.name:
        return method
    label = config.label.strip()
    if not label or any(c in label for c in "\n\t|"):
        raise UsageError(
            f"--label {config.label!r}: give a non-empty name without |, tabs or newlines"
        )
    if label in method_names():
        raise UsageError(
            f"--label {label!r} is another method's name; choose a name of its own "
            f"(e.g. {config.method}-{label})"
        )
    return replace(method, name=label)


def sweep_protocol(config: SweepConfig, suite: Suite) -> EvalProtocol:
    """The protocol of ``config``: the held-out tasks, or (``split="train"``) the training tasks,
    or just those of ``config.tasks`` among them. A subset is a protocol of its own, so its
    report expects exactly those episodes: a fit check on two training tasks, or one held-out
    MOSAIC family (``reproduce --hold-out drawer`` evaluates the drawer tasks only; its S4 row
    must not count the five other families as missing). The episodes of a subset are those of the
    full protocol (same seeds; a family's variations cycle as before when all of them are
    chosen)."""
    protocol = make_protocol(
        suite, episodes=config.episodes, base_seed=config.seed, split=config.split
    )
    if config.tasks:
        chosen = tuple(t for t in protocol.eval_tasks if t in config.tasks)
        if chosen:
            protocol = replace(protocol, eval_tasks=chosen)
    return protocol


def check_runtime(suite: Suite, config: SweepConfig) -> None:
    """A suite whose workers need an environment of their own (Meta-World): its task names are
    right, the workers are local processes (``--workers 0`` would play in this process, whose
    environment lacks the simulator; Ray actors start from the cluster's), and that environment is
    there (else one line naming ``bash scripts/setup.sh``)."""
    if suite.simulator == "metaworld":
        check_task_names(suite)
    if suite.simulator == SIMULATORS[0]:
        return
    check_local_workers(suite.name, suite.simulator, config.workers, config.backend)
    worker_python(suite.simulator)


def prepare_sweep(config: SweepConfig) -> SweepPlan:
    """Validate the whole sweep; raises a one-line error on bad input and writes nothing."""
    suite = load_suite(config.suite, config.suites_dir)
    protocol = sweep_protocol(config, suite)
    specs = build_episode_specs(suite, protocol)
    for task in config.tasks:
        if task not in protocol.eval_tasks:
            suite.task(task)  # unknown task: lists the valid ones
            raise UsageError(
                f"task {task} of suite {suite.name!r} is not evaluated; "
                f"choose among {list(protocol.eval_tasks)}"
            )
    if config.tasks:
        specs = [s for s in specs if s.task in config.tasks]
    if config.workers < 0:
        raise UsageError(f"--workers must be >= 0 (got {config.workers})")
    check_backend(config.backend, config.workers, config.ray_address)
    check_runtime(suite, config)
    if config.episode_timeout_s <= 0:
        raise UsageError(f"--episode-timeout must be positive (got {config.episode_timeout_s})")
    method = sweep_method(config)
    snapshots = tuple(select_snapshots(method, config.checkpoints, config.snapshots))
    jobs = tuple(Job(spec=s, method=method, snapshot=snap) for snap in snapshots for s in specs)
    expected = len(build_episode_specs(suite, protocol))
    return SweepPlan(suite, protocol, method, snapshots, jobs, expected)


def run_sweep(config: SweepConfig) -> SweepResult:
    """Run every pending episode of the sweep, recording each as it arrives."""
    plan = prepare_sweep(config)
    fingerprint = plan.protocol.fingerprint
    worker_config = WorkerConfig(
        suite_name=plan.suite.name,
        suites_dir=str(config.suites_dir),
        env_factory=config.env_factory,
        episode_timeout_s=config.episode_timeout_s,
    )
    t0 = time.perf_counter()
    # the pool first: a Ray cluster that cannot be reached is refused before the store is touched
    pool_context: AbstractContextManager[EpisodePool | None] = (
        open_pool(
            config.backend,
            worker_config,
            config.workers,
            plan.suite,
            ray_address=config.ray_address,
        )
        if config.workers
        else nullcontext(None)
    )
    with pool_context as pool, ResultsStore(config.out, create=True) as store:
        store.check_protocol(plan.protocol)
        store.plan(
            plan.protocol,
            plan.method.name,
            plan.method.learned,
            plan.snapshots,
            plan.expected_per_snapshot,
            config.command,
            {**software_versions(), **worker_versions(plan.suite.simulator)},
            plan.suite.display_name,
            plan.method.privileged,
        )
        finished = {
            snap.sha256: store.finished_keys(fingerprint, plan.method.name, snap.sha256)
            for snap in plan.snapshots
        }
        pending = [
            j for j in plan.jobs if (j.spec.task, j.spec.episode) not in finished[j.snapshot.sha256]
        ]
        skipped = len(plan.jobs) - len(pending)
        done_ok = store.raw(
            "SELECT COUNT(*), COALESCE(SUM(success_once), 0) FROM episodes "
            "WHERE protocol=? AND method=? AND status='ok'",
            (fingerprint, plan.method.name),
        )[0]
        counts = {"ok": int(done_ok[0]), "success": int(done_ok[1]), "errors": 0, "ran": 0}
        episode_time = 0.0
        inner = {"act": 0.0, "env": 0.0, "setup": 0.0}
        bar = tqdm(
            total=len(plan.jobs),
            initial=skipped,
            disable=not config.progress,
            unit="ep",
            desc=f"{plan.suite.name}/{plan.method.name}",
            dynamic_ncols=True,
        )

        def on_result(record: EpisodeRecord) -> None:
            nonlocal episode_time
            store.record(fingerprint, record)
            counts["ran"] += 1
            episode_time += record.wall_time_s
            inner["act"] += record.act_time_s
            inner["env"] += record.env_time_s
            inner["setup"] += record.setup_time_s
            if record.status == STATUS_OK:
                counts["ok"] += 1
                counts["success"] += int(bool(record.success_once))
            else:
                counts["errors"] += 1
                last = (record.error or "").strip().splitlines()[-1:] or [""]
                bar.write(f"error: task {record.task} episode {record.episode}: {last[0]}")
            rate = counts["success"] / counts["ok"] if counts["ok"] else 0.0
            bar.set_postfix(success=f"{rate:.2f}", errors=counts["errors"], refresh=False)
            bar.update(1)

        respawns, startup = 0, 0.0
        try:
            if pending and pool is None:
                run_inline(pending, worker_config, on_result)
            elif pending and pool is not None:
                pool.run(pending, on_result)
                respawns, startup = pool.respawns, pool.startup_s
        finally:
            bar.close()
        wall = time.perf_counter() - t0
    return SweepResult(
        planned=len(plan.jobs),
        skipped=skipped,
        ran=counts["ran"],
        errors=counts["errors"],
        successes=counts["success"] - int(done_ok[1]),
        wall_time_s=wall,
        episode_time_s=episode_time,
        respawns=respawns,
        startup_s=startup,
        act_time_s=inner["act"],
        env_time_s=inner["env"],
        setup_time_s=inner["setup"],
    )

"""The collection plan: units, seeds and the dataset definition, all fixed before scheduling.

A *unit* is ``(role, task)``; it must end with ``planned`` successful episodes. Attempt ``i`` of a
unit has a seed hashed from ``(suite, base seed, task, i, "collect-<split>-<role>")``
(:func:`awda_bench.episode.derive_seed`), never drawn from a shared generator.
Evaluation hashes the roles ``agent``/``demo``, so collected scenes are independent of evaluated
ones.

Which attempts are kept, and in which env history each is recorded::

    attempts 0, 1, 2, ... of a unit are played in order, each in an env that has played exactly
    the unit's earlier attempts (a job builds a fresh env and replays those unrendered first)
    => the unit holds the successful attempts among the shortest prefix 0..M-1 that contains
       `planned` successes, and `M - planned` attempts are counted as discards

Both the prefix and every recorded frame depend on the seeds only, so 1 or 2 workers, any chunk
size, and a run resumed after a kill record byte-identical episodes (see :class:`CollectJob`).

Splits: pick-and-place (``episode_unit = "task"``) trains on tasks 0-13 and holds out 14-15. For
MOSAIC (``episode_unit = "family"``) the held-out unit is a whole family, so ``train`` collects
every family (a leave-one-family-out training set is a selection of files) and ``test`` the
evaluated tasks, under seeds disjoint from ``train``'s. Meta-World (``episode_unit = "task"``)
trains on its 45 tasks and holds out the suite's five; its units replay nothing (its layouts do
not depend on the env's history, :mod:`awda_bench.data.metaworld_recorder`), and the rule above
holds trivially.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from awda_bench.data.config import ROLE_SYNTHESIZED, CollectConfig, embodiment_of
from awda_bench.episode import derive_seed
from awda_bench.errors import UsageError
from awda_bench.metaworld_tasks import check_task_names
from awda_bench.runtimes import check_local_workers
from awda_bench.suites import Suite, TaskDef, load_suite

FORMAT_VERSION = 1
"""Bumped whenever the layout of the trajectory files or the manifest changes."""

CODE_PATHS: tuple[str, ...] = (
    "envs",
    "experts",
    "robot",
    "primitives",
    "mining.py",
    "demo_recording.py",
    "rollout.py",
    "trajectory.py",
    "data/recorder.py",
    "data/metaworld_recorder.py",
    "data/trajectory_file.py",
    "metaworld",
)
"""Package paths whose source decides what an episode records. Their hash is stamped on every
episode (``code_sha256``) and listed in the manifest, but is not part of the fingerprint: a
collection resumed after a code change is completed (with a warning), and a mixed one shows up in
``dataset info``."""

PACKAGE_DIR = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Attempt:
    """One attempt of one unit: reset ``task``'s env with ``seed`` and play the role."""

    role: str
    """``agent``, ``demonstrator`` or ``synthesized``."""
    task: int
    """Suite-wide task index."""
    attempt: int
    """Attempt index within the unit (0-based)."""
    seed: int
    """Scene seed (``env.reset(seed=seed)``) and the synthesis waypoint generator's seed."""

    @property
    def unit(self) -> tuple[str, int]:
        return (self.role, self.task)

    def identity(self, task: TaskDef, suite: str, split: str) -> dict[str, Any]:
        """What every recorded episode's meta says of whose attempt it is (``task`` is this
        attempt's task in ``suite``)."""
        return {
            "suite": suite,
            "split": split,
            "task": self.task,
            "task_name": task.name,
            "family": task.family,
            "variation": task.reset_task,
            "role": self.role,
            "embodiment": embodiment_of(self.role),
        }


@dataclass(frozen=True)
class CollectJob:
    """Record the next ``chunk`` successful attempts of a unit, in a freshly built env.

    A PhysX scene's history leaks into later episodes (measured: the same seed played first and
    second in one env differs by ~1e-3 rad once the fingers close on an object), so an attempt's
    recording is reproducible only with the same env history. The worker therefore builds a fresh
    env per job and first *replays* (unrendered, ~20x faster than recording) the unit's attempts
    already done, in order: attempt ``i`` is always recorded after exactly attempts ``0..i-1`` of
    its unit, whatever the worker count, the order of units, or a resume after a kill.
    """

    role: str
    task: int
    planned: int
    """Successful episodes the unit must end with."""
    kept: tuple[int, ...]
    """Attempts already kept (shards on disk)."""
    discarded: tuple[int, ...]
    """Attempts already discarded."""
    max_attempts: int
    """The unit gives up (an error) after this many attempts."""
    chunk: int
    """Successful attempts this job records at most (the resume granularity)."""

    @property
    def unit(self) -> tuple[str, int]:
        return (self.role, self.task)


@dataclass(frozen=True)
class Unit:
    """One (role, task) and how many successful episodes it must hold."""

    role: str
    task: int
    family: str
    planned: int

    @property
    def key(self) -> tuple[str, int]:
        return (self.role, self.task)

    @property
    def name(self) -> str:
        """Relative path stem of the unit's files: ``<role>/<family>/task_XX``."""
        return f"{self.role}/{self.family}/task_{self.task:02d}"


def split_tasks(suite: Suite, split: str) -> tuple[TaskDef, ...]:
    """The tasks a split covers (see the module docstring)."""
    if split == "test":
        return suite.eval_tasks
    if suite.episode_unit == "family":
        return suite.tasks
    return suite.train_tasks


def code_sha256() -> str:
    """SHA-256 over the source files listed in :data:`CODE_PATHS` (path and bytes)."""
    digest = hashlib.sha256()
    for rel in CODE_PATHS:
        path = PACKAGE_DIR / rel
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for file in files:
            digest.update(str(file.relative_to(PACKAGE_DIR)).encode())
            digest.update(file.read_bytes())
    return digest.hexdigest()


def job_seed(config: CollectConfig, task: int, attempt: int, role: str) -> int:
    """Seed of attempt ``attempt`` of unit ``(role, task)``."""
    return derive_seed(config.suite, config.seed, task, attempt, f"collect-{config.split}-{role}")


def make_attempt(config: CollectConfig, role: str, task: int, attempt: int) -> Attempt:
    return Attempt(role, task, attempt, job_seed(config, task, attempt, role))


@dataclass(frozen=True)
class CollectPlan:
    """A validated collection: the suite, its units and the dataset definition."""

    suite: Suite
    units: tuple[Unit, ...]
    definition: dict
    """What the data depends on (hashed into :attr:`fingerprint`; stored in the manifest)."""

    @property
    def fingerprint(self) -> str:
        """First 16 hex digits of the SHA-256 of :attr:`definition`'s canonical JSON."""
        blob = json.dumps(self.definition, sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def max_attempts(self, unit: Unit, factor: int) -> int:
        return factor * unit.planned + 10


def check_metaworld_collection(suite: Suite, config: CollectConfig) -> None:
    """What a Meta-World collection refuses before anything runs: task names the package lacks,
    and ``--workers 0`` or Ray (its episodes play in ``.venv-metaworld`` workers)."""
    check_task_names(suite)
    check_local_workers(suite.name, suite.simulator, config.workers, config.backend)


def make_plan(config: CollectConfig) -> CollectPlan:
    """Validate ``config`` against its suite and list the units; writes nothing."""
    suite = load_suite(config.suite, config.suites_dir)
    if suite.simulator == "metaworld":
        check_metaworld_collection(suite, config)
    else:
        from awda_bench.experts import EXPERT_SUITES

        if suite.name not in EXPERT_SUITES:
            raise UsageError(
                f"suite {suite.name!r} has no scripted expert to collect with; "
                f"choose one of: {', '.join((*EXPERT_SUITES, 'metaworld', 'metaworld_ml45'))}"
            )
    tasks = split_tasks(suite, config.split)
    available = [t.index for t in tasks]
    for index in config.tasks:
        if index not in available:
            suite.task(index)  # unknown task: lists the suite's tasks
            raise UsageError(
                f"task {index} is not in the {config.split!r} split of {suite.name!r}; "
                f"choose among {available}"
            )
    if config.tasks:
        tasks = tuple(t for t in tasks if t.index in config.tasks)
    units: list[Unit] = []
    if config.episodes_per_task:
        for task in tasks:
            for role in config.expert_roles:
                units.append(Unit(role, task.index, task.family, config.episodes_per_task))
    if config.synthesize:
        n = len(tasks)
        for j, task in enumerate(tasks):
            count = config.synthesize // n + (1 if j < config.synthesize % n else 0)
            if count:
                units.append(Unit(ROLE_SYNTHESIZED, task.index, task.family, count))
    order = {t.index: i for i, t in enumerate(tasks)}
    units.sort(key=lambda u: (order[u.task], u.role))
    try:
        version = metadata.version("awda_bench")
    except metadata.PackageNotFoundError:
        version = "unknown"
    definition = {
        "format_version": FORMAT_VERSION,
        "suite": suite.name,
        "suite_sha256": suite.file_sha256(),
        "split": config.split,
        "roles": sorted({u.role for u in units}),
        "tasks": [t.index for t in tasks],
        "episodes_per_task": config.episodes_per_task,
        "synthesize": config.synthesize,
        "seed": config.seed,
        "image_size": list(config.frame_size(suite)),
        "depth_size": list(config.depth_size),
        "jpeg_quality": config.jpeg_quality,
        "synthesis": asdict(config.synthesis_config(suite)),
        "horizon_steps": suite.horizon_steps,
        "control_freq_hz": suite.control_freq_hz,
        "awda_bench_version": version,
    }
    definition = json.loads(json.dumps(definition))  # as the manifest will read it back
    return CollectPlan(suite=suite, units=tuple(units), definition=definition)

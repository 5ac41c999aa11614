"""``reproduce``: from an empty directory to Table S3/S4 rows, one resumable command.

::

    OUT/data/train        collect --split train   (agent + demonstrator episodes, synthesized;
                                                   --data DIR: that collection instead)
    OUT/data/test         collect --split test    (validation pairs; pick-place only)
    OUT/checkpoints/COL   train  (one Table S3 column each: snapshots every M steps)
    OUT/runs              run    (last N snapshots x the protocol's episodes, one store, the
                                  column's key as the method label); Full-1 also on two training
                                  tasks ("full-1 (train tasks)") to tell a failure to generalize
                                  from a failure to fit
    OUT/report            report (tables, figures, summary.json) + reproduce.md (scale vs paper)

Every stage is an ordinary command (``collect``, ``train``, ``run``, ``report``) run as a
subprocess with its arguments printed, and every one of them resumes by itself: a re-run skips
finished collections (their manifest is complete and describes the same request), finished training
runs (the last snapshot is at the recipe's step) and evaluated episodes (the store holds them for
the same protocol fingerprint, label and snapshot hash). Before anything runs, the plan is printed
with an estimated wall time per stage from the per-unit costs in :data:`COSTS` (measured on the
2-core CPU machine this project is developed on; a GPU trains much faster). What is left is read
through the functions the commands themselves call, from the config each ``collect`` and ``run``
stage's command line decides (:class:`~awda_bench.data.config.CollectConfig`,
:class:`~awda_bench.harness.sweep.SweepConfig`; ``Stage.config``).
"""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from awda_bench.data.config import CollectConfig
from awda_bench.errors import AwdaError, CorruptFileError, UnknownChoiceError, UsageError
from awda_bench.harness.paper_values import (
    PAPER_S3,
    PAPER_S3_PICK_PLACE,
    PAPER_S4,
    paper_analysis_text,
)
from awda_bench.harness.sweep import SweepConfig
from awda_bench.primitives.config import CENTRE_SUFFIX, GRASP_SELECTS
from awda_bench.training.columns import TRAINABLE, Column

if TYPE_CHECKING:
    from awda_bench.training.recipe import Recipe

SUITES: tuple[str, ...] = ("pick_place", "mosaic", "metaworld", "metaworld_ml45")
"""Suites ``reproduce`` knows how to lay out."""

DEFAULT_SYNTHESIZE = 200
"""Synthesized trajectories a collection adds (``--synthesize``) where the suite has synthesis."""


DEFAULT_EPISODES_PER_TASK = 20
"""Training demos per task and embodiment (``--episodes-per-task``) where
:data:`SUITE_EPISODES_PER_TASK` has no entry for the suite (the reference recorded 100)."""

SUITE_EPISODES_PER_TASK: dict[str, int] = {"pick_place": 30}
"""Suites whose default differs. Pick-and-place: 30, chosen from measurements
(reports/learned/recipe-study.md, sessions 20-23): with ``small`` Full-1 reached 0.8975 held-out
at 20 per task, 0.9475 at 30 and 0.965 / 0.975 (two training seeds) at 50, and is data-limited
there. 30 is the most that keeps ``--columns full-1,tosvi`` from an empty directory near issue
24's 3 hours on the 2-core machines: measured from an empty directory on session 22's machine
(sessions 24-25), 2 h 56.5 min (collection 34 min, Full-1 26 min, T-OSVI 62 + 54 min; recipe
study, Session 24); ~2 h 40 min predicted at session 20's speed; 50 per task takes ~4 h."""


def default_episodes_per_task(suite_name: str) -> int:
    """``--episodes-per-task``'s default for ``suite_name``."""
    return SUITE_EPISODES_PER_TASK.get(suite_name, DEFAULT_EPISODES_PER_TASK)


def default_synthesize(suite_name: str) -> int:
    """``--synthesize``'s default for ``suite_name``: :data:`DEFAULT_SYNTHESIZE`, or 0 on
    Meta-World, where trajectory synthesis is not implemented (its waypoint box is
    pick-and-place's world frame; :func:`awda_bench.data.plan.check_metaworld_collection`)."""
    from awda_bench.suites import load_suite

    if suite_name not in SUITES:  # plan_stages refuses it in one line
        return DEFAULT_SYNTHESIZE
    return 0 if load_suite(suite_name).simulator == "metaworld" else DEFAULT_SYNTHESIZE


class RunInterrupted(AwdaError):
    """A signal stopped ``reproduce`` mid-stage; exit code 128 + the signal's number."""

    def __init__(self, message: str, exit_code: int) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def column_key(column: Column) -> str:
    """``full-1``, ``no-adm``, ``tosvi``, ``tosvi-no-frame-stack``, ...: the ``--columns`` name
    and the method label (an ablation of ``awda`` is named by the ablation alone)."""
    if column.ablation is not None:
        return column.ablation if column.method == "awda" else f"{column.method}-{column.ablation}"
    return "full-1" if column.method == "awda" else column.method


COLUMN_KEYS: dict[str, Column] = {column_key(c): c for c in TRAINABLE}
"""Trained ``--columns`` names: Table S3's in its order, then the §S3 analysis's network."""


@dataclass(frozen=True)
class EvalVariant:
    """A ``--columns`` name that trains nothing: another ``run --method`` over a trained column's
    snapshots (the supplementary's §S3 analysis evaluates T-OSVI's with the mean and the mode
    action)."""

    name: str
    """Its title in tables."""
    trained: str
    """The :data:`COLUMN_KEYS` column whose snapshots it plays (it must be in ``--columns`` too)."""
    method: str
    """The ``run --method`` that plays them."""


EVAL_VARIANTS: dict[str, EvalVariant] = {
    "tosvi-mean": EvalVariant("T-OSVI, mean action", "tosvi", "tosvi-mean"),
    "tosvi-mode": EvalVariant("T-OSVI, mode action", "tosvi", "tosvi-mode"),
}
"""Evaluation-only ``--columns`` names."""


def column_title(key: str) -> str:
    """``Full-1``, ``T-OSVI, mean action``, ...: a ``--columns`` name's title."""
    return EVAL_VARIANTS[key].name if key in EVAL_VARIANTS else COLUMN_KEYS[key].name


DEFAULT_COLUMNS: tuple[str, ...] = ("full-1", "tosvi")

EVAL_METHOD: dict[str, str] = {"awda": "awda", "tosvi": "tosvi", "tosvi-depth": "tosvi-depth"}
"""Network architecture -> the ``run --method`` that evaluates its snapshots."""

DEFAULT_GRASP_SELECT = "centre"
"""How ``reproduce``'s AWDA columns pick the object to grasp: the reference's rule (the depth
component nearest the wrist image's centre). ``run``'s ``awda`` defaults to ``waypoint`` (grasp
where the waypoint points), which is exact for ground-truth waypoints but turns a learned
waypoint's 3-4 cm error into a missed grasp (pick-place-small-pointer-v3: 0.53 held-out with
``waypoint``, 0.83 with ``centre``, same snapshots and episodes)."""


def eval_method(arch: str, grasp_select: str) -> str:
    """The ``run --method`` that evaluates an ``arch`` column's snapshots under ``grasp_select``."""
    method = EVAL_METHOD[arch]
    return method + CENTRE_SUFFIX if arch == "awda" and grasp_select == "centre" else method


FIT_CHECK_COLUMN = "full-1"
FIT_CHECK_LABEL = "full-1 (train tasks)"
FIT_CHECK_TASKS = 2
FIT_CHECK_SNAPSHOTS = 3
"""Full-1's last 3 snapshots on the first 2 training tasks (same episodes per task)."""


@dataclass(frozen=True)
class Costs:
    """Per-unit wall times [s] for the printed estimate (2-core CPU machine, idle, 2026-11)."""

    collect_episode_s: float = 1.75
    """Per kept episode with 2 workers at 240x320 (pick-place: 760 episodes in 1314 s on an idle
    fresh machine, pick_place-small-v4; 1588-2154 s beside other work)."""
    train_step_s: dict[str, float] = field(
        default_factory=lambda: {"awda": 2.23, "tosvi": 3.16, "tosvi-depth": 4.7}
    )
    """Per step of the ``small`` recipe, 2 threads (``recipes/small.toml`` has the measurements)."""
    frozen_step_s: float = 0.3
    """Per step of a frozen-backbone recipe over cached features (``small``: median compute
    0.28 s a step on the idle machine in pick_place-small-v4 and -v7, plus ~0.01 s of data;
    0.49-0.65 s beside another job, -v5; batch 16, 2 threads)."""
    frozen_tosvi_step_s: dict[str, float] = field(
        default_factory=lambda: {"tosvi": 0.8, "tosvi-depth": 1.6}
    )
    """Per T-OSVI step over cached maps pooled 2x2 (``small``: batch 16, 2 threads), with
    ``train``'s denormal flush (:mod:`awda_bench.models.denormals`): the median compute of a real
    run's steps on the idle machine, 0.77 s + 0.01 s of data (pick-place v8, steps 1401-3000,
    2026-12-03). Without the flush a step grew with training (0.9 -> 3.1 s over v8's first 600
    steps; the 1.4 s this plan used before came from such runs). tosvi-depth (which trains its
    depth ResNet-18 over 96 wrist depth images a step) is not measured since the attention fix:
    it is scaled by the ratio measured before it (10.7 s vs 5.3 s at 1 thread beside a 2-thread
    job)."""
    frozen_tosvi_one_frame_step_s: float = 0.49
    """The same for a one-frame T-OSVI (``tosvi-no-frame-stack``): 0.485 s a step (median
    compute 0.47 s), pick-place's default collection, 2026-12-04, with the test suite running at
    the lowest priority beside it for ~17 of its 24.6 minutes (so an idle figure may be lower)."""
    agent_episode_steps: float = 62.4
    """Mean steps of a kept pick-place agent episode (T-OSVI caches every agent frame; the
    20-per-task train split: 17,472 steps in 280 episodes)."""
    synthesized_episode_frames: float = 23.5
    """Frames a T-OSVI-style column that trains on the synthesized episodes (``no-waypoints``)
    adds to the pooled cache per synthesized episode (every step, as agent stacks, plus its demo
    frames): 4,701 frames for pick-place's 200, session 25."""
    encode_frame_s: float = 0.035
    """Encoding one 240x320 frame into the feature cache (pick-place's T-OSVI cache: 20,272
    frames at ~29 frames/s, pick_place-small-v6; 0.077 s beside another job)."""
    paper_step_factor: float = 32.0
    """``paper`` recipe step cost ÷ ``small``'s on a CPU (~71 s vs 2.23 s)."""
    eval_episode_s: dict[str, float] = field(
        default_factory=lambda: {"awda": 1.5, "tosvi": 16.5, "tosvi-depth": 27.5}
    )
    """Per evaluated episode and worker, 2 workers on the 2 cores (awda: open loop, one forward
    pass; tosvi: a frame and a forward pass every step for the whole horizon; measured on
    pick-place: 120 T-OSVI episodes of 180 steps at 16.5 s each per worker; tosvi-depth:
    ``bench episode-cost`` alone, 1 worker, gives 22.0 s beside tosvi's 13.2 s, scaled by the
    same 1.25 to two workers)."""


COSTS = Costs()


@dataclass(frozen=True)
class ReproduceConfig:
    """Everything ``python -m awda_bench reproduce`` decides."""

    suite: str
    out: Path
    recipe: str = "small"
    columns: tuple[str, ...] = DEFAULT_COLUMNS
    hold_out: str | None = None
    workers: int = 2
    episodes_per_task: int | None = None
    """Training demos per task and embodiment; ``None``: :func:`default_episodes_per_task`."""
    synthesize: int | None = None
    """Synthesized trajectories; ``None``: :func:`default_synthesize` of the suite."""
    val_episodes_per_task: int = 5
    snapshots: int = 10
    episodes: int | None = None
    steps: int | None = None
    threads: int | None = None
    fit_check: bool = True
    grasp_select: str = DEFAULT_GRASP_SELECT
    """AWDA columns' grasp rule (:data:`DEFAULT_GRASP_SELECT`; one of ``GRASP_SELECTS``)."""
    data: Path | None = None
    """The training collection; ``None``: ``OUT/data/train``. The collection holds every training
    task of the suite whatever ``hold_out`` (``train --hold-out`` leaves the family's episodes
    out), so MOSAIC's six leave-one-family-out runs can share one collection, and its feature
    cache, each in its own ``out``."""
    dry_run: bool = False
    progress: bool = True
    """Let each stage show its progress bar (with ETA) on stderr."""

    @property
    def demos_per_task(self) -> int:
        """:attr:`episodes_per_task` with the suite's default filled in."""
        if self.episodes_per_task is not None:
            return self.episodes_per_task
        return default_episodes_per_task(self.suite)


@dataclass
class Stage:
    """One command of the pipeline."""

    name: str
    argv: list[str]
    estimate_s: float
    done: bool
    detail: str = ""
    config: CollectConfig | SweepConfig | None = None
    """What a ``collect`` or ``run`` stage's command decides (its ``argv`` says the same); the
    plan reads its progress from it."""


def train_data(config: ReproduceConfig) -> Path:
    """Where the training collection is (or is collected to): ``--data`` or ``OUT/data/train``."""
    return config.data if config.data is not None else config.out / "data" / "train"


def parse_columns(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise UsageError("--columns is empty; name at least one, e.g. full-1,tosvi")
    for n in names:
        if n not in COLUMN_KEYS and n not in EVAL_VARIANTS:
            raise UnknownChoiceError("column", n, (*COLUMN_KEYS, *EVAL_VARIANTS))
    if len(set(names)) != len(names):
        raise UsageError(f"--columns names a column twice: {text}")
    for n in names:
        if n in EVAL_VARIANTS and EVAL_VARIANTS[n].trained not in names:
            trained = EVAL_VARIANTS[n].trained
            raise UsageError(
                f"--columns {n} plays the {trained} column's snapshots: add {trained} to "
                f"--columns, e.g. --columns {trained},{n}"
            )
    return names


def _manifest(path: Path) -> dict[str, Any] | None:
    try:
        return dict(json.loads((path / "manifest.json").read_text()))
    except (OSError, ValueError):
        return None


def _collection_done(path: Path, split: str, per_task: int, synthesize: int) -> bool:
    manifest = _manifest(path)
    if manifest is None or not manifest.get("complete"):
        return False
    d = manifest.get("definition", {})
    return (
        d.get("split") == split
        and d.get("episodes_per_task") == per_task
        and d.get("synthesize", 0) == synthesize
    )


def _train_target(recipe_name: str, steps: int | None) -> int:
    from awda_bench.training.recipe import load_recipe

    return steps if steps is not None else load_recipe(recipe_name).train.max_steps


def _quiet(progress: bool) -> list[str]:
    return [] if progress else ["--no-progress"]


def _collect_argv(collect: CollectConfig) -> list[str]:
    """The ``collect`` command line that decides ``collect`` (the fields a stage sets)."""
    argv = [
        "collect", "--suite", collect.suite, "--split", collect.split,
        "--episodes-per-task", str(collect.episodes_per_task),
    ]  # fmt: skip
    if collect.split == "train":  # the training data names its synthesized share, 0 too
        argv += ["--synthesize", str(collect.synthesize)]
    return [
        *argv, "--out", str(collect.out), "--workers", str(collect.workers),
        *_quiet(collect.progress),
    ]  # fmt: skip


def _run_argv(sweep: SweepConfig) -> list[str]:
    """The ``run`` command line that decides ``sweep`` (the fields a stage sets)."""
    argv = [
        "run", "--suite", sweep.suite, "--method", sweep.method,
        "--checkpoints", str(sweep.checkpoints), "--snapshots", str(sweep.snapshots),
        "--label", str(sweep.label),
    ]  # fmt: skip
    if sweep.split != "test":
        argv += ["--split", sweep.split]
    argv += [
        "--out", str(sweep.out), "--workers", str(sweep.workers), *_quiet(sweep.progress),
        *(a for t in sweep.tasks for a in ("--task", str(t))),
    ]  # fmt: skip
    if sweep.episodes is not None:
        argv += ["--episodes", str(sweep.episodes)]
    return argv


def _collect_remaining(collect: CollectConfig) -> int:
    """Episodes ``collect`` would still record (all of them when nothing is there yet)."""
    from awda_bench.data.collect import collection_progress

    already, planned = collection_progress(collect)
    return planned - already


def _steps_done(ckpt: Path) -> int:
    """The step of the last snapshot in ``ckpt`` (0 without one): where ``train`` resumes."""
    from awda_bench.models.snapshot import SNAPSHOT_PATTERN, list_snapshots

    found = list_snapshots(ckpt) if ckpt.is_dir() else []
    match = SNAPSHOT_PATTERN.match(found[-1].name) if found else None
    return int(match.group(1)) if match is not None else 0


def _eval_remaining(sweep: SweepConfig) -> int | None:
    """Episodes ``run`` would still play (``None``: cannot tell yet, e.g. no snapshots)."""
    from awda_bench.harness.results_store import STORE_NAME, ResultsStore
    from awda_bench.harness.sweep import prepare_sweep

    if sweep.checkpoints is not None and not _has_snapshots(sweep.checkpoints):
        return None
    try:
        plan = prepare_sweep(sweep)
    except UsageError:
        return None
    if not (sweep.out / STORE_NAME).is_file():
        return len(plan.jobs)
    with ResultsStore(sweep.out, create=False) as store:
        done = {
            snap.sha256: store.finished_keys(
                plan.protocol.fingerprint, plan.method.name, snap.sha256
            )
            for snap in plan.snapshots
        }
    return sum((j.spec.task, j.spec.episode) not in done[j.snapshot.sha256] for j in plan.jobs)


def _cache_built(data: Path, recipe: Recipe, arch: str, *, synthesized: bool = False) -> bool:
    """Whether the frozen-trunk feature cache an ``arch`` column trains from is already built
    (by an earlier column of this collection: T-OSVI-style columns share theirs); with
    ``synthesized``, whether it also holds the synthesized episodes' frames (a column without
    them, e.g. ``tosvi``, built it without)."""
    from awda_bench.training.run import cached_features_path

    manifest = _manifest(data)
    if manifest is None or not manifest.get("fingerprint"):
        return False
    path = cached_features_path(data, str(manifest["fingerprint"]), recipe, arch)
    if not synthesized or not path.is_file():
        return path.is_file()
    import h5py

    from awda_bench.data.config import ROLE_SYNTHESIZED

    try:  # groups are named <unit path>/<traj>, and synthesized units live under their role
        with h5py.File(path, "r") as f:
            return ROLE_SYNTHESIZED in f
    except OSError:  # unreadable: training rebuilds it, so its encoding is still to come
        return False


def _has_snapshots(ckpt: Path) -> bool:
    from awda_bench.models.snapshot import list_snapshots

    return bool(list_snapshots(ckpt))


def _eval_tasks(suite_name: str, hold_out: str | None) -> tuple[list[int], int]:
    """``run --task`` restriction and the number of evaluation units (tasks or families)."""
    from awda_bench.suites import load_suite

    suite = load_suite(suite_name)
    tasks = list(suite.eval_tasks)
    if hold_out is not None:
        families = sorted({t.family for t in suite.tasks})
        if hold_out not in families:
            raise UnknownChoiceError("--hold-out family", hold_out, families)
        tasks = [t for t in tasks if t.family == hold_out]
        if not tasks:
            raise UsageError(f"--hold-out {hold_out}: suite {suite_name!r} evaluates no such task")
        return [t.index for t in tasks], 1
    units = len({t.family for t in tasks}) if suite.episode_unit == "family" else len(tasks)
    return [], units


def _paper_cell(config: ReproduceConfig, key: str) -> str:
    """The supplementary's printed cell beside ``key``'s: Table S3's pick-and-place row (or the
    §S3 analysis), its Meta-World [all] row (``metaworld``, the reference's five held-out tasks;
    ``metaworld_ml45`` holds out others, so it has none), or Table S4's held-out family."""
    if config.suite == "pick_place":
        return PAPER_S3_PICK_PLACE.get(key) or paper_analysis_text(key) or "–"
    if config.suite == "metaworld":
        return PAPER_S3["metaworld_all"].get(key, "–")
    if config.suite == "mosaic":
        return PAPER_S4.get((key, config.hold_out or ""), "–")
    return "–"


def _eval_stage(key: str, evaluate: SweepConfig, left: int, arch: str, detail: str) -> Stage:
    """``evaluate KEY``: ``evaluate``'s ``run`` command, ``left`` episodes to play (done at 0)."""
    estimate = left * COSTS.eval_episode_s[arch] / evaluate.workers
    return Stage(f"evaluate {key}", _run_argv(evaluate), estimate, left == 0, detail, evaluate)


def plan_stages(config: ReproduceConfig) -> list[Stage]:
    """The pipeline for ``config``, each stage marked done or not (nothing runs here)."""
    from awda_bench.suites import load_suite

    if config.suite not in SUITES:
        raise UnknownChoiceError("suite", config.suite, SUITES)
    if config.workers < 1:
        raise UsageError(f"--workers must be at least 1 (got {config.workers})")
    if config.grasp_select not in GRASP_SELECTS:
        raise UnknownChoiceError("--grasp-select", config.grasp_select, GRASP_SELECTS)
    if config.suite == "mosaic" and config.hold_out is None:
        raise UsageError(
            "--suite mosaic needs --hold-out FAMILY (train on the other families, evaluate that "
            "one), e.g. --hold-out drawer"
        )
    if config.suite != "mosaic" and config.hold_out is not None:
        raise UsageError(
            f"--hold-out is for --suite mosaic; {config.suite} holds out the tasks its suite file "
            "names (pick_place: 14 and 15); drop --hold-out"
        )
    suite = load_suite(config.suite)
    out = config.out
    data, test = train_data(config), out / "data" / "test"
    quiet = _quiet(config.progress)
    stages: list[Stage] = []
    from awda_bench.data.plan import split_tasks

    synthesize = (
        default_synthesize(config.suite) if config.synthesize is None else config.synthesize
    )
    n_train = len(split_tasks(suite, "train")) * config.demos_per_task * 2 + synthesize
    collect_train = CollectConfig(
        suite=config.suite, split="train", embodiment="both",
        episodes_per_task=config.demos_per_task, synthesize=synthesize, out=data,
        workers=config.workers, progress=config.progress,
    )  # fmt: skip
    left_train = _collect_remaining(collect_train)
    stages.append(
        Stage(
            "collect train",
            _collect_argv(collect_train),
            left_train * COSTS.collect_episode_s * 2 / config.workers,
            _collection_done(data, "train", config.demos_per_task, synthesize),
            f"{n_train} episodes" + (f", {left_train} left" if 0 < left_train < n_train else ""),
            collect_train,
        )
    )  # fmt: skip
    val: list[str] = []
    if config.hold_out is None:
        n_test = len(suite.eval_tasks) * config.val_episodes_per_task * 2
        collect_test = CollectConfig(
            suite=config.suite, split="test", embodiment="both",
            episodes_per_task=config.val_episodes_per_task, out=test, workers=config.workers,
            progress=config.progress,
        )  # fmt: skip
        left_test = _collect_remaining(collect_test)
        stages.append(
            Stage(
                "collect test",
                _collect_argv(collect_test),
                left_test * COSTS.collect_episode_s * 2 / config.workers,
                _collection_done(test, "test", config.val_episodes_per_task, 0),
                f"{n_test} validation episodes"
                + (f", {left_test} left" if 0 < left_test < n_test else ""),
                collect_test,
            )
        )  # fmt: skip
        val = ["--val-data", str(test)]
    target = _train_target(config.recipe, config.steps)
    from awda_bench.training.recipe import load_recipe

    recipe = load_recipe(config.recipe)
    frozen = recipe.model.freeze_backbone
    factor = COSTS.paper_step_factor if config.recipe == "paper" else 1.0
    tasks, units = _eval_tasks(config.suite, config.hold_out)
    episodes = config.episodes if config.episodes is not None else suite.episodes_per_task
    runs = out / "runs"
    trained_keys = [k for k in config.columns if k not in EVAL_VARIANTS]
    planned_caches: set[str] = set()  # feature caches an earlier column of this plan encodes
    for key in trained_keys:
        column = COLUMN_KEYS[key]
        ckpt = out / "checkpoints" / key
        argv = [
            "train", "--method", column.method, "--data", str(data), "--out", str(ckpt),
            "--recipe", config.recipe, *val, *quiet,
        ]  # fmt: skip
        if column.ablation is not None:
            argv += ["--ablation", column.ablation]
        if config.hold_out is not None:
            argv += ["--hold-out", config.hold_out]
        if config.steps is not None:
            argv += ["--steps", str(config.steps)]
        if config.threads is not None:
            argv += ["--threads", str(config.threads)]
        step_s, encode_s = COSTS.train_step_s[column.arch] * factor, 0.0
        pairs = (n_train - synthesize) / 2
        # frames to encode into the cache: (part, frames), the synthesized episodes' own part
        parts: list[tuple[str, float]] = []
        cache_kind = "awda" if column.arch == "awda" else "tosvi"  # T-OSVI-style nets share one
        if frozen and column.arch == "awda":  # cached features; the cache is encoded once
            step_s = COSTS.frozen_step_s
            # o_1 of every agent episode, the demo frames of every demonstrator and synthesized one
            parts = [(cache_kind, pairs * 11), (f"{cache_kind}+synthesized", synthesize * 10)]
        elif frozen:  # T-OSVI over cached (pooled) maps: every agent frame is encoded once
            from awda_bench.training.run import frame_stack_of

            one_frame = frame_stack_of(recipe, column) == 1
            step_s = COSTS.frozen_tosvi_one_frame_step_s if one_frame else (
                COSTS.frozen_tosvi_step_s[column.arch]
            )  # fmt: skip
            parts = [
                (cache_kind, pairs * (COSTS.agent_episode_steps + 10)),
                (f"{cache_kind}+synthesized", synthesize * COSTS.synthesized_episode_frames),
            ]
        if not column.synthesized:
            parts = parts[:1]
        for part, frames in parts:
            built = _cache_built(data, recipe, column.arch, synthesized=part != cache_kind)
            if part not in planned_caches and not built:
                encode_s += COSTS.encode_frame_s * frames
            planned_caches.add(part)
        steps_done = _steps_done(ckpt)
        stages.append(
            Stage(
                f"train {key}",
                argv,
                max(0, target - steps_done) * step_s + (encode_s if steps_done == 0 else 0.0),
                steps_done >= target,
                f"{column.name}: {target} steps"
                + (f", resumes at {steps_done}" if 0 < steps_done < target else ""),
            )
        )  # fmt: skip
        evaluate = SweepConfig(
            suite=config.suite, method=eval_method(column.arch, config.grasp_select), out=runs, checkpoints=ckpt,
            snapshots=config.snapshots, episodes=config.episodes, workers=config.workers,
            tasks=tuple(tasks), progress=config.progress, label=key,
        )  # fmt: skip
        n_eval = config.snapshots * episodes * units
        trained = steps_done >= target
        # until training is done the snapshots to evaluate are not all there: plan all of them
        remaining = _eval_remaining(evaluate) if trained else None
        stages.append(
            _eval_stage(
                key, evaluate, n_eval if remaining is None else remaining, column.arch,
                f"{config.snapshots} snapshots x {episodes} episodes x {units} "
                f"{'family' if suite.episode_unit == 'family' else 'tasks'}",
            )
        )  # fmt: skip
        if key == FIT_CHECK_COLUMN and config.fit_check and config.hold_out is None:
            train_tasks = tuple(t.index for t in suite.train_tasks[:FIT_CHECK_TASKS])
            fit = replace(
                evaluate, out=out / "runs-train-tasks", snapshots=FIT_CHECK_SNAPSHOTS,
                tasks=train_tasks, label=FIT_CHECK_LABEL, split="train",
            )  # fmt: skip
            remaining = _eval_remaining(fit) if trained else None
            n_fit = FIT_CHECK_SNAPSHOTS * episodes * FIT_CHECK_TASKS
            stages.append(
                Stage(
                    f"evaluate {key} on training tasks",
                    _run_argv(fit),
                    (n_fit if remaining is None else remaining)
                    * COSTS.eval_episode_s[column.arch]
                    / config.workers,
                    remaining == 0,
                    f"tasks {', '.join(map(str, train_tasks))}: did it fit?",
                    fit,
                )
            )
    for key in (k for k in config.columns if k in EVAL_VARIANTS):
        variant = EVAL_VARIANTS[key]
        ckpt = out / "checkpoints" / variant.trained
        evaluate = SweepConfig(
            suite=config.suite, method=variant.method, out=runs, checkpoints=ckpt,
            snapshots=config.snapshots, episodes=config.episodes, workers=config.workers,
            tasks=tuple(tasks), progress=config.progress, label=key,
        )  # fmt: skip
        trained = _steps_done(ckpt) >= target
        remaining = _eval_remaining(evaluate) if trained else None
        n_eval = config.snapshots * episodes * units
        stages.append(
            _eval_stage(
                key, evaluate, n_eval if remaining is None else remaining,
                COLUMN_KEYS[variant.trained].arch,
                f"{variant.trained}'s snapshots with --method {variant.method}",
            )
        )  # fmt: skip
    stages.append(
        Stage(
            "report",
            ["report", "--runs", str(runs), "--out", str(out / "report")],
            10.0,
            False,
            "tables, figures, reproduce.md",
        )
    )
    if any(st.name.endswith("on training tasks") for st in stages):
        stages.append(
            Stage(
                "report training tasks",
                [
                    "report", "--runs", str(out / "runs-train-tasks"),
                    "--out", str(out / "report" / "train-tasks"),
                ],
                10.0,
                False,
                "the fit check's tables",
            )
        )  # fmt: skip
    return stages


def _clock(seconds: float) -> str:
    minutes = round(seconds / 60.0)
    return f"{minutes // 60} h {minutes % 60:02d} min" if minutes >= 60 else f"{minutes} min"


def format_plan(config: ReproduceConfig, stages: list[Stage]) -> str:
    lines = [
        f"reproduce {config.suite}, recipe {config.recipe}, columns {', '.join(config.columns)}"
        + (f", hold-out {config.hold_out}" if config.hold_out else "")
        + f" -> {config.out}"
    ]
    todo = 0.0
    for stage in stages:
        state = "done" if stage.done else f"~{_clock(stage.estimate_s)}"
        if not stage.done:
            todo += stage.estimate_s
        lines.append(f"  {stage.name:<34} {state:>12}  {stage.detail}")
    lines.append(f"  estimated total for what is left: {_clock(todo)} (2-core CPU figures)")
    return "\n".join(lines)


STAGE_TIMES = "stage_times.json"
"""``OUT/stage_times.json``: every attempt at every stage, across invocations (a killed run's
stages add up)."""

LOCK_FILE = ".reproduce.lock"
HEARTBEAT_S = 30.0
"""How often a running stage's wall time is written to :data:`STAGE_TIMES`."""


@dataclass
class StageAttempt:
    """One run of one stage's command: how long, and how it ended."""

    stage: str
    started_at: str
    wall_s: float
    outcome: str
    """``finished``, ``failed (exit N)``, ``interrupted (SIGTERM)``, ``running`` while it runs, or
    ``killed`` when a later invocation finds a ``running`` attempt whose process is gone."""


def read_stage_times(out: Path) -> list[StageAttempt]:
    path = out / STAGE_TIMES
    if not path.is_file():
        return []
    try:
        return [StageAttempt(**row) for row in json.loads(path.read_text())]
    except (ValueError, TypeError) as exc:
        raise CorruptFileError(
            f"{path} is not a stage-time log ({exc}); delete it to start a new log (only the "
            "reported stage wall times are lost)"
        ) from exc


def write_stage_times(out: Path, attempts: list[StageAttempt]) -> None:
    path = out / STAGE_TIMES
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps([asdict(a) for a in attempts], indent=1) + "\n")
    os.replace(tmp, path)


def stage_totals(attempts: list[StageAttempt]) -> list[tuple[str, float, int, str]]:
    """``(stage, wall s summed over attempts, attempts, last outcome)`` in first-run order."""
    totals: dict[str, list[Any]] = {}
    for a in attempts:
        row = totals.setdefault(a.stage, [0.0, 0, ""])
        row[0] += a.wall_s
        row[1] += 1
        row[2] = a.outcome
    return [(name, wall, n, last) for name, (wall, n, last) in totals.items()]


@contextmanager
def _exclusive(out: Path) -> Iterator[None]:
    """Hold ``OUT/.reproduce.lock`` so that two invocations never run stages in one directory."""
    out.mkdir(parents=True, exist_ok=True)
    with open(out / LOCK_FILE, "a+") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            owner = handle.read().strip() or "?"
            raise UsageError(
                f"another reproduce (pid {owner}) is running in {out}; wait for it to finish or "
                "stop it (Ctrl-C or kill PID), then re-run this command to resume"
            ) from None
        handle.seek(0)
        handle.truncate()
        handle.write(str(os.getpid()))
        handle.flush()
        yield


@contextmanager
def _forward_stop_signals(child: subprocess.Popen, received: list[int]) -> Iterator[None]:
    """While ``child`` runs in its own process group: SIGINT/SIGTERM/SIGHUP to this process stop
    the whole group (the stage and its workers) with SIGTERM, a second one with SIGKILL."""

    def handler(signum: int, _frame: object) -> None:
        received.append(signum)
        try:
            os.killpg(child.pid, signal.SIGTERM if len(received) == 1 else signal.SIGKILL)
        except ProcessLookupError:
            pass

    stops = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    saved = {s: signal.signal(s, handler) for s in stops}
    try:
        yield
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


def run_stages(
    config: ReproduceConfig,
    stages: list[Stage],
    command: tuple[str, ...] = (sys.executable, "-m", "awda_bench"),
) -> list[StageAttempt]:
    """Run every stage not done, in order, each as a subprocess in its own process group.

    Every attempt is logged to ``OUT/stage_times.json`` (its wall time rewritten every
    :data:`HEARTBEAT_S` while it runs), so the summary's stage times add up over a run that was
    killed and resumed. Stopping this process (Ctrl-C, SIGTERM, SIGHUP) stops the running stage
    and its workers too, records the attempt as interrupted and raises :class:`RunInterrupted`;
    a failing stage raises :class:`UsageError`. ``command`` prefixes each stage's ``argv``.
    After each stage it prints :func:`pace_line` (its time beside the plan's, and the rest re-timed
    at this run's pace). Returns this invocation's attempts."""
    with _exclusive(config.out):
        log = read_stage_times(config.out)
        for attempt in log:
            if attempt.outcome == "running":  # its invocation died without a word (SIGKILL)
                attempt.outcome = "killed"
        mine: list[StageAttempt] = []
        paced: list[tuple[float, float]] = []  # (planned, actual) of the stages finished here
        for index, stage in enumerate(stages):
            if stage.done:
                print(f"[reproduce] {stage.name}: done, skipped", flush=True)
                continue
            argv = [*command, *stage.argv]
            print(f"[reproduce] {stage.name}: {' '.join(argv[1:])}", flush=True)
            attempt = StageAttempt(
                stage.name, datetime.now(UTC).isoformat(timespec="seconds"), 0.0, "running"
            )
            log.append(attempt)
            mine.append(attempt)
            write_stage_times(config.out, log)
            start = time.perf_counter()
            received: list[int] = []
            child = subprocess.Popen(argv, start_new_session=True)
            with _forward_stop_signals(child, received):
                while True:
                    try:
                        code = child.wait(timeout=HEARTBEAT_S)
                        break
                    except subprocess.TimeoutExpired:
                        attempt.wall_s = round(time.perf_counter() - start, 3)
                        write_stage_times(config.out, log)
            attempt.wall_s = round(time.perf_counter() - start, 3)
            if received:
                name = signal.Signals(received[0]).name
                attempt.outcome = f"interrupted ({name})"
                write_stage_times(config.out, log)
                raise RunInterrupted(
                    f"{name}: stopped stage {stage.name!r} after {attempt.wall_s:.0f} s; re-run the "
                    "same reproduce command to resume (finished stages and episodes are kept)",
                    128 + received[0],
                )
            attempt.outcome = "finished" if code == 0 else f"failed (exit {code})"
            write_stage_times(config.out, log)
            if code != 0:
                raise UsageError(
                    f"stage {stage.name!r} exited {code} after {attempt.wall_s:.0f} s; fix what it "
                    "printed and re-run the same reproduce command (finished stages are skipped)"
                )
            paced.append((stage.estimate_s, attempt.wall_s))
            left = sum(s.estimate_s for s in stages[index + 1 :] if not s.done)
            print(f"[reproduce] {stage.name}: {pace_line(paced, left)}", flush=True)
        return mine


def pace_line(paced: list[tuple[float, float]], left_s: float) -> str:
    """The line ``reproduce`` prints after a stage: its wall time beside its plan, and what is left
    at the plan's figures and at this invocation's pace so far (actual / planned over the stages
    it finished: the plan's costs are one 2-core machine's, and machines differ). ``paced`` holds
    ``(planned_s, actual_s)`` of the finished stages, the last one being the stage just done."""
    planned, actual = paced[-1]
    line = f"{actual:.0f} s (planned ~{_clock(planned)})"
    if left_s <= 0.0:
        return line
    line += f"; left: ~{_clock(left_s)} at the plan's figures"
    plan_sum = sum(p for p, _ in paced)
    if plan_sum > 0.0:
        pace = sum(a for _, a in paced) / plan_sum
        line += f", ~{_clock(left_s * pace)} at this run's pace so far ({pace:.2f}x the plan)"
    return line


PAPER_SCALE = {
    "image": "240x320",
    "demos_per_task": "100 per task per embodiment (reference collection)",
    "steps": "not stated for pick-and-place; snapshots every 10k steps, batch 30",
}
"""The reference's scale beside ours in ``reproduce.md`` (Table S2; pick-and-place's image)."""

PAPER_IMAGE = {"metaworld": "224x224", "metaworld_ml45": "224x224"}
"""Table S2's input size where it is not pick-and-place's (:data:`PAPER_SCALE`'s)."""


def _fmt(mean: float | None, se: float | None) -> str:
    return "n/a" if mean is None or se is None else f"{mean:.2f} ± {se:.2f}"


def command_line(config: ReproduceConfig) -> str:
    """The ``reproduce`` command that re-runs (or resumes) ``config``, every option that is not
    its default spelled out."""
    words = ["python -m awda_bench reproduce", f"--suite {config.suite}"]
    if config.hold_out is not None:
        words.append(f"--hold-out {config.hold_out}")
    words += [f"--recipe {config.recipe}", f"--columns {','.join(config.columns)}"]
    # always spelled out: its default differs by suite and has changed (20 -> 30 on pick-place)
    words.append(f"--episodes-per-task {config.demos_per_task}")
    defaults = ReproduceConfig(suite=config.suite, out=config.out)
    for name, flag in (
        ("workers", "--workers"),
        ("synthesize", "--synthesize"),
        ("snapshots", "--snapshots"),
        ("episodes", "--episodes"),
        ("steps", "--steps"),
        ("threads", "--threads"),
        ("grasp_select", "--grasp-select"),
    ):
        value = getattr(config, name)
        if value != getattr(defaults, name):
            words.append(f"{flag} {value}")
    if not config.fit_check:
        words.append("--no-fit-check")
    if config.data is not None:
        words.append(f"--data {config.data}")
    words.append(f"--out {config.out}")
    return " ".join(words)


def write_summary(config: ReproduceConfig) -> Path:
    """``OUT/report/reproduce.md``: scale vs the paper, our rows beside the paper's, costs."""
    from awda_bench.harness.results_store import STORE_NAME, ResultsStore
    from awda_bench.training.recipe import load_recipe

    out = config.out
    report = out / "report"
    summary = json.loads((report / "summary.json").read_text())
    recipe = load_recipe(config.recipe)
    model = recipe.for_suite(config.suite).model  # the sizes it trains this suite with
    manifest = _manifest(train_data(config)) or {}
    d = manifest.get("definition", {})
    counts = manifest.get("counts", {}).get("by_role", {})
    kept = {role: c.get("kept") for role, c in counts.items()}
    group = config.hold_out or "all"
    cells = {
        c["method"]: c
        for c in summary["cells"]
        if c["suite"] == config.suite and c["group"] == group
    }
    lines = [
        f"# reproduce: {config.suite}"
        + (f", held-out family {config.hold_out}" if config.hold_out else ""),
        "",
        "Generated by `python -m awda_bench reproduce`; every number below was measured by this "
        "pipeline. Paper values are in their own column and never enter ours.",
        "",
        f"Command: `{command_line(config)}`",
        "",
        "## Scale (ours vs the paper)",
        "",
        "| | ours | paper |",
        "|---|---|---|",
        f"| recipe | `{recipe.name}` (sha256 {recipe.sha256[:12]}) | `paper` (Table S2) |",
        f"| network input | {model.image_height_px}x{model.image_width_px} "
        f"(collected at {'x'.join(map(str, d.get('image_size', [])))}) | "
        f"{PAPER_IMAGE.get(config.suite, PAPER_SCALE['image'])} |",
        f"| demos per training task | {d.get('episodes_per_task')} per embodiment; "
        f"{d.get('synthesize', 0)} synthesized; kept {kept} | {PAPER_SCALE['demos_per_task']} |",
        f"| training | {_train_target(config.recipe, config.steps)} steps x batch "
        f"{recipe.train.batch_size}, snapshot "
        f"every {recipe.train.snapshot_every_steps} | {PAPER_SCALE['steps']} |",
        f"| dataset fingerprint | `{manifest.get('fingerprint')}` | – |",
        f"| grasp target (AWDA columns) | `{config.grasp_select}` (`reproduce --grasp-select`) "
        "| `centre` (nearest the wrist image's centre) |",
        f"| evaluation | last {config.snapshots} snapshots x the suite's episodes per held-out "
        f"unit | last 10 snapshots x 20 episodes |",
        "",
        "## Success on held-out tasks (success_once; mean ± SE over snapshots)",
        "",
        "| column | ours | snapshots | episodes | paper |",
        "|---|---:|---:|---:|---:|",
    ]
    for key in config.columns:
        c = cells.get(key)
        paper = _paper_cell(config, key)
        if c is None:
            lines.append(f"| {column_title(key)} (`{key}`) | not evaluated | | | {paper} |")
        else:
            lines.append(
                f"| {column_title(key)} (`{key}`) | {_fmt(c['mean'], c['se'])} | "
                f"{c['snapshots']}/{c['snapshots_planned']} | {c['episodes']} | {paper} |"
            )
    fit_summary = report / "train-tasks" / "summary.json"
    fit_cells = json.loads(fit_summary.read_text())["cells"] if fit_summary.is_file() else []
    fit = next(
        (c for c in fit_cells if c["method"] == FIT_CHECK_LABEL and c["group"] == "all"), None
    )
    if fit is not None:
        lines += [
            "",
            f"Full-1 on training tasks (fit check, last {fit['snapshots']} snapshots): "
            f"{_fmt(fit['mean'], fit['se'])} over {fit['episodes']} episodes.",
        ]
    with ResultsStore(out / "runs", create=False) as store:
        rows = store.raw(
            "SELECT method, COUNT(*), AVG(steps), AVG(wall_time_s), AVG(act_time_s), "
            "AVG(env_time_s), AVG(reached), AVG(grasped), AVG(success_once) FROM episodes "
            "WHERE status='ok' GROUP BY method ORDER BY method"
        )
    lines += [
        "",
        "## Why: reached / grasped, and what an episode costs",
        "",
        "| label | episodes | reached | grasped | success | steps | wall s | policy s | env s |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for m, n, steps, wall, act, env, reached, grasped, success in rows:
        r = "–" if reached is None else f"{reached:.2f}"
        g = "–" if grasped is None else f"{grasped:.2f}"
        lines.append(
            f"| {m} | {n} | {r} | {g} | {success:.2f} | {steps:.0f} | {wall:.2f} | {act:.2f} | "
            f"{env:.2f} |"
        )
    totals = stage_totals(read_stage_times(out))
    if totals:
        lines += [
            "",
            f"## Stage wall times (every invocation in this directory, from `{STAGE_TIMES}`)",
            "",
            "| stage | wall min | attempts | last attempt |",
            "|---|---:|---:|---|",
        ]
        lines += [f"| {n} | {w / 60:.1f} | {k} | {last} |" for n, w, k, last in totals]
        lines.append(f"| total | {sum(t[1] for t in totals) / 60:.1f} | | |")
    lines += [
        "",
        f"Store: `{out / 'runs' / STORE_NAME}`; tables: `report.md` beside this file.",
        "",
    ]
    path = report / "reproduce.md"
    path.write_text("\n".join(lines))
    return path

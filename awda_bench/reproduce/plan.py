"""``reproduce``'s plan: every stage's command line, its estimated wall time (:data:`COSTS`) and
whether it is done, read through the functions the commands themselves call; nothing runs here."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from awda_bench.data.config import CollectConfig
from awda_bench.errors import ProtocolMismatchError, UnknownChoiceError, UsageError
from awda_bench.evaluation.sweep import SweepConfig
from awda_bench.primitives.config import GRASP_SELECTS
from awda_bench.reproduce.config import (
    COLUMN_KEYS,
    EVAL_VARIANTS,
    FIT_CHECK_COLUMN,
    FIT_CHECK_LABEL,
    FIT_CHECK_SNAPSHOTS,
    SUITES,
    ReproduceConfig,
    default_synthesize,
    eval_method,
    fit_check_tasks,
    train_data,
)
from awda_bench.reproduce.costs import COSTS, clock

if TYPE_CHECKING:
    from awda_bench.training.recipe import Recipe


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


def read_manifest(path: Path) -> dict[str, Any] | None:
    try:
        return dict(json.loads((path / "manifest.json").read_text()))
    except (OSError, ValueError):
        return None


def _collection_done(path: Path, split: str, per_task: int, synthesize: int) -> bool:
    manifest = read_manifest(path)
    if manifest is None or not manifest.get("complete"):
        return False
    d = manifest.get("definition", {})
    return (
        d.get("split") == split
        and d.get("episodes_per_task") == per_task
        and d.get("synthesize", 0) == synthesize
    )


def train_target(recipe_name: str, steps: int | None) -> int:
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


def _check_trained_recipe(ckpt: Path, recipe: Recipe) -> None:
    """Refuse a checkpoint directory trained under other settings than ``recipe``'s (on the
    suite): with all its snapshots there, its training stage counts as done and would never run
    ``train``'s own check, so the old snapshots would be evaluated under today's recipe. The
    recipe's name is not compared (a copy under another name trains the same network)."""
    from awda_bench.training.run import TRAIN_JSON, identity

    meta = ckpt / TRAIN_JSON
    if not meta.is_file():
        return
    try:
        theirs = json.loads(meta.read_text())
        mine = identity({**theirs, "recipe": recipe.to_dict()})["recipe"]
        trained = identity(theirs)["recipe"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UsageError(f"{meta} is unreadable ({exc}); use another --out") from exc
    mine.pop("name", None)
    trained.pop("name", None)
    if mine != trained:
        differ = sorted(
            f"{table}.{key}"
            for table in mine
            if isinstance(mine[table], dict)
            for key in mine[table]
            if mine[table].get(key) != trained.get(table, {}).get(key)
        )
        raise ProtocolMismatchError(
            f"{ckpt} was trained under other recipe settings ({', '.join(differ) or 'its tables'}"
            f" not as in recipe {recipe.name!r}); reproduce into another --out, or delete that "
            "directory to train it again"
        )


def _steps_done(ckpt: Path) -> int:
    """The step of the last snapshot in ``ckpt`` (0 without one): where ``train`` resumes."""
    from awda_bench.models.snapshot import SNAPSHOT_PATTERN, list_snapshots

    found = list_snapshots(ckpt) if ckpt.is_dir() else []
    match = SNAPSHOT_PATTERN.match(found[-1].name) if found else None
    return int(match.group(1)) if match is not None else 0


def _eval_remaining(sweep: SweepConfig) -> int | None:
    """Episodes ``run`` would still play (``None``: cannot tell yet, e.g. no snapshots)."""
    from awda_bench.evaluation.results_store import STORE_NAME, ResultsStore
    from awda_bench.evaluation.sweep import prepare_sweep

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

    manifest = read_manifest(data)
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


def _collect_stage(name: str, collect: CollectConfig, total: int, noun: str, done: bool) -> Stage:
    """``collect NAME``: ``collect``'s command, ``total`` episodes, the ones still to record timed."""
    left = _collect_remaining(collect)
    estimate = left * COSTS.collect_episode_s * 2 / collect.workers
    detail = f"{total} {noun}" + (f", {left} left" if 0 < left < total else "")
    return Stage(name, _collect_argv(collect), estimate, done, detail, collect)


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
    stages.append(
        _collect_stage(
            "collect train", collect_train, n_train, "episodes",
            _collection_done(data, "train", config.demos_per_task, synthesize),
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
        stages.append(
            _collect_stage(
                "collect test", collect_test, n_test, "validation episodes",
                _collection_done(test, "test", config.val_episodes_per_task, 0),
            )
        )  # fmt: skip
        val = ["--val-data", str(test)]
    target = train_target(config.recipe, config.steps)
    from awda_bench.training.recipe import load_recipe

    recipe = load_recipe(config.recipe)
    frozen = recipe.model.trunk.freeze_backbone
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
        _check_trained_recipe(ckpt, recipe.for_suite(config.suite))
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
            train_tasks = fit_check_tasks(suite)
            fit = replace(
                evaluate, out=out / "runs-train-tasks", snapshots=FIT_CHECK_SNAPSHOTS,
                tasks=train_tasks, label=FIT_CHECK_LABEL, split="train",
            )  # fmt: skip
            remaining = _eval_remaining(fit) if trained else None
            n_fit = FIT_CHECK_SNAPSHOTS * episodes * len(train_tasks)
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


def format_plan(config: ReproduceConfig, stages: list[Stage]) -> str:
    lines = [
        f"reproduce {config.suite}, recipe {config.recipe}, columns {', '.join(config.columns)}"
        + (f", hold-out {config.hold_out}" if config.hold_out else "")
        + f" -> {config.out}"
    ]
    todo = 0.0
    for stage in stages:
        state = "done" if stage.done else f"~{clock(stage.estimate_s)}"
        if not stage.done:
            todo += stage.estimate_s
        lines.append(f"  {stage.name:<34} {state:>12}  {stage.detail}")
    lines.append(f"  estimated total for what is left: {clock(todo)} (2-core CPU figures)")
    return "\n".join(lines)

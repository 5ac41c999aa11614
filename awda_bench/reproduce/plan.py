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
from awda_bench.reproduce.costs import clock, costs_for

if TYPE_CHECKING:
    from awda_bench.suites import Suite
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


def train_target(recipe_name: str, steps: int | None, suite: str) -> int:
    """Steps a column trains to: ``--steps``, else the recipe's on ``suite``."""
    from awda_bench.training.recipe import load_recipe

    return steps if steps is not None else load_recipe(recipe_name).for_suite(suite).train.max_steps


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


def _eval_tasks(suite: Suite, hold_out: str | None) -> tuple[list[int], int]:
    """``run --task`` restriction and the number of evaluation units (tasks or families)."""
    tasks = list(suite.eval_tasks)
    if hold_out is not None:
        families = sorted({t.family for t in suite.tasks})
        if hold_out not in families:
            raise UnknownChoiceError("--hold-out family", hold_out, families)
        tasks = [t for t in tasks if t.family == hold_out]
        if not tasks:
            raise UsageError(f"--hold-out {hold_out}: suite {suite.name!r} evaluates no such task")
        return [t.index for t in tasks], 1
    units = len({t.family for t in tasks}) if suite.episode_unit == "family" else len(tasks)
    return [], units


def _collect_stage(name: str, collect: CollectConfig, total: int, noun: str, done: bool) -> Stage:
    """``collect NAME``: ``collect``'s command, ``total`` episodes, the ones still to record timed."""
    left = _collect_remaining(collect)
    estimate = left * costs_for(collect.suite).collect_episode_s * 2 / collect.workers
    detail = f"{total} {noun}" + (f", {left} left" if 0 < left < total else "")
    return Stage(name, _collect_argv(collect), estimate, done, detail, collect)


def _eval_stage(key: str, evaluate: SweepConfig, left: int, arch: str, detail: str) -> Stage:
    """``evaluate KEY``: ``evaluate``'s ``run`` command, ``left`` episodes to play (done at 0)."""
    estimate = left * costs_for(evaluate.suite).eval_episode_s[arch] / evaluate.workers
    return Stage(f"evaluate {key}", _run_argv(evaluate), estimate, left == 0, detail, evaluate)


def _check_config(config: ReproduceConfig) -> None:
    """One-line errors for a suite, worker count, grasp rule or hold-out ``reproduce`` cannot run."""
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
    if config.val_data is not None and config.hold_out is not None:
        raise UsageError(
            "--val-data and --hold-out both name the validation set (--hold-out validates on the "
            "held-out family); drop --val-data"
        )
    if config.seed is not None and config.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {config.seed}")


@dataclass(frozen=True)
class _Plan:
    """What every stage of one ``reproduce`` plan reads (:func:`plan_stages`)."""

    config: ReproduceConfig
    suite: Suite
    recipe: Recipe
    data: Path
    """The training collection."""
    val: list[str]
    """``train``'s ``--val-data`` arguments (none with a hold-out family)."""
    synthesize: int
    n_train: int
    """Episodes of the training collection, synthesized ones included."""
    target: int
    """Training steps."""
    tasks: list[int]
    """``run --task`` restriction (empty: the suite's evaluation tasks)."""
    units: int
    """Evaluation units: held-out tasks or families."""
    episodes: int
    """Episodes per unit."""

    @property
    def runs(self) -> Path:
        return self.config.out / "runs"


def _collect_stages(config: ReproduceConfig, suite: Suite) -> tuple[list[Stage], _Plan]:
    """The training collection's stage and, without a hold-out family, the validation one's;
    and the plan the later stages read."""
    from awda_bench.data.plan import split_tasks
    from awda_bench.training.recipe import load_recipe

    data, test = train_data(config), config.out / "data" / "test"
    synthesize = (
        default_synthesize(config.suite) if config.synthesize is None else config.synthesize
    )
    n_train = len(split_tasks(suite, "train")) * config.demos_per_task * 2 + synthesize
    collect_train = CollectConfig(
        suite=config.suite, split="train", embodiment="both",
        episodes_per_task=config.demos_per_task, synthesize=synthesize, out=data,
        workers=config.workers, progress=config.progress,
    )  # fmt: skip
    stages = [
        _collect_stage(
            "collect train", collect_train, n_train, "episodes",
            _collection_done(data, "train", config.demos_per_task, synthesize),
        )
    ]  # fmt: skip
    val: list[str] = []
    if config.val_data is not None:
        val = ["--val-data", str(config.val_data)]  # train checks it is a complete test split
    elif config.hold_out is None:
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
    target = train_target(config.recipe, config.steps, config.suite)
    recipe = load_recipe(config.recipe)
    tasks, units = _eval_tasks(suite, config.hold_out)
    plan = _Plan(
        config=config, suite=suite, recipe=recipe, data=data, val=val, synthesize=synthesize,
        n_train=n_train, target=target, tasks=tasks, units=units,
        episodes=config.episodes if config.episodes is not None else suite.episodes_per_task,
    )  # fmt: skip
    return stages, plan


def _train_argv(plan: _Plan, key: str, ckpt: Path) -> list[str]:
    """``train``'s command for column ``key`` into ``ckpt``."""
    config, column = plan.config, COLUMN_KEYS[key]
    argv = [
        "train", "--method", column.method, "--data", str(plan.data), "--out", str(ckpt),
        "--recipe", config.recipe, *plan.val, *_quiet(config.progress),
    ]  # fmt: skip
    if column.ablation is not None:
        argv += ["--ablation", column.ablation]
    if config.hold_out is not None:
        argv += ["--hold-out", config.hold_out]
    if config.steps is not None:
        argv += ["--steps", str(config.steps)]
    if config.seed is not None:
        argv += ["--seed", str(config.seed)]
    if config.threads is not None:
        argv += ["--threads", str(config.threads)]
    return argv


def _train_costs(plan: _Plan, key: str, planned_caches: set[str]) -> tuple[float, float]:
    """Seconds per training step of column ``key`` and seconds to encode the feature-cache parts
    it needs that neither exist nor an earlier column of this plan encodes (added to
    ``planned_caches``)."""
    column = COLUMN_KEYS[key]
    costs = costs_for(plan.config.suite)
    factor = costs.paper_step_factor if plan.config.recipe == "paper" else 1.0
    step_s, encode_s = costs.train_step_s[column.arch] * factor, 0.0
    frozen = plan.recipe.model.trunk.freeze_backbone
    pairs = (plan.n_train - plan.synthesize) / 2
    # frames to encode into the cache: (part, frames), the synthesized episodes' own part
    parts: list[tuple[str, float]] = []
    cache_kind = "awda" if column.arch == "awda" else "tosvi"  # T-OSVI-style nets share one
    if frozen and column.arch == "awda":  # cached features; the cache is encoded once
        step_s = costs.frozen_step_s
        # o_1 of every agent episode, the demo frames of every demonstrator and synthesized one
        parts = [(cache_kind, pairs * 11), (f"{cache_kind}+synthesized", plan.synthesize * 10)]
    elif frozen:  # T-OSVI over cached (pooled) maps: every agent frame is encoded once
        from awda_bench.training.run import frame_stack_of

        one_frame = frame_stack_of(plan.recipe, column) == 1
        step_s = costs.frozen_tosvi_one_frame_step_s if one_frame else (
            costs.frozen_tosvi_step_s[column.arch]
        )  # fmt: skip
        parts = [
            (cache_kind, pairs * (costs.agent_episode_steps + 10)),
            (f"{cache_kind}+synthesized", plan.synthesize * costs.synthesized_episode_frames),
        ]
    if not column.synthesized:
        parts = parts[:1]
    for part, frames in parts:
        built = _cache_built(plan.data, plan.recipe, column.arch, synthesized=part != cache_kind)
        if part not in planned_caches and not built:
            encode_s += costs.encode_frame_s * frames
        planned_caches.add(part)
    return step_s, encode_s


def _column_stages(plan: _Plan, key: str, planned_caches: set[str]) -> list[Stage]:
    """A trained column's stages: train, evaluate, and for Full-1 the fit check on training
    tasks."""
    config, column = plan.config, COLUMN_KEYS[key]
    ckpt = config.out / "checkpoints" / key
    step_s, encode_s = _train_costs(plan, key, planned_caches)
    trains = plan.recipe.for_suite(config.suite).with_schedule(config.steps, None, config.seed)
    _check_trained_recipe(ckpt, trains)  # as ``train`` compares: --seed replaces [train] seed
    steps_done, target = _steps_done(ckpt), plan.target
    stages = [
        Stage(
            f"train {key}",
            _train_argv(plan, key, ckpt),
            max(0, target - steps_done) * step_s + (encode_s if steps_done == 0 else 0.0),
            steps_done >= target,
            f"{column.name}: {target} steps"
            + (f", resumes at {steps_done}" if 0 < steps_done < target else ""),
        )
    ]  # fmt: skip
    evaluate = SweepConfig(
        suite=config.suite, method=eval_method(column.arch, config.grasp_select), out=plan.runs,
        checkpoints=ckpt, snapshots=config.snapshots, episodes=config.episodes,
        workers=config.workers, tasks=tuple(plan.tasks), progress=config.progress, label=key,
    )  # fmt: skip
    n_eval = config.snapshots * plan.episodes * plan.units
    trained = steps_done >= target
    # until training is done the snapshots to evaluate are not all there: plan all of them
    remaining = _eval_remaining(evaluate) if trained else None
    stages.append(
        _eval_stage(
            key, evaluate, n_eval if remaining is None else remaining, column.arch,
            f"{config.snapshots} snapshots x {plan.episodes} episodes x {plan.units} "
            f"{'family' if plan.suite.episode_unit == 'family' else 'tasks'}",
        )
    )  # fmt: skip
    if key == FIT_CHECK_COLUMN and config.fit_check and config.hold_out is None:
        stages.append(_fit_check_stage(plan, key, evaluate, trained))
    return stages


def _fit_check_stage(plan: _Plan, key: str, evaluate: SweepConfig, trained: bool) -> Stage:
    """Column ``key``'s last snapshots on the held-out tasks' training siblings: did it fit?"""
    train_tasks = fit_check_tasks(plan.suite)
    fit = replace(
        evaluate, out=plan.config.out / "runs-train-tasks", snapshots=FIT_CHECK_SNAPSHOTS,
        tasks=train_tasks, label=FIT_CHECK_LABEL, split="train",
    )  # fmt: skip
    remaining = _eval_remaining(fit) if trained else None
    n_fit = FIT_CHECK_SNAPSHOTS * plan.episodes * len(train_tasks)
    return Stage(
        f"evaluate {key} on training tasks",
        _run_argv(fit),
        (n_fit if remaining is None else remaining)
        * costs_for(plan.config.suite).eval_episode_s[COLUMN_KEYS[key].arch]
        / plan.config.workers,
        remaining == 0,
        f"tasks {', '.join(map(str, train_tasks))}: did it fit?",
        fit,
    )


def _variant_stage(plan: _Plan, key: str) -> Stage:
    """An evaluation-only column (another action rule over a trained column's snapshots)."""
    config, variant = plan.config, EVAL_VARIANTS[key]
    ckpt = config.out / "checkpoints" / variant.trained
    evaluate = SweepConfig(
        suite=config.suite, method=variant.method, out=plan.runs, checkpoints=ckpt,
        snapshots=config.snapshots, episodes=config.episodes, workers=config.workers,
        tasks=tuple(plan.tasks), progress=config.progress, label=key,
    )  # fmt: skip
    trained = _steps_done(ckpt) >= plan.target
    remaining = _eval_remaining(evaluate) if trained else None
    n_eval = config.snapshots * plan.episodes * plan.units
    return _eval_stage(
        key, evaluate, n_eval if remaining is None else remaining,
        COLUMN_KEYS[variant.trained].arch,
        f"{variant.trained}'s snapshots with --method {variant.method}",
    )  # fmt: skip


def _report_stages(out: Path, fit_checked: bool) -> list[Stage]:
    """The report over the evaluations, and the fit check's where there is one."""
    runs = out / "runs"
    stages = [
        Stage(
            "report",
            ["report", "--runs", str(runs), "--out", str(out / "report")],
            10.0,
            False,
            "tables, figures, reproduce.md",
        )
    ]
    if fit_checked:
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


def plan_stages(config: ReproduceConfig) -> list[Stage]:
    """The pipeline for ``config``, each stage marked done or not (nothing runs here):
    collections, then per trained column its training, evaluation (and fit check), then the
    evaluation-only columns, then the reports."""
    from awda_bench.suites import load_suite

    _check_config(config)
    stages, plan = _collect_stages(config, load_suite(config.suite))
    planned_caches: set[str] = set()  # feature caches an earlier column of this plan encodes
    for key in (k for k in config.columns if k not in EVAL_VARIANTS):
        stages += _column_stages(plan, key, planned_caches)
    stages += [_variant_stage(plan, k) for k in config.columns if k in EVAL_VARIANTS]
    fit_checked = any(st.name.endswith("on training tasks") for st in stages)
    return stages + _report_stages(config.out, fit_checked)


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

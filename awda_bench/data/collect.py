"""``collect``: record every planned episode into DATA_DIR, resumably.

Order of work, so that bad input never touches DATA_DIR::

    plan (suite, split, tasks, seeds, definition)          may refuse; nothing written yet
    -> the workers' environment (Meta-World: .venv-metaworld) is there, else one line
    -> check DATA_DIR: writable; empty, or holding a manifest with the same fingerprint
    -> manifest.json (complete: false) -> per unit: finished file pair, or shards to resume from
    -> jobs for the missing attempts -> workers -> each result: shard or discard marker
       -> a unit with all its episodes: consolidated into <role>/<family>/task_XX.h5/.json
    -> manifest.json (counts, complete: true when every unit is finished)

Re-running the same command skips finished units and recorded attempts, re-records attempts that
were in flight or ended in errors, and never duplicates an episode. Timings are returned (and
printed by the command), never written into DATA_DIR, so two identical collections have identical
manifests.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from awda_bench.data.config import ROLE_SYNTHESIZED, CollectConfig
from awda_bench.data.extend import check_extension, extend_collection
from awda_bench.data.plan import CollectJob, CollectPlan, Unit, code_sha256, make_plan
from awda_bench.data.pool import InlineRunner, JobResult, JobRunner, ProcessRunner
from awda_bench.data.trajectory_file import (
    consolidate_unit,
    discard_path,
    kept_shard_count,
    load_unit_json,
    read_shard_meta,
    scan_unit,
    unit_is_complete,
    unit_paths,
    write_discard,
    write_json,
    write_shard,
)
from awda_bench.errors import CorruptFileError, ProtocolMismatchError, UsageError
from awda_bench.runtimes import worker_python

MANIFEST = "manifest.json"
"""The collection's manifest inside DATA_DIR."""

MANIFEST_FORMAT = "awda_bench.trajectories"
"""``manifest["format"]``: tells a collection apart from any other JSON."""


@dataclass
class CollectResult:
    """What one ``collect`` call did (timings are not written to DATA_DIR)."""

    planned: int
    """Episodes the collection must keep in all."""
    already: int = 0
    """Kept before this call (finished units and shards)."""
    kept: int = 0
    """Kept by this call."""
    discarded: int = 0
    """Attempts this call discarded (task failed / waypoint not reached)."""
    errors: int = 0
    """Attempts that raised or hung (retried by the next call)."""
    error_messages: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    """Wall time of the recording phase [s]."""
    episode_s: float = 0.0
    """Sum of recorded attempts' own wall times [s]."""
    render_s: float = 0.0
    """Of which spent rendering and encoding frames [s]."""
    frames: int = 0
    """Camera frames rendered by this call."""
    steps: int = 0
    """Control steps recorded by this call."""
    bytes_kept: int = 0
    """Bytes of the shards this call kept."""
    complete: bool = False
    """Every unit is finished."""
    extended: int = 0
    """Episodes this call took from ``config.extend_from`` (counted in :attr:`already`)."""
    warnings: list[str] = field(default_factory=list)
    """Things the user should know (e.g. a collection resumed under changed code)."""


def _describe(plan: CollectPlan, unit: Unit) -> str:
    if unit.role == ROLE_SYNTHESIZED:
        return (
            f"awda_bench collect: trajectory synthesis (free-space motion through 1-3 random "
            f"waypoints, agent embodiment) in scenes of {plan.suite.name} task {unit.task}"
        )
    return (
        f"awda_bench collect: privileged scripted expert, {unit.role} embodiment, "
        f"{plan.suite.name} task {unit.task} ({plan.suite.task(unit.task).name}), successful only"
    )


def _load_manifest(path: Path) -> dict[str, Any]:
    try:
        manifest = json.loads(path.read_text())
        if manifest.get("format") != MANIFEST_FORMAT:
            raise ValueError(f"format is {manifest.get('format')!r}, not {MANIFEST_FORMAT!r}")
        return manifest
    except (OSError, ValueError) as exc:
        raise CorruptFileError(
            f"{path} is not a collect manifest ({exc}); point --out at a collect directory "
            "or at a new one"
        ) from exc


def check_data_dir(root: Path, plan: CollectPlan) -> list[str]:
    """Refuse a DATA_DIR that is a file, foreign, or holds another collection; nothing written.

    Returns the code hashes its manifest lists (empty for a new directory)."""
    if root.exists() and not root.is_dir():
        raise UsageError(f"--out {root} is a file, not a directory; choose a directory")
    if not root.is_dir():
        return []
    manifest_path = root / MANIFEST
    if manifest_path.is_file():
        manifest = _load_manifest(manifest_path)
        if manifest.get("fingerprint") != plan.fingerprint:
            theirs = manifest.get("definition", {})
            diff = sorted(
                k
                for k in set(theirs) | set(plan.definition)
                if theirs.get(k) != plan.definition.get(k)
            )
            raise ProtocolMismatchError(
                f"{root} holds another collection (fingerprint {manifest.get('fingerprint')}, "
                f"this command {plan.fingerprint}; differs in {', '.join(diff)}); repeat its "
                "original options to resume it, or collect into a new --out"
            )
        return [str(c) for c in manifest.get("code_sha256", [])]
    if any(root.iterdir()):
        raise UsageError(
            f"--out {root} is not empty and holds no {MANIFEST}: not a collect directory; "
            "choose an empty or new directory"
        )
    return []


def _manifest(
    plan: CollectPlan, units: list[dict[str, Any]], complete: bool, code: list[str]
) -> dict[str, Any]:
    by_role: dict[str, dict[str, int]] = {}
    for u in units:
        entry = by_role.setdefault(u["role"], {"planned": 0, "kept": 0, "discarded": 0})
        for key in entry:
            entry[key] += int(u[key])
    return {
        "format": MANIFEST_FORMAT,
        "fingerprint": plan.fingerprint,
        "definition": plan.definition,
        "complete": complete,
        "code_sha256": code,
        "counts": {
            "planned": sum(u["planned"] for u in units),
            "kept": sum(u["kept"] for u in units),
            "discarded": sum(u["discarded"] for u in units),
            "by_role": by_role,
        },
        "units": units,
    }


class _UnitState:
    def __init__(self, unit: Unit, kept: dict[int, Path], discarded: set[int]) -> None:
        self.unit = unit
        self.kept = kept
        self.discarded = discarded

    @property
    def finished(self) -> bool:
        return len(self.kept) >= self.unit.planned

    def job(self, plan: CollectPlan, config: CollectConfig) -> CollectJob:
        """The job recording this unit's next chunk."""
        return CollectJob(
            role=self.unit.role,
            task=self.unit.task,
            planned=self.unit.planned,
            kept=tuple(sorted(self.kept)),
            discarded=tuple(sorted(self.discarded)),
            max_attempts=plan.max_attempts(self.unit, config.max_attempts_factor),
            chunk=config.chunk_episodes,
        )


def collection_progress(config: CollectConfig) -> tuple[int, int]:
    """``(episodes already kept toward the plan, episodes planned)`` in ``config.out``: what a
    resumed ``collect`` starts its progress bar from, read without writing or opening a shard.
    A DATA_DIR ``collect`` would refuse (another collection, not a collect directory) is refused
    here the same way, so a plan (``reproduce --dry-run``) says so rather than counting it."""
    plan = make_plan(config)
    check_data_dir(config.out, plan)
    already = 0
    for unit in plan.units:
        if unit_is_complete(config.out, unit.name, unit.planned):
            already += unit.planned
        else:
            already += min(kept_shard_count(config.out, unit.name), unit.planned)
    return already, sum(u.planned for u in plan.units)


def run_collect(config: CollectConfig, runner: JobRunner | None = None) -> CollectResult:
    """Record every pending episode of ``config`` into ``config.out`` (see the module docstring)."""
    plan = make_plan(config)
    if runner is None:
        worker_python(plan.suite.simulator)  # its environment is missing: one line, nothing written
    root = config.out
    previous_code = check_data_dir(root, plan)
    result = CollectResult(planned=sum(u.planned for u in plan.units))
    if config.extend_from is not None:
        check_extension(config.extend_from, plan)  # refused: nothing written
        _start_manifest(root, plan, previous_code)  # a kill while seeding leaves a collect dir
        result.extended = extend_collection(config.extend_from, plan, root)
    states: dict[tuple[str, int], _UnitState] = {}
    jobs: list[CollectJob] = []
    finished: list[_UnitState] = []  # every attempt recorded, killed before consolidation
    for unit in plan.units:  # read what is there before writing anything
        if unit_is_complete(root, unit.name, unit.planned):
            result.already += unit.planned
            continue
        kept, discarded = scan_unit(root, unit.name)
        state = _UnitState(unit, kept, discarded)
        states[unit.key] = state
        result.already += min(len(kept), unit.planned)
        if state.finished:
            finished.append(state)
        else:
            jobs.append(state.job(plan, config))

    _start_manifest(root, plan, previous_code)
    for state in finished:
        _consolidate(root, plan, state)

    current = code_sha256()
    if previous_code and current not in previous_code and jobs:
        result.warnings.append(
            f"{root} was partly recorded by other code (code_sha256 "
            f"{', '.join(c[:12] for c in previous_code)}); the episodes recorded now use "
            f"{current[:12]} (the manifest and `dataset info` list every version)"
        )

    bar = tqdm(
        total=result.planned,
        initial=result.already,
        disable=not config.progress,
        unit="ep",
        desc=f"collect {plan.suite.name}/{config.split}",
        dynamic_ncols=True,
    )

    def on_result(res: JobResult) -> list[CollectJob]:
        state = states[res.job.unit]
        unit = state.unit
        for data in res.episodes:
            result.episode_s += data.timing.get("wall_s", 0.0)
            result.render_s += data.timing.get("render_s", 0.0)
            result.frames += int(data.timing.get("frames", 0))
            result.steps += data.steps
            if data.success:
                path = write_shard(root, unit.name, data)
                state.kept[data.job.attempt] = path
                result.kept += 1
                result.bytes_kept += path.stat().st_size
                bar.update(1)
            else:
                write_discard(root, unit.name, data)
                state.discarded.add(data.job.attempt)
                result.discarded += 1
        rate = result.frames / result.render_s if result.render_s else 0.0
        bar.set_postfix(discarded=result.discarded, errors=result.errors, fps=f"{rate:.0f}")
        if state.finished:
            _consolidate(root, plan, state)
            return []
        if res.error is not None:
            result.errors += 1
            last = (res.error or "").strip().splitlines()[-1:] or [""]
            message = f"{unit.name}: {last[0]}"
            result.error_messages.append(message)
            bar.write(f"error: {message}")
            return []
        if res.gave_up:
            result.errors += 1
            message = (
                f"{unit.name}: gave up after {res.job.max_attempts} attempts "
                f"({len(state.discarded)} failed); the expert is broken on this task"
            )
            result.error_messages.append(message)
            bar.write(f"error: {message}")
            return []
        return [state.job(plan, config)]  # the unit's next chunk

    t0 = time.perf_counter()
    try:
        if jobs:
            if runner is None and config.backend == "ray":
                from awda_bench.data.ray_runner import RayJobRunner

                simulator = plan.suite.simulator
                with RayJobRunner(
                    config, simulator, config.workers, address=config.ray_address
                ) as ray_runner:
                    ray_runner.run(jobs, on_result)
            else:
                if runner is None:
                    runner = (
                        InlineRunner(config)
                        if config.workers == 0
                        else ProcessRunner(config, plan.suite.simulator, config.workers)
                    )
                runner.run(jobs, on_result)
    finally:
        bar.close()
        result.wall_s = time.perf_counter() - t0
        result.complete = _write_final_manifest(root, plan)
    return result


def _start_manifest(root: Path, plan: CollectPlan, previous_code: list[str]) -> None:
    """The manifest of an unfinished collection (the directory is ``collect``'s from then on)."""
    try:
        root.mkdir(parents=True, exist_ok=True)
        write_json(root / MANIFEST, _manifest(plan, [], complete=False, code=previous_code))
    except OSError as exc:
        raise UsageError(
            f"cannot write to --out {root} ({exc.strerror or exc}); fix its permissions or "
            "choose another directory"
        ) from exc


def _consolidate(root: Path, plan: CollectPlan, state: _UnitState) -> None:
    unit = state.unit
    attempts = sorted(state.kept)[: unit.planned]
    discarded = [
        _read_discard(discard_path(root, unit.name, attempt)) for attempt in sorted(state.discarded)
    ]
    shards = [state.kept[a] for a in attempts]
    consolidate_unit(root, unit.name, shards, discarded, _describe(plan, unit))


def _read_discard(path: Path) -> dict[str, Any]:
    try:
        return dict(json.loads(path.read_text()))
    except (OSError, ValueError) as exc:
        raise CorruptFileError(
            f"{path} is unreadable ({exc}); delete it and re-run the same collect command"
        ) from exc


def _write_final_manifest(root: Path, plan: CollectPlan) -> bool:
    units: list[dict[str, Any]] = []
    code: set[str] = set()
    complete = True
    for unit in plan.units:
        h5_path, json_path = unit_paths(root, unit.name)
        entry: dict[str, Any] = {
            "role": unit.role,
            "task": unit.task,
            "family": unit.family,
            "file": str(h5_path.relative_to(root)),
            "planned": unit.planned,
            "kept": 0,
            "discarded": 0,
            "steps": 0,
            "complete": False,
        }
        if unit_is_complete(root, unit.name, unit.planned):
            payload = load_unit_json(json_path)
            code |= {str(e["code_sha256"]) for e in payload["episodes"] if "code_sha256" in e}
            entry.update(
                kept=len(payload["episodes"]),
                discarded=len(payload.get("discarded", [])),
                steps=sum(int(e["elapsed_steps"]) for e in payload["episodes"]),
                complete=True,
            )
        else:
            complete = False
            kept, discarded = scan_unit(root, unit.name)
            for shard in kept.values():
                episode, _ = read_shard_meta(shard)
                if "code_sha256" in episode:
                    code.add(str(episode["code_sha256"]))
            entry.update(kept=len(kept), discarded=len(discarded))
        units.append(entry)
    write_json(root / MANIFEST, _manifest(plan, units, complete, sorted(code)))
    return complete

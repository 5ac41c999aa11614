"""``collect --extend-from DIR``: start a larger collection from a finished smaller one.

An attempt's seed depends on (suite, base seed, task, attempt, split, role) alone
(:func:`awda_bench.data.plan.job_seed`), and a job replays its unit's earlier attempts before it
records (:class:`~awda_bench.data.plan.CollectJob`), so attempt ``i`` of a unit is the same episode
whatever the number of episodes the collection plans: a collection of N per task holds the first
attempts of one of M > N per task (measured on Meta-World: the 50-per-task collection's first
shards equal the 20-per-task one's episodes, actions identical). Extending copies the smaller
collection's kept episodes and discarded attempts into the new collection's partial directory, as
the new one would have recorded them, and ``collect`` then records only the rest::

    for each unit of the new plan with nothing of its own yet, finished in DIR:
        DIR/<unit>.h5 traj_i  -> OUT/.partial/<unit>/a<attempt>.h5     (the shard it came from)
        DIR/<unit>.json discarded[j] -> OUT/.partial/<unit>/a<attempt>.discard.json

The two collections must agree on everything but their size (the manifest's definition, less
``episodes_per_task`` and ``synthesize``), and no unit may shrink.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py

from awda_bench.data.plan import CollectPlan
from awda_bench.data.trajectory_file import (
    discard_path,
    load_unit_json,
    scan_unit,
    shard_path,
    unit_is_complete,
    unit_paths,
    write_json,
)
from awda_bench.errors import CorruptFileError, UsageError

SIZE_KEYS = ("episodes_per_task", "synthesize")
"""Definition fields an extension may change (upwards)."""


def _source_definition(source: Path) -> dict[str, Any]:
    """The finished source collection's definition; one-line errors otherwise."""
    manifest_path = source / "manifest.json"
    if not manifest_path.is_file():
        raise UsageError(
            f"--extend-from {source}: no manifest.json there; name a finished `collect` directory"
        )
    try:
        manifest = json.loads(manifest_path.read_text())
        definition, complete = dict(manifest["definition"]), bool(manifest["complete"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CorruptFileError(f"{manifest_path} is unreadable ({exc})") from exc
    if not complete:
        raise UsageError(
            f"--extend-from {source}: that collection is unfinished; finish it first (re-run its "
            "collect command) or extend from another"
        )
    return definition


def check_extension(source: Path, plan: CollectPlan) -> None:
    """Refuse (one line) a source that is not ``plan``'s collection made smaller and finished."""
    theirs = _source_definition(source)
    ours = plan.definition
    differ = sorted(
        key
        for key in set(theirs) | set(ours)
        if key not in SIZE_KEYS and theirs.get(key) != ours.get(key)
    )
    if differ:
        raise UsageError(
            f"--extend-from {source}: another collection (it differs in {', '.join(differ)}); "
            "extend only from one made with the same options but fewer episodes"
        )
    smaller = [k for k in SIZE_KEYS if int(theirs.get(k, 0)) > int(ours.get(k, 0))]
    if smaller:
        raise UsageError(
            f"--extend-from {source}: it holds more than this collection plans "
            f"({', '.join(f'{k} {theirs[k]} > {ours[k]}' for k in smaller)}); plan at least as "
            "many"
        )


def _split_unit(source: Path, out: Path, unit_name: str) -> int:
    """Write a finished source unit's episodes and discards as ``out``'s shards; kept count."""
    h5_path, json_path = unit_paths(source, unit_name)
    payload = load_unit_json(json_path)
    env_info = json.dumps(payload["env_info"])
    try:
        with h5py.File(h5_path, "r") as src:
            for i, episode in enumerate(payload["episodes"]):
                path = shard_path(out, unit_name, int(episode["attempt"]))
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_name(f".{path.name}.tmp")
                with h5py.File(tmp, "w", track_order=True) as shard:
                    src.copy(src[f"traj_{i}"], shard, name="traj_0")
                    shard.attrs["episode"] = json.dumps({**episode, "episode_id": 0})
                    shard.attrs["env_info"] = env_info
                tmp.replace(path)
    except (OSError, KeyError, ValueError) as exc:
        raise CorruptFileError(f"{h5_path} is unreadable ({exc}); extend from another") from exc
    for record in payload.get("discarded", []):
        write_json(discard_path(out, unit_name, int(record["attempt"])), record)
    return len(payload["episodes"])


def extend_collection(source: Path, plan: CollectPlan, out: Path) -> int:
    """Seed ``out`` (the collection ``plan`` describes) with ``source``'s episodes: every unit
    that has nothing in ``out`` yet and is finished in ``source``. Returns the episodes seeded (0
    on a re-run: what was seeded then is ``out``'s own now). The caller has run
    :func:`check_extension` (``run_collect`` does, before it writes anything)."""
    seeded = 0
    for unit in plan.units:
        if unit_is_complete(out, unit.name, unit.planned):
            continue
        kept, discarded = scan_unit(out, unit.name)
        if kept or discarded:
            continue
        h5_path, json_path = unit_paths(source, unit.name)
        if h5_path.is_file() and json_path.is_file():
            seeded += _split_unit(source, out, unit.name)
    return seeded

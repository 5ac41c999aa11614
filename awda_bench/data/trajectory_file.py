"""The trajectory files: ManiSkill's HDF5 + JSON conventions, plus this project's extras.

One file pair per unit, ``<role>/<family>/task_XX.h5`` and ``.json`` (what ManiSkill's
``RecordEpisode`` writes and ``replay_trajectory`` reads)::

    traj_<i>/                              i = 0 .. N-1, kept episodes in attempt order
        actions             (T, 4) float32     env actions (dx, dy, dz, grip; > 0 closes)
        terminated, truncated, success  (T,) bool
        env_states/...      (T+1, D) float32   the tree of env.get_state_dict()
        obs/agent/qpos, qvel                     (T+1, dof) float32
        obs/extra/tcp_pose                       (T+1, 7) float32  world frame: xyz [m], wxyz
        obs/extra/gripper_opening_m              (T+1, 1) float32  [m]
        obs/sensor_data/third_person/rgb_jpeg    (T+1,) variable-length uint8: JPEG bytes (RGB)
        obs/sensor_data/wrist_depth/depth        (T+1, Hd, Wd, 1) uint16 [mm] (agent roles)
        obs/sensor_param/<camera>/...            (T+1, ...) float32 intrinsics / extrinsics
        attributes/grasp, attributes/press       (T,) bool   mined (awda_bench.mining)
        truth/<name>                             (T,) bool   simulator truth (grasp, press)

    task_XX.json: {"env_info": {env_id, env_kwargs, max_episode_steps}, "source_type",
                   "source_desc", "episodes": [{episode_id, episode_seed, reset_kwargs,
                   control_mode, elapsed_steps, success, info, <awda metadata>}, ...]}

Index ``t`` of per-action arrays belongs to the state *before* action ``t``. While collecting,
each attempt is written on its own as a *shard* (``.partial/<unit>/a00007.h5`` holding ``traj_0``
and its JSON in the file's attributes; discards as ``a00007.discard.json``), each by writing a
temporary file and renaming it, so a killed run leaves only whole shards. A finished unit is
consolidated into its file pair the same way, then its shards are removed.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from awda_bench.data.recorder import EpisodeData, encode_jpeg
from awda_bench.errors import CorruptFileError

PARTIAL_DIR = ".partial"
"""Shards of unfinished units live under ``DATA_DIR/.partial/``."""

SOURCE_TYPE = "motionplanning"
"""ManiSkill's ``source_type`` category closest to a privileged scripted expert."""

_JPEG = h5py.vlen_dtype(np.dtype(np.uint8))
_GZIP = {"compression": "gzip", "compression_opts": 4}


def _write_tree(group: h5py.Group, name: str, tree: Any, compress: bool = False) -> None:
    if isinstance(tree, dict):
        sub = group.create_group(name, track_order=True)
        for key, value in tree.items():
            _write_tree(sub, key, value, compress)
        return
    array = np.asarray(tree)
    if compress and array.size > 64:
        group.create_dataset(name, data=array, chunks=True, track_times=False, **_GZIP)
    else:
        group.create_dataset(name, data=array, track_times=False)


def write_traj_group(group: h5py.Group, data: EpisodeData) -> None:
    """Fill ``group`` (a ``traj_<i>``) with the episode's arrays (layout in the module docstring)."""
    T = data.steps
    group.create_dataset("actions", data=data.actions, track_times=False)
    group.create_dataset("terminated", data=np.zeros(T, dtype=bool), track_times=False)
    truncated = np.zeros(T, dtype=bool)
    group.create_dataset("truncated", data=truncated, track_times=False)
    group.create_dataset("success", data=data.success_steps, track_times=False)
    _write_tree(group, "env_states", data.env_states)
    obs = group.create_group("obs", track_order=True)
    for key, value in data.obs.items():
        _write_tree(obs, key, value, compress=True)
    sensor_data = obs.require_group("sensor_data").require_group("third_person")
    jpeg = sensor_data.create_dataset("rgb_jpeg", shape=(len(data.rgb_jpeg),), dtype=_JPEG)
    for i, blob in enumerate(data.rgb_jpeg):
        jpeg[i] = np.frombuffer(blob, dtype=np.uint8)
    _write_tree(group, "attributes", data.attributes)
    _write_tree(group, "truth", data.truth)


def episode_json(data: EpisodeData, episode_id: int) -> dict[str, Any]:
    """The JSON entry of one episode (ManiSkill's keys first, then ours)."""
    return {"episode_id": episode_id, **data.meta}


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary sibling of ``path``; rename it to ``path`` when the block succeeds."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.unlink(missing_ok=True)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_json(path: Path, payload: Any) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(payload, indent=2, sort_keys=False) + "\n")


def shard_dir(root: Path, unit_name: str) -> Path:
    return root / PARTIAL_DIR / unit_name


def shard_path(root: Path, unit_name: str, attempt: int) -> Path:
    return shard_dir(root, unit_name) / f"a{attempt:05d}.h5"


def discard_path(root: Path, unit_name: str, attempt: int) -> Path:
    return shard_dir(root, unit_name) / f"a{attempt:05d}.discard.json"


def write_shard(root: Path, unit_name: str, data: EpisodeData) -> Path:
    """Write a kept attempt as its own file (``traj_0`` + metadata attributes), atomically."""
    path = shard_path(root, unit_name, data.job.attempt)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w", track_order=True) as f:
            write_traj_group(f.create_group("traj_0", track_order=True), data)
            f.attrs["episode"] = json.dumps(episode_json(data, 0))
            f.attrs["env_info"] = json.dumps(data.env_info)
    return path


def write_discard(root: Path, unit_name: str, data: EpisodeData) -> Path:
    """Record a failed attempt (only its description: it is not kept)."""
    path = discard_path(root, unit_name, data.job.attempt)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, {"attempt": data.job.attempt, "seed": data.job.seed, **data.meta})
    return path


def _corrupt(path: Path, why: object) -> CorruptFileError:
    return CorruptFileError(
        f"{path} is unreadable ({why}); delete it and re-run the same collect command to "
        "record that episode again (everything else is kept)"
    )


def read_shard_meta(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(episode JSON, env_info)`` of a shard; :class:`CorruptFileError` if it is not one."""
    try:
        with h5py.File(path, "r") as f:
            if "traj_0" not in f or "actions" not in f["traj_0"]:
                raise KeyError("no traj_0/actions")
            return json.loads(f.attrs["episode"]), json.loads(f.attrs["env_info"])
    except (OSError, KeyError, ValueError) as exc:
        raise _corrupt(path, exc) from exc


def scan_unit(root: Path, unit_name: str) -> tuple[dict[int, Path], set[int]]:
    """Kept shards by attempt and discarded attempts found for an unfinished unit.

    Left-over temporary files of a killed run are removed; every shard's metadata is read, so a
    damaged one is reported here, before any work.
    """
    directory = shard_dir(root, unit_name)
    kept: dict[int, Path] = {}
    discarded: set[int] = set()
    if not directory.is_dir():
        return kept, discarded
    for path in sorted(directory.iterdir()):
        name = path.name
        if name.startswith(".") and name.endswith(".tmp"):
            path.unlink()
        elif name.endswith(".discard.json"):
            discarded.add(int(name[1:6]))
        elif name.endswith(".h5"):
            read_shard_meta(path)
            kept[int(name[1:6])] = path
    return kept, discarded


def kept_shard_count(root: Path, unit_name: str) -> int:
    """How many kept shards an unfinished unit has, by name alone: read-only (unlike
    :func:`scan_unit`, it neither removes temporary files nor opens a shard), so a plan may call
    it while a collection writes there."""
    directory = shard_dir(root, unit_name)
    if not directory.is_dir():
        return 0
    return sum(
        1 for p in directory.iterdir() if p.name.endswith(".h5") and not p.name.startswith(".")
    )


def unit_paths(root: Path, unit_name: str) -> tuple[Path, Path]:
    """``(h5, json)`` of a finished unit."""
    return root / f"{unit_name}.h5", root / f"{unit_name}.json"


def unit_is_complete(root: Path, unit_name: str, planned: int) -> bool:
    """True when the unit's file pair exists and lists ``planned`` episodes."""
    h5_path, json_path = unit_paths(root, unit_name)
    if not (h5_path.is_file() and json_path.is_file()):
        return False
    try:
        episodes = json.loads(json_path.read_text())["episodes"]
    except (OSError, ValueError, KeyError) as exc:
        raise _corrupt(json_path, exc) from exc
    return len(episodes) == planned


def consolidate_unit(
    root: Path, unit_name: str, shards: list[Path], discarded: list[dict[str, Any]], desc: str
) -> tuple[Path, Path]:
    """Merge a finished unit's shards (in attempt order) into its ManiSkill file pair.

    The ``.h5`` is renamed into place before the ``.json``: a unit counts as finished only
    once its JSON exists, so a kill in between re-consolidates from the shards, which are
    removed last.
    """
    h5_path, json_path = unit_paths(root, unit_name)
    h5_path.parent.mkdir(parents=True, exist_ok=True)
    episodes: list[dict[str, Any]] = []
    env_info: dict[str, Any] | None = None
    with atomic_path(h5_path) as tmp:
        with h5py.File(tmp, "w", track_order=True) as out:
            for i, shard in enumerate(shards):
                try:
                    with h5py.File(shard, "r") as src:
                        src.copy(src["traj_0"], out, name=f"traj_{i}")
                        episode = json.loads(src.attrs["episode"])
                        env_info = json.loads(src.attrs["env_info"])
                except (OSError, KeyError, ValueError) as exc:
                    raise _corrupt(shard, exc) from exc
                episode["episode_id"] = i
                episodes.append(episode)
    payload = {
        "env_info": env_info,
        "source_type": SOURCE_TYPE,
        "source_desc": desc,
        "episodes": episodes,
        "discarded": discarded,
    }
    json_path.unlink(missing_ok=True)
    write_json(json_path, payload)
    shutil.rmtree(shard_dir(root, unit_name), ignore_errors=False)
    return h5_path, json_path


def load_unit_json(json_path: Path) -> dict[str, Any]:
    """A unit's JSON; :class:`CorruptFileError` naming the file if unreadable."""
    try:
        payload = json.loads(json_path.read_text())
        payload["episodes"]  # noqa: B018 (presence check)
        return payload
    except (OSError, ValueError, KeyError) as exc:
        raise _corrupt(json_path, exc) from exc


def decode_jpeg(blob: np.ndarray) -> np.ndarray:
    """JPEG bytes (uint8 array) -> (H, W, 3) uint8 RGB."""
    import cv2

    image = cv2.imdecode(np.asarray(blob, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError("not a JPEG image")
    return np.ascontiguousarray(image[..., ::-1])


DEFAULT_JPEG_QUALITY = 90
"""``collect --jpeg-quality``'s default: what snapshots trained before the quality was recorded
in their training record were trained on."""


def as_stored(frames: np.ndarray, quality: int) -> np.ndarray:
    """``(..., H, W, 3)`` uint8 RGB frames as a collection stores and reads them back: encoded as
    JPEG at ``quality``, decoded. Learned policies see their live frames so, as their training
    frames were: on frozen ImageNet features the compression alone moved the ``demo-pointer``
    head's object choice from 0.68 (raw renders) to 0.93 (stored) within a cell of the target, on
    the same 40 held-out episodes (reports/learned/recipe-study.md, session 11)."""
    flat = np.asarray(frames, dtype=np.uint8).reshape(-1, *np.shape(frames)[-3:])
    out = [decode_jpeg(np.frombuffer(encode_jpeg(f, quality), np.uint8)) for f in flat]
    return np.stack(out).reshape(np.shape(frames))


def trained_jpeg_quality(training: dict[str, Any] | None) -> int:
    """The JPEG quality of the collection a snapshot was trained on, from its training record
    (``train`` writes ``data.jpeg_quality``); :data:`DEFAULT_JPEG_QUALITY` for older records."""
    recorded = ((training or {}).get("data") or {}).get("jpeg_quality")
    return int(recorded) if recorded is not None else DEFAULT_JPEG_QUALITY

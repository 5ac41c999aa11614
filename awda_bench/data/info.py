"""``dataset info``: what a DATA_DIR holds (counts, lengths, disk size) and a contact sheet."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.data.config import ROLES
from awda_bench.data.datasets import CollectedData, EpisodeRef
from awda_bench.errors import CorruptFileError

MAX_SHEET_FRAME_WIDTH_PX = 200
"""Frames wider than this are drawn at half size on the contact sheet."""


@dataclass(frozen=True)
class UnitRow:
    """One (role, task) of the collection."""

    role: str
    task: int
    family: str
    episodes: int
    discarded: int
    steps_min: int
    steps_mean: float
    steps_max: int
    bytes: int


@dataclass
class DatasetInfo:
    root: Path
    fingerprint: str
    suite: str
    split: str
    complete: bool
    rows: list[UnitRow] = field(default_factory=list)
    disk_bytes: int = 0
    """Every file under DATA_DIR [bytes]."""
    code_sha256: list[str] = field(default_factory=list)
    """Hashes of the code that recorded the episodes (more than one: a mixed collection)."""

    def totals(self) -> dict[str, dict[str, float]]:
        """Per role: episodes, discarded, steps, bytes per episode."""
        out: dict[str, dict[str, float]] = {}
        for row in self.rows:
            t = out.setdefault(row.role, {"episodes": 0, "discarded": 0, "steps": 0, "bytes": 0})
            t["episodes"] += row.episodes
            t["discarded"] += row.discarded
            t["steps"] += row.steps_mean * row.episodes
            t["bytes"] += row.bytes
        return out

    def format(self) -> str:
        lines = [
            f"{self.root}: suite {self.suite}, split {self.split}, fingerprint {self.fingerprint}, "
            f"{'complete' if self.complete else 'INCOMPLETE'}, {self.disk_bytes / 1e6:.1f} MB on disk"
        ]
        lines.append(
            f"{'role':<13}{'task':>5} {'family':<13}{'episodes':>9}{'discarded':>10}"
            f"{'steps min/mean/max':>20}{'MB/episode':>11}"
        )
        for r in self.rows:
            per = r.bytes / r.episodes / 1e6 if r.episodes else 0.0
            lines.append(
                f"{r.role:<13}{r.task:>5} {r.family:<13}{r.episodes:>9}{r.discarded:>10}"
                f"{f'{r.steps_min}/{r.steps_mean:.0f}/{r.steps_max}':>20}{per:>11.2f}"
            )
        versions = ", ".join(c[:12] for c in self.code_sha256) or "unknown"
        mixed = " (WARNING: mixed collection)" if len(self.code_sha256) > 1 else ""
        lines.append(f"recorded by code {versions}{mixed}")
        for role, t in self.totals().items():
            n = int(t["episodes"])
            per = t["bytes"] / n / 1e6 if n else 0.0
            lines.append(
                f"{role}: {n} episodes ({int(t['discarded'])} discarded), "
                f"{int(t['steps'])} steps, {per:.2f} MB/episode"
            )
        return "\n".join(lines)


def dataset_info(data: CollectedData) -> DatasetInfo:
    """Counts and sizes from the manifest and the unit files (frames are not decoded)."""
    manifest = data.manifest
    definition: dict[str, Any] = manifest.get("definition", {})
    info = DatasetInfo(
        root=data.root,
        fingerprint=str(manifest.get("fingerprint")),
        suite=str(definition.get("suite")),
        split=str(definition.get("split")),
        complete=bool(manifest.get("complete")),
        code_sha256=[str(c) for c in manifest.get("code_sha256", [])],
    )
    by_unit: dict[tuple[str, int], list[EpisodeRef]] = {}
    for e in data.episodes:
        by_unit.setdefault((e.role, e.task), []).append(e)
    for unit in manifest["units"]:
        episodes = by_unit.get((unit["role"], int(unit["task"])), [])
        steps = np.asarray([e.steps for e in episodes] or [0])
        h5 = data.root / unit["file"]
        size = sum(p.stat().st_size for p in (h5, h5.with_suffix(".json")) if p.is_file())
        info.rows.append(
            UnitRow(
                role=unit["role"],
                task=int(unit["task"]),
                family=unit["family"],
                episodes=len(episodes),
                discarded=int(unit.get("discarded", 0)),
                steps_min=int(steps.min()),
                steps_mean=float(steps.mean()),
                steps_max=int(steps.max()),
                bytes=size,
            )
        )
    info.disk_bytes = sum(p.stat().st_size for p in data.root.rglob("*") if p.is_file())
    return info


def verify(data: CollectedData) -> int:
    """Read every array and decode every frame; :class:`CorruptFileError` names the first bad
    file. Returns the number of frames decoded."""
    frames = 0
    for ref in data.episodes:
        group = data.group(ref)
        T = ref.steps
        if group["actions"].shape != (T, 4):
            raise CorruptFileError(
                f"{ref.file}:{ref.traj} has actions {group['actions'].shape}, expected ({T}, 4); "
                "delete the file and re-run the collect command"
            )
        data.tcp_pos(ref)
        data.attributes(ref, ("grasp", "press"))
        frames += len(data.frames(ref, range(T + 1)))
        if "wrist_depth" in group["obs/sensor_data"]:
            data.depth_m(ref, range(T + 1))
    return frames


def contact_sheet(
    data: CollectedData, path: Path, episodes_per_role: int = 4, frames_per_episode: int = 5
) -> Path:
    """A PNG grid: per role, up to ``episodes_per_role`` episodes (distinct tasks first), each a
    row of ``frames_per_episode`` frames from first to last, labelled ``role task episode``."""
    import cv2

    rows: list[np.ndarray] = []
    for role in ROLES:
        refs = [e for e in data.episodes if e.role == role]
        chosen: list[EpisodeRef] = []
        seen: set[int] = set()
        for ref in refs:  # one per task first, then fill up
            if ref.task not in seen and len(chosen) < episodes_per_role:
                chosen.append(ref)
                seen.add(ref.task)
        chosen += [r for r in refs if r not in chosen][: episodes_per_role - len(chosen)]
        for ref in chosen:
            index = np.linspace(0, ref.steps, frames_per_episode).round().astype(int)
            frames = data.frames(ref, index)
            if frames.shape[2] > MAX_SHEET_FRAME_WIDTH_PX:  # halve big frames: a smaller PNG
                h, w = frames.shape[1] // 2, frames.shape[2] // 2
                frames = np.stack(
                    [cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) for f in frames]
                )
            row = np.concatenate(list(frames), axis=1)
            label = f"{role} task {ref.task} {ref.traj} ({ref.steps} steps)"
            cv2.putText(row, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 0), 1)
            rows.append(row)
    if not rows:
        raise CorruptFileError(f"{data.root} holds no episodes to draw")
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows]
    sheet = np.concatenate(rows, axis=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), sheet[..., ::-1]):
        raise OSError(f"could not write {path}")
    return path

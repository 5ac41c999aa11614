"""Snapshot files: one training state per file, ``<dir>/snapshot-<step, 9 digits>.pt``.

A snapshot is ``torch.save`` of a plain dict (read back with ``weights_only=True``, so loading a
file never runs pickled code)::

    format_version   int, FORMAT_VERSION
    arch             "awda" | "tosvi" | "tosvi-depth"
    config           the model config as a dict (config_to_dict)
    model_state      model.state_dict()
    optimizer_state  optimizer.state_dict() or None
    step             optimizer steps taken when the file was written
    rng_state        {"torch", "cuda", "numpy", "python"}: generator states to resume bit-exactly
    train_config     the TrainConfig as a dict, or None
    training         optional: what the run trained on and how (``train`` command: method,
                     ablation, Table S3 column, recipe, dataset fingerprint, hold-out), or absent

The evaluation harness identifies a snapshot by the SHA-256 of the file's bytes
(:attr:`Snapshot.sha256`), lists a run's snapshots with :func:`list_snapshots` and loads one with
:func:`load_snapshot` then :meth:`Snapshot.build_model`.
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import random
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.models.architectures import (
    ARCHITECTURES,
    ModelConfig,
    arch_of,
    build_model,
    config_for_arch,
)
from awda_bench.models.config import config_to_dict

FORMAT_VERSION = 1
"""Bumped whenever the dict layout changes; other versions are refused."""

SNAPSHOT_PATTERN = re.compile(r"^snapshot-(\d+)\.pt$")
"""File names :func:`list_snapshots` recognizes; the number is the training step."""

_REQUIRED_KEYS = (
    "format_version",
    "arch",
    "config",
    "model_state",
    "optimizer_state",
    "step",
    "rng_state",
)


def snapshot_path(directory: Path, step: int) -> Path:
    """``directory/snapshot-000010000.pt`` for step 10000."""
    return Path(directory) / f"snapshot-{step:09d}.pt"


def list_snapshots(directory: Path | str) -> list[Path]:
    """Snapshot files in ``directory`` ordered by training step (ascending); other files ignored.

    The step is read from the file name (``snapshot-<step>.pt``), so listing never opens a file.
    A missing directory has no snapshots.
    """
    directory = Path(directory)
    if not directory.is_dir():
        return []
    found: list[tuple[int, Path]] = []
    for path in directory.iterdir():
        match = SNAPSHOT_PATTERN.match(path.name)
        if match and path.is_file():
            found.append((int(match.group(1)), path))
    return [path for _, path in sorted(found)]


def capture_rng_state() -> dict[str, Any]:
    """The torch (CPU and CUDA), numpy and python generator states, in weights_only-safe types."""
    # The legacy global numpy generator is what third-party code draws from, so it is what we save.
    kind, keys, pos, has_gauss, cached = np.random.get_state()  # noqa: NPY002
    version, internal, gauss_next = random.getstate()
    return {
        "torch": torch.get_rng_state(),
        "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
        "numpy": {
            "kind": str(kind),
            "keys": torch.from_numpy(np.asarray(keys, dtype=np.int64)),
            "pos": int(pos),
            "has_gauss": int(has_gauss),
            "cached_gaussian": float(cached),
        },
        "python": [int(version), list(internal), gauss_next],
    }


def restore_rng_state(state: dict[str, Any]) -> None:
    """Inverse of :func:`capture_rng_state` (CUDA states only when CUDA is present)."""
    torch.set_rng_state(state["torch"])
    if state["cuda"] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])
    n = state["numpy"]
    np.random.set_state(  # noqa: NPY002
        (
            n["kind"],
            n["keys"].numpy().astype(np.uint32),
            n["pos"],
            n["has_gauss"],
            n["cached_gaussian"],
        )
    )
    version, internal, gauss_next = state["python"]
    random.setstate((version, tuple(internal), gauss_next))


@dataclass(frozen=True)
class Snapshot:
    """One snapshot file, read and checked."""

    path: Path
    """Where it was read from."""
    sha256: str
    """Hex SHA-256 of the file's bytes: the snapshot's identity for the evaluation harness."""
    arch: str
    """Architecture name (one of :data:`ARCHITECTURES`)."""
    config: ModelConfig
    """The model config it was trained with."""
    model_state: dict[str, torch.Tensor]
    """The model's ``state_dict``."""
    optimizer_state: dict[str, Any] | None
    """The optimizer's ``state_dict``, if one was saved."""
    step: int
    """Training steps taken."""
    rng_state: dict[str, Any]
    """Generator states (:func:`restore_rng_state`)."""
    train_config: dict[str, Any] | None
    """The training config as a dict, if saved."""
    training: dict[str, Any] | None = None
    """What the run trained on and how (the ``train`` command's record), if saved."""
    training_state: dict[str, torch.Tensor] | None = None
    """The raw weights the optimizer steps, when :attr:`model_state` holds their moving average
    (``[train] ema_decay``); what resuming continues from. ``None``: :attr:`model_state` is both."""

    def build_model(self, device: torch.device | str = "cpu") -> nn.Module:
        """A model of this architecture with the snapshot's weights, in eval mode, on ``device``.

        Never fetches backbone weights (the snapshot's replace them).
        """
        model = build_model(self.config, load_backbone_weights=False)
        restore(model, self)
        return model.to(device).eval()


def save_snapshot(
    path: Path | str,
    model: nn.Module,
    *,
    step: int,
    optimizer: torch.optim.Optimizer | None = None,
    train_config: object | None = None,
    training: dict[str, Any] | None = None,
    averaged: nn.Module | None = None,
) -> Path:
    """Write ``model`` (+ optimizer, step, RNG states) to ``path`` atomically (temp + rename).

    ``training``: plain-data record of the run (str/int/float/bool/None, lists, dicts).
    ``averaged``: a moving average of ``model`` (the same architecture): its weights become the
    snapshot's model (what evaluation plays) and ``model``'s are kept to resume training."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format_version": FORMAT_VERSION,
        "arch": arch_of(model),
        "config": config_to_dict(model.config),
        "model_state": (averaged if averaged is not None else model).state_dict(),
        "optimizer_state": optimizer.state_dict() if optimizer is not None else None,
        "step": int(step),
        "rng_state": capture_rng_state(),
        "train_config": config_to_dict(train_config) if train_config is not None else None,
    }
    if training is not None:
        payload["training"] = training
    if averaged is not None:
        payload["training_state"] = model.state_dict()
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    torch.save(payload, tmp)
    os.replace(tmp, path)
    return path


def load_snapshot(path: Path | str) -> Snapshot:
    """Read and check a snapshot file; anything unreadable raises :class:`CorruptFileError`."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(
            f"snapshot {path} does not exist; list a run's snapshots with list_snapshots(dir)"
        )
    data = path.read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    try:
        raw = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except (RuntimeError, pickle.UnpicklingError, EOFError, ValueError, zipfile.BadZipFile) as exc:
        reason = " ".join(str(exc).split())[:120]
        raise CorruptFileError(
            f"{path} is not a readable snapshot ({type(exc).__name__}: {reason}); "
            "re-copy or delete it"
        ) from exc
    if not isinstance(raw, dict) or any(key not in raw for key in _REQUIRED_KEYS):
        missing = [k for k in _REQUIRED_KEYS if not isinstance(raw, dict) or k not in raw]
        raise CorruptFileError(f"{path} is not an awda_bench snapshot (missing {missing})")
    if raw["format_version"] != FORMAT_VERSION:
        raise CorruptFileError(
            f"{path} has snapshot format {raw['format_version']!r}; "
            f"this version reads {FORMAT_VERSION}"
        )
    if raw["arch"] not in ARCHITECTURES:
        raise CorruptFileError(
            f"{path} holds unknown architecture {raw['arch']!r}; known: {ARCHITECTURES}"
        )
    try:
        config = config_for_arch(raw["arch"], raw["config"])
    except (UsageError, TypeError) as exc:
        raise CorruptFileError(f"{path} holds an invalid {raw['arch']} config ({exc})") from exc
    return Snapshot(
        path=path,
        sha256=digest,
        arch=raw["arch"],
        config=config,
        model_state=raw["model_state"],
        optimizer_state=raw["optimizer_state"],
        step=int(raw["step"]),
        rng_state=raw["rng_state"],
        train_config=raw.get("train_config"),
        training=raw.get("training"),
        training_state=raw.get("training_state"),
    )


def restore(
    model: nn.Module,
    snapshot: Snapshot,
    optimizer: torch.optim.Optimizer | None = None,
    *,
    rng: bool = False,
) -> None:
    """Load ``snapshot`` into ``model`` (and ``optimizer``; and the RNGs if ``rng``).

    Refuses (``CorruptFileError``) a snapshot of another architecture or of another model config
    (``backbone_weights`` may differ: it only names the initialization).
    """
    arch = arch_of(model)
    if snapshot.arch != arch:
        raise CorruptFileError(
            f"{snapshot.path} holds a {snapshot.arch!r} model, not {arch!r}; "
            f"load it with --model {snapshot.arch}"
        )
    ours = config_to_dict(model.config)
    theirs = config_to_dict(snapshot.config)
    ours["trunk"]["backbone_weights"] = theirs["trunk"]["backbone_weights"]
    if ours != theirs:
        differ = _differing_fields(ours, theirs)
        raise CorruptFileError(
            f"{snapshot.path} was trained with another {arch} config (differs in {differ}); "
            "build the model from the snapshot (Snapshot.build_model)"
        )
    try:
        model.load_state_dict(snapshot.model_state, strict=True)
    except RuntimeError as exc:
        raise CorruptFileError(
            f"{snapshot.path}: model weights do not fit the {arch} model"
        ) from exc
    if optimizer is not None:
        if snapshot.optimizer_state is None:
            raise CorruptFileError(
                f"{snapshot.path} has no optimizer state; it cannot resume training"
            )
        optimizer.load_state_dict(snapshot.optimizer_state)
    if rng:
        restore_rng_state(snapshot.rng_state)


def _differing_fields(a: dict[str, Any], b: dict[str, Any], prefix: str = "") -> list[str]:
    out: list[str] = []
    for key in sorted(set(a) | set(b)):
        va, vb = a.get(key), b.get(key)
        if isinstance(va, dict) and isinstance(vb, dict):
            out += _differing_fields(va, vb, f"{prefix}{key}.")
        elif va != vb:
            out.append(f"{prefix}{key}")
    return out

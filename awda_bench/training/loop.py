"""The training loop: Adam on ``model.compute_loss(batch)``, snapshots every N steps, resumable.

Works on any map-style dataset (``len(ds)``, ``ds[i] -> dict[str, Tensor]``) whose samples stack
into the model's batch format (:mod:`awda_bench.models.awda_net`,
:mod:`awda_bench.models.tosvi_net`).

Batch order is a function of ``(seed, step)`` only: the sample at global position
``p = step * batch_size + i`` is ``perm(seed, p // len(ds))[p % len(ds)]`` (a fresh permutation per
epoch). Together with the RNG states stored in each snapshot, resuming from a snapshot continues the
exact loss curve of an uninterrupted run on the same device::

    step:        1   2   3 | 4   5   6
    full run:    l1  l2  l3  l4  l5  l6
    interrupted: l1  l2  l3 [snapshot-000000003.pt] -> resume: l4  l5  l6   (identical values)
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from torch.utils.data import default_collate

from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import TrainConfig
from awda_bench.models.snapshot import (
    list_snapshots,
    load_snapshot,
    restore,
    save_snapshot,
    snapshot_path,
)
from awda_bench.models.tosvi_net import TosviNet


class SampleDataset(Protocol):
    """What :func:`train` needs from a dataset."""

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> Mapping[str, torch.Tensor]: ...


@dataclass
class TrainResult:
    """What one :func:`train` call did."""

    start_step: int
    """Step the call started from (0 fresh, else the resumed snapshot's step)."""
    end_step: int
    """Step reached."""
    losses: list[float] = field(default_factory=list)
    """Loss of each step taken in this call (step ``start_step + 1`` first)."""
    snapshots: list[Path] = field(default_factory=list)
    """Snapshot files written by this call."""
    resumed_from: Path | None = None
    """The snapshot resumed from, if any."""


def resolve_device(name: str) -> torch.device:
    """``auto`` -> CUDA when available, else CPU; ``cuda`` without CUDA is an error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise UsageError(
            "device 'cuda' requested but torch sees no CUDA device; use --device auto or cpu"
        )
    return torch.device(name)


def batch_indices(step: int, batch_size: int, dataset_size: int, seed: int) -> list[int]:
    """Dataset indices of the batch taken at ``step`` (0-based) — see the module docstring."""
    out: list[int] = []
    perms: dict[int, torch.Tensor] = {}
    for position in range(step * batch_size, (step + 1) * batch_size):
        epoch, offset = divmod(position, dataset_size)
        if epoch not in perms:
            generator = torch.Generator().manual_seed(seed * 1_000_003 + epoch)
            perms[epoch] = torch.randperm(dataset_size, generator=generator)
        out.append(int(perms[epoch][offset]))
    return out


def _seed_everything(seed: int) -> None:
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)  # noqa: NPY002 (the legacy global generator)
    random.seed(seed)


def moving_average(model: AwdaNet | TosviNet, decay: float) -> AveragedModel:
    """An exponential moving average of ``model``'s weights and buffers (PyTorch's
    ``AveragedModel``; the first update copies the weights). ``.module`` is the averaged model."""
    return AveragedModel(model, multi_avg_fn=get_ema_multi_avg_fn(decay), use_buffers=True)


def learning_rate_at(config: TrainConfig, step: int) -> float:
    """Adam's step size for the step taken at 0-based ``step`` (``config.lr_schedule``): a function
    of the step alone, so a resumed run continues the same curve."""
    if config.lr_schedule == "cosine":
        return config.learning_rate * 0.5 * (1.0 + math.cos(math.pi * step / config.max_steps))
    return config.learning_rate


BatchTransform = Callable[[dict[str, Any], int], dict[str, Any]]
"""``transform(batch, step) -> batch``: training-time data treatment of the collated batch taken at
``step`` (0-based), already on the device. It must draw its randomness from ``(seed, step)``
only (never the global generators), so that a resumed run sees the same batches."""


def train(
    model: AwdaNet | TosviNet,
    dataset: SampleDataset,
    config: TrainConfig,
    snapshot_dir: Path | str,
    *,
    on_step: Callable[[int, dict[str, float]], None] | None = None,
    transform: BatchTransform | None = None,
    on_snapshot: Callable[[int, Path], None] | None = None,
    training_record: dict[str, Any] | None = None,
    on_start: Callable[[int], None] | None = None,
    averaged: AveragedModel | None = None,
) -> TrainResult:
    """Train ``model`` in place up to ``config.max_steps``, writing snapshots to ``snapshot_dir``.

    With ``config.resume`` and a snapshot in ``snapshot_dir``, the latest one is loaded first
    (model, optimizer, step, RNG states); a snapshot of another architecture or config is refused.
    ``on_start(start_step)`` is called once the start step is known (0 or the resumed one);
    ``on_step(step, info)`` after every step, with the model's loss dict plus ``data_s`` (reading
    and treating the batch) and ``compute_s`` (forward, backward, optimizer) [s];
    ``on_snapshot(step, path)`` after each snapshot is written. ``transform`` is applied to every
    collated batch (:data:`BatchTransform`); ``training_record`` is stored in every snapshot.

    With a ``config.lr_schedule`` other than ``constant`` the step size follows
    :func:`learning_rate_at` and ``info`` also holds ``lr``.

    With ``config.precision`` ``bf16`` the forward pass runs under ``torch.autocast`` (bfloat16);
    the networks' ``compute_loss`` keep their losses in float32, and the weights and Adam are float32.

    With ``config.ema_decay`` > 0 the snapshots hold a moving average of the weights
    (:func:`moving_average`, updated after every step; pass ``averaged`` to read it during
    training, e.g. to validate it), and the raw weights beside it to resume.
    """
    if len(dataset) == 0:
        raise UsageError("the training dataset is empty")
    low_precision = config.precision == "bf16"
    snapshot_dir = Path(snapshot_dir)
    device = resolve_device(config.device)
    model.to(device)
    # a frozen backbone has no gradient and gets no optimizer state
    trainable = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.Adam(trainable, lr=config.learning_rate)
    result = TrainResult(start_step=0, end_step=0)
    if config.ema_decay > 0 and averaged is None:
        averaged = moving_average(model, config.ema_decay)
    if averaged is not None:
        averaged.to(device)
    existing = list_snapshots(snapshot_dir) if config.resume else []
    if existing:
        snapshot = load_snapshot(existing[-1])
        restore(model, snapshot, optimizer, rng=True)
        if (averaged is not None) != (snapshot.training_state is not None):
            held = "a moving average" if snapshot.training_state is not None else "raw weights"
            raise CorruptFileError(
                f"{snapshot.path} holds {held}, which this run (ema_decay {config.ema_decay}) "
                "cannot resume; train into a new directory"
            )
        if averaged is not None and snapshot.training_state is not None:
            averaged.module.load_state_dict(snapshot.model_state)
            averaged.n_averaged.fill_(snapshot.step)
            model.load_state_dict(snapshot.training_state)
        result.start_step = snapshot.step
        result.resumed_from = snapshot.path
    else:
        _seed_everything(config.seed)
    model.train()
    step = result.start_step
    if on_start is not None:
        on_start(step)
    while step < config.max_steps:
        t0 = time.perf_counter()
        indices = batch_indices(step, config.batch_size, len(dataset), config.seed)
        batch = default_collate([dataset[i] for i in indices])
        batch = {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in batch.items()}
        if transform is not None:
            batch = transform(batch, step)
        t1 = time.perf_counter()
        with torch.autocast(device.type, dtype=torch.bfloat16, enabled=low_precision):
            loss, info = model.compute_loss(batch)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if config.lr_schedule != "constant":
            learning_rate = learning_rate_at(config, step)
            for group in optimizer.param_groups:
                group["lr"] = learning_rate
            info = {**info, "lr": learning_rate}
        optimizer.step()
        if averaged is not None:
            averaged.update_parameters(model)
        step += 1
        result.losses.append(info["loss"])
        if on_step is not None:
            if device.type == "cuda":
                torch.cuda.synchronize(device)
            info = {**info, "data_s": t1 - t0, "compute_s": time.perf_counter() - t1}
            on_step(step, info)
        if step % config.snapshot_every_steps == 0 or step == config.max_steps:
            path = save_snapshot(
                snapshot_path(snapshot_dir, step),
                model,
                step=step,
                optimizer=optimizer,
                train_config=config,
                training=training_record,
                averaged=averaged.module if averaged is not None else None,
            )
            result.snapshots.append(path)
            if on_snapshot is not None:
                on_snapshot(step, path)
    result.end_step = step
    return result

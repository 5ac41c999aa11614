"""``train``: one Table S3 column, trained from a collected DATA_DIR into CKPT_DIR.

Order of work, so that bad input never touches CKPT_DIR::

    column (method, ablation) + recipe (+ --steps/--snapshot-every) + device      may refuse
    -> DATA_DIR: a complete collect directory of a suite the recipe names, recorded at the
       recipe's image size (and depth size for +depth); --hold-out a family it holds
    -> datasets (training selection; validation: the held-out family, or --val-data's pairs),
       first and last samples read (a damaged file is found now)
    -> CKPT_DIR: new/empty, or one whose train.json names the same column, recipe, data and
       hold-out (then training resumes from its latest snapshot)
    -> train.json, then the loop (training/loop.py): snapshots every N steps, each recording
       the column, recipe and dataset fingerprint; metrics.csv, TensorBoard scalars,
       learning_curve.png (training/logbook.py)

CKPT_DIR layout::

    snapshot-000000250.pt ...   the snapshots (the ``awda`` evaluation method reads these)
    train.json                  what this directory trains (checked on every resume)
    metrics.csv, tensorboard/, learning_curve.png
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import torch
from torch.utils.data import default_collate

from awda_bench.data.datasets import AwdaPairDataset, CollectedData, Selection, TosviDataset
from awda_bench.errors import ProtocolMismatchError, UnknownChoiceError, UsageError
from awda_bench.models.agent_cameras import camera_fields, camera_index
from awda_bench.models.architectures import build_model
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import (
    AwdaConfig,
    ModelSpec,
    TosviConfig,
    TrainConfig,
    config_to_dict,
)
from awda_bench.models.denormals import denormals_flushed
from awda_bench.models.frame_encoder import frozen_encoder
from awda_bench.models.tosvi_net import TosviNet, pool_feature_maps
from awda_bench.training.augment import BatchTreatment
from awda_bench.training.columns import Column, column_for
from awda_bench.training.feature_cache import cache_path, load_or_build
from awda_bench.training.feature_datasets import (
    CachedAwdaPairs,
    CachedTosviSamples,
    frames_needed,
    tosvi_frames_needed,
)
from awda_bench.training.logbook import Logbook, plot_learning_curve
from awda_bench.training.loop import (
    SampleDataset,
    TrainResult,
    moving_average,
    resolve_device,
    train,
)
from awda_bench.training.recipe import (
    AWDA_ONLY_FIELDS,
    TOSVI_ONLY_FIELDS,
    AugmentRecipe,
    DataRecipe,
    Recipe,
    TrainRecipe,
    load_recipe,
    model_table,
)

TRAIN_JSON = "train.json"
"""What a checkpoint directory trains (column, recipe, data, hold-out)."""

_SCHEDULE_KEYS = ("max_steps", "snapshot_every_steps")
"""Recipe fields a resumed run may change (train longer, snapshot more or less often)."""


@dataclass(frozen=True)
class TrainRequest:
    """Everything ``python -m awda_bench train`` decides."""

    method: str
    """``awda``, ``tosvi`` or ``tosvi-depth``."""
    ablation: str | None
    """An ablation of ``awda`` (:data:`awda_bench.training.columns.ABLATIONS`) or ``None``."""
    data: Path
    """DATA_DIR: a ``collect`` directory (train split)."""
    out: Path
    """CKPT_DIR: snapshots and logs."""
    recipe: str = "small"
    """Recipe name (``recipes/<name>.toml``) or a path to a recipe file."""
    steps: int | None = None
    """Overrides the recipe's ``max_steps``."""
    snapshot_every: int | None = None
    """Overrides the recipe's ``snapshot_every_steps``."""
    seed: int | None = None
    """Overrides the recipe's ``[train] seed`` (initial weights, batch order, augmentation)."""
    device: str = "auto"
    """``auto``, ``cpu`` or ``cuda``."""
    hold_out: str | None = None
    """A task family left out of training; its pairs are the validation set (MOSAIC)."""
    val_data: Path | None = None
    """A collection (e.g. ``--split test``) whose pairs are the validation set."""
    threads: int | None = None
    """``torch.set_num_threads`` (``None``: torch's default)."""
    progress: bool = True
    """Show a progress bar with ETA on stderr."""

    def __post_init__(self) -> None:
        if self.steps is not None and self.steps < 1:
            raise UsageError(f"--steps must be >= 1, got {self.steps}")
        if self.snapshot_every is not None and self.snapshot_every < 1:
            raise UsageError(f"--snapshot-every must be >= 1, got {self.snapshot_every}")
        if self.seed is not None and self.seed < 0:
            raise UsageError(f"--seed must be >= 0, got {self.seed}")
        if self.threads is not None and self.threads < 1:
            raise UsageError(f"--threads must be >= 1, got {self.threads}")
        if self.hold_out is not None and self.val_data is not None:
            raise UsageError(
                "give either --hold-out (validate on the held-out family) or --val-data, not both"
            )


@dataclass
class TrainOutcome:
    """What :func:`run_training` did."""

    column: Column
    recipe: Recipe
    result: TrainResult
    out: Path
    validation: list[tuple[int, float]] = field(default_factory=list)
    """``(step, loss)`` of every validation this call ran."""
    step_s: list[float] = field(default_factory=list)
    """Wall time of each step this call took [s] (data + compute)."""
    data_s: list[float] = field(default_factory=list)
    """Of which reading and treating the batch [s]."""
    curve: Path | None = None


# ----------------------------------------------------------------------------- checks
def open_data(path: Path, recipe: Recipe, column: Column, what: str) -> CollectedData:
    """A complete collection that ``recipe`` can train ``column`` on, or a one-line refusal."""
    if not path.is_dir():
        raise UsageError(f"{what} {path} does not exist or is not a directory")
    data = CollectedData(path)
    definition = data.manifest.get("definition", {})
    suite = definition.get("suite")
    if suite not in recipe.suites:
        raise UsageError(
            f"{what} {path} holds a {suite!r} collection; recipe {recipe.name!r} trains on "
            f"{', '.join(recipe.suites)}"
        )
    on_suite = recipe.for_suite(suite).model
    size = tuple(definition.get("image_size", ()))
    want = (on_suite.trunk.image_height_px, on_suite.trunk.image_width_px)
    # Larger frames are area-downscaled by the dataset exactly as the evaluated policies downscale
    # the harness camera's frames (rendered at the suite's camera size); a smaller collection would
    # have to be upscaled, which evaluation never does.
    if len(size) != 2 or size[0] < want[0] or size[1] < want[1]:
        raise UsageError(
            f"{what} {path} was recorded at {'x'.join(map(str, size))} but recipe "
            f"{recipe.name!r} trains at {want[0]}x{want[1]}; collect with --image-size "
            f"{want[0]}x{want[1]} or larger (the suite's camera size matches evaluation best)"
        )
    depth = tuple(definition.get("depth_size", ()))
    want_depth = (on_suite.tosvi["depth_height_px"], on_suite.tosvi["depth_width_px"])
    if column.arch == "tosvi-depth" and depth != want_depth:
        raise UsageError(
            f"{what} {path} has {'x'.join(map(str, depth))} wrist depth but recipe "
            f"{recipe.name!r} needs {want_depth[0]}x{want_depth[1]}"
        )
    if not data.episodes:
        raise UsageError(f"{what} {path} holds no finished episodes")
    return data


def check_hold_out(data: CollectedData, family: str) -> None:
    families = sorted({e.family for e in data.episodes})
    if family not in families:
        raise UnknownChoiceError("--hold-out family", family, families)
    if len(families) < 2:
        raise UsageError(
            f"--hold-out {family}: {data.root} holds no other family to train on; "
            "hold out a family of a multi-family (mosaic) collection"
        )


def identity(record: dict[str, Any]) -> dict[str, Any]:
    """The part of a ``train.json`` record that must match to resume (schedule excluded). A recipe
    field added after the run started (absent from its record) counts at its default, which is
    what the run trained with; an AWDA column ignores the T-OSVI-only fields and a T-OSVI column
    the AWDA-only ones (:data:`~awda_bench.training.recipe.AWDA_ONLY_FIELDS`), and the recipe's
    ``suites`` list is left out (the data's fingerprint says what the run trains on; Meta-World
    joining the list does not change a pick-and-place run)."""
    recipe = json.loads(json.dumps(record["recipe"]))
    recipe.pop("suites", None)
    defaults = {
        "model": model_table(ModelSpec(), DataRecipe()),
        "train": config_to_dict(TrainRecipe()),
        "augment": config_to_dict(AugmentRecipe()),
    }
    for table, default in defaults.items():
        recipe[table] = {**default, **recipe.get(table, {})}
    ignored = TOSVI_ONLY_FIELDS if record["column"].get("arch") == "awda" else AWDA_ONLY_FIELDS
    for key in ignored:
        recipe["model"].pop(key)
    for key in _SCHEDULE_KEYS:
        recipe["train"].pop(key, None)
    return {
        "column": record["column"],
        "recipe": recipe,
        "data_fingerprint": record["data"]["fingerprint"],
        "hold_out": record["hold_out"],
        "validation_fingerprint": (record.get("validation") or {}).get("fingerprint"),
    }


def check_checkpoint_dir(out: Path, record: dict[str, Any]) -> bool:
    """True when ``out`` holds a run of the same identity (resume); refuses anything else."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file, not a directory")
    if not out.is_dir() or not any(out.iterdir()):
        return False
    meta = out / TRAIN_JSON
    if not meta.is_file():
        raise UsageError(
            f"--out {out} is not empty and holds no {TRAIN_JSON}: not a train directory; "
            "choose an empty or new directory"
        )
    try:
        theirs = identity(json.loads(meta.read_text()))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UsageError(f"{meta} is unreadable ({exc}); choose a new --out") from exc
    ours = identity(record)
    if theirs != ours:
        differ = [k for k in ours if ours[k] != theirs[k]]
        detail = []
        if "column" in differ:
            detail.append(f"it trains {theirs['column']['slug']}, not {ours['column']['slug']}")
        if "recipe" in differ:
            detail.append(_recipe_difference(theirs["recipe"], ours["recipe"]))
        if "data_fingerprint" in differ:
            detail.append("other data")
        if "hold_out" in differ:
            detail.append(f"hold-out {theirs['hold_out']!r}")
        if "validation_fingerprint" in differ:
            detail.append("other validation data")
        raise ProtocolMismatchError(
            f"--out {out} holds another training run ({'; '.join(detail)}); repeat its options "
            "to resume it, or train into a new --out"
        )
    return True


def _recipe_difference(theirs: dict[str, Any], ours: dict[str, Any]) -> str:
    """How a checkpoint directory's recipe differs from the one asked for: its name, or (same
    name, e.g. another ``--seed``) the fields that differ."""
    if theirs.get("name") != ours.get("name"):
        return f"recipe {theirs.get('name')!r}, not {ours.get('name')!r}"
    fields = [
        f"[{table}] {key} = {theirs.get(table, {}).get(key)!r}, not {value!r}"
        for table, values in ours.items()
        if isinstance(values, dict)
        for key, value in values.items()
        if theirs.get(table, {}).get(key) != value
    ]
    return f"recipe {ours.get('name')!r} with {', '.join(fields) or 'other fields'}"


# ----------------------------------------------------------------------------- pieces
def agent_cameras(
    data: CollectedData, dataset: AwdaPairDataset, val_dataset: AwdaPairDataset | None
) -> dict[str, Any]:
    """The ``camera_*`` fields of :class:`AwdaConfig`: every third-person camera the training
    pairs' agents were filmed with, then those only the validation pairs were (a suite's scenes
    may be filmed from several places: MOSAIC's door and drawer from one side, its other
    families from another). Both datasets' ``"camera"`` indices then point into that list."""
    cameras = list(dataset.cameras)
    if val_dataset is not None:
        cameras += [c for c in val_dataset.cameras if camera_index(cameras, c) is None]
        val_dataset.index_cameras(cameras)
    dataset.index_cameras(cameras)
    return camera_fields(cameras, data.manifest["definition"].get("image_size"))


def frame_stack_of(recipe: Recipe, column: Column) -> int:
    """Agent frames per T-OSVI sample: the column's override (``no-frame-stack``: 1) or the
    recipe's ``frame_stack``."""
    return (
        column.frame_stack if column.frame_stack is not None else recipe.model.tosvi["frame_stack"]
    )


def model_config(
    recipe: Recipe, column: Column, camera: dict[str, Any] | None = None
) -> AwdaConfig | TosviConfig:
    """The network ``column`` trains under ``recipe``; ``camera`` (:func:`agent_cameras`) is
    what the cell heads (``demo-to-scene``, ``demo-pointer``) vote along."""
    if column.arch == "awda":
        return recipe.model.awda_config(column.num_heads, camera)
    return recipe.model.tosvi_config(column.frame_stack, use_depth=column.arch == "tosvi-depth")


def make_dataset(
    data: CollectedData,
    recipe: Recipe,
    column: Column,
    selection: Selection | None,
    *,
    synthesized: bool,
    validation: bool = False,
) -> AwdaPairDataset | TosviDataset:
    trunk, tosvi = recipe.model.trunk, recipe.model.tosvi
    size = (trunk.image_height_px, trunk.image_width_px)
    if column.arch == "awda":
        return AwdaPairDataset(
            data,
            demo_frames=trunk.demo_frames,
            image_size=size,
            trajectory_points=recipe.data.trajectory_points,
            selection=selection,
            include_synthesized=synthesized,
            allow_test=validation,
            contact_points=recipe.data.identification_contact
            and recipe.model.awda["identification_weight"] > 0,
        )
    return TosviDataset(
        data,
        demo_frames=trunk.demo_frames,
        frame_stack=frame_stack_of(recipe, column),
        image_size=size,
        depth_size=(tosvi["depth_height_px"], tosvi["depth_width_px"]),
        with_depth=column.arch == "tosvi-depth",
        selection=selection,
        include_synthesized=synthesized,
        allow_test=validation,
    )


def cache_variant(pool: int) -> str:
    """The cache variant of backbone maps average-pooled by ``pool`` (1: the maps themselves,
    the file AWDA's datasets read)."""
    return "rgb" if pool == 1 else f"rgb-avgpool{pool}"


def cached_features_path(root: Path, fingerprint: str, recipe: Recipe, arch: str) -> Path:
    """Where the frozen-trunk feature cache an ``arch`` network trains from under ``recipe`` lives
    for collection ``root`` (present or not): AWDA's maps, or T-OSVI's pooled ones (shared by
    every T-OSVI-style column, whatever its frame-stack)."""
    pool = 1 if arch == "awda" else recipe.model.tosvi["feature_pool"]
    return cache_path(root, fingerprint, recipe.model.trunk, cache_variant(pool))


def with_cached_features(
    dataset: AwdaPairDataset | TosviDataset, recipe: Recipe, progress: bool
) -> CachedAwdaPairs | CachedTosviSamples:
    """``dataset`` served from the frozen backbone's feature cache (built first if needed).
    T-OSVI's maps are cached after its ``feature_pool`` (what ``TosviNet.frame_features``
    returns), under their own variant when pooled."""
    trunk = recipe.model.trunk
    frozen = frozen_encoder(trunk)  # eval mode: what evaluation computes live
    pool = recipe.model.tosvi["feature_pool"] if isinstance(dataset, TosviDataset) else 1

    def encode(images: torch.Tensor) -> torch.Tensor:
        return pool_feature_maps(frozen(images), pool)

    if isinstance(dataset, TosviDataset):
        needed = tosvi_frames_needed(dataset)
    else:
        needed = frames_needed(dataset)
    cache = load_or_build(
        dataset.data, trunk, needed, encode, variant=cache_variant(pool), progress=progress
    )
    if isinstance(dataset, TosviDataset):
        return CachedTosviSamples(dataset, cache)
    return CachedAwdaPairs(dataset, cache)


class OneHead:
    """An AWDA dataset seen by a one-head network: every sample's ``head`` is 0 (synthesized
    samples included: ``single-head`` trains them on the task head)."""

    def __init__(self, dataset: SampleDataset) -> None:
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        sample = dict(self.dataset[index])
        sample["head"] = torch.zeros_like(sample["head"])
        return sample


def validation_indices(size: int, batch_size: int, batches: int, seed: int) -> list[int]:
    """The samples (of ``size``) a :class:`Validator` reads, in its order."""
    g = torch.Generator().manual_seed(seed + 7)
    return torch.randperm(size, generator=g).tolist()[: batch_size * batches]


class Validator:
    """Mean loss over a fixed subset of held-out pairs, in eval mode (no dropout, BN running
    statistics, no augmentation), without touching any random generator."""

    def __init__(self, dataset: SampleDataset, batch_size: int, batches: int, seed: int) -> None:
        chosen = validation_indices(len(dataset), batch_size, batches, seed)
        self.batches = [chosen[i : i + batch_size] for i in range(0, len(chosen), batch_size)]
        self.dataset = dataset
        self.samples = len(chosen)

    @torch.no_grad()
    def __call__(self, model: AwdaNet | TosviNet, device: torch.device) -> float:
        was_training = model.training
        model.eval()
        total, count = 0.0, 0
        try:
            for indices in self.batches:
                batch = default_collate([self.dataset[i] for i in indices])
                batch = {k: v.to(device) for k, v in batch.items()}
                _, info = model.compute_loss(batch)
                total += info["loss"] * len(indices)
                count += len(indices)
        finally:
            model.train(was_training)
        return total / count


def _write_json(path: Path, payload: dict[str, Any]) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(payload, indent=2) + "\n")
    os.replace(tmp, path)


# ----------------------------------------------------------------------------- the run
def run_training(request: TrainRequest) -> TrainOutcome:
    """Train one column (module docstring); returns what was done. Denormal floats are flushed
    to zero throughout (:mod:`awda_bench.models.denormals`: without it a T-OSVI step slows ~3x
    as training goes on)."""
    # first: torch's threads inherit the flag when they start. In a process whose torch threads
    # already run (a notebook, the test suite) only this thread flushes: slower, not wrong.
    with denormals_flushed():
        return _run_training(request)


@dataclass
class _Sources:
    """The collections a run reads: the training data and its selection, and where the
    validation pairs come from (the held-out family of the same data, or ``--val-data``)."""

    data: CollectedData
    selection: Selection | None = None
    val_data: CollectedData | None = None
    val_selection: Selection | None = None

    def close(self) -> None:
        self.data.close()
        if self.val_data is not None and self.val_data is not self.data:
            self.val_data.close()


def _open_sources(request: TrainRequest, recipe: Recipe, column: Column) -> tuple[_Sources, Recipe]:
    """DATA_DIR (and ``--val-data``) opened and checked, with the recipe as it trains on their
    suite (its ``[suite.<name>.model]`` table applied)."""
    data = open_data(request.data, recipe, column, "--data")
    recipe = recipe.for_suite(str(data.manifest["definition"].get("suite")))
    if data.split != "train":
        raise UsageError(
            f"--data {request.data} is a {data.split!r}-split collection; train on a train split "
            "(a test split is validation data: --val-data)"
        )
    if request.hold_out is not None:
        check_hold_out(data, request.hold_out)
        held_out = (request.hold_out,)
        return _Sources(
            data, Selection(exclude_families=held_out), data, Selection(families=held_out)
        ), recipe
    if request.val_data is not None:
        val_data = open_data(request.val_data, recipe, column, "--val-data")
        if val_data.manifest["definition"].get("suite") != data.manifest["definition"].get("suite"):
            raise UsageError(
                f"--val-data {request.val_data} is from another suite than --data {request.data}"
            )
        return _Sources(data, val_data=val_data), recipe
    return _Sources(data), recipe


@dataclass
class _Samples:
    """What the loop and the validator read."""

    dataset: SampleDataset
    """The training samples (served from the feature cache with a frozen backbone)."""
    train_set: SampleDataset
    """What the loop draws: ``dataset``, or a one-head column's view of it."""
    val_dataset: SampleDataset | None
    """The validation samples, or ``None``."""
    cameras: dict[str, Any]
    """The ``camera_*`` fields of an AWDA network (empty for T-OSVI)."""


def _make_samples(sources: _Sources, recipe: Recipe, column: Column, progress: bool) -> _Samples:
    """The datasets, their cameras indexed, cache-served when the backbone is frozen, and their
    first and last samples read (a damaged file is refused up front)."""
    dataset: SampleDataset = make_dataset(
        sources.data, recipe, column, sources.selection, synthesized=column.synthesized
    )
    val_dataset: SampleDataset | None = (
        make_dataset(
            sources.val_data,
            recipe,
            column,
            sources.val_selection,
            synthesized=False,
            validation=True,
        )
        if sources.val_data is not None
        else None
    )
    cameras: dict[str, Any] = {}
    if isinstance(dataset, AwdaPairDataset):  # before the cache wrappers read "camera"
        assert val_dataset is None or isinstance(val_dataset, AwdaPairDataset)
        cameras = agent_cameras(sources.data, dataset, val_dataset)
    if recipe.model.trunk.freeze_backbone:
        assert isinstance(dataset, AwdaPairDataset | TosviDataset)
        dataset = with_cached_features(dataset, recipe, progress)
        if isinstance(val_dataset, TosviDataset):
            # only the stacks the validator reads are encoded, not every frame of the validation
            # episodes (the validator then reads all of them: the same samples, the same mean)
            v = recipe.train
            val_dataset = val_dataset.subset(
                validation_indices(len(val_dataset), v.batch_size, v.validation_batches, v.seed)
            )
        if isinstance(val_dataset, AwdaPairDataset | TosviDataset):
            val_dataset = with_cached_features(val_dataset, recipe, progress)
    train_set: SampleDataset = dataset
    if column.arch == "awda" and column.num_heads == 1:
        train_set = OneHead(dataset)
    for ds in (dataset, val_dataset):  # read the ends now: a damaged file is refused up front
        if ds is not None:
            ds[0]
            ds[len(ds) - 1]
    return _Samples(dataset, train_set, val_dataset, cameras)


def _training_record(
    request: TrainRequest, column: Column, recipe: Recipe, sources: _Sources, samples: _Samples
) -> dict[str, Any]:
    """What ``train.json`` and every snapshot record (and a resume compares: :func:`identity`)."""
    data, val_data, val_dataset = sources.data, sources.val_data, samples.val_dataset
    return {
        "column": {
            "name": column.name,
            "slug": column.slug,
            "method": column.method,
            "ablation": column.ablation,
            "arch": column.arch,
            "num_heads": column.num_heads,
            "adm": column.adm,
            "synthesized": column.synthesized,
        },
        "recipe": recipe.to_dict(),
        "recipe_sha256": recipe.sha256,
        "data": {
            "path": str(request.data),
            "fingerprint": data.fingerprint,
            "suite": data.manifest["definition"].get("suite"),
            "split": data.split,
            "image_size": data.manifest["definition"].get("image_size"),
            "jpeg_quality": data.manifest["definition"].get("jpeg_quality"),
            "samples": len(samples.dataset),
        },
        "hold_out": request.hold_out,
        "validation": None
        if val_data is None or val_dataset is None
        else {
            "source": "hold-out family" if request.hold_out else "--val-data",
            "path": str(val_data.root),
            "fingerprint": val_data.fingerprint,
            "samples": len(val_dataset),
        },
    }


class _Progress:
    """The loop's callbacks: the logbook, the progress bar, validation (every
    ``validate_every_steps`` and at every snapshot, once a step) and the learning curve."""

    def __init__(
        self,
        request: TrainRequest,
        column: Column,
        recipe: Recipe,
        model: AwdaNet | TosviNet,
        validator: Validator | None,
        device: torch.device,
        outcome: TrainOutcome,
        title: str,
    ) -> None:
        self.request, self.column, self.schedule = request, column, recipe.train
        self.model, self.validator, self.device = model, validator, device
        self.outcome, self.title = outcome, title
        self.state: dict[str, Any] = {}

    def validate(self, step: int) -> None:
        state = self.state
        if self.validator is None or state.get("validated") == step:
            return
        loss = self.validator(self.model, self.device)
        state["validated"] = step
        self.outcome.validation.append((step, loss))
        state["log"].log(step, "val", {"loss": loss})
        shown = {"loss": f"{state['loss']:.4g}"} if "loss" in state else {}  # none before step 1
        state["bar"].set_postfix(**shown, val=f"{loss:.4g}")

    def on_start(self, start: int) -> None:
        from tqdm import tqdm

        self.state["log"] = Logbook(self.request.out, start)
        self.state["bar"] = tqdm(
            total=self.schedule.max_steps,
            initial=start,
            disable=not self.request.progress,
            unit="step",
            desc=f"train {self.column.slug}",
            dynamic_ncols=True,
        )
        if start == 0:
            self.validate(0)

    def on_step(self, step: int, info: dict[str, float]) -> None:
        state, outcome = self.state, self.outcome
        data_s, compute_s = info.pop("data_s"), info.pop("compute_s")
        outcome.step_s.append(data_s + compute_s)
        outcome.data_s.append(data_s)
        state["loss"] = info["loss"]
        log: Logbook = state["log"]
        log.log(step, "train", info)
        log.log(step, "time", {"data_s": data_s, "compute_s": compute_s})
        if step % self.schedule.validate_every_steps == 0:
            self.validate(step)
        state["bar"].update(1)
        if "validated" not in state or state["validated"] != step:
            state["bar"].set_postfix(loss=f"{info['loss']:.4g}", refresh=False)

    def on_snapshot(self, step: int, path: Path) -> None:
        self.validate(step)
        self.state["log"].flush()
        self.outcome.curve = plot_learning_curve(self.request.out, self.title)

    def close(self) -> None:
        if "log" in self.state:
            self.state["log"].close()
            self.state["bar"].close()


def _run_training(request: TrainRequest) -> TrainOutcome:
    column = column_for(request.method, request.ablation)
    recipe = load_recipe(request.recipe)
    device = resolve_device(request.device)
    sources, recipe = _open_sources(request, recipe, column)  # the suite's tables applied
    recipe = recipe.with_schedule(request.steps, request.snapshot_every, request.seed)
    if request.threads is not None:
        torch.set_num_threads(request.threads)
    samples = _make_samples(sources, recipe, column, request.progress)
    record = _training_record(request, column, recipe, sources, samples)
    resuming = check_checkpoint_dir(request.out, record)
    request.out.mkdir(parents=True, exist_ok=True)
    _write_json(request.out / TRAIN_JSON, {**record, "device": device.type})

    t = recipe.train
    torch.manual_seed(t.seed)  # initial weights (a resumed run loads them from its snapshot)
    model = build_model(model_config(recipe, column, samples.cameras or None))
    config = TrainConfig(
        learning_rate=t.learning_rate,
        batch_size=t.batch_size,
        max_steps=t.max_steps,
        snapshot_every_steps=t.snapshot_every_steps,
        seed=t.seed,
        device=request.device,
        resume=resuming,
        ema_decay=t.ema_decay,
        lr_schedule=t.lr_schedule,
        precision=t.precision,
    )
    averaged = moving_average(model, t.ema_decay) if t.ema_decay > 0 else None
    val_dataset = samples.val_dataset
    validator = (
        Validator(
            OneHead(val_dataset) if samples.train_set is not samples.dataset else val_dataset,
            t.batch_size,
            t.validation_batches,
            t.seed,
        )
        if val_dataset is not None
        else None
    )
    outcome = TrainOutcome(column=column, recipe=recipe, result=TrainResult(0, 0), out=request.out)
    title = f"{column.name} ({column.slug}), recipe {recipe.name}, data {sources.data.fingerprint}"
    title += f", hold-out {request.hold_out}" if request.hold_out else ""
    # what the snapshots hold, and so what is validated
    validated = cast(AwdaNet | TosviNet, averaged.module) if averaged is not None else model
    progress = _Progress(request, column, recipe, validated, validator, device, outcome, title)
    try:
        outcome.result = train(
            model,
            samples.train_set,
            config,
            request.out,
            on_step=progress.on_step,
            on_start=progress.on_start,
            on_snapshot=progress.on_snapshot,
            transform=BatchTreatment(recipe.augment, adm=column.adm, seed=t.seed),
            training_record=record,
            averaged=averaged,
        )
    finally:
        progress.close()
        sources.close()
    if outcome.result.end_step > outcome.result.start_step:
        outcome.curve = plot_learning_curve(request.out, title)
    return outcome

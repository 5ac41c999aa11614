"""Training recipes: the data files in ``recipes/<name>.toml``, read into frozen dataclasses.

A recipe fixes everything a Table S3 column's training needs apart from the column itself (the
method and ablation, :mod:`awda_bench.training.columns`): image size and trunk, loss settings,
batch, learning rate, steps and snapshot spacing, validation cadence, and the training-time data
treatment (ADM's lambda range, shifts, colour jitter). ``paper`` is Table S2; ``small`` is sized
by measurement for a 2-core CPU (numbers in its file). ``--recipe`` also takes a path to a
``.toml`` of the same layout (tests use tiny ones).

Layout::

    name = "small"
    suites = ["pick_place", "mosaic"]      # suites whose collections it trains on
    [model]   the networks (:class:`~awda_bench.models.config.ModelSpec`): every
              TrunkConfig field (image_height_px, image_width_px, demo_frames, backbone, ...);
              AwdaConfig's head_hidden_dim, demo_reference_frame, identification_weight,
              ray_height_offset_m, points_per_segment, gamma, attribute_scale; TosviConfig's
              frame_stack, mixture_components, depth_height_px, depth_width_px and
              tosvi_feature_pool (its feature_pool); and the samples (:class:`DataRecipe`):
              trajectory_points, identification_contact
    [train]   batch_size, learning_rate, max_steps, snapshot_every_steps,
              validate_every_steps, validation_batches, seed
    [augment] adm_lambda_low, adm_lambda_high, adm_mix_agent, shift_px, brightness, contrast,
              saturation
    [suite.<name>.model]  [model] fields that differ on that suite's collections (optional; e.g.
              Meta-World's 224x224 frames); ``train`` applies them (:meth:`Recipe.for_suite`)
    [suite.<name>.train]  [train] fields that differ there (optional; e.g. Meta-World's steps);
              ``--steps`` / ``--snapshot-every`` / ``--seed`` still override them

A variant may start from another recipe: ``extends = "small"`` (a name in the same directory, or
a ``.toml`` path relative to the variant's file) takes every table of the base and overrides the
fields the variant's own tables name (``suites`` and ``[suite.*]`` too); ``name`` is always the
variant's own. A variant therefore follows its base when the base changes; its ``sha256`` (over
the resolved fields) changes with it, and snapshots and reports record that hash.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from awda_bench.errors import CorruptFileError, UnknownChoiceError, UsageError
from awda_bench.models.config import (
    AWDA_TABLE_FIELDS,
    LR_SCHEDULES,
    PRECISIONS,
    TOSVI_TABLE_FIELDS,
    ModelSpec,
    check_field,
    config_from_dict,
    config_to_dict,
)

RECIPES_DIR = Path(__file__).resolve().parent.parent.parent / "recipes"
"""Where the recipe files live (``recipes/`` at the project root, beside ``tasks/``)."""


@dataclass(frozen=True)
class DataRecipe:
    """What the training samples are made of beyond the network's inputs (``[model]`` keys too,
    so a ``[suite.<name>.model]`` table may set them; no network reads them)."""

    trajectory_points: int = 50
    """Ground-truth trajectory points (reference: 50)."""
    identification_contact: bool = False
    """``demo-pointer`` with the identification loss: episodes that never grasp are labelled by
    where the hand first moves the task's object (:mod:`awda_bench.data.contact_point`; Meta-World's
    pushes); ``False``: by the first grasp only, rows without one left out."""

    def __post_init__(self) -> None:
        check_field(
            self.trajectory_points >= 2,
            "DataRecipe",
            "trajectory_points",
            self.trajectory_points,
            "an int >= 2",
        )


TOSVI_ONLY_FIELDS: tuple[str, ...] = tuple(TOSVI_TABLE_FIELDS)
"""``[model]`` fields only T-OSVI networks read (an AWDA run resumes whatever they say)."""

AWDA_ONLY_FIELDS: tuple[str, ...] = (*AWDA_TABLE_FIELDS, *(f.name for f in fields(DataRecipe)))
"""``[model]`` fields only AWDA networks and their samples read (a T-OSVI run resumes whatever
they say: a Meta-World recipe that changed its ray heights or identification labels trains the
same T-OSVI network)."""


def model_table(model: ModelSpec, data: DataRecipe) -> dict[str, Any]:
    """The ``[model]`` table (flat, as the recipe files write it) of ``model`` and ``data``."""
    return {**model.to_table(), **config_to_dict(data)}


def split_model_table(table: dict[str, Any], where: str) -> tuple[ModelSpec, DataRecipe]:
    """A ``[model]`` table read into the network configs and the data options; ``where`` names
    the table in a refusal (one line naming the field and what is allowed)."""
    data_keys = tuple(f.name for f in fields(DataRecipe))
    valid = (*ModelSpec.table_keys(), *data_keys)
    unknown = sorted(set(table) - set(valid))
    if unknown:
        raise UsageError(f"{where} has no field(s) {unknown}; valid: {', '.join(valid)}")
    try:
        data = config_from_dict(DataRecipe, {k: v for k, v in table.items() if k in data_keys})
        model = ModelSpec.from_table({k: v for k, v in table.items() if k not in data_keys})
    except UsageError as exc:
        message = str(exc)
        for key, name in TOSVI_TABLE_FIELDS.items():  # the one key that is not its field's name
            if key != name:
                message = message.replace(f"TosviConfig.{name} ", f"TosviConfig.{name} ({key}) ")
        raise UsageError(f"{where}: {message}") from None
    return model, data


@dataclass(frozen=True)
class TrainRecipe:
    """The loop's schedule (the ``[train]`` table)."""

    batch_size: int = 30
    """Samples per step (Table S2: 30)."""
    learning_rate: float = 5e-4
    """Adam step size (Table S2: 5e-4)."""
    max_steps: int = 100_000
    """Steps to train (``--steps`` overrides)."""
    snapshot_every_steps: int = 10_000
    """Snapshot spacing (Table S2: 10k; ``--snapshot-every`` overrides)."""
    validate_every_steps: int = 500
    """Validation loss on held-out-task pairs every this many steps (and at every snapshot)."""
    validation_batches: int = 4
    """Batches of held-out pairs per validation (a fixed subset, the same every time)."""
    seed: int = 0
    """Batch order, ADM and augmentation draws, and the initial weights."""
    ema_decay: float = 0.0
    """Exponential moving average of the weights (``torch.optim.swa_utils``, as diffusion_policy
    keeps one): each step ``ema = decay * ema + (1 - decay) * weights``, and snapshots, validation
    and evaluation use the average (the raw weights stay in the snapshot to resume). 0: off, as
    in the reference. 0.995 averages over ~200 steps."""
    lr_schedule: str = "constant"
    """``constant`` (Table S2, the reference) or ``cosine``: the step size anneals from
    ``learning_rate`` to 0 at ``max_steps`` (half a cosine). A run resumed with more steps follows
    the new ``max_steps``'s curve from its step on (the step size jumps up)."""
    precision: str = "fp32"
    """``fp32`` (the reference) or ``bf16``: the AWDA network's training forward pass under
    ``torch.autocast(dtype=torch.bfloat16)``; the weights, gradients, Adam and the losses stay
    float32, and validation, snapshots and evaluation are float32. For CPUs with bfloat16
    arithmetic (AVX512-BF16, AMX): a Full-1 Meta-World step 0.084 s against 0.143-0.155 in
    float32 on the 2-core EPYC of sessions 39-42 (docs/training.md); a CPU without it emulates bf16 and gets slower."""

    def __post_init__(self) -> None:
        o = "recipe train"
        for name in (
            "batch_size",
            "max_steps",
            "snapshot_every_steps",
            "validate_every_steps",
            "validation_batches",
        ):
            check_field(getattr(self, name) >= 1, o, name, getattr(self, name), "an int >= 1")
        check_field(self.learning_rate > 0, o, "learning_rate", self.learning_rate, "a float > 0")
        check_field(self.seed >= 0, o, "seed", self.seed, "an int >= 0")
        check_field(0.0 <= self.ema_decay < 1.0, o, "ema_decay", self.ema_decay, "in [0, 1)")
        check_field(
            self.lr_schedule in LR_SCHEDULES,
            o,
            "lr_schedule",
            self.lr_schedule,
            f"one of {LR_SCHEDULES}",
        )
        check_field(
            self.precision in PRECISIONS, o, "precision", self.precision, f"one of {PRECISIONS}"
        )


@dataclass(frozen=True)
class AugmentRecipe:
    """Training-time data treatment (the ``[augment]`` table; never applied to validation)."""

    adm_lambda_low: float = 0.3
    """ADM: lambda ~ U(low, high) per sample (reference: U(0.3, 1))."""
    adm_lambda_high: float = 1.0
    """ADM: upper end of lambda's range."""
    adm_mix_agent: bool = True
    """ADM mixes the agent's frames with the partner's first agent frame, as the reference does;
    ``false``: only the demo frames are mixed and o_1 stays the sample's own scene (a deviation,
    screened on Meta-World: recipe-study-metaworld.md)."""
    shift_px: int = 4
    """Random translation of each sample's demo frames and (independently) its agent frames by
    up to this many pixels per axis, edges replicated. No flips and no rescaling: the labels are
    world-frame metres and the camera does not move, so a shift only perturbs the image-to-world
    mapping by a few pixels (0 disables)."""
    brightness: float = 0.2
    """Colour jitter: brightness factor ~ U(1 - b, 1 + b) (0 disables)."""
    contrast: float = 0.2
    """Colour jitter: contrast factor ~ U(1 - c, 1 + c) about each frame's mean grey."""
    saturation: float = 0.2
    """Colour jitter: saturation factor ~ U(1 - s, 1 + s) about each pixel's grey."""

    def __post_init__(self) -> None:
        o = "recipe augment"
        check_field(
            0.0 <= self.adm_lambda_low <= self.adm_lambda_high <= 1.0,
            o,
            "adm_lambda_low/high",
            (self.adm_lambda_low, self.adm_lambda_high),
            "0 <= low <= high <= 1",
        )
        check_field(self.shift_px >= 0, o, "shift_px", self.shift_px, "an int >= 0")
        for name in ("brightness", "contrast", "saturation"):
            check_field(0.0 <= getattr(self, name) < 1.0, o, name, getattr(self, name), "in [0, 1)")


@dataclass(frozen=True)
class Recipe:
    """A training recipe as read from ``recipes/<name>.toml`` (layout in the module docstring)."""

    name: str
    """Name used on the command line (``--recipe NAME``)."""
    suites: tuple[str, ...]
    """Suites whose collections this recipe trains on."""
    model: ModelSpec = field(default_factory=ModelSpec)
    """The networks' configuration (the ``[model]`` table's network fields)."""
    data: DataRecipe = field(default_factory=DataRecipe)
    """The ``[model]`` table's data fields (what the samples are made of)."""
    train: TrainRecipe = field(default_factory=TrainRecipe)
    augment: AugmentRecipe = field(default_factory=AugmentRecipe)
    path: Path | None = None
    """The file it was read from."""
    suite_models: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Suite -> ``[model]`` fields that differ on that suite's collections (the ``[suite.<name>.
    model]`` tables: Meta-World's 224x224 frames); applied by :meth:`for_suite`."""
    suite_trains: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Suite -> ``[train]`` fields that differ there (the ``[suite.<name>.train]`` tables);
    applied by :meth:`for_suite`."""

    def to_dict(self) -> dict[str, Any]:
        """Plain data (what snapshots and ``train.json`` record); ``path`` left out, and the
        per-suite tables only while not applied (``train`` records :meth:`for_suite`'s)."""
        out: dict[str, Any] = {
            "name": self.name,
            "suites": list(self.suites),
            "model": model_table(self.model, self.data),
            "train": config_to_dict(self.train),
            "augment": config_to_dict(self.augment),
        }
        if self.suite_models:
            out["suite_models"] = json.loads(json.dumps(self.suite_models))
        if self.suite_trains:
            out["suite_trains"] = json.loads(json.dumps(self.suite_trains))
        return out

    def for_suite(self, suite: str) -> Recipe:
        """The recipe as it trains on a collection of ``suite``: that suite's ``[model]`` and
        ``[train]`` overrides applied, none left (apply :meth:`with_schedule` after this)."""
        from dataclasses import replace

        overrides = self.suite_models.get(suite, {})
        table = {**model_table(self.model, self.data), **overrides}
        model, data = split_model_table(table, f"recipe {self.name} [suite.{suite}.model]")
        train = self.train
        if suite in self.suite_trains:
            train_table = {**config_to_dict(self.train), **self.suite_trains[suite]}
            train = config_from_dict(TrainRecipe, train_table)
        return replace(self, model=model, data=data, train=train, suite_models={}, suite_trains={})

    @property
    def sha256(self) -> str:
        """First 16 hex digits of the SHA-256 of :meth:`to_dict`'s canonical JSON."""
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def with_schedule(
        self, max_steps: int | None, snapshot_every: int | None, seed: int | None = None
    ) -> Recipe:
        """The recipe with ``--steps`` / ``--snapshot-every`` / ``--seed`` applied (``--seed``
        replaces ``[train] seed``: a replicate training of the same recipe)."""
        from dataclasses import replace

        train = self.train
        if max_steps is not None:
            train = replace(train, max_steps=max_steps)
        if snapshot_every is not None:
            train = replace(train, snapshot_every_steps=snapshot_every)
        if seed is not None:
            train = replace(train, seed=seed)
        return replace(self, train=train)


def available_recipes(recipes_dir: Path = RECIPES_DIR) -> list[str]:
    """Recipe names found in ``recipes_dir``."""
    return sorted(p.stem for p in recipes_dir.glob("*.toml"))


def _resolved_toml(path: Path, recipes_dir: Path, chain: tuple[Path, ...]) -> dict[str, Any]:
    """``path``'s tables, with its ``extends`` base's (recursively) underneath."""
    try:
        raw = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise CorruptFileError(f"recipe {path} is not valid TOML ({exc})") from exc
    base_name = raw.pop("extends", None)
    if base_name is None:
        return raw
    if not isinstance(base_name, str):
        raise UsageError(f"recipe {path}: extends must be a recipe name or a .toml path")
    base_path = (
        path.parent / base_name
        if base_name.endswith(".toml")
        else recipes_dir / f"{base_name}.toml"
    )
    if not base_path.is_file():
        raise UsageError(
            f"recipe {path} extends {base_name!r}, which does not exist; valid: "
            f"{', '.join(available_recipes(recipes_dir))} or a .toml path"
        )
    if base_path.resolve() in chain or base_path.resolve() == path.resolve():
        raise UsageError(f"recipe {path}: extends {base_name!r} makes a cycle; remove one link")
    base = _resolved_toml(base_path, recipes_dir, (*chain, path.resolve()))
    merged = {**base, **raw, "name": raw.get("name")}  # the name is never inherited
    for table in ("model", "train", "augment"):
        inherited, own = base.get(table, {}), raw.get(table, {})
        both = isinstance(inherited, dict) and isinstance(own, dict)
        merged[table] = {**inherited, **own} if both else own  # malformed: refused below
    suites = dict(base.get("suite", {}))
    for suite, own_suite in raw.get("suite", {}).items():
        if isinstance(own_suite, dict):
            merged_suite = {**suites.get(suite, {}), **own_suite}
            for sub in ("model", "train"):
                inherited = suites.get(suite, {}).get(sub, {})
                own = own_suite.get(sub, {})
                if isinstance(inherited, dict) and isinstance(own, dict) and (inherited or own):
                    merged_suite[sub] = {**inherited, **own}
            own_suite = merged_suite
        suites[suite] = own_suite  # anything malformed is refused by load_recipe, naming it
    merged["suite"] = suites
    return merged


def load_recipe(name_or_path: str, recipes_dir: Path = RECIPES_DIR) -> Recipe:
    """Read recipe ``name`` from ``recipes_dir``, or a ``.toml`` file given by path."""
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml":
        path = candidate
        if not path.is_file():
            raise UsageError(f"recipe file {path} does not exist")
    else:
        path = recipes_dir / f"{name_or_path}.toml"
        if not path.is_file():
            raise UnknownChoiceError("recipe", name_or_path, available_recipes(recipes_dir))
    raw = _resolved_toml(path, recipes_dir, ())
    known = {"name", "suites", "model", "train", "augment", "suite"}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise UsageError(f"recipe {path} has unknown key(s) {unknown}; valid: {sorted(known)}")
    if not isinstance(raw.get("name"), str) or not raw.get("suites"):
        raise UsageError(f"recipe {path} needs a name and a non-empty suites list")
    suites = tuple(str(s) for s in raw["suites"])
    suite_models: dict[str, dict[str, Any]] = {}
    suite_trains: dict[str, dict[str, Any]] = {}
    for suite, table in raw.get("suite", {}).items():
        subs = table if isinstance(table, dict) else {}
        if (
            suite not in suites
            or not isinstance(table, dict)
            or set(table) - {"model", "train"}
            or not all(isinstance(v, dict) for v in subs.values())
        ):
            raise UsageError(
                f"recipe {path}: [suite.{suite}] must name one of its suites ({', '.join(suites)}) "
                "and hold only [suite.<name>.model] and [suite.<name>.train] tables"
            )
        if "model" in table:
            suite_models[suite] = dict(table["model"])
        if "train" in table:
            suite_trains[suite] = dict(table["train"])
    table = raw.get("model", {})
    if not isinstance(table, dict):
        raise UsageError(f"recipe {path}: model must be a [model] table")
    model, data = split_model_table(table, f"recipe {path} [model]")
    recipe = Recipe(
        name=raw["name"],
        suites=suites,
        model=model,
        data=data,
        train=config_from_dict(TrainRecipe, raw.get("train", {})),
        augment=config_from_dict(AugmentRecipe, raw.get("augment", {})),
        path=path,
        suite_models=suite_models,
        suite_trains=suite_trains,
    )
    for suite in {*suite_models, *suite_trains}:
        recipe.for_suite(suite)  # a bad override is refused here, naming the field
    return recipe

"""What ``reproduce`` decides: the suites it lays out and their collection defaults, the
``--columns`` names (trained Table S3 columns and evaluation-only variants) and
:class:`ReproduceConfig`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.primitives.config import CENTRE_SUFFIX
from awda_bench.suites import Suite
from awda_bench.training.columns import TRAINABLE, Column

SUITES: tuple[str, ...] = ("pick_place", "mosaic", "metaworld", "metaworld_ml45")
"""Suites ``reproduce`` knows how to lay out."""

DEFAULT_SYNTHESIZE = 200
"""Synthesized trajectories a collection adds (``--synthesize``) where
:data:`SUITE_SYNTHESIZE` has no entry for the suite."""

SUITE_SYNTHESIZE: dict[str, int] = {"metaworld": 450, "metaworld_ml45": 450}
"""Suites whose default differs. Meta-World: 10 per training env (45 envs), half the 20 task-driven
agent episodes per task, as pick-and-place's 200 are about half its 420 (the reference: 100 per
env beside 100 scripted demos per task, the same 1:1 ratio at five times our data)."""


DEFAULT_EPISODES_PER_TASK = 20
"""Training demos per task and embodiment (``--episodes-per-task``) where
:data:`SUITE_EPISODES_PER_TASK` has no entry for the suite (the reference recorded 100)."""

SUITE_EPISODES_PER_TASK: dict[str, int] = {"pick_place": 30}
"""Suites whose default differs. Pick-and-place: 30, chosen from measurements
(reports/learned/recipe-study.md, sessions 20-23): with ``small`` Full-1 reached 0.8975 held-out
at 20 per task, 0.9475 at 30 and 0.965 / 0.975 (two training seeds) at 50, and is data-limited
there. 30 is the most that keeps ``--columns full-1,tosvi`` from an empty directory near issue
24's 3 hours on the 2-core machines: measured from an empty directory on session 22's machine
(sessions 24-25), 2 h 56.5 min (collection 34 min, Full-1 26 min, T-OSVI 62 + 54 min; recipe
study, Session 24); ~2 h 40 min predicted at session 20's speed; 50 per task takes ~4 h."""


def default_episodes_per_task(suite_name: str) -> int:
    """``--episodes-per-task``'s default for ``suite_name``."""
    return SUITE_EPISODES_PER_TASK.get(suite_name, DEFAULT_EPISODES_PER_TASK)


def default_synthesize(suite_name: str) -> int:
    """``--synthesize``'s default for ``suite_name`` (:data:`SUITE_SYNTHESIZE`)."""
    return SUITE_SYNTHESIZE.get(suite_name, DEFAULT_SYNTHESIZE)


def column_key(column: Column) -> str:
    """``full-1``, ``no-adm``, ``tosvi``, ``tosvi-no-frame-stack``, ...: the ``--columns`` name
    and the method label (an ablation of ``awda`` is named by the ablation alone)."""
    if column.ablation is not None:
        return column.ablation if column.method == "awda" else f"{column.method}-{column.ablation}"
    return "full-1" if column.method == "awda" else column.method


COLUMN_KEYS: dict[str, Column] = {column_key(c): c for c in TRAINABLE}
"""Trained ``--columns`` names: Table S3's in its order, then the §S3 analysis's network."""


@dataclass(frozen=True)
class EvalVariant:
    """A ``--columns`` name that trains nothing: another ``run --method`` over a trained column's
    snapshots (the supplementary's §S3 analysis evaluates T-OSVI's with the mean and the mode
    action)."""

    name: str
    """Its title in tables."""
    trained: str
    """The :data:`COLUMN_KEYS` column whose snapshots it plays (it must be in ``--columns`` too)."""
    method: str
    """The ``run --method`` that plays them."""


EVAL_VARIANTS: dict[str, EvalVariant] = {
    "tosvi-mean": EvalVariant("T-OSVI, mean action", "tosvi", "tosvi-mean"),
    "tosvi-mode": EvalVariant("T-OSVI, mode action", "tosvi", "tosvi-mode"),
}
"""Evaluation-only ``--columns`` names."""


def column_title(key: str) -> str:
    """``Full-1``, ``T-OSVI, mean action``, ...: a ``--columns`` name's title."""
    return EVAL_VARIANTS[key].name if key in EVAL_VARIANTS else COLUMN_KEYS[key].name


DEFAULT_COLUMNS: tuple[str, ...] = ("full-1", "tosvi")

EVAL_METHOD: dict[str, str] = {"awda": "awda", "tosvi": "tosvi", "tosvi-depth": "tosvi-depth"}
"""Network architecture -> the ``run --method`` that evaluates its snapshots."""

DEFAULT_GRASP_SELECT = "centre"
"""How ``reproduce``'s AWDA columns pick the object to grasp: the reference's rule (the depth
component nearest the wrist image's centre). ``run``'s ``awda`` defaults to ``waypoint`` (grasp
where the waypoint points), which is exact for ground-truth waypoints but turns a learned
waypoint's 3-4 cm error into a missed grasp (pick-place-small-pointer-v3: 0.53 held-out with
``waypoint``, 0.83 with ``centre``, same snapshots and episodes)."""


def eval_method(arch: str, grasp_select: str) -> str:
    """The ``run --method`` that evaluates an ``arch`` column's snapshots under ``grasp_select``."""
    method = EVAL_METHOD[arch]
    return method + CENTRE_SUFFIX if arch == "awda" and grasp_select == "centre" else method


FIT_CHECK_COLUMN = "full-1"
FIT_CHECK_LABEL = "full-1 (train tasks)"
FIT_CHECK_TASKS = 2
FIT_CHECK_SNAPSHOTS = 3
"""Full-1's last 3 snapshots on training tasks (:func:`fit_check_tasks`; same episodes per
task as the held-out evaluation)."""


def _shared_words(a: str, b: str) -> int:
    """Leading hyphen-separated words two family names share (``door-unlock``, ``door-lock``: 1)."""
    n = 0
    for x, y in zip(a.split("-"), b.split("-"), strict=False):
        if x != y:
            break
        n += 1
    return n


def fit_check_tasks(suite: Suite) -> tuple[int, ...]:
    """The training tasks Full-1's fit check plays: did the recipe fit the tasks most like the
    held-out ones?

    Where every held-out task is a family of its own that training never shows (Meta-World), each
    held-out task's *sibling*: the training task whose family name shares the most leading words
    with it (at least one; the first by index on ties), so ``button-press`` -> ``button-press-
    topdown``, ``door-unlock`` -> ``door-close``, ``pick-place-wall`` -> ``pick-place``,
    ``sweep-into`` -> ``sweep``, ``window-open`` -> ``window-close``. A held-out task without one
    adds nothing. Otherwise (pick-and-place, whose held-out tasks are variations of the training
    family; or no sibling at all) the first :data:`FIT_CHECK_TASKS` training tasks."""
    train = suite.train_tasks
    train_families = {t.family for t in train}
    held_out = suite.eval_tasks
    if not held_out or any(t.family in train_families for t in held_out):
        return tuple(t.index for t in train[:FIT_CHECK_TASKS])
    siblings: list[int] = []
    for task in held_out:
        best = max(train, key=lambda t: (_shared_words(task.family, t.family), -t.index))
        if _shared_words(task.family, best.family) and best.index not in siblings:
            siblings.append(best.index)
    return tuple(siblings) or tuple(t.index for t in train[:FIT_CHECK_TASKS])


@dataclass(frozen=True)
class ReproduceConfig:
    """Everything ``python -m awda_bench reproduce`` decides."""

    suite: str
    out: Path
    recipe: str = "small"
    columns: tuple[str, ...] = DEFAULT_COLUMNS
    hold_out: str | None = None
    workers: int = 2
    episodes_per_task: int | None = None
    """Training demos per task and embodiment; ``None``: :func:`default_episodes_per_task`."""
    synthesize: int | None = None
    """Synthesized trajectories; ``None``: :func:`default_synthesize` of the suite."""
    val_episodes_per_task: int = 5
    snapshots: int = 10
    episodes: int | None = None
    steps: int | None = None
    seed: int | None = None
    """Every trained column's ``[train] seed`` (``train --seed``); ``None``: the recipe's."""
    threads: int | None = None
    fit_check: bool = True
    grasp_select: str = DEFAULT_GRASP_SELECT
    """AWDA columns' grasp rule (:data:`DEFAULT_GRASP_SELECT`; one of ``GRASP_SELECTS``)."""
    data: Path | None = None
    """The training collection; ``None``: ``OUT/data/train``. The collection holds every training
    task of the suite whatever ``hold_out`` (``train --hold-out`` leaves the family's episodes
    out), so MOSAIC's six leave-one-family-out runs can share one collection, and its feature
    cache, each in its own ``out``."""
    val_data: Path | None = None
    """The validation collection (a ``--split test`` one); ``None``: ``OUT/data/test``, collected
    there. Variants of a recipe on one training collection can share one (``--data`` beside it)."""
    dry_run: bool = False
    progress: bool = True
    """Let each stage show its progress bar (with ETA) on stderr."""

    @property
    def demos_per_task(self) -> int:
        """:attr:`episodes_per_task` with the suite's default filled in."""
        if self.episodes_per_task is not None:
            return self.episodes_per_task
        return default_episodes_per_task(self.suite)


def train_data(config: ReproduceConfig) -> Path:
    """Where the training collection is (or is collected to): ``--data`` or ``OUT/data/train``."""
    return config.data if config.data is not None else config.out / "data" / "train"


def parse_columns(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise UsageError("--columns is empty; name at least one, e.g. full-1,tosvi")
    for n in names:
        if n not in COLUMN_KEYS and n not in EVAL_VARIANTS:
            raise UnknownChoiceError("column", n, (*COLUMN_KEYS, *EVAL_VARIANTS))
    if len(set(names)) != len(names):
        raise UsageError(f"--columns names a column twice: {text}")
    for n in names:
        if n in EVAL_VARIANTS and EVAL_VARIANTS[n].trained not in names:
            trained = EVAL_VARIANTS[n].trained
            raise UsageError(
                f"--columns {n} plays the {trained} column's snapshots: add {trained} to "
                f"--columns, e.g. --columns {trained},{n}"
            )
    return names

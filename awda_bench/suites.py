"""Suite definitions: the data files in ``tasks/<name>.toml``, read into frozen dataclasses.

A suite names the ManiSkill env it runs, its tasks (each a ``task`` index passed to
``env.reset(options={"task": ...})``), which tasks are held out for evaluation, the horizon, and the
cameras a policy sees. Everything downstream (episode specs, workers, tables) starts from here.

Example file (``tasks/pick_place.toml``)::

    name = "pick_place"
    env_id = "AWDA-PickPlace-v1"
    display_name = "Pick-and-place"
    control_freq_hz = 20
    horizon_steps = 200
    held_out = [14, 15]
    episodes_per_task = 20
    [camera]
    height = 240
    width = 320
    [[tasks]]
    index = 0
    name = "milk->compartment 0"
    family = "pick_place"
"""

from __future__ import annotations

import hashlib
import tomllib
from dataclasses import dataclass
from pathlib import Path

from awda_bench.errors import CorruptFileError, UnknownChoiceError, UsageError

SUITES_DIR = Path(__file__).resolve().parent.parent / "tasks"
"""Where the suite definition files live (``tasks/`` at the project root)."""

DIFFICULTIES = ("easy", "medium", "hard", "very_hard")
"""Values a task's ``difficulty`` may take: the published Meta-World grouping the Meta-World suite
files cite (Seo et al. 2022); ManiSkill suites leave it unset."""

SIMULATORS = ("maniskill", "metaworld")
"""What a suite's episodes run on: the project's ManiSkill envs (in the project's environment), or
the ``metaworld`` package (in an environment of its own, see :mod:`awda_bench.runtimes`)."""


@dataclass(frozen=True)
class TaskDef:
    """One task (variation) of a suite."""

    index: int
    """Value of ``options["task"]`` at reset; unique within the suite."""
    name: str
    """Human-readable name, e.g. ``"can -> compartment 2"``."""
    family: str
    """Task family (``pick_place``, ``door``, ...): the column of Table S4."""
    env_id: str | None = None
    """ManiSkill env serving this task when it differs from the suite's (suites mixing families)."""
    variation: int | None = None
    """Value passed as ``options["task"]`` to that env; ``None`` means :attr:`index`."""
    difficulty: str | None = None
    """Published difficulty group (one of :data:`DIFFICULTIES`; Meta-World tasks), which Table S3's
    [easy] / [hard] rows are built from; ``None``: none."""

    @property
    def reset_task(self) -> int:
        """What ``env.reset(options={"task": ...})`` receives for this task."""
        return self.index if self.variation is None else self.variation


@dataclass(frozen=True)
class CameraDef:
    """The third-person RGB camera a policy observes."""

    height: int = 240
    """Image height [px] (reference pick-and-place: 240)."""
    width: int = 320
    """Image width [px] (reference pick-and-place: 320)."""
    name: str | None = None
    """The simulator's own camera to render from (Meta-World: ``"corner2"``); ``None`` for the
    camera the suite's env defines itself (the ManiSkill suites)."""


@dataclass(frozen=True)
class Suite:
    """A task suite as read from ``tasks/<name>.toml``."""

    name: str
    """Name used on the command line (``--suite NAME``)."""
    display_name: str
    """Row label in Table S3."""
    env_id: str
    """Registered ManiSkill env id (one env serves every task of the suite)."""
    control_freq_hz: int
    """Control steps per simulated second."""
    horizon_steps: int
    """Control steps per episode."""
    tasks: tuple[TaskDef, ...]
    """All tasks, train and held out."""
    held_out: tuple[int, ...]
    """Task indices evaluated by ``run`` (non-learned methods too)."""
    episodes_per_task: int
    """Evaluation episodes per held-out task per snapshot (paper: 20)."""
    camera: CameraDef
    """Third-person observation camera."""
    path: Path
    """The file this suite was read from."""
    episode_unit: str = "task"
    """``"task"``: ``episodes_per_task`` per held-out task; ``"family"``: that many per family,
    variations cycled deterministically (MOSAIC, Table S4)."""
    simulator: str = "maniskill"
    """One of :data:`SIMULATORS`. ``"metaworld"``: ``env_id`` is ``"metaworld"`` and each task's
    :attr:`TaskDef.name` is the Meta-World env it runs (``"sweep-into-v3"``)."""

    @property
    def horizon_s(self) -> float:
        """Episode length [s]."""
        return self.horizon_steps / self.control_freq_hz

    def file_sha256(self) -> str:
        """SHA-256 of the suite file's bytes (recorded by evaluation protocols and collections)."""
        return hashlib.sha256(self.path.read_bytes()).hexdigest()

    def env_id_for(self, task: int) -> str:
        """The env id serving suite task ``task``."""
        return self.task(task).env_id or self.env_id

    @property
    def env_ids(self) -> tuple[str, ...]:
        """Every env id the suite uses, in first-use order."""
        return tuple(dict.fromkeys(t.env_id or self.env_id for t in self.tasks))

    def task(self, index: int) -> TaskDef:
        for t in self.tasks:
            if t.index == index:
                return t
        raise UnknownChoiceError(
            f"task of suite {self.name!r}", index, [t.index for t in self.tasks]
        )

    @property
    def train_tasks(self) -> tuple[TaskDef, ...]:
        return tuple(t for t in self.tasks if t.index not in self.held_out)

    @property
    def eval_tasks(self) -> tuple[TaskDef, ...]:
        return tuple(self.task(i) for i in self.held_out)


def available_suites(directory: Path = SUITES_DIR) -> list[str]:
    """Names of the suites defined in ``directory``."""
    return sorted(p.stem for p in directory.glob("*.toml"))


def load_suite(name: str, directory: Path = SUITES_DIR) -> Suite:
    """Read ``directory/<name>.toml``; unknown names list the valid ones."""
    path = directory / f"{name}.toml"
    if not path.is_file():
        raise UnknownChoiceError("suite", name, available_suites(directory) or ["(none defined)"])
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise CorruptFileError(
            f"suite file {path} is not valid TOML ({exc}); fix or restore it"
        ) from exc
    try:
        tasks = tuple(
            TaskDef(
                index=int(t["index"]),
                name=str(t["name"]),
                family=str(t["family"]),
                env_id=str(t["env_id"]) if "env_id" in t else None,
                variation=int(t["variation"]) if "variation" in t else None,
                difficulty=str(t["difficulty"]) if "difficulty" in t else None,
            )
            for t in raw["tasks"]
        )
        suite = Suite(
            name=str(raw["name"]),
            display_name=str(raw.get("display_name", raw["name"])),
            env_id=str(raw["env_id"]),
            control_freq_hz=int(raw["control_freq_hz"]),
            horizon_steps=int(raw["horizon_steps"]),
            tasks=tasks,
            held_out=tuple(int(i) for i in raw["held_out"]),
            episodes_per_task=int(raw.get("episodes_per_task", 20)),
            camera=CameraDef(**raw.get("camera", {})),
            path=path,
            episode_unit=str(raw.get("episode_unit", "task")),
            simulator=str(raw.get("simulator", SIMULATORS[0])),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise CorruptFileError(
            f"suite file {path} is missing or mistypes a field ({exc!r})"
        ) from exc
    indices = [t.index for t in suite.tasks]
    if len(set(indices)) != len(indices):
        raise CorruptFileError(f"suite file {path} repeats a task index")
    for i in suite.held_out:
        if i not in indices:
            raise UsageError(
                f"suite file {path}: held-out task {i} is not among its tasks {indices}"
            )
    if suite.simulator not in SIMULATORS:
        raise CorruptFileError(
            f"suite file {path}: simulator {suite.simulator!r} is not one of {list(SIMULATORS)}"
        )
    for t in suite.tasks:
        if t.difficulty is not None and t.difficulty not in DIFFICULTIES:
            raise CorruptFileError(
                f"suite file {path}: task {t.index} has difficulty {t.difficulty!r}, not one of "
                f"{list(DIFFICULTIES)}"
            )
    if suite.name != name:
        raise CorruptFileError(
            f"suite file {path} declares name {suite.name!r}; rename one of them"
        )
    return suite

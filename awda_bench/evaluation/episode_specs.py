"""The evaluation protocol and its episode list, fixed before any scheduling.

Everything that decides whether two result tables are comparable goes into :class:`EvalProtocol`
and its :attr:`~EvalProtocol.fingerprint`: the suite file's bytes, the horizon, the evaluated tasks,
episodes per unit, the base seed and the harness's protocol version. The episode list follows from
the protocol alone, so results never depend on the number of workers or on their order.

Seeds are derived by hashing ``(suite, base seed, task, episode, role)``, never drawn from a shared
generator: episode ``i`` of task ``t`` gets the same scene whatever else is evaluated.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from awda_bench.episode import EpisodeSpec, derive_seed
from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.suites import SUITES_DIR, Suite, load_suite

PROTOCOL_VERSION = 2
"""Bumped whenever the harness changes how an episode is played or judged.

2: every episode, and every demo it shows, starts in a rebuilt scene (no PhysX history from the
worker's earlier episodes; see :mod:`awda_bench.evaluation.episode_runner`)."""

EPISODE_UNITS = ("task", "family")
"""How ``episodes`` is counted: per held-out task, or per family with variations cycled."""


@dataclass(frozen=True)
class EvalProtocol:
    """What defines comparability of results; hashed into :attr:`fingerprint`."""

    suite: str
    """Suite name."""
    suite_sha256: str
    """SHA-256 of the suite file's bytes (tasks, horizon, held-out set, cameras)."""
    horizon_steps: int
    """Control steps per episode."""
    eval_tasks: tuple[int, ...]
    """Evaluated task indices, in suite order."""
    episodes: int
    """Episodes per evaluation unit (per task, or per family; see :attr:`episode_unit`)."""
    episode_unit: str
    """``"task"``: ``episodes`` per held-out task; ``"family"``: per family, variations cycled."""
    base_seed: int
    """Base seed every episode seed is derived from."""
    protocol_version: int = PROTOCOL_VERSION
    """Harness protocol version (see :data:`PROTOCOL_VERSION`)."""

    @property
    def fingerprint(self) -> str:
        """First 16 hex digits of the SHA-256 of the protocol's canonical JSON."""
        blob = json.dumps(asdict(self), sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)


EVAL_SPLITS: tuple[str, ...] = ("test", "train")
"""``test``: the suite's held-out tasks (the paper's protocol); ``train``: its training tasks
(telling a low held-out number apart from a failure to fit). The evaluated tasks are part of the
fingerprint, so the two never mix in one cell."""


def make_protocol(
    suite: Suite, *, episodes: int | None, base_seed: int, split: str = "test"
) -> EvalProtocol:
    """The protocol for evaluating ``suite``; ``episodes=None`` takes the suite's default."""
    if split not in EVAL_SPLITS:
        raise UnknownChoiceError("--split", split, EVAL_SPLITS)
    n = suite.episodes_per_task if episodes is None else episodes
    if n < 1:
        raise UsageError(f"--episodes must be at least 1 (got {n})")
    if base_seed < 0:
        raise UsageError(f"--seed must be non-negative (got {base_seed})")
    unit = suite.episode_unit
    if unit not in EPISODE_UNITS:
        raise UsageError(
            f"suite {suite.name!r}: episode_unit {unit!r} is not one of {EPISODE_UNITS}"
        )
    return EvalProtocol(
        suite=suite.name,
        suite_sha256=suite.file_sha256(),
        horizon_steps=suite.horizon_steps,
        eval_tasks=tuple(
            t.index for t in (suite.eval_tasks if split == "test" else suite.train_tasks)
        ),
        episodes=n,
        episode_unit=unit,
        base_seed=base_seed,
    )


def protocol_drift(stored: Mapping[str, Any], suites_dir: Path = SUITES_DIR) -> list[str]:
    """What separates a recorded protocol (a report's ``summary.json`` ``protocols`` entry: its
    definition and ``fingerprint``) from the one today's code makes with the same settings; empty
    when they are the same protocol.

    Checked: the definition still hashes to its recorded fingerprint (else ``"fingerprint does not
    match its definition"``), the suite file's bytes (``"suite file changed"``, ``"suite gone"``)
    and the harness's :data:`PROTOCOL_VERSION` (``"protocol v1, today v2"``).
    """
    names = {f.name for f in fields(EvalProtocol)}
    definition: dict[str, Any] = {k: v for k, v in stored.items() if k in names}
    if "eval_tasks" in definition:
        definition["eval_tasks"] = tuple(definition["eval_tasks"])
    try:
        recorded = EvalProtocol(**definition)
    except TypeError as exc:
        return [f"not a protocol definition ({exc})"]
    drift = []
    if recorded.fingerprint != stored.get("fingerprint"):
        drift.append("fingerprint does not match its definition")
    try:
        suite = load_suite(recorded.suite, suites_dir)
    except UsageError:
        return [*drift, f"suite {recorded.suite!r} gone"]
    if suite.file_sha256() != recorded.suite_sha256:
        drift.append("suite file changed")
    if recorded.protocol_version != PROTOCOL_VERSION:
        drift.append(f"protocol v{recorded.protocol_version}, today v{PROTOCOL_VERSION}")
    return drift


def build_episode_specs(suite: Suite, protocol: EvalProtocol) -> list[EpisodeSpec]:
    """The full, ordered episode list of ``protocol`` (sorted by task, then episode index).

    ``episode_unit == "task"``: episodes ``0..n-1`` of every evaluated task.
    ``episode_unit == "family"``: episode ``i`` of a family runs its ``i % V``-th variation
    (``V`` evaluated variations in suite order); its episode index stays ``i``.
    """
    pairs: list[tuple[int, int]] = []
    if protocol.episode_unit == "task":
        pairs = [(t, i) for t in protocol.eval_tasks for i in range(protocol.episodes)]
    else:
        families: dict[str, list[int]] = {}
        for index in protocol.eval_tasks:
            families.setdefault(suite.task(index).family, []).append(index)
        for variations in families.values():
            pairs += [(variations[i % len(variations)], i) for i in range(protocol.episodes)]
    specs = [
        EpisodeSpec(
            suite=suite.name,
            task=task,
            episode=i,
            seed=derive_seed(suite.name, protocol.base_seed, task, i, "agent"),
            demo_seed=derive_seed(suite.name, protocol.base_seed, task, i, "demo"),
        )
        for task, i in pairs
    ]
    return sorted(specs, key=lambda s: (s.task, s.episode))

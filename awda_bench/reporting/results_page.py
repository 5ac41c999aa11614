"""``reports/RESULTS.md``: Table S3, Table S4, the reference rows and a grasp failure analysis on
one page, generated from the report directories the results index names (:mod:`results_index`).

What is read from each source directory (what ``python -m awda_bench report`` writes)::

    summary.json            mean ± SE per (suite, group, method)          -> "ours (mean ± SE)"
    per_snapshot.csv        successes and ok episodes per snapshot        -> "95% CI"
    grasp.csv               reached / grasped / success rates             -> failure analysis
    README.md, reproduce.md a ``reproduce`` command line, if they name one -> "regenerate"

The paper's values (:mod:`paper_values`) are printed in their own labelled columns and are never
an input to ours. Building the page reads everything first and writes last, so a bad index entry
leaves an existing page as it was.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.evaluation.carry import CARRY_OUTCOMES
from awda_bench.evaluation.episode_specs import PROTOCOL_VERSION, protocol_drift
from awda_bench.evaluation.methods import get_method
from awda_bench.reporting import bootstrap_ci, tables
from awda_bench.reporting.aggregate import ALL, FIRST_GRIP_COLUMNS, S4_FAMILIES, Cell, family_key
from awda_bench.reporting.paper_values import (
    NO_COUNTERPART,
    PAPER_S3,
    PAPER_S3_ANALYSIS,
    PAPER_S4,
    PAPER_S4_MOSAIC,
    S3_ANALYSIS_COLUMNS,
    S3_COLUMNS,
    S3_DIFFICULTY_GROUPS,
    S3_ROWS,
)
from awda_bench.reporting.results_index import (
    ANALYSIS_KEYS,
    INDEX_NAME,
    LEARNED_KEYS,
    REFERENCE_KEYS,
    SUITES,
    SourceEntry,
    load_index,
    load_missing,
)
from awda_bench.suites import TaskDef, load_suite

PAGE_NAME = "RESULTS.md"
"""The page's file name, written beside the index."""

COMMAND = "python -m awda_bench report --results-page"
"""The command that writes the page (``--index`` defaults to ``reports/results_sources.toml``)."""

TOX_COMMAND = "tox -e report -- --results-page"
"""The same through tox."""

NOT_RUN = "not run"
NOT_RECORDED = "not recorded"
"""A first-grip cell of a source evaluated before episodes recorded their first grip."""
FIRST_GRIP = "first grip: target / other / nothing / never"
"""The §S3 analysis column of first-grip rates (:data:`~awda_bench.reporting.aggregate.FIRST_GRIP_COLUMNS`)."""
FULL1_GRIP = "Full-1: reached / grasped / first grip (target / other / nothing / never)"
"""The Meta-World task table's breakdown of Full-1's episodes on the tasks that grasp."""
"""What a cell without a source says (its note says why)."""

NO_RUN_YET = "no run yet"
"""Why a column we can run has no source (followed by the index's ``missing`` text, if any)."""

METAWORLD_SUITE = "metaworld"
"""The suite behind Table S3's Meta-World rows (the reference's five held-out tasks)."""

SUITE_TITLES = {"pick_place": "Pick-and-place", "mosaic": "MOSAIC", METAWORLD_SUITE: "Meta-World"}
"""Suite display names."""

OURS = "ours (mean ± SE)"
CI = "95% CI"
SIZE = "snapshots × episodes"
PAPER = "paper"
SOURCE = "source"
NOTE = "note"

FAILURE_COLUMNS = ("missed the grasp", "grasped, then dropped or misplaced", "placed (success)")
"""The failure split's columns (fractions of the reached episodes)."""

AFTER_THE_GRASP = "after the grasp (carry.csv)"
"""The failure table's column from a source's ``carry.csv`` (printed when a source has one)."""

REQUIRED_FILES = ("summary.json", "per_snapshot.csv", "grasp.csv")
"""Files a source directory must hold."""


@dataclass(frozen=True)
class ReportDir:
    """One source directory, read once."""

    path: Path
    """The directory."""
    metric: str
    """Success metric its report used."""
    cells: dict[tuple[str, str, str], Cell]
    """summary.json's cells by (suite, group, method)."""
    per_snapshot: pd.DataFrame = field(repr=False)
    """per_snapshot.csv."""
    grasp: pd.DataFrame = field(repr=False)
    """grasp.csv."""
    per_task: pd.DataFrame | None = field(default=None, repr=False)
    """per_task.csv (``None``: a source written without one)."""
    carry: pd.DataFrame | None = field(default=None, repr=False)
    """carry.csv (``None``: no episode of the source recorded a carry)."""
    protocols: dict[str, dict[str, Any]] = field(default_factory=dict)
    """summary.json's evaluation protocols by suite (definition and fingerprint)."""


def read_report_dir(directory: Path, where: str) -> ReportDir:
    """Read a source directory; ``where`` names the index entry in error messages."""
    if not directory.is_dir():
        raise UsageError(
            f"{where}: source directory {directory} does not exist; set `source` to a report "
            "directory (relative to the index's folder) or delete the entry"
        )
    for name in REQUIRED_FILES:
        if not (directory / name).is_file():
            raise UsageError(
                f"{where}: {directory} has no {name}; write it with `python -m awda_bench report "
                f"--out {directory}` or set `source` to another report directory"
            )
    try:
        summary = json.loads((directory / "summary.json").read_text())
        cells = {(c["suite"], c["group"], c["method"]): Cell(**c) for c in summary["cells"]}
        metric = str(summary["metric"])
        protocols = {str(k): dict(v) for k, v in summary.get("protocols", {}).items()}
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise CorruptFileError(
            f"{where}: {directory / 'summary.json'} is not a report summary ({exc}); "
            "regenerate it with `python -m awda_bench report`"
        ) from exc
    return ReportDir(
        path=directory,
        metric=metric,
        cells=cells,
        per_snapshot=pd.read_csv(directory / "per_snapshot.csv"),
        grasp=pd.read_csv(directory / "grasp.csv"),
        per_task=(
            pd.read_csv(directory / "per_task.csv")
            if (directory / "per_task.csv").is_file()
            else None
        ),
        carry=pd.read_csv(directory / "carry.csv") if (directory / "carry.csv").is_file() else None,
        protocols=protocols,
    )


@dataclass(frozen=True)
class PageCell:
    """One of our cells as the page prints it."""

    mean: float | None
    """Mean over snapshots (over families too, for All) of the success rate; ``None``: no ok
    episode."""
    se: float | None
    """Standard error of ``mean``."""
    binomial: bool
    """The SE is binomial over one snapshot's episodes (printed with a dagger)."""
    errors: int
    """Error episodes (in no rate)."""
    size: str
    """Snapshots × episodes per snapshot, as text."""
    ci: tuple[float, float] | None
    """95 % stratified bootstrap CI; ``None``: see ``ci_note``."""
    ci_note: str
    """Why there is no CI."""
    entries: tuple[SourceEntry, ...]
    """Index entries it was read from."""
    strata: tuple[tuple[np.ndarray, ...], ...] | None = field(repr=False, compare=False)
    """Per family, each snapshot's 0/1 episode outcomes (``None``: not rebuildable)."""
    summary: str = ""
    """A mean over other rows (All, [easy], ...): the note printed instead of theirs, which
    stand in those rows."""

    def ours(self) -> str:
        """``"0.83 ± 0.07"`` (``†``: binomial SE; ``(N err)``: error episodes)."""
        if self.mean is None or self.se is None:
            return "n/a (no ok episode)"
        text = f"{self.mean:.2f} ± {self.se:.2f}"
        if self.binomial:
            text += tables.BINOMIAL_MARK
        return text + (f" ({self.errors} err)" if self.errors else "")

    def ci_text(self) -> str:
        """``"[0.79, 0.86]"`` or ``"n/a: why"``."""
        if self.ci is None:
            return f"n/a: {self.ci_note}"
        return f"[{self.ci[0]:.2f}, {self.ci[1]:.2f}]"


def snapshot_samples(report: ReportDir, suite: str, label: str, where: str) -> list[np.ndarray]:
    """Each snapshot's 0/1 outcomes of ``label`` on ``suite``, from per_snapshot.csv's
    ``successes`` and ``ok`` (snapshots without an ok episode are no sample), checked against the
    whole-suite cell of summary.json."""
    ps = report.per_snapshot
    rows = ps[(ps["suite"] == suite) & (ps["method"] == label)].sort_values("ord")
    rows = rows[rows["ok"] > 0]
    samples = [
        bootstrap_ci.outcomes(int(s), int(n))
        for s, n in zip(rows["successes"], rows["ok"], strict=True)
    ]
    whole = report.cells[(suite, ALL, label)]
    found = (len(samples), int(rows["ok"].sum()), int(rows["successes"].sum()))
    if found != (whole.snapshots, whole.episodes, whole.successes):
        raise UsageError(
            f"{where}: per_snapshot.csv of {report.path} ({found[0]} snapshots, {found[1]} "
            f"episodes, {found[2]} successes) disagrees with its summary.json ({whole.snapshots}, "
            f"{whole.episodes}, {whole.successes}); regenerate the directory with one "
            "`python -m awda_bench report`"
        )
    return samples


def _size(samples: Sequence[np.ndarray]) -> str:
    sizes = {s.size for s in samples}
    if len(sizes) == 1:
        return f"{len(samples)} × {sizes.pop()}"
    return f"{len(samples)} snapshots, {sum(s.size for s in samples)} episodes"


def _with_ci(
    strata: tuple[tuple[np.ndarray, ...], ...] | None, mean: float | None, why: str
) -> tuple[tuple[float, float] | None, str]:
    if mean is None:
        return None, "no ok episode"
    if strata is None:
        return None, why
    return bootstrap_ci.stratified_bootstrap_ci(strata), ""


def source_cell(entry: SourceEntry, report: ReportDir, group: str, where: str) -> PageCell:
    """Our cell for ``group`` (``"all"`` or a family) of ``entry``'s label in ``report``.

    The CI's samples: per_snapshot.csv's rows for a whole-suite cell; for a family cell, those
    rows when the family is all the source evaluated (a held-out family), its own counts when it
    has one snapshot, else none (per_snapshot.csv has no per-family rows).
    """
    cell = report.cells[(entry.suite, group, entry.label)]
    whole = report.cells[(entry.suite, ALL, entry.label)]
    suite_samples = snapshot_samples(report, entry.suite, entry.label, where)
    samples: list[np.ndarray] | None
    if group == ALL or (cell.episodes, cell.successes) == (whole.episodes, whole.successes):
        samples = suite_samples
    elif cell.snapshots == 1:
        samples = [bootstrap_ci.outcomes(cell.successes, cell.episodes)]
    else:
        samples = None
    strata = None if samples is None else (tuple(samples),)
    why = "per_snapshot.csv has no per-family rows"
    ci, ci_note = _with_ci(strata, cell.mean, why)
    return PageCell(
        mean=cell.mean,
        se=cell.se,
        binomial=cell.se_kind == "binomial",
        errors=cell.errors,
        size=_size(samples) if samples else f"{cell.snapshots} snapshots, {cell.episodes} episodes",
        ci=ci,
        ci_note=ci_note,
        entries=(entry,),
        strata=strata,
    )


def mean_over_families(cells: Sequence[PageCell], unit: str = "families") -> PageCell:
    """Table S4's All: the mean over families of their cells, SE = sqrt(sum of SE^2) / #families
    (families evaluated on separate episodes), CI stratified by family and snapshot. Table S3's
    Meta-World rows are the same mean over held-out tasks (``unit`` names them in the size)."""
    if any(c.mean is None or c.se is None for c in cells):
        return PageCell(None, None, False, 0, "", None, "no ok episode", (), None)
    means = [c.mean for c in cells if c.mean is not None]
    ses = [c.se for c in cells if c.se is not None]
    mean = sum(means) / len(means)
    se = math.sqrt(sum(s * s for s in ses)) / len(ses)
    strata = (
        None
        if any(c.strata is None for c in cells)
        else tuple(s for c in cells if c.strata is not None for s in c.strata)
    )
    ci, ci_note = _with_ci(strata, mean, "a family's snapshots cannot be rebuilt")
    sizes = {c.size for c in cells}
    entries = tuple(dict.fromkeys(e for c in cells for e in c.entries))
    return PageCell(
        mean=mean,
        se=se,
        binomial=False,
        errors=sum(c.errors for c in cells),
        size=f"{len(cells)} {unit} × {sizes.pop()}" if len(sizes) == 1 else "mixed",
        ci=ci,
        ci_note=ci_note,
        entries=entries,
        strata=strata,
        summary=f"the mean of the {len(cells)} {unit} above (how each was made: its row's note)",
    )


_REPRODUCE = re.compile(r"python -m awda_bench reproduce\b[^`#\n]*")


_DEMOS_PER_TASK = re.compile(r"^\| demos per training task \| (\d+) per embodiment", re.M)
"""reproduce.md's row naming the collection's episodes per task and embodiment."""


def regenerate_command(directory: Path) -> str | None:
    """The first ``python -m awda_bench reproduce ... --suite ...`` line in the directory's
    README.md or reproduce.md (backslash continuations joined), or ``None``.

    A command that leaves ``--episodes-per-task`` to its default gets the collection's figure
    from reproduce.md appended: the default has changed (pick-place: 20 until session 23, then
    30), so a command that relied on it would now collect another dataset."""
    for name in ("README.md", "reproduce.md"):
        path = directory / name
        if not path.is_file():
            continue
        text = re.sub(r"\\\n\s*", " ", path.read_text())
        for match in _REPRODUCE.finditer(text):
            command = " ".join(match.group(0).split())
            if "--suite" in command:
                return _with_demos_per_task(command, directory / "reproduce.md")
    return None


def _with_demos_per_task(command: str, reproduce_md: Path) -> str:
    if "--episodes-per-task" in command or not reproduce_md.is_file():
        return command
    found = _DEMOS_PER_TASK.search(reproduce_md.read_text())
    return command if found is None else f"{command} --episodes-per-task {found.group(1)}"


@dataclass(frozen=True)
class FailureSplit:
    """What became of the reached episodes of a grasping cell, derived from grasp.csv's rates
    (over the same episodes: the ok episodes of tasks with a grasp target), assuming
    success ⊆ grasped ⊆ reached."""

    missed: float
    """(reached - grasped) / reached: reached the object, missed the grasp."""
    dropped: float
    """(grasped - success) / reached: grasped and lifted it, then dropped or misplaced it."""
    placed: float
    """success / reached: placed it (succeeded)."""


RATE_TOLERANCE = 1e-9
"""How far rates may break success <= grasped <= reached (float round-off)."""


def protocol_text(report: ReportDir, suites: Sequence[str]) -> str:
    """A source's evaluation protocol per suite: its fingerprint and whether today's code makes the
    same one (:func:`~awda_bench.evaluation.episode_specs.protocol_drift`)."""
    parts = []
    for suite in suites:
        stored = report.protocols.get(suite)
        if stored is None:
            parts.append(f"{suite}: not recorded")
            continue
        drift = protocol_drift({**stored, "suite": stored.get("suite", suite)})
        state = "today's" if not drift else "**differs: " + "; ".join(drift) + "**"
        parts.append(f"{suite} `{stored.get('fingerprint')}` ({state})")
    return "; ".join(parts)


def failure_split(reached: float, grasped: float, success: float) -> FailureSplit | None:
    """:class:`FailureSplit` from the three rates (fractions of the same episodes); ``None`` when
    no episode reached the object. Rates that break success <= grasped <= reached raise
    ``ValueError`` (the assumption does not hold for them)."""
    if success > grasped + RATE_TOLERANCE or grasped > reached + RATE_TOLERANCE:
        raise ValueError(
            f"rates break success <= grasped <= reached: {success}, {grasped}, {reached}"
        )
    if reached <= 0:
        return None
    return FailureSplit(
        missed=max(reached - grasped, 0.0) / reached,
        dropped=max(grasped - success, 0.0) / reached,
        placed=success / reached,
    )


@dataclass
class ResultsPage:
    """The page's tables (DataFrames of text) and the Markdown they make."""

    index: Path
    """The index it was built from."""
    metric: str
    """Success metric of every cell."""
    s3_pick_place: pd.DataFrame
    s3_metaworld: pd.DataFrame
    s3_metaworld_tasks: pd.DataFrame
    """Each held-out Meta-World task's cell, per column with a source."""
    s3_analysis: pd.DataFrame
    """The supplementary's §S3 analysis: T-OSVI with the mean / mode action, without a stack."""
    s4: pd.DataFrame
    reference: pd.DataFrame
    failures: pd.DataFrame
    no_grasp: list[str]
    """Cells whose tasks report no grasp flags (no failure analysis)."""
    sources: pd.DataFrame

    def markdown(self) -> str:
        """The page."""
        lines = [
            "# Results: Tables S3 and S4, reference rows, grasp failures",
            "",
            f"Generated by `{COMMAND}` (through tox: `{TOX_COMMAND}`) from "
            f"[`{self.index.name}`]({self.index.name}), the committed index that names the report "
            "directory behind every cell. Do not edit this page: edit the index and regenerate.",
            "",
            f"- **{OURS}**: the source's `summary.json` cell: mean over snapshots of each "
            f"snapshot's success rate (`{self.metric}`, held-out tasks) ± standard error across "
            f"snapshots; `{tables.BINOMIAL_MARK}` marks a single snapshot, whose SE is binomial "
            "over its episodes.",
            f"- **{CI}**: stratified percentile bootstrap (`scipy.stats.bootstrap`, "
            f"{bootstrap_ci.N_RESAMPLES} resamples, `random_state={bootstrap_ci.RANDOM_STATE}`): "
            "each snapshot's episode outcomes (rebuilt from `per_snapshot.csv`'s `successes` and "
            "`ok`) are resampled on their own, the statistic is the mean over snapshots of their "
            "success rates. The snapshots stay fixed: it is the episode noise, not the spread "
            "between snapshots (the SE is that). All-success or all-failure data give [p, p].",
            f"- **{PAPER}**: the AWDA supplementary's cell, verbatim (mean ± SE over its last 10 "
            "snapshots). It is never an input to ours.",
            f"- **{NOT_RUN}**: no source for the cell; its note says why.",
            f"- **{SOURCE}**: the report directory (relative to this page) and the method label "
            "in it; how to regenerate each directory is under Sources.",
            "- **protocol** (Sources): each source's evaluation-protocol fingerprint (suite file "
            "bytes, horizon, evaluated tasks, episodes, seed, harness version), marked *today's* "
            "when the committed suite files and harness (protocol "
            f"v{PROTOCOL_VERSION}) make the same protocol, so a run made now is comparable; "
            "otherwise what differs.",
            "",
            "## Table S3: success on held-out tasks",
            "",
            "### Pick-and-place",
            "",
            tables.to_markdown(self.s3_pick_place),
            "### Meta-World",
            "",
            "Suite `metaworld` (the reference's five held-out tasks). The supplementary prints "
            "[easy] and [hard] rows without naming their tasks; ours group the held-out tasks by "
            "the published difficulty their suite file cites (Seo et al. 2022): [easy] = "
            + ", ".join(S3_DIFFICULTY_GROUPS["metaworld_easy"])
            + "; [hard] = "
            + ", ".join(S3_DIFFICULTY_GROUPS["metaworld_hard"])
            + ". Each row is the mean over its tasks' cells (SE = sqrt of the summed squared SEs "
            "/ tasks, as Table S4's All); the tasks' own cells are below the table.",
            "",
            tables.to_markdown(self.s3_metaworld),
            tables.to_markdown(self.s3_metaworld_tasks),
            "### §S3 analysis: T-OSVI's action selection and frame-stack (pick-and-place)",
            "",
            'The supplementary (§S3, "DAgger problem continued") evaluates the T-OSVI baseline '
            "with the mixture's mean and its mode action instead of a sample, and trains one "
            "without a frame-stack, judging them by *reaching* (the failure it studies: the "
            "policy reaches the wrong object). Its values are in its text, not a table; the "
            "baseline's own reaching rate is not given. Ours: reached and grasped are the rates "
            "of `grasp.csv` (all of the label's episodes), success is the cell's mean ± SE over "
            "snapshots. First grip: of the same episodes, the rates of what the gripper was "
            "first commanded closed on, the target (the nearest object within 4 cm of the TCP), "
            "another object, nothing within 4 cm, or never (episodes record it since "
            "2026-12-05; a source evaluated before says not recorded).",
            "",
            tables.to_markdown(self.s3_analysis),
            "## Table S4: MOSAIC, success on each held-out family",
            "",
            "All = the mean over the six families, where all six exist for the column (SE = "
            "sqrt of the summed squared SEs / 6; CI stratified by family and snapshot). The "
            "paper's columns: the same row of Table S4, and MOSAIC [3]'s row (another method; "
            "SE estimated by the AWDA authors from MOSAIC's standard deviation over 3 snapshots).",
            "",
            tables.to_markdown(self.s4),
            "## Reference rows (not learned)",
            "",
            "Privileged rows read the simulator: upper bounds, not comparable methods. "
            "MOSAIC's All is the mean over the six families, as in Table S4.",
            "",
            tables.to_markdown(self.reference),
            "## Grasp failures (issue 25)",
            "",
            "Derived from each source's `grasp.csv` rates, not from episode records: `reached`, "
            "`grasped` and `success` are fractions of the same episodes (the ok episodes of tasks "
            "with a grasp target; in MOSAIC stack block, basketball and nut assembly), and the "
            "split assumes success ⊆ grasped ⊆ reached (an episode that grasped also reached). Of "
            "the reached episodes: missed the grasp = (reached − grasped) / reached; grasped, "
            "then dropped or misplaced = (grasped − success) / reached; placed = success / "
            "reached. They sum to 1 (n/a where the rates break the assumption). Counts are the "
            "rates times the episodes. A row covers every episode of the label in its source (for "
            "a held-out family: that family).",
            "",
        ]
        if AFTER_THE_GRASP in self.failures.columns:
            lines += [
                f"{AFTER_THE_GRASP}: from the episode records (`awda_bench/evaluation/carry.py`), "
                "what became of the grasped targets: the shares of placed (success), held "
                "(never let go), dropped (let go with the gripper commanded closed), off target / "
                "on target (released open farther than the task's tolerance from over its goal, "
                "or over it and still failed); the median release point, and the median "
                "distance from over the goal of the last grasp-attributed predicted waypoint "
                f"(where the method meant to put it). {NOT_RECORDED}: evaluated before the "
                "analysis (2026-12-06).",
                "",
            ]
        lines.append(tables.to_markdown(self.failures))
        if self.no_grasp:
            lines += [
                "No grasp flags (their tasks have no grasp target): " + "; ".join(self.no_grasp),
                "",
            ]
        lines += ["## Sources", "", tables.to_markdown(self.sources)]
        return "\n".join(lines)


def _link(entry: SourceEntry) -> str:
    target = entry.source.rstrip("/") or "."
    shown = "reports/" if target == "." else f"{target}/"
    return f"[{shown}]({target}/) `{entry.label}`"


def _sources(cell: PageCell) -> str:
    return "; ".join(dict.fromkeys(_link(e) for e in cell.entries))


def _entry_notes(cell: PageCell) -> str:
    """The notes of the index entries ``cell`` was read from."""
    return "; ".join(dict.fromkeys(e.note for e in cell.entries if e.note))


def _notes(cell: PageCell) -> str:
    """A row's note: a mean's summary, else its entries' notes."""
    return cell.summary or _entry_notes(cell)


def _count(rate: float, n: int) -> int:
    return round(rate * n)


class _Builder:
    """Reads every source once and lays out the tables."""

    def __init__(self, index: Path) -> None:
        self.index = index
        self.entries = load_index(index)
        self.missing = load_missing(index)
        self.reports: dict[Path, ReportDir] = {}
        self.where: dict[SourceEntry, str] = {e: f"{index} {e.name}" for e in self.entries}
        for entry in self.entries:
            self._check(entry)
        metrics = {r.metric for r in self.reports.values()}
        if len(metrics) > 1:
            raise UsageError(
                f"{index}: its sources use different metrics ({', '.join(sorted(metrics))}); "
                "regenerate them with one `report --metric`"
            )
        self.metric = metrics.pop() if metrics else "success_once"

    def report(self, entry: SourceEntry) -> ReportDir:
        path = (self.index.parent / entry.source).resolve()
        if path not in self.reports:
            self.reports[path] = read_report_dir(path, self.where[entry])
        return self.reports[path]

    def _check(self, entry: SourceEntry) -> None:
        report = self.report(entry)
        where = self.where[entry]
        suites = sorted({s for s, _, _ in report.cells})
        if entry.suite not in suites:
            raise UsageError(
                f"{where}: {report.path} has no {entry.suite} cells (suites there: "
                f"{', '.join(suites) or 'none'}); set `source` to a {entry.suite} report directory"
            )
        labels = sorted({m for s, g, m in report.cells if s == entry.suite and g == ALL})
        if entry.label not in labels:
            raise UsageError(
                f"{where}: label {entry.label!r} not in {report.path / 'summary.json'} "
                f"(labels there: {', '.join(labels)}); set `label` to one of them"
            )
        if entry.family is not None and (entry.suite, entry.family, entry.label) not in (
            report.cells
        ):
            groups = sorted(
                g for s, g, m in report.cells if (s, m) == (entry.suite, entry.label) and g != ALL
            )
            raise UsageError(
                f"{where}: {report.path} has no {entry.family} cell for {entry.label!r} "
                f"(families there: {', '.join(groups) or 'none'}); fix the family or `source`"
            )
        snapshot_samples(report, entry.suite, entry.label, where)

    def find(self, suite: str, column: str, family: str | None) -> SourceEntry | None:
        """The entry that fills (suite, column, family): its own, else the whole suite's."""
        for wanted in (family, None) if family else (None,):
            for entry in self.entries:
                if (entry.suite, entry.column, entry.family) == (suite, column, wanted):
                    return entry
        return None

    def cell(self, suite: str, column: str, group: str) -> PageCell | str:
        """Our cell, or the reason it is not run."""
        entry = self.find(suite, column, None if group == ALL else group)
        if entry is None:
            if column in NO_COUNTERPART:
                return NO_COUNTERPART[column]
            if column not in LEARNED_KEYS + ANALYSIS_KEYS:
                return ""
            family = None if group == ALL else group
            why = self.missing.get((suite, column, family), self.missing.get((suite, column, None)))
            return NO_RUN_YET if why is None else f"{NO_RUN_YET}: {why}"
        report = self.report(entry)
        if (suite, group, entry.label) not in report.cells:
            return f"{entry.source} has no {group} episodes of {entry.label!r}"
        return source_cell(entry, report, group, self.where[entry])

    def family_cells(self, suite: str, column: str) -> list[tuple[str, PageCell | str]]:
        """Each S4 family's cell, then All (mean over families when all six exist)."""
        rows: list[tuple[str, PageCell | str]] = [
            (title, self.cell(suite, column, key)) for key, title in S4_FAMILIES
        ]
        found = [c for _, c in rows if isinstance(c, PageCell)]
        if len(found) == len(S4_FAMILIES):
            rows.append(("All", mean_over_families(found)))
        else:
            have = ", ".join(t for t, c in rows if isinstance(c, PageCell)) or "none"
            rows.append(("All", f"needs all six families (has: {have})"))
        return rows

    @staticmethod
    def _row(cell: PageCell | str, extra_note: str = "") -> dict[str, str]:
        if isinstance(cell, str):
            note = "; ".join(n for n in (cell, extra_note) if n)
            return {OURS: NOT_RUN, CI: "–", SIZE: "–", SOURCE: "–", NOTE: note}
        note = "; ".join(n for n in (_notes(cell), extra_note) if n)
        return {
            OURS: cell.ours(),
            CI: cell.ci_text(),
            SIZE: cell.size,
            SOURCE: _sources(cell),
            NOTE: note,
        }

    def s3_pick_place(self) -> pd.DataFrame:
        rows, index = [], []
        for key, title in S3_COLUMNS:
            row = self._row(self.cell("pick_place", key, ALL))
            row[PAPER] = PAPER_S3["pick_place"][key]
            rows.append(row)
            index.append(f"{title} (`{key}`)")
        columns = [OURS, CI, SIZE, PAPER, SOURCE, NOTE]
        return pd.DataFrame(rows, index=pd.Index(index, name="column"), columns=columns)

    def task_cells(self, suite: str, column: str) -> list[tuple[TaskDef, PageCell | str]]:
        """Each held-out task of ``suite`` (a suite whose tasks are their own families, as
        Meta-World's) with ``column``'s cell."""
        return [
            (task, self.cell(suite, column, family_key(task.family)))
            for task in load_suite(suite).eval_tasks
        ]

    def difficulty_cells(self, suite: str, column: str) -> dict[str, PageCell | str]:
        """Table S3's Meta-World rows (:data:`S3_DIFFICULTY_GROUPS`) for ``column``: the mean over
        the held-out tasks of each row's difficulties, or why there is none."""
        tasks = self.task_cells(suite, column)
        rows: dict[str, PageCell | str] = {}
        for row, groups in S3_DIFFICULTY_GROUPS.items():
            members = [(t, c) for t, c in tasks if t.difficulty in groups]
            missing = [c for _, c in members if isinstance(c, str)]
            if not members:
                rows[row] = "no held-out task of this difficulty"
            elif missing:
                rows[row] = missing[0]
            else:
                rows[row] = mean_over_families(
                    [c for _, c in members if isinstance(c, PageCell)], "tasks"
                )
        return rows

    def s3_metaworld(self) -> pd.DataFrame:
        rows, index = [], []
        for key, title in S3_COLUMNS:
            cells = self.difficulty_cells(METAWORLD_SUITE, key)
            found = [c for c in cells.values() if isinstance(c, PageCell)]
            row: dict[str, str] = {}
            for r, t in S3_ROWS[1:]:
                cell = cells[r]
                row[f"ours: {t}"] = cell.ours() if isinstance(cell, PageCell) else NOT_RUN
            for r, t in S3_ROWS[1:]:
                row[f"{PAPER}: {t}"] = PAPER_S3[r][key]
            all_cell = cells["metaworld_all"]
            row[f"{CI} [all]"] = all_cell.ci_text() if isinstance(all_cell, PageCell) else "–"
            row[SOURCE] = _sources(found[0]) if found else "–"
            why = next((c for c in cells.values() if isinstance(c, str)), "")
            row[NOTE] = "; ".join(n for n in ((_entry_notes(found[0]) if found else ""), why) if n)
            rows.append(row)
            index.append(f"{title} (`{key}`)")
        return pd.DataFrame(rows, index=pd.Index(index, name="column"))

    def s3_metaworld_tasks(self) -> pd.DataFrame:
        keys = [k for k, _ in S3_COLUMNS] + list(REFERENCE_KEYS)
        present = [k for k in keys if self.find(METAWORLD_SUITE, k, None) is not None]
        titles = dict(S3_COLUMNS)
        columns = [f"{titles.get(k, k)} (`{k}`)" for k in present]
        rows, index = [], []
        for task in load_suite(METAWORLD_SUITE).eval_tasks:
            row = {"difficulty": task.difficulty or "–"}
            for key, name in zip(present, columns, strict=True):
                cell = self.cell(METAWORLD_SUITE, key, family_key(task.family))
                row[name] = cell.ours() if isinstance(cell, PageCell) else NOT_RUN
            if "full-1" in present:
                row[FULL1_GRIP] = self.task_grips(METAWORLD_SUITE, "full-1", task.index)
            rows.append(row)
            index.append(task.name)
        if "full-1" in present:
            columns.append(FULL1_GRIP)
        if not present:
            rows = [{"difficulty": "–", NOTE: "no Meta-World source in the index yet"}]
            index = ["–"]
            columns = [NOTE]
        return pd.DataFrame(
            rows, index=pd.Index(index, name="held-out task"), columns=["difficulty", *columns]
        )

    def task_grips(self, suite: str, column: str, task: int) -> str:
        """``0.97 / 0.97 / 0.97 / 0.00 / 0.04 / 0.00``: reached, grasped and the first-grip rates
        of ``column``'s episodes of one task from its source's per_task.csv (on a push, reached
        is the hand at the object and the grip is "never"), :data:`NOT_RECORDED` where the source
        predates the per-task breakdown."""
        entry = self.find(suite, column, None)
        table = None if entry is None else self.report(entry).per_task
        wanted = ["reached", "grasped", *FIRST_GRIP_COLUMNS.values()]
        if entry is None or table is None or not set(wanted) <= set(table.columns):
            return NOT_RECORDED
        match = table[
            (table["suite"] == suite) & (table["method"] == entry.label) & (table["task"] == task)
        ]
        if match.empty or match.iloc[0][wanted].isna().any():
            return NOT_RECORDED
        return " / ".join(f"{float(r):.2f}" for r in match.iloc[0][wanted])

    def s3_analysis(self) -> pd.DataFrame:
        rows, index = [], []
        for key, title in (("tosvi", dict(S3_COLUMNS)["tosvi"]), *S3_ANALYSIS_COLUMNS):
            cell = self.cell("pick_place", key, ALL)
            paper = PAPER_S3_ANALYSIS.get(key, {})
            row = {
                "reached": "–",
                "grasped": "–",
                FIRST_GRIP: "–",
                OURS: NOT_RUN,
                f"{PAPER}: reached": paper.get("reached", "not given"),
                f"{PAPER}: success": paper.get(
                    "success", PAPER_S3["pick_place"][key] if key == "tosvi" else "not given"
                ),
                SOURCE: "–",
                NOTE: cell if isinstance(cell, str) else _notes(cell),
            }
            entry = self.find("pick_place", key, None)
            if isinstance(cell, PageCell) and entry is not None:
                rates = self.rates(entry)
                if rates is not None:
                    row["reached"], row["grasped"] = (f"{r:.2f}" for r in rates[:2])
                row[FIRST_GRIP] = self.first_grips(entry)
                row[OURS] = cell.ours()
                row[SOURCE] = _sources(cell)
            rows.append(row)
            index.append(f"{title} (`{key}`)")
        columns = [
            "reached", "grasped", FIRST_GRIP, OURS, f"{PAPER}: reached", f"{PAPER}: success",
            SOURCE, NOTE,
        ]  # fmt: skip
        return pd.DataFrame(rows, index=pd.Index(index, name="column"), columns=columns)

    def first_grips(self, entry: SourceEntry) -> str:
        """``target / other / nothing / never`` rates of the entry's label from its grasp.csv,
        or :data:`NOT_RECORDED` where it has none (a source evaluated before the analysis)."""
        match = self.grasp_row(entry)
        columns = list(FIRST_GRIP_COLUMNS.values())
        if match is None or not set(columns) <= set(match.index):
            return NOT_RECORDED
        rates = match[columns]
        if rates.isna().any():
            return NOT_RECORDED
        return " / ".join(f"{float(r):.2f}" for r in rates)

    def rates(self, entry: SourceEntry) -> tuple[float, float, float, int] | None:
        """``(reached, grasped, success, episodes)`` of the entry's label from its grasp.csv, or
        ``None`` where its tasks report no grasp flags."""
        r = self.grasp_row(entry)
        if r is None or pd.isna(r["reached"]):
            return None
        return float(r["reached"]), float(r["grasped"]), float(r["success"]), int(r["episodes"])

    def grasp_row(self, entry: SourceEntry) -> pd.Series | None:
        """The entry's label's row of its source's grasp.csv (``None``: the label has none)."""
        g = self.report(entry).grasp
        match = g[(g["suite"] == entry.suite) & (g["method"] == entry.label)]
        return None if match.empty else match.iloc[0]

    def s4(self) -> pd.DataFrame:
        keys = ["full-1"] + [
            k
            for k in LEARNED_KEYS
            if k != "full-1"
            and (
                any(e.suite == "mosaic" and e.column == k for e in self.entries)
                or any(s == "mosaic" and c == k for s, c, _ in self.missing)
            )
        ]
        titles = dict(S3_COLUMNS)
        by_key = {k: dict(self.family_cells("mosaic", k)) for k in keys}
        rows, index = [], []
        for family, family_title in [*S4_FAMILIES, (ALL, "All")]:
            for key in keys:
                row = {"column": f"{titles[key]} (`{key}`)", **self._row(by_key[key][family_title])}
                if key == "full-1":
                    row[f"{PAPER}: Full-1"] = PAPER_S4[(key, family)]
                else:
                    row[f"{PAPER}: Full-1"] = f"Table S4 has no {titles[key]} row"
                row[f"{PAPER}: MOSAIC [3]"] = PAPER_S4_MOSAIC[family]
                rows.append(row)
                index.append(family_title)
        columns = ["column", OURS, CI, SIZE, f"{PAPER}: Full-1", f"{PAPER}: MOSAIC [3]", SOURCE]
        return pd.DataFrame(rows, index=pd.Index(index, name="family"), columns=[*columns, NOTE])

    def reference(self) -> pd.DataFrame:
        rows, index = [], []
        for suite in SUITES:
            for key in REFERENCE_KEYS:
                description = get_method(key).description
                cells: list[tuple[str, PageCell | str]]
                if suite == "pick_place":
                    cells = [("–", self.cell(suite, key, ALL))]
                elif suite == METAWORLD_SUITE:
                    tasks = [(t.name, c) for t, c in self.task_cells(suite, key)]
                    cells = [*tasks, ("All", self.cell(suite, key, ALL))]
                else:
                    cells = self.family_cells(suite, key)
                if all(isinstance(c, str) for _, c in cells):
                    cells = [("–", "no source in the index (not evaluated yet)")]
                for group, cell in cells:
                    rows.append({"family": group, "method": key, **self._row(cell, description)})
                    index.append(SUITE_TITLES[suite])
        columns = ["family", "method", OURS, CI, SIZE, SOURCE, NOTE]
        return pd.DataFrame(rows, index=pd.Index(index, name="suite"), columns=columns)

    def failures(self) -> tuple[pd.DataFrame, list[str]]:
        titles = dict(S3_COLUMNS) | dict(S3_ANALYSIS_COLUMNS)
        rows, index, no_grasp = [], [], []
        for entry in self.entries:
            scope = f" ({entry.family})" if entry.family else ""
            name = f"{titles.get(entry.column, entry.column)}{scope}"
            rates = self.rates(entry)
            if rates is None:
                no_grasp.append(f"{SUITE_TITLES[entry.suite]} {name}")
                continue
            reached, grasped, success, n = rates
            n_reached = _count(reached, n)
            row = {
                "cell": name,
                SOURCE: _link(entry),
                "episodes with a grasp target": str(n),
                "reached": f"{reached:.2f} ({n_reached}/{n})",
            }
            try:
                split = failure_split(reached, grasped, success)
            except ValueError:  # the split's assumption does not hold for these rates: say so
                split, why = None, f"n/a: grasped {grasped:.2f}, success {success:.2f}"
            else:
                why = "– (none reached)"
            if split is None:
                row |= dict.fromkeys(FAILURE_COLUMNS, why)
            else:
                row |= {
                    "missed the grasp": f"{split.missed:.2f} "
                    f"({_count(reached - grasped, n)}/{n_reached})",
                    "grasped, then dropped or misplaced": f"{split.dropped:.2f} "
                    f"({_count(grasped - success, n)}/{n_reached})",
                    "placed (success)": f"{split.placed:.2f} ({_count(success, n)}/{n_reached})",
                }
            carry = self.after_the_grasp(entry)
            if carry is not None:
                row[AFTER_THE_GRASP] = carry
            rows.append(row)
            index.append(SUITE_TITLES[entry.suite])
        columns = ["cell", SOURCE, "episodes with a grasp target", "reached", *FAILURE_COLUMNS]
        if any(AFTER_THE_GRASP in row for row in rows):
            columns.append(AFTER_THE_GRASP)
            rows = [{AFTER_THE_GRASP: NOT_RECORDED, **row} for row in rows]
        return pd.DataFrame(rows, index=pd.Index(index, name="suite"), columns=columns), no_grasp

    def after_the_grasp(self, entry: SourceEntry) -> str | None:
        """What became of the entry's grasped targets, from its source's carry.csv (the carry
        analysis' outcome shares over the grasped episodes, the median release point and where
        the method meant to put the target), or ``None`` where the source has no such row."""
        carry = self.report(entry).carry
        if carry is None:
            return None
        match = carry[(carry["suite"] == entry.suite) & (carry["method"] == entry.label)]
        if entry.family is not None:
            match = match[match["family"] == entry.family]
        if match.empty:
            return None
        r = match.iloc[0]
        shares = ", ".join(
            f"{name.replace('_', ' ')} {float(r[name]):.2f}" for name in CARRY_OUTCOMES
        )
        text = f"{int(r['grasped'])} grasped: {shares}"
        if not pd.isna(r["release_xy_cm"]):
            text += (
                f"; released {float(r['release_xy_cm']):.1f} cm from over the goal, "
                f"{float(r['release_dz_cm']):.1f} cm above it"
            )
        if not pd.isna(r["place_wp_xy_cm"]):
            text += f"; meant {float(r['place_wp_xy_cm']):.1f} cm from it"
        return text

    def sources(self) -> pd.DataFrame:
        by_dir: dict[str, list[SourceEntry]] = {}
        for entry in self.entries:
            by_dir.setdefault(entry.source.rstrip("/") or ".", []).append(entry)
        rows, index = [], []
        for source, entries in by_dir.items():
            directory = self.index.parent / source
            command = regenerate_command(directory)
            if command is not None:
                how = f"`{command}`"
            else:
                notes = [n for n in ("README.md", "reproduce.md") if (directory / n).is_file()]
                readme = f"{source}/{notes[0]}".removeprefix("./") if notes else "README.md"
                how = f"see [{readme}]({readme})"
            report = self.report(entries[0])
            rows.append(
                {
                    "cells": ", ".join(f"{e.name} (`{e.label}`)" for e in entries),
                    "protocol": protocol_text(report, sorted({e.suite for e in entries})),
                    "regenerate": how,
                }
            )
            index.append(f"[{'reports/' if source == '.' else source + '/'}]({source}/)")
        return pd.DataFrame(rows, index=pd.Index(index, name="source"))


def build_results_page(index: Path) -> ResultsPage:
    """Read ``index`` and every source it names; lay out the page (nothing is written)."""
    builder = _Builder(index)
    failures, no_grasp = builder.failures()
    return ResultsPage(
        index=index,
        metric=builder.metric,
        s3_pick_place=builder.s3_pick_place(),
        s3_metaworld=builder.s3_metaworld(),
        s3_metaworld_tasks=builder.s3_metaworld_tasks(),
        s3_analysis=builder.s3_analysis(),
        s4=builder.s4(),
        reference=builder.reference(),
        failures=failures,
        no_grasp=no_grasp,
        sources=builder.sources(),
    )


def write_results_page(index: Path) -> Path:
    """Build the page from ``index`` and write it beside the index (``RESULTS.md``); any error
    is raised before the page is touched."""
    text = build_results_page(index).markdown()
    path = index.parent / PAGE_NAME
    tmp = path.with_name(f".{PAGE_NAME}.tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path


DEFAULT_INDEX = Path("reports") / INDEX_NAME
"""The committed index."""

"""The results page's index: which report directory feeds which cell (``reports/results_sources.toml``).

One inline table per cell, so pointing a cell at another directory is a one-line change::

    [pick_place]                       # a suite: whole-suite cells, keyed by column
    full-1 = { source = "learned/pick_place-small-v4" }
    scripted = { source = "." }        # "." is the index's own directory (reports/)

    [mosaic]                           # whole-suite MOSAIC cells: every family and All
    gt-waypoints = { source = "." }

    [mosaic.drawer]                    # one held-out family
    full-1 = { source = "learned/mosaic-small-drawer", note = "older recipe" }

``source``: a report directory (what ``python -m awda_bench report`` writes), relative to the
index's directory. ``label``: the method label inside it (default: the column key, which is the
label ``reproduce`` gives a column). ``note``: a short text printed beside the cell.

A cell that has no run yet may say why, what it would cost and the command that fills it, in place
of a source (:func:`load_missing`)::

    tosvi-depth = { missing = "train ~80 + evaluate ~75 min: reproduce ... --columns tosvi-depth" }
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from awda_bench.errors import CorruptFileError, UnknownChoiceError, UsageError
from awda_bench.reporting.aggregate import S4_FAMILIES
from awda_bench.reporting.paper_values import NO_COUNTERPART, S3_ANALYSIS_COLUMNS, S3_COLUMNS

INDEX_NAME = "results_sources.toml"
"""The index's file name (in ``reports/``)."""

SUITES: tuple[str, ...] = ("pick_place", "mosaic", "metaworld")
"""Suites the page has tables for."""

REFERENCE_KEYS: tuple[str, ...] = ("scripted", "gt-waypoints", "gt-waypoints-centre", "random")
"""Column keys of the reference rows (not learned): the run method names."""

LEARNED_KEYS: tuple[str, ...] = tuple(k for k, _ in S3_COLUMNS if k not in NO_COUNTERPART)
"""Column keys of Table S3 this project can train."""

ANALYSIS_KEYS: tuple[str, ...] = tuple(k for k, _ in S3_ANALYSIS_COLUMNS)
"""Column keys of the supplementary's §S3 analysis (T-OSVI variants; pick-and-place only)."""

FAMILY_KEYS: tuple[str, ...] = tuple(k for k, _ in S4_FAMILIES)
"""MOSAIC families an entry may name (Table S4's columns)."""

ENTRY_FIELDS: tuple[str, ...] = ("source", "label", "note")
"""Fields of one entry."""

MISSING_FIELD = "missing"
"""The one field of an entry for a cell with no run yet: why, and how to fill it."""


@dataclass(frozen=True)
class SourceEntry:
    """One line of the index: a cell and where its numbers come from."""

    suite: str
    """Suite (``pick_place``, ``mosaic``)."""
    column: str
    """Column key (``full-1``, ``tosvi``, ``gt-waypoints``, ...)."""
    family: str | None
    """MOSAIC family of a held-out-family entry; ``None``: the whole suite (and its families)."""
    source: str
    """Report directory, relative to the index's directory (``"."``: that directory)."""
    label: str
    """Method label inside the source's summary.json / per_snapshot.csv / grasp.csv."""
    note: str
    """Printed beside the cell (empty: none)."""

    @property
    def name(self) -> str:
        """How an error names the entry: ``[mosaic.drawer] full-1``."""
        table = self.suite if self.family is None else f"{self.suite}.{self.family}"
        return f"[{table}] {self.column}"


def _entry(index: Path, suite: str, family: str | None, column: str, value: object) -> SourceEntry:
    where = f"{index} [{suite if family is None else f'{suite}.{family}'}] {column}"
    if column in NO_COUNTERPART:
        raise UsageError(f"{where}: {NO_COUNTERPART[column]}; delete the entry")
    known = LEARNED_KEYS + REFERENCE_KEYS + ANALYSIS_KEYS
    if column not in known:
        raise UnknownChoiceError(f"column in {where}", column, known)
    if column in ANALYSIS_KEYS and suite != "pick_place":
        raise UsageError(
            f"{where}: the §S3 analysis ({column}) is a pick-and-place analysis; move the entry "
            "to [pick_place]"
        )
    if not isinstance(value, dict) or not isinstance(value.get("source"), str):
        raise UsageError(
            f'{where}: write it as {column} = {{ source = "DIR" }} (DIR relative to {index.parent})'
        )
    unknown = sorted(set(value) - set(ENTRY_FIELDS))
    if unknown:
        raise UnknownChoiceError(f"field in {where}", unknown[0], ENTRY_FIELDS)
    for field_name in ("label", "note"):
        if not isinstance(value.get(field_name, ""), str):
            raise UsageError(f"{where}: {field_name} must be a string")
    return SourceEntry(
        suite=suite,
        column=column,
        family=family,
        source=value["source"],
        label=value.get("label", column),
        note=value.get("note", ""),
    )


def _cells(index: Path) -> Iterator[tuple[str, str | None, str, object]]:
    """``(suite, family, column, value)`` of every line of ``index``, in file order."""
    if not index.is_file():
        raise UsageError(f"no results index at {index}; write one (see reports/{INDEX_NAME})")
    try:
        data = tomllib.loads(index.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise CorruptFileError(f"{index} is not valid TOML: {exc}") from exc
    for suite, table in data.items():
        if suite not in SUITES:
            raise UnknownChoiceError(f"suite table in {index}", suite, SUITES)
        if not isinstance(table, dict):
            raise UsageError(f"{index}: [{suite}] must be a table of cells")
        for key, value in table.items():
            if suite == "mosaic" and key in FAMILY_KEYS and isinstance(value, dict):
                for column, cell in value.items():
                    yield suite, key, column, cell
            else:
                yield suite, None, key, value


def _is_missing(value: object) -> bool:
    return isinstance(value, dict) and MISSING_FIELD in value


def load_missing(index: Path) -> dict[tuple[str, str, str | None], str]:
    """``(suite, column, family) -> text`` of the index's cells with no run yet (``missing =``;
    family ``None``: the whole suite, so every family without a source of its own)."""
    missing: dict[tuple[str, str, str | None], str] = {}
    for suite, family, column, value in _cells(index):
        if not _is_missing(value):
            continue
        assert isinstance(value, dict)
        table = suite if family is None else f"{suite}.{family}"
        where = f"{index} [{table}] {column}"
        known = LEARNED_KEYS + ANALYSIS_KEYS
        if column not in known:
            raise UnknownChoiceError(f"column in {where}", column, known)
        if set(value) != {MISSING_FIELD} or not isinstance(value[MISSING_FIELD], str):
            raise UsageError(
                f'{where}: a cell with no run is written {column} = {{ {MISSING_FIELD} = "WHY" }} '
                '(a text only; with a run, use source = "DIR" instead)'
            )
        missing[(suite, column, family)] = value[MISSING_FIELD]
    return missing


def load_index(index: Path) -> list[SourceEntry]:
    """The entries of ``index`` that name a source, in file order (cells with no run yet:
    :func:`load_missing`); a bad file raises a one-line :class:`~awda_bench.errors.UsageError`
    naming the entry and the fix."""
    entries = [
        _entry(index, suite, family, column, value)
        for suite, family, column, value in _cells(index)
        if not _is_missing(value)
    ]
    seen: dict[tuple[str, str, str | None], SourceEntry] = {}
    for entry in entries:
        for family in (entry.family, None) if entry.family else (None, *FAMILY_KEYS):
            other = seen.get((entry.suite, entry.column, family))
            if other is not None:
                raise UsageError(
                    f"{index}: {entry.name} and {other.name} both fill the same cells; "
                    "delete one of them"
                )
        seen[(entry.suite, entry.column, entry.family)] = entry
    return entries

"""Report tables as DataFrames of strings, and their Markdown / CSV / LaTeX renderings.

Cells read ``"mean ± SE"`` with two decimals; a dagger marks an SE that is binomial over the
episodes of a single snapshot (instead of across snapshots). Methods that read the simulator are
named with :data:`PRIVILEGED_MARK`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pandas as pd

from awda_bench.reporting.aggregate import ALL, S4_FAMILIES, Cell

BINOMIAL_MARK = "†"
"""Suffix of a cell whose SE is binomial over episodes (one snapshot)."""

PRIVILEGED_MARK = " (privileged)"
"""Suffix of a method that reads the simulator (an upper bound, not a comparable method)."""


def mark_privileged(cells: list[Cell], privileged: set[str]) -> list[Cell]:
    """``cells`` with :data:`PRIVILEGED_MARK` after the names of the ``privileged`` methods."""
    return [
        replace(c, method=c.method + PRIVILEGED_MARK) if c.method in privileged else c
        for c in cells
    ]


def format_cell(cell: Cell | None) -> str:
    if cell is None:
        return "–"
    if cell.mean is None or cell.se is None:
        return f"n/a ({cell.errors} err)" if cell.errors else "n/a"
    text = f"{cell.mean:.2f} ± {cell.se:.2f}"
    if cell.se_kind == "binomial":
        text += BINOMIAL_MARK
    if cell.errors:
        text += f" ({cell.errors} err)"
    return text


def table_s3(cells: list[Cell], display_names: dict[str, str]) -> pd.DataFrame:
    """Rows = suites, columns = methods; whole-suite cells."""
    whole = [c for c in cells if c.group == ALL]
    methods = sorted({c.method for c in whole})
    suites = sorted({c.suite for c in whole})
    index = {(c.suite, c.method): c for c in whole}
    data = [[format_cell(index.get((s, m))) for m in methods] for s in suites]
    return pd.DataFrame(
        data,
        index=pd.Index([display_names.get(s, s) for s in suites], name="Suite"),
        columns=methods,
    )


def table_s4(cells: list[Cell]) -> pd.DataFrame | None:
    """Rows = methods (per suite), columns = the six S4 families + All; ``None`` if none. A row
    that lacks some of the six families (a held-out family evaluated alone) has no "All"."""
    keys = {k for k, _ in S4_FAMILIES}
    suites = sorted({c.suite for c in cells if c.group in keys})
    if not suites:
        return None
    rows, labels = [], []
    for suite in suites:
        index = {(c.group, c.method): c for c in cells if c.suite == suite}
        has_subset = any(g == "s4_all" for g, _ in index)
        for method in sorted({c.method for c in cells if c.suite == suite}):
            row = [format_cell(index.get((k, method))) for k, _ in S4_FAMILIES]
            complete = all((k, method) in index for k, _ in S4_FAMILIES)
            whole = index.get(("s4_all" if has_subset else ALL, method)) if complete else None
            row.append(format_cell(whole))
            rows.append(row)
            labels.append(method if len(suites) == 1 else f"{method} ({suite})")
    columns = [title for _, title in S4_FAMILIES] + ["All"]
    return pd.DataFrame(rows, index=pd.Index(labels, name="Method"), columns=columns)


def to_markdown(df: pd.DataFrame) -> str:
    header = [str(df.index.name or "")] + [str(c) for c in df.columns]
    lines = [
        "| " + " | ".join(header) + " |",
        "|" + "|".join(["---"] + ["---:"] * len(df.columns)) + "|",
    ]
    for label, row in df.iterrows():
        lines.append("| " + " | ".join([str(label)] + [_text(v) for v in row]) + " |")
    return "\n".join(lines) + "\n"


def _text(value: object) -> str:
    if value is None or (isinstance(value, float) and value != value):
        return "–"
    if isinstance(value, float):
        return f"{value:.3f}"
    return str(value)


_LATEX_ESCAPES = {
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "±": r"$\pm$",
    BINOMIAL_MARK: r"$^\dagger$",
    "–": "--",
    "~": r"\textasciitilde{}",
}


def _latex(text: str) -> str:
    return "".join(_LATEX_ESCAPES.get(ch, ch) for ch in text)


def to_latex(df: pd.DataFrame) -> str:
    header = [str(df.index.name or "")] + [str(c) for c in df.columns]
    lines = [
        r"\begin{tabular}{l" + "r" * len(df.columns) + "}",
        r"\toprule",
        " & ".join(_latex(h) for h in header) + r" \\",
        r"\midrule",
    ]
    for label, row in df.iterrows():
        lines.append(" & ".join([_latex(str(label))] + [_latex(_text(v)) for v in row]) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


def write_table(df: pd.DataFrame, directory: Path, stem: str) -> list[Path]:
    """Write ``stem.md``, ``stem.csv`` and ``stem.tex``; return the paths."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = [directory / f"{stem}.{ext}" for ext in ("md", "csv", "tex")]
    paths[0].write_text(to_markdown(df))
    df.to_csv(paths[1])
    paths[2].write_text(to_latex(df))
    return paths

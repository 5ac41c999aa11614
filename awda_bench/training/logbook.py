"""What a training run writes beside its snapshots: ``metrics.csv``, TensorBoard scalars and
``learning_curve.png``.

``metrics.csv`` is long-format, one row per (step, split, name)::

    step,split,name,value
    1,train,loss,0.8421
    1,train,sdtw_set1,0.51
    1,time,data_s,0.12
    50,val,loss,0.77

Resuming from the snapshot at step ``s`` first drops every row past ``s`` (they belong to steps
the killed run took after its last snapshot, which are taken again; a run killed before its
first snapshot starts over from an empty file), so the file shows one continuous curve.
TensorBoard event files are written under ``tensorboard/`` with
``purge_step = s + 1`` for the same reason.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

METRICS_CSV = "metrics.csv"
CURVE_PNG = "learning_curve.png"
TENSORBOARD_DIR = "tensorboard"
_FIELDS = ("step", "split", "name", "value")


class Logbook:
    """Appends metrics to ``metrics.csv`` (and TensorBoard, when installed) in ``directory``."""

    def __init__(self, directory: Path, start_step: int, *, tensorboard: bool = True) -> None:
        self.directory = directory
        self.path = directory / METRICS_CSV
        self._truncate(start_step)
        new = not self.path.is_file()
        self._file = self.path.open("a", newline="")
        self._csv = csv.writer(self._file)
        if new:
            self._csv.writerow(_FIELDS)
        self._tb: Any = None
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter
            except ImportError:  # tensorboard is a dependency; without it only the CSV is written
                self._tb = None
            else:
                self._tb = SummaryWriter(
                    str(directory / TENSORBOARD_DIR), purge_step=start_step + 1
                )

    def _truncate(self, start_step: int) -> None:
        if not self.path.is_file():
            return
        with self.path.open(newline="") as f:  # a fresh start (step 0) keeps nothing
            rows = [r for r in csv.DictReader(f) if start_step > 0 and int(r["step"]) <= start_step]
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        with tmp.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=_FIELDS)
            writer.writeheader()
            writer.writerows(rows)
        tmp.replace(self.path)

    def log(self, step: int, split: str, values: dict[str, float]) -> None:
        for name, value in values.items():
            self._csv.writerow((step, split, name, f"{value:.6g}"))
            if self._tb is not None:
                self._tb.add_scalar(f"{split}/{name}", value, step)

    def flush(self) -> None:
        self._file.flush()
        if self._tb is not None:
            self._tb.flush()

    def close(self) -> None:
        self._file.close()
        if self._tb is not None:
            self._tb.close()


def read_metrics(path: Path) -> dict[tuple[str, str], tuple[list[int], list[float]]]:
    """``{(split, name): (steps, values)}`` from a ``metrics.csv``."""
    series: dict[tuple[str, str], tuple[list[int], list[float]]] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            steps, values = series.setdefault((row["split"], row["name"]), ([], []))
            steps.append(int(row["step"]))
            values.append(float(row["value"]))
    return series


def plot_learning_curve(directory: Path, title: str) -> Path:
    """``learning_curve.png``: training loss (per step and a moving average) and validation loss."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    series = read_metrics(directory / METRICS_CSV)
    fig, ax = plt.subplots(figsize=(7, 4))
    if ("train", "loss") in series:
        steps, values = series[("train", "loss")]
        ax.plot(steps, values, color="tab:blue", alpha=0.25, lw=0.8, label="train (per step)")
        window = max(1, min(50, len(values) // 10))
        if window > 1:
            smooth = np.convolve(values, np.ones(window) / window, mode="valid")
            ax.plot(
                steps[window - 1 :],
                smooth,
                color="tab:blue",
                lw=1.5,
                label=f"train ({window}-step mean)",
            )
    if ("val", "loss") in series:
        steps, values = series[("val", "loss")]
        ax.plot(steps, values, "o-", color="tab:red", ms=3, lw=1.5, label="validation (held-out)")
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = directory / CURVE_PNG
    tmp = out.with_name(f".{out.stem}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(out)
    return out

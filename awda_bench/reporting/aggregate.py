"""From episode rows to cells: success per snapshot, then mean ± SE over snapshots.

A snapshot's success rate is ``successes / ok episodes`` (errors are in neither count). A cell
(suite or family x method) is the mean over the method's snapshots of their rates, with

- ``se_kind == "snapshots"`` (two or more snapshots): SE = sample std (ddof 1) / sqrt(#snapshots);
- ``se_kind == "binomial"`` (one snapshot): SE = sqrt(p (1 - p) / n) over its n ok episodes.

Every function here reads only the store's tables, so the numbers can be recomputed from the rows.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from awda_bench.episode import GRIP_OUTCOMES, NEVER_GRIPPED
from awda_bench.evaluation.carry import CARRY_OUTCOMES

METRICS = ("success_once", "success_at_end")
"""Success columns a report can use."""

DEFAULT_METRIC = "success_once"
"""``info["success"]`` at any step (the reference evaluations stop at the first success)."""

S4_FAMILIES = (
    ("door", "Door"),
    ("drawer", "Drawer"),
    ("press_button", "Press Button"),
    ("stack_block", "Stack Block"),
    ("basketball", "Basketball"),
    ("nut_assembly", "Nut Assembly"),
)
"""Table S4's family ids (as in suite files) and column titles, in the paper's order."""

ALL = "all"
"""Group name of a whole suite (Table S3) or of all S4 families together."""


def family_key(name: str) -> str:
    """Normalize a family name (``"Press Button"``, ``"press-button"`` -> ``"press_button"``)."""
    return name.strip().lower().replace("-", "_").replace(" ", "_")


@dataclass(frozen=True)
class Cell:
    """One table cell, as written to ``summary.json``."""

    suite: str
    """Suite name."""
    group: str
    """``"all"`` (the whole suite) or a task family."""
    method: str
    """Method name."""
    metric: str
    """Success column used."""
    snapshots: int
    """Snapshots with at least one ok episode (the samples of the mean)."""
    snapshots_planned: int
    """Snapshots planned for the method in the store."""
    episodes: int
    """Ok episodes (successes + failures)."""
    successes: int
    """Ok episodes that succeeded."""
    errors: int
    """Episodes recorded as errors (in no rate)."""
    mean: float | None
    """Mean over snapshots of the success rate (``None``: no ok episode)."""
    se: float | None
    """Standard error (see ``se_kind``)."""
    se_kind: str
    """``"snapshots"``, ``"binomial"`` or ``"none"``."""

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def per_snapshot(episodes: pd.DataFrame, snapshots: pd.DataFrame, metric: str) -> pd.DataFrame:
    """One row per (suite, protocol, method, snapshot): ok, successes, errors, expected, rate."""
    keys = ["protocol", "method", "snapshot"]
    ok = episodes[episodes["status"] == "ok"]
    counts = pd.DataFrame(
        {
            "ok": ok.groupby(keys).size(),
            "successes": ok.groupby(keys)[metric].sum(),
            "errors": episodes[episodes["status"] == "error"].groupby(keys).size(),
        }
    )
    plan = snapshots.set_index(keys)[["name", "ord", "learned", "episodes_expected"]]
    table = (
        plan.join(counts, how="left").fillna({"ok": 0, "successes": 0, "errors": 0}).reset_index()
    )
    for column in ("ok", "successes", "errors"):
        table[column] = table[column].astype(int)
    table["recorded"] = table["ok"] + table["errors"]
    table["rate"] = [
        s / n if n else math.nan for s, n in zip(table["successes"], table["ok"], strict=True)
    ]
    return table


def mean_se(
    rates: list[float], successes: int, episodes: int
) -> tuple[float | None, float | None, str]:
    """Mean over snapshot rates and its SE (see the module docstring)."""
    if not rates:
        return None, None, "none"
    mean = sum(rates) / len(rates)
    if len(rates) == 1:
        p = successes / episodes
        return mean, math.sqrt(p * (1 - p) / episodes), "binomial"
    var = sum((r - mean) ** 2 for r in rates) / (len(rates) - 1)
    return mean, math.sqrt(var / len(rates)), "snapshots"


def make_cell(
    rows: pd.DataFrame, plan: pd.DataFrame, *, suite: str, group: str, method: str, metric: str
) -> Cell:
    """A cell from the episode rows of one (suite, group, method) and the method's snapshot plan."""
    ok = rows[rows["status"] == "ok"]
    rates, total_s, total_n = [], 0, 0
    for snapshot in plan["snapshot"]:
        snap_rows = ok[ok["snapshot"] == snapshot]
        if len(snap_rows):
            s = int(snap_rows[metric].sum())
            rates.append(s / len(snap_rows))
            total_s += s
            total_n += len(snap_rows)
    mean, se, kind = mean_se(rates, total_s, total_n)
    return Cell(
        suite=suite,
        group=group,
        method=method,
        metric=metric,
        snapshots=len(rates),
        snapshots_planned=len(plan),
        episodes=total_n,
        successes=total_s,
        errors=int((rows["status"] == "error").sum()),
        mean=mean,
        se=se,
        se_kind=kind,
    )


def all_cells(
    episodes: pd.DataFrame, snapshots: pd.DataFrame, protocols: pd.DataFrame, metric: str
) -> list[Cell]:
    """Every cell: per (suite, method) the whole suite, and each family of the suite."""
    if metric not in METRICS:
        raise ValueError(f"metric must be one of {METRICS}")
    cells = []
    for _, proto in protocols.iterrows():
        rows_p = episodes[episodes["protocol"] == proto["fingerprint"]]
        plans_p = snapshots[snapshots["protocol"] == proto["fingerprint"]]
        for method in sorted(plans_p["method"].unique()):
            rows = rows_p[rows_p["method"] == method]
            plan = plans_p[plans_p["method"] == method].sort_values("ord")
            common = dict(suite=proto["suite"], method=method, metric=metric)
            cells.append(make_cell(rows, plan, group=ALL, **common))
            families = sorted({family_key(f) for f in rows["family"]})
            s4_keys = {k for k, _ in S4_FAMILIES}
            # one S4 family alone (a held-out family: reproduce --hold-out drawer) is its cell too
            if len(families) > 1 or s4_keys.intersection(families):
                keyed = rows["family"].map(family_key)
                for family in families:
                    cells.append(make_cell(rows[keyed == family], plan, group=family, **common))
            s4 = [k for k, _ in S4_FAMILIES if k in families]
            if s4 and set(s4) != set(families):
                cells.append(
                    make_cell(
                        rows[rows["family"].map(family_key).isin(s4)],
                        plan,
                        group="s4_all",
                        **common,
                    )
                )
    return cells


GRASP_ATTRIBUTE = 3
"""Column of the grasp attribute in a stored waypoint ``[x, y, z, grasp, ...]``."""


def _grasp_xy(waypoints: object) -> tuple[float, float] | None:
    """The first grasp-attributed waypoint's (x, y) [m] of one stored episode, or None."""
    if not isinstance(waypoints, str) or not waypoints:
        return None
    for point in json.loads(waypoints):
        if len(point) > GRASP_ATTRIBUTE and point[GRASP_ATTRIBUTE] > 0.5:
            return float(point[0]), float(point[1])
    return None


def grasp_waypoint_spread_cm(episodes: pd.DataFrame) -> float | None:
    """How far a method's predicted grasp point moves with the scene [cm]: per (snapshot, task),
    the xy standard deviation (norm of the per-axis population std) of the first grasp-attributed
    waypoint over that group's episodes, averaged over groups with two or more such episodes.

    Episodes of one task differ in their seeded scene (object poses), so a method that reads its
    images moves its grasp point with them (gt-waypoints: as much as the objects move), while a
    network that outputs its training set's mean trajectory stays put (near 0). None without
    waypoints (closed-loop and scripted methods store none).
    """
    points = episodes.assign(grasp_xy=episodes["waypoints"].map(_grasp_xy)).dropna(
        subset=["grasp_xy"]
    )
    spreads = []
    for _, group in points.groupby(["snapshot", "task"], sort=True):
        if len(group) >= 2:
            xy = np.array(group["grasp_xy"].tolist())
            spreads.append(float(np.linalg.norm(xy.std(axis=0))) * 100.0)
    return float(np.mean(spreads)) if spreads else None


FIRST_GRIP_COLUMNS: dict[str, str] = {
    outcome: f"first_grip_{outcome}" for outcome in (*GRIP_OUTCOMES, NEVER_GRIPPED)
}
"""grasp.csv's column of each first-grip outcome's rate: ``first_grip_target``, ``_other``,
``_nothing``, ``_never``."""


def _grasp_rates(g: pd.DataFrame) -> dict[str, float | None]:
    """Reached / grasped and the first-grip outcomes' rates over the episodes of ``g`` that report
    both flags (``None`` where none does; first grip over those that recorded one)."""
    graspable = g[g["reached"].notna() & g["grasped"].notna()]
    row: dict[str, float | None] = {}
    for column in ("reached", "grasped"):
        row[column] = float(graspable[column].mean()) if len(graspable) else None
    told = graspable["first_grip"].dropna() if "first_grip" in g else pd.Series(dtype=object)
    for outcome, column in FIRST_GRIP_COLUMNS.items():
        row[column] = float((told == outcome).mean()) if len(told) else None
    return row


def grasp_analysis(episodes: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Per (suite, method): reached / grasped / success rates over the ok episodes of tasks with a
    grasp target (those whose env reports both flags; in MOSAIC: stack block, basketball, nut
    assembly). Where no episode reports them the rates are ``None`` and success is over all ok
    episodes. ``first_grip_*`` (:data:`FIRST_GRIP_COLUMNS`): the rate of each ``first_grip``
    outcome over those of the episodes that recorded one (``None`` where none did: a task that
    does not tell, or a store written before the analysis). ``grasp_wp_spread_cm``:
    :func:`grasp_waypoint_spread_cm` over all ok episodes.
    """
    ok = episodes[episodes["status"] == "ok"]
    out = []
    for (suite, method), g in ok.groupby(["suite", "method"], sort=True):
        graspable = g[g["reached"].notna() & g["grasped"].notna()]
        rows = graspable if len(graspable) else g
        rates = _grasp_rates(g)
        row = {"suite": suite, "method": method, "episodes": len(rows)}
        row |= {"reached": rates["reached"], "grasped": rates["grasped"]}
        row["success"] = float(rows[metric].mean())
        row |= {column: rates[column] for column in FIRST_GRIP_COLUMNS.values()}
        row["grasp_wp_spread_cm"] = grasp_waypoint_spread_cm(g)
        out.append(row)
    return pd.DataFrame(
        out,
        columns=[
            "suite", "method", "episodes", "reached", "grasped", "success", *FIRST_GRIP_COLUMNS.values(),
            "grasp_wp_spread_cm",
        ],
    )  # fmt: skip


def place_waypoint_error_m(waypoints: object, place_goal: object) -> float | None:
    """How far from over its goal a method meant to put the target [m]: the horizontal distance
    from the stored ``place_goal`` to the last grasp-attributed waypoint (where the hand still
    holds the target; the release follows it). None without both."""
    if not isinstance(waypoints, str) or not waypoints or not isinstance(place_goal, str):
        return None
    held = [
        p for p in json.loads(waypoints) if len(p) > GRASP_ATTRIBUTE and p[GRASP_ATTRIBUTE] > 0.5
    ]
    if not held:
        return None
    goal = json.loads(place_goal)
    return float(np.hypot(held[-1][0] - goal[0], held[-1][1] - goal[1]))


def carry_analysis(episodes: pd.DataFrame) -> pd.DataFrame:
    """Per (suite, method, family): what became of the grasped targets
    (:mod:`awda_bench.evaluation.carry`), over the ok episodes that recorded a ``carry``: how many
    grasped, the share of each outcome (:data:`CARRY_OUTCOMES`), over those released the median
    distance from over the goal and height above it at the release [cm], and over those with
    waypoints the median :func:`place_waypoint_error_m` [cm] (where the method *meant* to put it:
    a large one says the place was misread, a small one with off-target releases that the hand
    did not get there). Empty where no episode recorded a carry (a task without a place goal, or
    a store written before the analysis). ``placed`` counts success_once episodes."""
    columns = [
        "suite", "method", "family", "grasped", *CARRY_OUTCOMES, "release_xy_cm",
        "release_dz_cm", "place_wp_xy_cm",
    ]  # fmt: skip
    if "carry" not in episodes:
        return pd.DataFrame(columns=columns)
    told = episodes[(episodes["status"] == "ok") & episodes["carry"].notna()]
    out = []
    for (suite, method, family), g in told.groupby(["suite", "method", "family"], sort=True):
        released = g[g["release_xy_m"].notna()]
        row: dict[str, object] = {"suite": suite, "method": method, "family": family}
        row["grasped"] = len(g)
        row |= {outcome: float((g["carry"] == outcome).mean()) for outcome in CARRY_OUTCOMES}
        for key, source in (("release_xy_cm", "release_xy_m"), ("release_dz_cm", "release_dz_m")):
            row[key] = float(released[source].median()) * 100.0 if len(released) else None
        meant = [
            place_waypoint_error_m(w, p)
            for w, p in zip(g["waypoints"], g.get("place_goal", [None] * len(g)), strict=True)
        ]
        meant_m = [m for m in meant if m is not None]
        row["place_wp_xy_cm"] = float(np.median(meant_m)) * 100.0 if meant_m else None
        out.append(row)
    return pd.DataFrame(out, columns=columns)


def per_task(episodes: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Per (suite, method, task): ok episodes, successes and rate, pooled over snapshots, and the
    task's reached / grasped / first-grip rates (:func:`grasp_analysis`'s, empty where its episodes
    report none). A MOSAIC family mixes variations that a policy can pass by accident (a random
    hand shuts a drawer) with ones it cannot: the family's cell alone does not say which it
    passed; on a grasping task the grip columns say where the episodes stopped."""
    ok = episodes[episodes["status"] == "ok"]
    out = [
        {
            "suite": suite, "method": method, "task": int(task), "family": g["family"].iloc[0],
            "episodes": len(g), "successes": int(g[metric].sum()), "rate": float(g[metric].mean()),
            **_grasp_rates(g),
        }
        for (suite, method, task), g in ok.groupby(["suite", "method", "task"], sort=True)
    ]  # fmt: skip
    return pd.DataFrame(
        out,
        columns=[
            "suite", "method", "task", "family", "episodes", "successes", "rate", "reached",
            "grasped", *FIRST_GRIP_COLUMNS.values(),
        ],
    )  # fmt: skip

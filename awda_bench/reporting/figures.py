"""Pictures: success-vs-snapshot curves (matplotlib), Fig. S5-style waypoint overlays, Fig. S6-style
paths and MP4s (OpenCV). Frames are plain ``(H, W, 3)`` uint8 RGB arrays; colours below are RGB.

Fig. S5 convention: free-space waypoints red, brightening with their order; waypoints carrying the
grasp attribute (the end of a grasp-attributed segment) green; consecutive waypoints joined. Our
second attribute, pressing (not in the paper's figure), is drawn blue.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

GRASP_RGB = (40, 220, 40)
"""Colour of grasp-attributed waypoints."""
PRESS_RGB = (40, 120, 255)
"""Colour of press-attributed waypoints (the second attribute; grasp wins if both are set)."""
RED_DIM_RGB = (110, 0, 0)
"""Colour of the first free-space waypoint; later ones brighten towards pure red."""
RED_BRIGHT_RGB = (255, 40, 40)
"""Colour of the last free-space waypoint."""


def project_points(
    points_world: np.ndarray, intrinsic_cv: np.ndarray, extrinsic_cv: np.ndarray
) -> np.ndarray:
    """Pixel coordinates ``(N, 2)`` (u right, v down) of world points ``(N, 3)`` [m].

    ``extrinsic_cv`` is the 3x4 (or 4x4) world->camera transform in OpenCV convention (z forward),
    ``intrinsic_cv`` the 3x3 camera matrix. Points behind the camera get NaN.
    """
    pts = np.asarray(points_world, dtype=float).reshape(-1, 3)
    ext = np.asarray(extrinsic_cv, dtype=float)[:3, :4]
    cam = pts @ ext[:, :3].T + ext[:, 3]
    uvw = cam @ np.asarray(intrinsic_cv, dtype=float).T
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = uvw[:, :2] / uvw[:, 2:3]
    uv[cam[:, 2] <= 0] = np.nan
    return uv


def waypoint_colours(
    grasp: Sequence[bool], press: Sequence[bool] | None = None
) -> list[tuple[int, int, int]]:
    """Per-waypoint colour: green if grasp-attributed, blue if press-attributed, else red
    brightening with order among the free-space waypoints."""
    pressed = [False] * len(grasp) if press is None else [bool(p) for p in press]
    if len(pressed) != len(grasp):
        raise ValueError(f"{len(grasp)} grasp flags but {len(pressed)} press flags")
    free = [i for i, g in enumerate(grasp) if not g and not pressed[i]]
    colours = []
    for i, g in enumerate(grasp):
        if g:
            colours.append(GRASP_RGB)
            continue
        if pressed[i]:
            colours.append(PRESS_RGB)
            continue
        t = free.index(i) / max(1, len(free) - 1)
        r, g_, b = (
            round(lo + t * (hi - lo)) for lo, hi in zip(RED_DIM_RGB, RED_BRIGHT_RGB, strict=True)
        )
        colours.append((r, g_, b))
    return colours


def draw_waypoints(
    frame: np.ndarray,
    pixels: np.ndarray,
    grasp: Sequence[bool],
    radius_px: int = 5,
    press: Sequence[bool] | None = None,
) -> np.ndarray:
    """A copy of ``frame`` with the waypoints (``(K, 2)`` pixels) drawn in order."""
    out = np.ascontiguousarray(frame, dtype=np.uint8).copy()
    colours = waypoint_colours(grasp, press)
    pts = [
        None if np.isnan(p).any() else (int(round(p[0])), int(round(p[1])))
        for p in np.asarray(pixels, float)
    ]
    for k in range(1, len(pts)):
        start, end = pts[k - 1], pts[k]
        if start is not None and end is not None:
            cv2.line(out, start, end, colours[k], 2, cv2.LINE_AA)
    for p, colour in zip(pts, colours, strict=True):
        if p is not None:
            cv2.circle(out, p, radius_px, colour, -1, cv2.LINE_AA)
            cv2.circle(out, p, radius_px, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def path_colours(count: int, colormap: str = "plasma") -> list[tuple[int, int, int]]:
    """``count`` RGB colours ordered along ``colormap`` (first dark, last bright): the order of a
    path's points in Fig. S6."""
    cmap = matplotlib.colormaps[colormap]
    return [
        tuple(int(round(255 * c)) for c in cmap(t)[:3])  # type: ignore[misc]
        for t in np.linspace(0.0, 0.95, max(1, count))
    ]


def draw_path(frame: np.ndarray, pixels: np.ndarray, thickness_px: int = 2) -> np.ndarray:
    """A copy of ``frame`` with a path (``(N, 2)`` pixels, NaN = not drawn) as segments coloured by
    their order (:func:`path_colours`), a white-rimmed dot at its start and a square at its end."""
    out = np.ascontiguousarray(frame, dtype=np.uint8).copy()
    pts = np.asarray(pixels, float)
    colours = path_colours(len(pts))
    for k in range(1, len(pts)):
        if np.isnan(pts[k - 1]).any() or np.isnan(pts[k]).any():
            continue
        start = (int(round(pts[k - 1][0])), int(round(pts[k - 1][1])))
        end = (int(round(pts[k][0])), int(round(pts[k][1])))
        cv2.line(out, start, end, colours[k], thickness_px, cv2.LINE_AA)
    ok = [i for i in range(len(pts)) if not np.isnan(pts[i]).any()]
    if ok:
        first = (int(round(pts[ok[0]][0])), int(round(pts[ok[0]][1])))
        last = (int(round(pts[ok[-1]][0])), int(round(pts[ok[-1]][1])))
        cv2.circle(out, first, 4, colours[ok[0]], -1, cv2.LINE_AA)
        cv2.circle(out, first, 4, (255, 255, 255), 1, cv2.LINE_AA)
        cv2.rectangle(out, (last[0] - 3, last[1] - 3), (last[0] + 3, last[1] + 3), colours[-1], -1)
        cv2.rectangle(out, (last[0] - 3, last[1] - 3), (last[0] + 3, last[1] + 3), (255,) * 3, 1)
    return out


def _fit_height(frame: np.ndarray, height: int) -> np.ndarray:
    h, w = frame.shape[:2]
    return cv2.resize(frame, (max(1, round(w * height / h)), height), interpolation=cv2.INTER_AREA)


def fig_s5(
    demo_frames: Sequence[np.ndarray],
    agent_frame: np.ndarray,
    pixels: np.ndarray,
    grasp: Sequence[bool],
    press: Sequence[bool] | None = None,
) -> np.ndarray:
    """Demo frames in a row (scaled to half the agent frame's height, wrapped), then the agent's
    first frame with the waypoints drawn; returns one RGB image."""
    agent = draw_waypoints(agent_frame, pixels, grasp, press=press)
    h, w = agent.shape[:2]
    thumbs = [_fit_height(np.asarray(f, np.uint8), h // 2) for f in demo_frames]
    per_row = max(1, len(thumbs) // 2 + len(thumbs) % 2)
    rows = []
    for start in range(0, len(thumbs), per_row):
        row = np.concatenate(thumbs[start : start + per_row], axis=1)
        rows.append(row)
    demo_w = max((r.shape[1] for r in rows), default=0)
    demo = np.zeros((h, demo_w, 3), np.uint8)
    for i, r in enumerate(rows[:2]):
        demo[i * (h // 2) : i * (h // 2) + r.shape[0], : r.shape[1]] = r
    gap = np.full((h, 8, 3), 255, np.uint8)
    image = np.concatenate([demo, gap, agent], axis=1)
    cv2.putText(
        image, "demo", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 0), 1, cv2.LINE_AA
    )
    cv2.putText(
        image,
        "agent + waypoints",
        (demo_w + 12, 14),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.45,
        (255, 255, 0),
        1,
        cv2.LINE_AA,
    )
    return image


def scene_figure(first: np.ndarray, during: np.ndarray) -> np.ndarray:
    """Two third-person frames side by side, labelled "first frame" and "during the expert's
    episode" (the task scenes in ``reports/figures/``, written by ``demo --figure``)."""
    image = np.concatenate([np.asarray(first, np.uint8), np.asarray(during, np.uint8)], axis=1)
    scale = first.shape[0] / 240
    for x, text in ((6, "first frame"), (first.shape[1] + 6, "during the expert's episode")):
        cv2.putText(
            image,
            text,
            (round(x * scale), round(22 * scale)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.6 * scale,
            (255, 255, 255),
            max(1, round(2 * scale)),
            cv2.LINE_AA,
        )
    return image


def write_png(image_rgb: np.ndarray, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f"OpenCV could not write {path}")
    return path


def write_mp4(frames: Sequence[np.ndarray], path: Path, fps: float) -> Path:
    """Write RGB frames as an MP4 (``mp4v``)."""
    if not frames:
        raise ValueError("no frames to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), fps, (w, h))
    if not writer.isOpened():
        raise OSError(f"OpenCV could not open a video writer for {path}")
    try:
        for frame in frames:
            writer.write(cv2.cvtColor(np.asarray(frame, np.uint8), cv2.COLOR_RGB2BGR))
    finally:
        writer.release()
    return path


def plot_success_vs_snapshot(table: pd.DataFrame, title: str, path: Path) -> Path:
    """Success rate per snapshot (x: training order, labelled by file) with binomial SE bars."""
    fig, ax = plt.subplots(figsize=(6, 3.5))
    n = table["ok"].clip(lower=1)
    se = np.sqrt(table["rate"] * (1 - table["rate"]) / n)
    ax.errorbar(table["ord"], table["rate"], yerr=se, marker="o", capsize=3)
    ax.set_xticks(table["ord"], table["name"], rotation=30, ha="right", fontsize=7)
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel("snapshot")
    ax.set_ylabel("success rate")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path

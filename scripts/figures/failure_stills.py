"""Fig. S4-style failure stills: evenly spaced frames of episode videos, one labelled row each.

    python scripts/figures/failure_stills.py --out PNG --row "LABEL=VIDEO.mp4" [--row ...] [--frames 5]

The videos are what ``run --videos K`` writes (``RUN_DIR/videos/SUITE/LABEL/SNAPSHOT/*.mp4``);
nothing is re-simulated here.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np


def strip(video: Path, frames: int) -> np.ndarray:
    """``frames`` evenly spaced frames of ``video`` (first and last included), side by side (BGR)."""
    capture = cv2.VideoCapture(str(video))
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    if count < 1:
        raise SystemExit(f"error: {video} has no frames; give an MP4 written by run --videos")
    picked = []
    for index in np.linspace(0, count - 1, frames).round().astype(int):
        capture.set(cv2.CAP_PROP_POS_FRAMES, int(index))
        ok, frame = capture.read()
        if not ok:
            raise SystemExit(f"error: could not read frame {index} of {video}")
        cv2.putText(frame, f"t={index}", (4, frame.shape[0] - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (255, 255, 255), 1, cv2.LINE_AA)  # fmt: skip
        picked.append(frame)
    capture.release()
    return np.concatenate(picked, axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--row", action="append", required=True, metavar="LABEL=VIDEO")
    parser.add_argument("--frames", type=int, default=5)
    args = parser.parse_args()
    rows = []
    for item in args.row:
        label, _, video = item.partition("=")
        row = strip(Path(video), args.frames)
        cv2.putText(row, label, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 255), 1,
                    cv2.LINE_AA)  # fmt: skip
        rows.append(row)
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 4), (0, width - r.shape[1]), (0, 0))) for r in rows]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.out), np.concatenate(rows, axis=0)):
        raise SystemExit(f"error: could not write {args.out}")
    print(f"failure stills: {args.out}")


if __name__ == "__main__":
    main()

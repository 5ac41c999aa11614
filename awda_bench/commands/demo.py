"""``python -m awda_bench demo``: record one scripted demonstration (MP4 + trajectory ``.npz``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from awda_bench.errors import UsageError
from awda_bench.experts import EMBODIMENT_NAMES

HELP = "record a scripted demonstration (video + per-step states)"
DESCRIPTION = (
    "Run the scripted expert of a suite task and save third-person frames as MP4 "
    "and, next to it, the per-step trajectory (TCP, gripper opening, actions, grasp truth) "
    "as .npz."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--suite", default="pick_place", help="suite name (tasks/<name>.toml)")
    parser.add_argument("--task", type=int, required=True, help="task index within the suite")
    parser.add_argument("--seed", type=int, default=0, help="scene seed")
    parser.add_argument("--embodiment", choices=EMBODIMENT_NAMES, default="demonstrator")
    parser.add_argument("--out", type=Path, required=True, help="output video path (.mp4)")
    parser.add_argument(
        "--figure",
        type=Path,
        default=None,
        help="also write a PNG: the first frame beside the middle one (reports/figures/FAMILY.png)",
    )
    parser.add_argument(
        "--render-every",
        type=int,
        default=2,
        help="render every k-th control step (video fps = control rate / k)",
    )


def run(args: argparse.Namespace) -> int:
    from awda_bench.demo_recording import record_demo, save_video
    from awda_bench.suites import load_suite

    suite = load_suite(args.suite)
    if suite.simulator != "maniskill":
        raise UsageError(
            f"demo is not offered on suite {suite.name!r} yet (it plays in workers of its own "
            f"environment); `run --suite {suite.name}` plays its episodes"
        )
    frames, trajectory = record_demo(
        suite, args.task, args.seed, args.embodiment, render_every=args.render_every, frames=True
    )
    assert frames is not None
    video = save_video(frames, args.out, fps=suite.control_freq_hz / args.render_every)
    npz = video.with_suffix(".npz")
    trajectory.save(npz)
    if args.figure is not None:
        from awda_bench.reporting.figures import scene_figure, write_png

        write_png(scene_figure(frames[0], frames[len(frames) // 2]), args.figure)
        print(f"{args.figure}: first frame | frame {len(frames) // 2} of {len(frames)}")
    meta = trajectory.meta
    print(
        f"{video}: {len(frames)} frames; {npz}: {len(trajectory)} steps; "
        f"success={meta['success']} success_once={meta['success_once']} "
        f"reached={meta['reached']} grasped={meta['grasped']}"
    )
    return 0

"""``python -m awda_bench collect``: record training data (scripted demos, synthesized motion)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from awda_bench.data.config import (
    EMBODIMENT_CHOICES,
    SPLITS,
    CollectConfig,
    parse_image_size,
)
from awda_bench.execution.backends import add_backend_args
from awda_bench.suites import SUITES_DIR

QUICK_EPISODES = 2
"""``--quick``: episodes per task."""
QUICK_TASKS = 2
"""``--quick``: the first this-many tasks of the split."""


HELP = "record training data into DATA_DIR (ManiSkill trajectory files; resumable)"
DESCRIPTION = (
    "Run the scripted expert of every task of a split (and/or trajectory "
    "synthesis) and keep the successful episodes: per step the third-person frame (JPEG), "
    "wrist depth (agent), TCP pose, gripper opening, action, mined attributes, simulator "
    "truth and env state. Re-running the same command resumes; exit 1 if attempts ended in "
    "errors (re-run to retry them)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--suite", required=True, help="suite name (pick_place, mosaic, metaworld)")
    parser.add_argument("--split", default="train", help=f"one of {', '.join(SPLITS)}")
    parser.add_argument(
        "--embodiment", default="both", help=f"one of {', '.join(EMBODIMENT_CHOICES)}"
    )
    parser.add_argument(
        "--episodes-per-task",
        type=int,
        default=20,
        help="successful episodes kept per task and embodiment (default 20; reference 100)",
    )
    parser.add_argument("--out", type=Path, required=True, help="DATA_DIR")
    parser.add_argument(
        "--extend-from",
        type=Path,
        default=None,
        metavar="DIR",
        help="a finished collection made with the same options and fewer episodes: its episodes "
        "are this one's first (the same seeds), only the rest is recorded",
    )
    add_backend_args(parser)
    parser.add_argument(
        "--image-size",
        default=None,
        help="third-person frame HxW (default: the suite's camera size, 240x320 on pick_place and "
        "mosaic, 224x224 on metaworld; at least 64x64)",
    )
    parser.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    parser.add_argument(
        "--synthesize", type=int, default=0, metavar="N", help="N synthesized trajectories"
    )
    parser.add_argument(
        "--task", type=int, action="append", default=[], help="only these tasks (repeatable)"
    )
    parser.add_argument("--jpeg-quality", type=int, default=90, help="JPEG quality (default 90)")
    parser.add_argument(
        "--episode-timeout", type=float, default=600.0, help="watchdog per episode [s]"
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"{QUICK_EPISODES} episodes of the first {QUICK_TASKS} tasks (and at most "
        f"{QUICK_EPISODES} synthesized)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--tasks-dir", type=Path, default=SUITES_DIR, help=argparse.SUPPRESS)
    parser.add_argument("--chunk-episodes", type=int, default=10, help=argparse.SUPPRESS)


def config_from_args(args: argparse.Namespace) -> CollectConfig:
    episodes, tasks, synthesize = args.episodes_per_task, tuple(args.task), args.synthesize
    if args.quick:
        from awda_bench.data.plan import split_tasks
        from awda_bench.suites import load_suite

        episodes = QUICK_EPISODES
        synthesize = min(synthesize, QUICK_EPISODES)
        if not tasks:
            suite = load_suite(args.suite, args.tasks_dir)
            if args.split in SPLITS:
                tasks = tuple(t.index for t in split_tasks(suite, args.split)[:QUICK_TASKS])
    return CollectConfig(
        suite=args.suite,
        split=args.split,
        embodiment=args.embodiment,
        episodes_per_task=episodes,
        out=args.out,
        workers=args.workers,
        backend=args.backend,
        ray_address=args.ray_address,
        image_size=None if args.image_size is None else parse_image_size(args.image_size),
        seed=args.seed,
        synthesize=synthesize,
        tasks=tasks,
        jpeg_quality=args.jpeg_quality,
        episode_timeout_s=args.episode_timeout,
        chunk_episodes=args.chunk_episodes,
        suites_dir=args.tasks_dir,
        progress=not args.no_progress,
        extend_from=args.extend_from,
    )


def run(args: argparse.Namespace) -> int:
    from awda_bench.data.collect import run_collect

    config = config_from_args(args)
    result = run_collect(config)
    minutes = result.wall_s / 60
    rate = (result.kept + result.discarded) / minutes if minutes > 0 else 0.0
    fps = result.frames / result.wall_s if result.wall_s > 0 else 0.0
    per_episode = result.bytes_kept / result.kept if result.kept else 0
    extended = f" ({result.extended} from {config.extend_from})" if result.extended else ""
    print(
        f"{config.out}: {result.planned} episodes planned, {result.already} already kept"
        f"{extended}, {result.kept} kept and {result.discarded} discarded now ({result.errors} errors) in "
        f"{result.wall_s:.1f} s: {rate:.1f} episodes/min, {result.steps} steps, "
        f"{result.frames} frames ({fps:.1f} frames/s; rendering+JPEG {result.render_s:.1f} s "
        f"of {result.episode_s:.1f} s episode time), {per_episode / 1e6:.2f} MB/episode; "
        f"{'complete' if result.complete else 'INCOMPLETE'}"
    )
    for warning in result.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    if result.errors:
        print(
            f"warning: {result.errors} attempts ended in errors; re-run the same command to "
            "retry them",
            file=sys.stderr,
        )
        return 1
    return 0

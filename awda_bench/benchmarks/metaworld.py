"""Meta-World measurements. They run with the second environment's interpreter (the
``metaworld`` package lives only there); from the project's environment ``bench metaworld``
re-runs this module there::

    python -m awda_bench bench metaworld frames [--frames 20]
    python -m awda_bench bench metaworld experts [--seeds 10] [TASK ...]
    .venv-metaworld/bin/python -m awda_bench.benchmarks.metaworld frames     # the same

``frames``: ms per 224x224 third-person frame and per 128x128 wrist depth frame with the models'
own render settings and with :data:`awda_bench.metaworld.renderer.FAST`, in one run, on one
task. ``experts``: the package's scripted policies over seeded layouts of every task: successes
and steps to the first success (how the Meta-World suites' horizon was chosen).
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import time

from awda_bench.execution.interpreter_process import child_environment
from awda_bench.metaworld_tasks import ALL_TASKS
from awda_bench.runtimes import worker_python

MODULE = "awda_bench.benchmarks.metaworld"
"""This module's name (``__name__`` is ``"__main__"`` when it runs with ``-m``)."""

THIRD_PERSON = ("corner4", 224)
"""Camera and square size of the third-person frames measured (the suites')."""


def frame_ms(task: str, frames: int, *, fast: bool) -> tuple[float, float]:
    """Median ms of a third-person RGB frame and of a wrist depth frame, on a fresh env of
    ``task`` (the model's settings untouched by an earlier measurement)."""
    from awda_bench.metaworld.layout import make_task_env, reset_to_layout
    from awda_bench.metaworld.observations import WRIST_CAMERA, WRIST_SIZE
    from awda_bench.metaworld.renderer import FrameRenderer

    env = make_task_env(task)
    reset_to_layout(env, 0)
    renderer = FrameRenderer(fast=fast)
    camera, size = THIRD_PERSON
    out = []
    for name, side, rgb in ((camera, size, True), (WRIST_CAMERA, WRIST_SIZE, False)):
        renderer.capture(env.model, env.data, name, height=side, width=side, rgb=rgb, depth=not rgb)
        times = []
        for _ in range(frames):
            t0 = time.perf_counter()
            renderer.capture(
                env.model, env.data, name, height=side, width=side, rgb=rgb, depth=not rgb
            )
            times.append(time.perf_counter() - t0)
        out.append(1000 * statistics.median(times))
    renderer.close()
    env.close()
    return out[0], out[1]


def run_frames(args: argparse.Namespace) -> None:
    from awda_bench.metaworld.observations import WRIST_SIZE

    for fast in (False, True):
        rgb, depth = frame_ms(args.task, args.frames, fast=fast)
        label = "fast (no multisampling, shadows, reflections)" if fast else "model's own settings"
        print(
            f"{label:48s} rgb {THIRD_PERSON[1]}px {rgb:7.1f} ms   depth {WRIST_SIZE}px {depth:7.1f} ms"
        )


def run_experts(args: argparse.Namespace) -> None:
    from awda_bench.metaworld.demo import first_success_step
    from awda_bench.metaworld.layout import make_task_env

    tasks = args.task_names or list(ALL_TASKS)
    worst = 0
    total = succeeded = 0
    for task in tasks:
        env = make_task_env(task)
        lengths: list[int] = []
        for seed in range(args.seeds):
            step = first_success_step(env, task, seed, args.max_steps)
            if step:
                lengths.append(step)
        env.close()
        total += args.seeds
        succeeded += len(lengths)
        worst = max([worst, *lengths])
        spread = (
            f"median {statistics.median(lengths):5.0f} max {max(lengths):4d}" if lengths else ""
        )
        print(f"{task:28s} {len(lengths):3d}/{args.seeds} succeed  {spread}", flush=True)
    print(f"all: {succeeded}/{total} succeed; longest time to success {worst} steps")


def add_metaworld_args(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="what", required=True)
    frames = sub.add_parser("frames", help="ms per frame, models' own settings vs fast")
    frames.add_argument("--task", default="pick-place-wall-v3")
    frames.add_argument("--frames", type=int, default=20)
    experts = sub.add_parser("experts", help="scripted policies: successes, steps to success")
    experts.add_argument("--seeds", type=int, default=10)
    experts.add_argument("--max-steps", type=int, default=500)
    experts.add_argument("task_names", nargs="*", help="tasks (default: all 50)")


def argv_of(args: argparse.Namespace) -> list[str]:
    """The command line that parses back into ``args``."""
    if args.what == "frames":
        return ["frames", "--task", args.task, "--frames", str(args.frames)]
    return ["experts", "--seeds", str(args.seeds), "--max-steps", str(args.max_steps)] + list(
        args.task_names
    )


def run_metaworld_bench(args: argparse.Namespace) -> int:
    """Measure here if ``metaworld`` imports, else in ``.venv-metaworld`` (one line if absent)."""
    if importlib.util.find_spec("metaworld") is None:
        python = worker_python("metaworld")
        assert python is not None
        command = [python, "-m", MODULE, *argv_of(args)]
        return subprocess.run(command, env=child_environment(), check=False).returncode
    import awda_bench.metaworld  # noqa: F401  (MUJOCO_GL before mujoco is imported)

    run_frames(args) if args.what == "frames" else run_experts(args)
    return 0


def main() -> None:
    parser = argparse.ArgumentParser(prog=f"python -m {MODULE}")
    add_metaworld_args(parser)
    sys.exit(run_metaworld_bench(parser.parse_args()))


if __name__ == "__main__":
    main()

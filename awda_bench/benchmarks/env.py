"""``python -m awda_bench bench env``: task env speed with the scripted expert, and rendering cost.

Prints (one env, CPU sim, state observations):

- env steps/s with the expert acting (expert + ``env.step``), and ``env.step`` alone;
- the first third-person capture (render pipeline build) and the mean cost of later captures;
- with ``--sweep-seeds S``: expert success per task over seeds ``0 .. S-1`` (state only), a
  per-task table, and optionally one CSV row per episode (``--sweep-csv``).
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.experts import EMBODIMENT_NAMES
from awda_bench.rollout import SettleAfterDone, roll_out


def add_env_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--suite", default="pick_place", help="suite name (tasks/<name>.toml)")
    parser.add_argument("--embodiment", choices=EMBODIMENT_NAMES, default="agent")
    parser.add_argument("--task", type=int, default=0, help="task of the speed episodes")
    parser.add_argument(
        "--episodes", type=int, default=3, help="expert episodes timed (state only)"
    )
    parser.add_argument(
        "--frames", type=int, default=10, help="third-person captures timed after the first"
    )
    parser.add_argument(
        "--sweep-seeds", type=int, default=0, help="expert success sweep: seeds per task (0: none)"
    )
    parser.add_argument(
        "--sweep-tasks", default="all", help="comma-separated task indices of the sweep, or 'all'"
    )
    parser.add_argument(
        "--sweep-csv", type=Path, default=None, help="write one row per sweep episode here"
    )
    parser.add_argument(
        "--per-family",
        action="store_true",
        help="time the expert on the first task of every family of the suite (no rendering)",
    )


def _time_expert(env, suite, task: int, episodes: int) -> tuple[int, float, float]:
    """Run ``episodes`` expert episodes; return (steps, total seconds, seconds inside env.step)."""
    from awda_bench.episode import EpisodeContext, EpisodeSpec
    from awda_bench.experts import make_expert

    base = env.unwrapped
    steps, total, in_step = 0, 0.0, 0.0
    for seed in range(episodes):
        expert = make_expert(
            suite.name, "agent" if base.robot_uids == "panda_awda" else "demonstrator"
        )
        obs, _ = env.reset(seed=seed, options={"task": suite.task(task).reset_task})
        expert.reset(EpisodeContext(env=base, spec=EpisodeSpec(suite.name, task, seed, seed, seed)))
        start = time.perf_counter()
        end = roll_out(
            env.step, obs, expert.act, suite.horizon_steps, after_step=SettleAfterDone(expert, 0)
        )
        in_step += end.step_s
        steps += end.steps
        total += time.perf_counter() - start
    return steps, total, in_step


def _count(rows: list[dict[str, Any]], flag: str) -> str:
    """``k/n`` episodes with ``flag`` set, or ``-`` where the task does not report it."""
    if all(r[flag] is None for r in rows):
        return "-"
    return f"{sum(1 for r in rows if r[flag])}/{len(rows)}"


def _bench_families(suite: Any, envs: dict[tuple[str, str], Any], args: argparse.Namespace) -> int:
    """Env steps/s with the expert, state only, on the first task of each family."""
    from awda_bench.demo_recording import demo_env_for

    first_task: dict[str, int] = {}
    for t in suite.tasks:
        first_task.setdefault(t.family, t.index)
    print(
        f"expert env steps/s per family ({args.embodiment}, state only, {args.episodes} episodes)"
    )
    print(f"{'family':<14}{'task':>6}{'steps':>8}{'steps/s':>10}{'env.step alone':>16}")
    for family, task in first_task.items():
        env = demo_env_for(envs, suite, task, args.embodiment)
        env.reset(seed=0, options={"task": suite.task(task).reset_task})
        steps, total, in_step = _time_expert(env, suite, task, args.episodes)
        print(f"{family:<14}{task:>6}{steps:>8}{steps / total:>10.1f}{steps / in_step:>16.1f}")
    for opened in envs.values():
        opened.close()
    return 0


def run_env_bench(args: argparse.Namespace) -> int:
    from awda_bench.demo_recording import THIRD_PERSON, demo_env_for, record_demo
    from awda_bench.robot.cameras import capture_rgb
    from awda_bench.suites import load_suite

    suite = load_suite(args.suite)
    suite.task(args.task)
    envs: dict[tuple[str, str], Any] = {}
    if args.per_family:
        return _bench_families(suite, envs, args)
    t0 = time.perf_counter()
    env = demo_env_for(envs, suite, args.task, args.embodiment)
    env.reset(seed=0, options={"task": suite.task(args.task).reset_task})
    print(
        f"env {suite.env_id_for(args.task)} robot={env.unwrapped.robot_uids}: "
        f"make + first reset {time.perf_counter() - t0:.2f} s"
    )

    steps, total, in_step = _time_expert(env, suite, args.task, args.episodes)
    print(
        f"expert, state only: {steps} steps in {total:.2f} s -> {steps / total:.1f} env steps/s "
        f"(env.step alone {steps / in_step:.1f} steps/s; "
        f"{args.episodes} episodes of task {args.task})"
    )

    t0 = time.perf_counter()
    capture_rgb(env, THIRD_PERSON)
    first = time.perf_counter() - t0
    costs = []
    for _ in range(args.frames):
        env.step(np.zeros((1, 4), dtype=np.float32))
        t0 = time.perf_counter()
        frame = capture_rgb(env, THIRD_PERSON)
        costs.append(time.perf_counter() - t0)
    h, w = frame.shape[1:3]
    print(
        f"third-person frame {h}x{w}: first capture {first * 1000:.0f} ms, then "
        f"{np.mean(costs) * 1000:.1f} ms mean / {np.max(costs) * 1000:.1f} ms max over {len(costs)}"
    )

    if args.sweep_seeds > 0:
        tasks = (
            [t.index for t in suite.tasks]
            if args.sweep_tasks == "all"
            else [int(x) for x in args.sweep_tasks.split(",")]
        )
        rows: list[dict[str, Any]] = []
        print(
            f"expert sweep ({args.embodiment}): seeds 0..{args.sweep_seeds - 1} per task",
            flush=True,
        )
        # success_once (the harness's default metric): a pressed button pops back, so its
        # success at the end is false by design; at_end is printed beside it
        print("task  success  at_end  reached  grasped  mean_steps  max_steps", flush=True)
        for task in tasks:
            per_task: list[dict[str, Any]] = []
            for seed in range(args.sweep_seeds):
                task_env = demo_env_for(envs, suite, task, args.embodiment)
                _, traj = record_demo(
                    suite, task, seed, args.embodiment, frames=False, env=task_env
                )
                m = traj.meta
                row = {
                    k: m[k]
                    for k in (
                        "task",
                        "seed",
                        "embodiment",
                        "success",
                        "success_once",
                        "reached",
                        "grasped",
                        "steps",
                    )
                }
                per_task.append(row)
                rows.append(row)
            n = len(per_task)
            steps_t = [r["steps"] for r in per_task]
            print(
                f"{task:4d}  {sum(r['success_once'] for r in per_task):3d}/{n:<3d}  "
                f"{sum(r['success'] for r in per_task):3d}/{n:<3d} "
                f"{_count(per_task, 'reached'):>7}  {_count(per_task, 'grasped'):>7}  "
                f"{np.mean(steps_t):10.1f}  {max(steps_t):9d}",
                flush=True,
            )
        total_success = sum(r["success_once"] for r in rows)
        print(
            f"all   {total_success}/{len(rows)} = {total_success / len(rows):.3f} (success once)",
            flush=True,
        )
        if args.sweep_csv is not None:
            args.sweep_csv.parent.mkdir(parents=True, exist_ok=True)
            with args.sweep_csv.open("w", newline="") as fh:
                writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
                writer.writeheader()
                writer.writerows(rows)
            print(f"wrote {args.sweep_csv}")
    for opened in envs.values():
        opened.close()
    return 0

"""``python -m awda_bench bench episode-cost``: what one evaluated episode costs, per method, side by
side in one run: wall time, steps, rendered frames (the agent's cameras and the demonstrator's
video), network inference time.

Each ``--method NAME[=CKPT_DIR]`` (a learned method evaluates the last snapshot of CKPT_DIR) plays
the same ``--episodes`` held-out episodes in this process, one env per method. The demonstrator's
video is recorded on the first episode a worker sees and cached for every later snapshot
(:func:`awda_bench.demo_recording.demo_video_frames`), so both costs are printed: ``demo``
(recording it) and the rest of the episode. Inference is the policy's own timer (``predict_s`` of
``awda``: one forward pass per episode; ``inference_s`` of ``tosvi``: every step).

Where a cached episode's time goes, per step (second table): ``env`` (the simulator's step and
the controller's IK, the record's ``env_time_s``), ``encode`` (frames through the trunk: ``tosvi``'s
``encode_s``), ``net`` (the rest of inference: attention and heads), ``render+other`` (the
policy's time outside inference: rendering its camera frames, JPEG round trip, resizing).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from awda_bench.errors import UsageError


def add_episode_cost_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--method",
        action="append",
        required=True,
        metavar="NAME[=CKPT_DIR]",
        help="a method, learned ones with their checkpoint directory (repeatable)",
    )
    parser.add_argument("--suite", default="pick_place", help="suite (default pick_place)")
    parser.add_argument("--episodes", type=int, default=4, help="episodes per method (default 4)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")


def _frames(env: Any) -> int:
    counter = getattr(env, "capture_counter", None)
    return 0 if counter is None else int(counter.frames)


def _demo_frames() -> int:
    """Frames rendered so far by this process's demonstrator envs (the harness's, shared by every
    observation-only policy)."""
    from awda_bench.evaluation.observations import DEMO_ENVS

    return sum(_frames(e.unwrapped) for e in DEMO_ENVS.values())


def measure(suite_name: str, method: str, checkpoints: Path | None, episodes: int) -> dict:
    from awda_bench.demo_recording import clear_demo_video_cache
    from awda_bench.evaluation.env_factory import make_env
    from awda_bench.evaluation.episode_runner import run_episode
    from awda_bench.evaluation.episode_specs import build_episode_specs, make_protocol
    from awda_bench.evaluation.methods import get_method, make_policy, select_snapshots
    from awda_bench.suites import load_suite

    suite = load_suite(suite_name)
    spec = get_method(method)
    snapshot = select_snapshots(spec, checkpoints, 1)[0]
    policy = make_policy(spec, snapshot)
    env = make_env(suite)
    specs = build_episode_specs(suite, make_protocol(suite, episodes=episodes, base_seed=0))
    specs = specs[:episodes]
    clear_demo_video_cache()
    rows = []
    for episode in specs:
        for cached in (False, True):
            if not cached:
                clear_demo_video_cache()
            agent0, demo0 = _frames(env.unwrapped), _demo_frames()
            start = time.perf_counter()
            record = run_episode(env, policy, episode, suite, method=method, snapshot="bench")
            wall = time.perf_counter() - start
            inference = float(getattr(policy, "predict_s", getattr(policy, "inference_s", 0.0)))
            rows.append(
                {
                    "cached": cached,
                    "wall_s": wall,
                    "env_s": record.env_time_s,
                    "act_s": record.act_time_s,
                    "encode_s": float(getattr(policy, "encode_s", 0.0)),
                    "steps": record.steps,
                    "agent_frames": _frames(env.unwrapped) - agent0,
                    "demo_frames": _demo_frames() - demo0,
                    "inference_s": inference,
                    "success": bool(record.success_once),
                }
            )
    env.close()
    return {"method": method, "rows": rows}


def run_episode_cost_bench(args: argparse.Namespace) -> int:
    import numpy as np
    import torch

    torch.set_num_threads(args.threads)
    if args.episodes < 1:
        raise UsageError(f"--episodes must be at least 1 (got {args.episodes})")
    results = []
    for item in args.method:
        name, _, ckpt = item.partition("=")
        results.append(measure(args.suite, name, Path(ckpt) if ckpt else None, args.episodes))
    print(
        f"{args.suite}: {args.episodes} episodes per method, each played twice (demo video "
        f"recorded / cached), {args.threads} torch thread(s)"
    )
    header = (
        f"{'method':<16} {'steps':>6} {'wall s':>7} {'wall s (demo cached)':>21} "
        f"{'agent frames':>13} {'demo frames':>12} {'inference ms/ep':>16} {'ms/step':>8}"
    )
    print(header)
    for r in results:
        cold = [x for x in r["rows"] if not x["cached"]]
        warm = [x for x in r["rows"] if x["cached"]]

        def mean(rows: list[dict], key: str) -> float:
            return float(np.mean([x[key] for x in rows]))

        steps = mean(warm, "steps")
        inference_ms = 1000 * mean(warm, "inference_s")
        print(
            f"{r['method']:<16} {steps:>6.0f} {mean(cold, 'wall_s'):>7.2f} "
            f"{mean(warm, 'wall_s'):>21.2f} {mean(warm, 'agent_frames'):>13.1f} "
            f"{mean(cold, 'demo_frames'):>12.1f} {inference_ms:>16.1f} "
            f"{inference_ms / max(steps, 1):>8.2f}"
        )
    print("\nper step of a cached episode [ms]")
    print(
        f"{'method':<16} {'wall':>7} {'env':>7} {'act':>7} {'encode':>7} {'net':>7} "
        f"{'render+other':>13}"
    )
    for r in results:
        warm = [x for x in r["rows"] if x["cached"]]
        per_step = {
            key: 1000 * float(np.mean([x[key] / max(x["steps"], 1) for x in warm]))
            for key in ("wall_s", "env_s", "act_s", "encode_s", "inference_s")
        }
        net = per_step["inference_s"] - per_step["encode_s"]
        other = per_step["act_s"] - per_step["inference_s"]
        print(
            f"{r['method']:<16} {per_step['wall_s']:>7.1f} {per_step['env_s']:>7.1f} "
            f"{per_step['act_s']:>7.1f} {per_step['encode_s']:>7.1f} {net:>7.1f} {other:>13.1f}"
        )
    return 0

"""``python -m awda_bench bench serve``: what serving a policy costs, side by side in one run, for
both protocols (``--protocol awda``, the default, and ``--protocol openpi``).

1. Round-trip latency per control step on loopback, server in its own process
   (``python -m awda_bench serve [--protocol openpi]``): a step with one 240x320x3 uint8 frame up
   and one action down, and a step with nothing up (the served policy reads nothing)::

       awda:   harness --act--> server --observe rgb--> harness --frame (230 kB)--> server --action--> harness
       openpi: harness --observation dict with the frame (230 kB)--> server --actions--> harness

   (the native server asks for what its policy reads; the openpi client sends what the server's
   metadata lists, ``observation_keys``), median and 99th percentile over ``--steps`` steps,
   after ``--warmup``, and the ratio of the medians, openpi / awda.
2. The harness's episodes/min with ``random`` in-process against ``random`` served over each
   protocol (the same sweep: suite, episodes, seeds, worker count; each into its own temporary
   store), and whether each gave the in-process per-episode outcomes::

       episodes/min         = episodes / sweep wall time * 60   (worker start-up included)
       steady episodes/min  = episodes / (wall - start-up) * 60
       act ms/step          = sum(policy reset + act time) / steps
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.benchmarks.throughput import episode_outcomes
from awda_bench.episode import ClosedLoopPolicy, EpisodeContext, EpisodeSpec
from awda_bench.evaluation.methods import served_method
from awda_bench.evaluation.results_store import STORE_NAME
from awda_bench.evaluation.sweep import SweepConfig, SweepResult, run_sweep
from awda_bench.serving.openpi_policy import OpenpiPolicy
from awda_bench.serving.openpi_schema import IMAGE
from awda_bench.serving.protocol import NATIVE, OPENPI, PROTOCOLS
from awda_bench.serving.remote_policy import RemotePolicy
from awda_bench.suites import SUITES_DIR

FRAME_SHAPE = (240, 320, 3)
"""The third-person frame the latency probe sends up each step."""
EPISODE_STEPS = 100_000
"""The latency probe's steps per episode (one episode: every timed step is an ``act``)."""


class FrameReadingPolicy(ClosedLoopPolicy):
    """The latency probe's served policy: reads the third-person frame every step (one frame up)
    and returns a zero action (one action down)."""

    name = "frame-reading"
    observation_keys: tuple[str, ...] = (IMAGE,)
    """Served over openpi's protocol: the frame only."""

    def reset(self, ctx: EpisodeContext) -> None:
        pass

    def act(self, obs: Any) -> np.ndarray:
        frame = obs.rgb()
        action = np.zeros((obs.num_envs, 4), np.float32)
        action[:, 3] = -1.0 if frame.size else 1.0
        return action


class BlindPolicy(FrameReadingPolicy):
    """The latency probe's served policy that reads nothing (nothing up, one action down)."""

    name = "blind"
    observation_keys = ()

    def act(self, obs: Any) -> np.ndarray:
        return np.zeros((obs.num_envs, 4), np.float32)


class _FixedFrame:
    """Observations whose frame is always the same random 240x320x3 image (the harness's side of
    the latency probe; rendering is not what is timed)."""

    num_envs = 1

    def __init__(self) -> None:
        rng = np.random.default_rng(0)
        self._frame = rng.integers(0, 256, (1, *FRAME_SHAPE), dtype=np.uint8)

    def rgb(self) -> np.ndarray:
        return self._frame


def add_serve_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--suite", default="pick_place", help="suite (default pick_place)")
    parser.add_argument(
        "--episodes", type=int, default=1, help="episodes per held-out task (default 1)"
    )
    parser.add_argument(
        "--workers", type=int, default=1, help="harness workers, both sweeps (default 1)"
    )
    parser.add_argument("--steps", type=int, default=1000, help="timed steps (default 1000)")
    parser.add_argument("--warmup", type=int, default=50, help="untimed steps (default 50)")
    parser.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    parser.add_argument("--tasks-dir", type=Path, default=SUITES_DIR, help=argparse.SUPPRESS)


@contextmanager
def _server(method: str, protocol: str = NATIVE) -> Iterator[str]:
    """``python -m awda_bench serve --method METHOD --protocol PROTOCOL`` on a free port, in its
    own process."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "awda_bench", "serve", "--method", method, "--port", "0"]
    process = subprocess.Popen(
        [*command, "--protocol", protocol], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        if " on ws://" not in line:
            raise RuntimeError(f"the policy server did not start (exit {process.wait()})")
        yield line.split(" on ")[1].split(";")[0].split(" ")[0]
    finally:
        process.terminate()
        process.wait(timeout=30)


def _latency_ms(url: str, protocol: str, steps: int, warmup: int) -> np.ndarray:
    """Per-``act`` round-trip times [ms] of the harness's policy for ``protocol`` on ``url``."""
    served = served_method(url, protocol=protocol).served
    assert served is not None
    policy = OpenpiPolicy(served) if protocol == OPENPI else RemotePolicy(served)
    observations = _FixedFrame()
    spec = EpisodeSpec(suite="bench", task=0, episode=0, seed=0, demo_seed=0)
    ctx = EpisodeContext(None, spec, observations=observations)  # type: ignore[arg-type]
    times = []
    try:
        for step in range(warmup + steps):
            if step % EPISODE_STEPS == 0:  # openpi's first request of an episode is in reset
                policy.reset(ctx)
            t0 = time.perf_counter()
            policy.act(observations)
            if step >= warmup:
                times.append((time.perf_counter() - t0) * 1e3)
    finally:
        policy.close()
    return np.asarray(times)


def _steps(run_dir: Path) -> int:
    db = sqlite3.connect(run_dir / STORE_NAME)
    try:
        return int(db.execute("SELECT SUM(steps) FROM episodes").fetchone()[0] or 0)
    finally:
        db.close()


def _summary(ms: np.ndarray) -> str:
    return f"{np.median(ms):5.2f} / {np.percentile(ms, 99):5.2f}"


def run_serve_bench(args: argparse.Namespace) -> int:
    print(
        "round trip per step on loopback (server in its own process), median / p99 ms over "
        f"{args.steps} steps:"
    )
    print(f"  {'':<48} {NATIVE:>15} {OPENPI:>15} {OPENPI + ' / ' + NATIVE:>14}")
    for policy, what in (
        (FrameReadingPolicy, "one 240x320x3 uint8 frame up, one action down"),
        (BlindPolicy, "nothing up, one action down"),
    ):
        latency = {}
        for protocol in PROTOCOLS:
            with _server(f"{__name__}:{policy.__name__}", protocol) as url:
                latency[protocol] = _latency_ms(url, protocol, args.steps, args.warmup)
        ratio = np.median(latency[OPENPI]) / np.median(latency[NATIVE])
        print(
            f"  {what:<48} {_summary(latency[NATIVE]):>15} {_summary(latency[OPENPI]):>15} "
            f"{ratio:>13.2f}x"
        )

    rows: list[tuple[str, SweepResult, int]] = []
    outcomes = []
    with tempfile.TemporaryDirectory(prefix="awda-bench-serve-") as tmp:
        for label, over in (("in-process", None), *((f"{p} served", p) for p in PROTOCOLS)):
            out = Path(tmp) / label.replace(" ", "-")
            server: AbstractContextManager[str | None] = (
                _server("random", over) if over else nullcontext(None)
            )
            with server as policy_url:
                config = SweepConfig(
                    suite=args.suite,
                    method="remote" if over else "random",
                    policy_url=policy_url,
                    policy_protocol=over or NATIVE,
                    out=out,
                    episodes=args.episodes,
                    seed=args.seed,
                    workers=args.workers,
                    suites_dir=args.tasks_dir,
                    progress=False,
                    command=f"bench serve ({label})",
                )
                rows.append((label, run_sweep(config), _steps(out)))
            outcomes.append(episode_outcomes(out))
    print(
        f"harness throughput, {args.suite} / random, {args.episodes} episodes per task, "
        f"{args.workers} worker(s):"
    )
    print(
        f"  {'':>14} {'episodes':>8} {'wall s':>7} {'ep/min':>7} {'steady':>7} "
        f"{'act ms/step':>11} {'env ms/step':>11}  {'/ in-process':>12}"
    )
    local = rows[0][1]
    for label, r, steps in rows:
        busy = max(r.wall_time_s - r.startup_s, 1e-9)
        relative = r.ran / r.wall_time_s / (local.ran / local.wall_time_s)
        print(
            f"  {label:>14} {r.ran:>8} {r.wall_time_s:>7.1f} {r.ran / r.wall_time_s * 60:>7.2f} "
            f"{r.ran / busy * 60:>7.2f} {r.act_time_s / max(steps, 1) * 1e3:>11.2f} "
            f"{r.env_time_s / max(steps, 1) * 1e3:>11.2f}  {relative:>11.2f}x"
        )
    same = [o == outcomes[0] for o in outcomes[1:]]
    for protocol, equal in zip(PROTOCOLS, same, strict=True):
        print(
            f"identical per-episode outcomes, {protocol} served vs in-process: "
            f"{'yes' if equal else 'NO'}"
        )
    errors = sum(r.errors for _, r, _ in rows)
    return 0 if all(same) and not errors else 1

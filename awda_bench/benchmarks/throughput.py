"""``python -m awda_bench bench harness``: episodes/minute with 1 and 2 workers, the parallel
speed-up, and the harness's own overhead as a share of episode time (goal < 5 %);
``--backends local ray`` also times the Ray backend beside the local pool (goal >= 0.9x).
Beside the speed-up it prints the machine's own ceiling for it (:mod:`core_scaling`: what N
processes of pure compute, and of memory streaming, achieve at once against one alone, N the
largest worker count; ~15 s), unless ``--no-ceiling``.

Each (backend, worker count) runs the same sweep into its own temporary store. Definitions::

    episodes/min          = episodes / sweep wall time * 60         (worker start-up included)
    steady episodes/min   = episodes / (wall - start-up) * 60
    harness overhead      = 1 - (sum(episode wall) + sum(policy build))
                              / (workers * (wall - start-up))
                            (scheduling, IPC, store commits, idle tail: everything outside episodes;
                            building the policy once per worker counts as start-up, not overhead)
    in-episode overhead   = sum(episode wall - policy time - env time) / sum(episode wall)
"""

from __future__ import annotations

import argparse
import sqlite3
import tempfile
from pathlib import Path

from awda_bench.benchmarks.core_scaling import measure_core_scaling
from awda_bench.evaluation.methods import DEFAULT_METHOD
from awda_bench.evaluation.results_store import STORE_NAME
from awda_bench.evaluation.sweep import SweepConfig, SweepResult, run_sweep
from awda_bench.evaluation.worker_pool import DEFAULT_ENV_FACTORY
from awda_bench.execution.backends import BACKENDS
from awda_bench.suites import SUITES_DIR


def add_harness_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--suite", default="pick_place", help="suite (default pick_place)")
    parser.add_argument(
        "--method", default=DEFAULT_METHOD, help=f"method (default {DEFAULT_METHOD})"
    )
    parser.add_argument(
        "--episodes", type=int, default=4, help="episodes per held-out task (default 4)"
    )
    parser.add_argument(
        "--workers", type=int, nargs="+", default=[1, 2], help="worker counts (default 1 2)"
    )
    parser.add_argument(
        "--backends",
        nargs="+",
        choices=BACKENDS,
        default=[BACKENDS[0]],
        help="backends to time, each with every worker count (default local)",
    )
    parser.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    parser.add_argument(
        "--no-ceiling",
        action="store_true",
        help="skip the machine's own N-process speed-up (compute and memory kernels, ~15 s)",
    )
    parser.add_argument("--keep", type=Path, help="keep the run directories under this path")
    parser.add_argument("--tasks-dir", type=Path, default=SUITES_DIR, help=argparse.SUPPRESS)
    parser.add_argument("--env-factory", default=DEFAULT_ENV_FACTORY, help=argparse.SUPPRESS)


def episode_outcomes(run_dir: Path) -> list[tuple]:
    """Every episode's outcome row in ``run_dir``'s store, in (task, episode) order: what two runs
    of the same episodes must agree on."""
    db = sqlite3.connect(run_dir / STORE_NAME)
    try:
        return db.execute(
            "SELECT task, episode, status, success_once, success_at_end, reached, grasped, steps "
            "FROM episodes ORDER BY task, episode"
        ).fetchall()
    finally:
        db.close()


def describe(workers: int, r: SweepResult, backend: str = BACKENDS[0]) -> dict[str, float | str]:
    busy = max(r.wall_time_s - r.startup_s, 1e-9)
    return {
        "backend": backend,
        "workers": workers,
        "episodes": r.ran,
        "errors": r.errors,
        "wall_s": r.wall_time_s,
        "startup_s": r.startup_s,
        "episodes_per_min": r.ran / r.wall_time_s * 60,
        "steady_episodes_per_min": r.ran / busy * 60,
        "mean_episode_s": r.episode_time_s / max(r.ran, 1),
        "harness_overhead": 1 - (r.episode_time_s + r.setup_time_s) / (max(workers, 1) * busy),
        "policy_build_s": r.setup_time_s,
        "in_episode_overhead": (r.episode_time_s - r.act_time_s - r.env_time_s)
        / max(r.episode_time_s, 1e-9),
    }


def _ratio(row: dict[str, float | str], base: dict[str, float | str], key: str) -> float:
    return float(row[key]) / float(base[key])


def run_harness_bench(args: argparse.Namespace) -> int:
    rows, outcomes = [], []
    with tempfile.TemporaryDirectory(prefix="awda-bench-harness-") as tmp:
        root = args.keep or Path(tmp)
        runs = [(b, w) for b in args.backends for w in args.workers]
        for backend, workers in runs:
            out = root / (f"workers{workers}" if backend == "local" else f"{backend}{workers}")
            config = SweepConfig(
                suite=args.suite,
                method=args.method,
                out=out,
                episodes=args.episodes,
                seed=args.seed,
                workers=workers,
                backend=backend,
                suites_dir=args.tasks_dir,
                env_factory=args.env_factory,
                progress=False,
                command=f"bench harness --backends {backend} --workers {workers}",
            )
            result = run_sweep(config)
            if result.skipped:
                print(
                    f"note: {result.skipped} episodes were already in {out}; "
                    "only new ones are timed"
                )
            rows.append(describe(workers, result, backend))
            outcomes.append(episode_outcomes(out))
    print(f"harness throughput: {args.suite} / {args.method}, {args.episodes} episodes per task")
    print(
        f"{'backend':>7} {'workers':>7} {'episodes':>8} {'wall s':>8} {'start s':>8} {'ep/min':>8} "
        f"{'steady':>8} {'ep s':>7} {'overhead':>9} {'in-ep':>7}"
    )
    for r in rows:
        print(
            f"{r['backend']:>7} {r['workers']:>7} {r['episodes']:>8} {r['wall_s']:>8.1f} "
            f"{r['startup_s']:>8.1f} "
            f"{r['episodes_per_min']:>8.2f} {r['steady_episodes_per_min']:>8.2f} "
            f"{r['mean_episode_s']:>7.2f} "
            f"{r['harness_overhead']:>8.1%} {r['in_episode_overhead']:>7.2%}"
        )
    local = [r for r in rows if r["backend"] == BACKENDS[0]]
    if len(local) >= 2:
        base = local[0]
        for r in local[1:]:
            print(
                f"speed-up {r['workers']} vs {base['workers']} workers: "
                f"{_ratio(r, base, 'episodes_per_min'):.2f}x "
                f"(steady {_ratio(r, base, 'steady_episodes_per_min'):.2f}x)"
            )
    for r in rows:
        peer = [b for b in local if b["workers"] == r["workers"]]
        if r["backend"] != BACKENDS[0] and peer:
            print(
                f"{r['backend']} vs local, {r['workers']} workers: "
                f"{_ratio(r, peer[0], 'episodes_per_min'):.2f}x episodes/min "
                f"(steady {_ratio(r, peer[0], 'steady_episodes_per_min'):.2f}x)"
            )
    most = max(args.workers)
    if len(local) >= 2 and most >= 2 and not args.no_ceiling:
        ceilings = measure_core_scaling(most)
        found = ", ".join(f"{c.kernel} {c.speedup:.2f}x" for c in ceilings)
        print(
            f"machine ceiling, {most} processes at once vs 1 (bench's core_scaling): {found} "
            f"(ideal {most}.00x)"
        )
    same = all(o == outcomes[0] for o in outcomes[1:])
    across = "backends and worker counts" if len(args.backends) > 1 else "worker counts"
    print(f"identical per-episode outcomes across {across}: {'yes' if same else 'NO'}")
    return 0 if same else 1

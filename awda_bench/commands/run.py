"""``python -m awda_bench run``: evaluate a method on a suite into a resumable results store."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from awda_bench.errors import UsageError
from awda_bench.evaluation.episode_specs import EVAL_SPLITS
from awda_bench.evaluation.methods import DEFAULT_METHOD, REMOTE_METHOD, method_names
from awda_bench.evaluation.results_store import STORE_NAME
from awda_bench.evaluation.sweep import SweepConfig, run_sweep
from awda_bench.evaluation.worker_pool import DEFAULT_ENV_FACTORY
from awda_bench.execution.backends import add_backend_args
from awda_bench.policies.tosvi_policy import ACTION_SELECTS, tosvi_method_name
from awda_bench.primitives.config import CENTRE_SUFFIX, GRASP_SELECTS
from awda_bench.serving.protocol import NATIVE, OPENPI, PROTOCOLS
from awda_bench.serving.remote_policy import DEFAULT_TIMEOUT_S
from awda_bench.suites import SIMULATORS, SUITES_DIR, available_suites, load_suite

QUICK_EPISODES = 3
"""``--quick``: episodes per evaluation unit (one snapshot)."""


HELP = "evaluate a method on a suite (resumable; results in RUN_DIR/results.sqlite)"
DESCRIPTION = (
    "Play every episode of the suite's evaluation protocol with a method and "
    "record one "
    "row per episode. Re-running the same command skips finished episodes and retries errors. "
    "Exit 1 if episodes of this invocation ended in errors (they are stored and retried next "
    "time)."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--suite",
        required=True,
        help=f"suite name ({', '.join(available_suites()) or 'see tasks/'})",
    )
    parser.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        help=f"method ({', '.join(method_names())}, pkg.module:Factory, or {REMOTE_METHOD}: "
        f"the one served at --policy-url); default {DEFAULT_METHOD}",
    )
    parser.add_argument(
        "--policy-url",
        metavar="ws://HOST:PORT",
        help=f"--method {REMOTE_METHOD}: the policy server (`python -m awda_bench serve`); its "
        "rows are labelled with the method and snapshot it serves",
    )
    parser.add_argument(
        "--protocol",
        choices=PROTOCOLS,
        default=NATIVE,
        help=f"--method {REMOTE_METHOD}: what the server at --policy-url speaks: {NATIVE} "
        f"(`python -m awda_bench serve`, default) or {OPENPI} (openpi's websocket policy "
        "protocol: any openpi policy server; docs/serving.md gives the observation keys)",
    )
    parser.add_argument(
        "--policy-timeout",
        type=float,
        default=DEFAULT_TIMEOUT_S,
        metavar="S",
        help=f"--method {REMOTE_METHOD}: longest wait for one message from the server "
        f"(default {DEFAULT_TIMEOUT_S:g} s); a timeout is that episode's error",
    )
    parser.add_argument(
        "--num-waypoints",
        type=int,
        choices=(3, 5, 8),
        help="gt-waypoints only: K waypoints per episode (default 5, the paper's); K = 3 and 8 "
        "are their own methods and table columns, gt-waypoints-k3 and gt-waypoints-k8",
    )
    parser.add_argument(
        "--action-select",
        choices=ACTION_SELECTS,
        help="tosvi / tosvi-depth only: the action read from the predicted mixture (default "
        "sample, the reference's; mean and mode are their own methods, e.g. tosvi-mean)",
    )
    parser.add_argument(
        "--grasp-select",
        choices=GRASP_SELECTS,
        help="gt-waypoints / awda only: which wrist-depth component the grasp primitive grasps: "
        "waypoint (nearest the grasp waypoint's projection; default) or centre (nearest the "
        "image centre, the reference's rule; its own method, e.g. gt-waypoints-centre)",
    )
    parser.add_argument("--checkpoints", type=Path, help="snapshot directory of a learned method")
    parser.add_argument(
        "--label",
        help="name of this method's rows in the store and tables (default: the method's), e.g. "
        "no-adm for --method awda on an ablation's checkpoints",
    )
    parser.add_argument(
        "--split",
        choices=EVAL_SPLITS,
        default=EVAL_SPLITS[0],
        help="test: the held-out tasks (the protocol, default); train: the training tasks (with "
        "--task: just those), to tell a low held-out number from a failure to fit",
    )
    parser.add_argument(
        "--snapshots", type=int, default=10, help="evaluate the last N snapshots (default 10)"
    )
    parser.add_argument(
        "--episodes",
        type=int,
        help="episodes per held-out task (or family); default: the suite's (paper: 20)",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="base seed of all episode seeds (default 0)"
    )
    add_backend_args(parser)
    parser.add_argument(
        "--out", type=Path, default=Path("runs"), help="run directory (default runs/)"
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"small sweep: {QUICK_EPISODES} episodes per task, last snapshot only",
    )
    parser.add_argument(
        "--task",
        type=int,
        action="append",
        default=[],
        help="only these evaluated tasks (repeatable)",
    )
    parser.add_argument(
        "--episode-timeout",
        type=float,
        default=600.0,
        help="watchdog limit per episode [s] (default 600)",
    )
    parser.add_argument(
        "--videos",
        type=int,
        default=0,
        metavar="K",
        help="save K successful and K failed episodes per task as MP4",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--tasks-dir", type=Path, default=SUITES_DIR, help=argparse.SUPPRESS)
    parser.add_argument("--env-factory", default=DEFAULT_ENV_FACTORY, help=argparse.SUPPRESS)


def _method(args: argparse.Namespace) -> str:
    """``--method`` with ``--num-waypoints`` / ``--action-select`` folded in (gt-waypoints' K
    variants and T-OSVI's action statistics are methods of their own)."""
    if args.action_select is not None:
        if args.method not in ("tosvi", "tosvi-depth"):
            raise UsageError(
                f"--action-select applies to --method tosvi or tosvi-depth, not {args.method!r}; "
                "drop --action-select"
            )
        return tosvi_method_name(args.method, args.action_select)
    if args.grasp_select is not None:
        if args.method not in ("gt-waypoints", "awda"):
            raise UsageError(
                f"--grasp-select applies to --method gt-waypoints or awda, not {args.method!r}; "
                "drop --grasp-select"
            )
        if args.grasp_select == "centre" and args.num_waypoints not in (None, 5):
            raise UsageError(
                "--grasp-select centre is offered with K = 5 waypoints only; drop --num-waypoints"
            )
        if args.grasp_select == "centre":
            return str(args.method) + CENTRE_SUFFIX
    if args.num_waypoints is None:
        return str(args.method)
    if args.method != "gt-waypoints":
        raise UsageError(
            f"--num-waypoints applies to --method gt-waypoints, not {args.method!r}; "
            "drop --num-waypoints or use --method gt-waypoints"
        )
    from awda_bench.policies.gt_waypoints import gt_waypoints_method_name

    return gt_waypoints_method_name(args.num_waypoints)


def config_from_args(args: argparse.Namespace) -> SweepConfig:
    episodes = args.episodes if args.episodes is not None or not args.quick else QUICK_EPISODES
    return SweepConfig(
        suite=args.suite,
        method=_method(args),
        out=args.out,
        checkpoints=args.checkpoints,
        snapshots=1 if args.quick else args.snapshots,
        episodes=episodes,
        seed=args.seed,
        workers=args.workers,
        backend=args.backend,
        ray_address=args.ray_address,
        tasks=tuple(args.task),
        episode_timeout_s=args.episode_timeout,
        suites_dir=args.tasks_dir,
        env_factory=args.env_factory,
        progress=not args.no_progress,
        command=" ".join(["python -m awda_bench", *sys.argv[1:]]),
        label=args.label,
        split=args.split,
        policy_url=args.policy_url,
        policy_timeout_s=args.policy_timeout,
        policy_protocol=args.protocol,
    )


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    if args.videos and load_suite(config.suite, config.suites_dir).simulator != SIMULATORS[0]:
        raise UsageError(
            f"--videos is not offered on suite {config.suite!r} yet (videos are rendered in this "
            "process, whose environment lacks its simulator); drop --videos"
        )
    result = run_sweep(config)
    print(
        f"{config.suite}/{config.label or config.method}: {result.planned} episodes planned, "
        f"{result.skipped} already done, "
        f"{result.ran} played ({result.errors} errors) in {result.wall_time_s:.1f} s; "
        f"store {config.out / STORE_NAME}"
    )
    if args.videos:
        from awda_bench.reporting.videos import record_videos

        written = record_videos(config, args.videos)
        print(f"videos: {len(written)} files under {config.out / 'videos'}")
    if result.errors:
        print(
            f"warning: {result.errors} episodes ended in errors; "
            "re-run the same command to retry them",
            file=sys.stderr,
        )
        return 1
    return 0

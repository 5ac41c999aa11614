"""``python -m awda_bench bench <what>``: speed measurements printed side by side in one run.

Each benchmark lives beside the code it measures; this module only wires them:

    controller  mink IK vs ManiSkill pd_ee_delta_pos vs pd_joint_pos (env steps/s)
    env         task env steps/s with the scripted expert + cost of one rendered frame
    primitives  primitive + executor overhead per env step, rendered frames per episode
    harness     episodes/minute with 1 and 2 workers, harness overhead share
    inference   waypoint network forward latency
"""

from __future__ import annotations

import argparse
import importlib

from awda_bench.errors import UsageError
from awda_bench.render_device import require_renderer

BENCHMARKS: dict[str, tuple[str, str, str, bool]] = {
    # name: (module, add-args function, run function, needs the renderer)
    "controller": ("awda_bench.robot.bench_controller", "add_controller_args", "run_controller_bench", True),
    "env": ("awda_bench.envs.bench_env", "add_env_args", "run_env_bench", True),
    "primitives": ("awda_bench.primitives.bench_primitives", "add_primitives_args", "run_primitives_bench", True),
    "harness": ("awda_bench.harness.bench_throughput", "add_harness_args", "run_harness_bench", True),
    "inference": ("awda_bench.models.bench_inference", "add_inference_args", "run_inference_bench", False),
}


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser("bench", help="speed benchmarks (controller, env, primitives, harness, inference)")
    sub = parser.add_subparsers(dest="benchmark", required=True, metavar="BENCHMARK")
    for name, (module_name, add_args, _run, _render) in BENCHMARKS.items():
        bench_parser = sub.add_parser(name, help=f"benchmark: {name}")
        bench_parser.set_defaults(_benchmark=name)
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if not exc.name or not module_name.startswith(exc.name):
                raise
            bench_parser.set_defaults(_missing=module_name)
            continue
        getattr(module, add_args)(bench_parser)
    return parser


def run(args: argparse.Namespace) -> int:
    module_name, _add, run_name, needs_renderer = BENCHMARKS[args._benchmark]
    if getattr(args, "_missing", None):
        raise UsageError(f"benchmark {args._benchmark!r} is not available: module {module_name} is missing")
    if needs_renderer:
        require_renderer()
    return int(getattr(importlib.import_module(module_name), run_name)(args))

"""``python -m awda_bench bench <what> [options]``: speed measurements printed side by side in one run.

Each benchmark is a module of :mod:`awda_bench.benchmarks`; this module only wires them (and
imports the chosen one alone, so the CLI starts fast):

    controller  mink IK vs ManiSkill pd_ee_delta_pos vs pd_joint_pos (env steps/s)
    env         task env steps/s with the scripted expert + cost of one rendered frame
    primitives  primitive + executor overhead per env step, rendered frames per episode
    harness     episodes/minute with 1 and 2 workers, harness overhead share
    episode-cost  per method: wall s, frames rendered, inference ms of one evaluated episode
    render-cost   a frame's render time per render body (and with the robot's meshes decimated)
    inference   waypoint network forward latency
    soft-dtw    the multi-waypoint Soft-DTW loss per implementation (and its share of a step)
    serve       a served policy, both protocols (awda, openpi) side by side: loopback round trip
                per step, episodes/min served vs in-process
    metaworld   Meta-World frames (models' own render settings vs fast) and expert lengths, run in
                .venv-metaworld
"""

from __future__ import annotations

import argparse
import importlib

from awda_bench.errors import UnknownChoiceError
from awda_bench.render_device import require_renderer

BENCHMARKS: dict[str, tuple[str, str, str, bool]] = {
    # name: (module, add-args function, run function, needs the renderer)
    "controller": (
        "awda_bench.benchmarks.controller",
        "add_controller_args",
        "run_controller_bench",
        True,
    ),
    "env": ("awda_bench.benchmarks.env", "add_env_args", "run_env_bench", True),
    "primitives": (
        "awda_bench.benchmarks.primitives",
        "add_primitives_args",
        "run_primitives_bench",
        True,
    ),
    "harness": (
        "awda_bench.benchmarks.throughput",
        "add_harness_args",
        "run_harness_bench",
        True,
    ),
    "episode-cost": (
        "awda_bench.benchmarks.episode_cost",
        "add_episode_cost_args",
        "run_episode_cost_bench",
        True,
    ),
    "render-cost": (
        "awda_bench.benchmarks.render_cost",
        "add_render_cost_args",
        "run_render_cost_bench",
        True,
    ),
    "inference": (
        "awda_bench.benchmarks.inference",
        "add_inference_args",
        "run_inference_bench",
        False,
    ),
    "soft-dtw": (
        "awda_bench.benchmarks.soft_dtw",
        "add_soft_dtw_args",
        "run_soft_dtw_bench",
        False,
    ),
    "serve": ("awda_bench.benchmarks.serve", "add_serve_args", "run_serve_bench", True),
    "metaworld": (
        "awda_bench.benchmarks.metaworld",
        "add_metaworld_args",
        "run_metaworld_bench",
        False,
    ),
}


HELP = (
    "speed benchmarks (controller, env, primitives, harness, episode-cost, render-cost, "
    "inference, soft-dtw, serve, metaworld)"
)
DESCRIPTION = "Run one benchmark; 'bench NAME --help' lists its options."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("benchmark", metavar="BENCHMARK", help=f"one of: {', '.join(BENCHMARKS)}")
    parser.add_argument("options", nargs=argparse.REMAINDER, help="the benchmark's own options")


def run(args: argparse.Namespace) -> int:
    if args.benchmark not in BENCHMARKS:
        raise UnknownChoiceError("benchmark", args.benchmark, BENCHMARKS)
    module_name, add_args, run_name, needs_renderer = BENCHMARKS[args.benchmark]
    module = importlib.import_module(module_name)
    parser = argparse.ArgumentParser(prog=f"python -m awda_bench bench {args.benchmark}")
    getattr(module, add_args)(parser)
    options = parser.parse_args(args.options)
    if needs_renderer:
        require_renderer()
    return int(getattr(module, run_name)(options))

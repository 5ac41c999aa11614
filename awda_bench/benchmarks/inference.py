"""``python -m awda_bench bench inference``: forward-pass latency of a learned model.

One forward pass in eval mode under ``torch.inference_mode`` on random inputs of the configured
size (paper: 7 ms on an A40 GPU for AWDA). Reports the median and spread over ``--repeats`` timed
passes after ``--warmup`` untimed ones, on the CPU and, when CUDA exists, on the GPU too.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.cli_options import add_model_args, model_from_args
from awda_bench.models.synthetic import random_forward_inputs
from awda_bench.models.tosvi_net import TosviNet


def add_inference_args(parser: argparse.ArgumentParser) -> None:
    add_model_args(parser)
    parser.add_argument(
        "--batch", type=int, default=1, help="samples per forward pass (default: 1)"
    )
    parser.add_argument("--repeats", type=int, default=10, help="timed passes (default: 10)")
    parser.add_argument("--warmup", type=int, default=2, help="untimed passes first (default: 2)")
    parser.add_argument(
        "--threads", type=int, default=0, help="torch CPU threads (default: torch's choice)"
    )


def time_forward(
    model: AwdaNet | TosviNet, device: torch.device, *, batch: int, repeats: int, warmup: int
) -> list[float]:
    """Wall-clock seconds of ``repeats`` forward passes (after ``warmup``) on ``device``."""
    model = model.to(device).eval()
    inputs = random_forward_inputs(model, batch, device)
    times: list[float] = []
    with torch.inference_mode():
        for i in range(warmup + repeats):
            if device.type == "cuda":
                torch.cuda.synchronize(device)
            start = time.perf_counter()
            model(*inputs)
            if device.type == "cuda":
                torch.cuda.synchronize(device)
            if i >= warmup:
                times.append(time.perf_counter() - start)
    return times


def run_inference_bench(args: argparse.Namespace) -> int:
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    model = model_from_args(args)
    frames = model.config.trunk.demo_frames + (
        1 if isinstance(model, AwdaNet) else model.config.frame_stack
    )
    print(
        f"{args.model}: batch {args.batch} x {frames} frames of {args.height}x{args.width}, "
        f"eval mode, {args.repeats} timed passes after {args.warmup} warm-up"
    )
    devices = [torch.device("cpu")] + ([torch.device("cuda")] if torch.cuda.is_available() else [])
    for device in devices:
        times = [
            t * 1e3
            for t in time_forward(
                model, device, batch=args.batch, repeats=args.repeats, warmup=args.warmup
            )
        ]
        label = (
            f"cpu ({torch.get_num_threads()} threads)"
            if device.type == "cpu"
            else torch.cuda.get_device_name(device)
        )
        print(
            f"  {label:<24} median {statistics.median(times):8.1f} ms   "
            f"min {min(times):8.1f} ms   max {max(times):8.1f} ms"
        )
    print("  paper (AWDA, Nvidia A40): 7 ms")
    return 0

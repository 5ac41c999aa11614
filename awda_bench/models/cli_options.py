"""Command-line options shared by ``describe`` and ``bench inference``: which model, what size."""

from __future__ import annotations

import argparse

from awda_bench.models.architectures import ARCHITECTURES, build_model, default_config
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.tosvi_net import TosviNet


def add_model_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model", choices=ARCHITECTURES, default="awda", help="architecture (default: awda)"
    )
    parser.add_argument("--height", type=int, default=240, help="image height [px] (default: 240)")
    parser.add_argument("--width", type=int, default=320, help="image width [px] (default: 320)")
    parser.add_argument(
        "--demo-frames", type=int, default=10, help="demonstration frames (default: 10, Table S2)"
    )
    parser.add_argument(
        "--backbone-weights",
        default="none",
        help="imagenet | none | a .pth path (default none: shapes, speed do not depend on it)",
    )


def model_from_args(args: argparse.Namespace) -> AwdaNet | TosviNet:
    config = default_config(
        args.model,
        height_px=args.height,
        width_px=args.width,
        backbone_weights=args.backbone_weights,
        demo_frames=args.demo_frames,
    )
    return build_model(config)

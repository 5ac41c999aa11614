"""``python -m awda_bench doctor``: versions, simulation backend, render device, one test frame."""

from __future__ import annotations

import argparse
import importlib.metadata
import platform
import time
from pathlib import Path

import numpy as np

from awda_bench.errors import AwdaError
from awda_bench.render_device import require_renderer

PACKAGES = (
    "awda_bench",
    "mani-skill",
    "sapien",
    "mink",
    "mujoco",
    "torch",
    "torchvision",
    "gymnasium",
    "numpy",
    "opencv-python-headless",
    "pandas",
)


HELP = "check the installation: versions, sim backend, render device, one rendered frame"
DESCRIPTION = (
    "Print versions, the simulation backend and the render device SAPIEN found, then "
    "render one test frame. Exits 3 with the fix when rendering is impossible."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--frame",
        type=Path,
        default=Path("reports/figures/doctor_frame.png"),
        help="where to write the test frame (default: %(default)s)",
    )


def run(args: argparse.Namespace) -> int:
    print(f"python        {platform.python_version()} ({platform.machine()}, {platform.system()})")
    for name in PACKAGES:
        try:
            version = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            version = "not installed"
        print(f"{name:<13} {version}")
    print(f"meta-world    {metaworld_environment()}")

    import torch

    backend = (
        "physx_cuda (CUDA available)" if torch.cuda.is_available() else "physx_cpu (no CUDA device)"
    )
    print(f"sim backend   {backend}")
    device = require_renderer()
    print(f"render device {device.label}")

    frame, seconds = render_test_frame()
    if float(frame.std()) < 1.0:
        raise AwdaError(
            f"the test frame rendered blank (std {frame.std():.2f}); the renderer is broken"
        )
    import cv2

    args.frame.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.frame), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    print(
        f"test frame    {args.frame} ({frame.shape[1]}x{frame.shape[0]}, first capture {seconds:.1f} s)"
    )
    print("ok")
    return 0


def metaworld_environment() -> str:
    """What the Meta-World suites' workers would start from (they need an environment of their
    own): its packages, or how to make it."""
    from awda_bench.runtimes import SECOND_VENVS, MissingEnvironmentError, worker_versions

    try:
        versions = worker_versions("metaworld")
    except MissingEnvironmentError:
        return f"{SECOND_VENVS['metaworld']} missing (Meta-World suites): bash scripts/setup.sh"
    listed = ", ".join(f"{k.split(' ', 1)[1]} {v}" for k, v in sorted(versions.items()))
    return f"{SECOND_VENVS['metaworld']}: {listed}"


def render_test_frame() -> tuple[np.ndarray, float]:
    """Render the third-person camera of the empty-table scene once: (H, W, 3) uint8, seconds."""
    import gymnasium as gym

    import awda_bench.envs  # noqa: F401  (registers panda_awda and AWDA-EmptyTable-v1)
    from awda_bench.render_device import render_backend
    from awda_bench.robot.cameras import capture_rgb

    env = gym.make(
        "AWDA-EmptyTable-v1", obs_mode="state", reward_mode="none", render_backend=render_backend()
    )
    try:
        env.reset(seed=0)
        start = time.perf_counter()
        frame = capture_rgb(env)[0]
        return frame, time.perf_counter() - start
    finally:
        env.close()

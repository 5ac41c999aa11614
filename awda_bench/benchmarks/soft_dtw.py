"""``python -m awda_bench bench soft-dtw``: the multi-waypoint Soft-DTW loss per implementation.

Times the AWDA loss (forward + backward of :func:`multi_waypoint_sdtw_loss`, the 5 waypoint sets in
one ragged call) at a recipe's batch size and trajectory length, for every Soft-DTW implementation
that runs natively on the device (CPU: ``numpy``, ``torch``; CUDA: ``torch``, ``triton``), side by
side in one run, and checks that they agree with the ``torch`` reference (loss and gradient).
With ``--step`` it also times one whole Full-1 training step (AwdaNet forward and backward, the
loss, Adam) on random inputs at the recipe's image size, and prints the loss's share of the step
for each implementation: ``loss_impl / (step - loss_default + loss_impl)``, where ``loss_default``
is the implementation the step itself used (``auto``). Issue 13's goal is a share <= 10 %.

Triton's CPU interpreter is not timed by default (a test vehicle: 60 s vs numpy's 15 ms at the small
recipe's batch, measured 2026-11-26); pass
``--implementations triton`` to include it anyway.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from dataclasses import replace

import torch

from awda_bench.errors import UsageError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import CELL_HEADS, AwdaConfig
from awda_bench.models.waypoint_loss import multi_waypoint_sdtw_loss
from awda_bench.soft_dtw.core import IMPLEMENTATIONS, auto_implementation
from awda_bench.training.loop import resolve_device

NATIVE = {"cpu": ("numpy", "torch"), "cuda": ("torch", "triton")}


def add_soft_dtw_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--recipe", default="paper", help="recipe whose batch and sizes to use (default: paper)"
    )
    parser.add_argument("--device", default="auto", help="auto | cpu | cuda (default: auto)")
    parser.add_argument(
        "--implementations",
        default="",
        help="comma-separated (default: the device's native ones: CPU numpy,torch; "
        "CUDA torch,triton)",
    )
    parser.add_argument("--repeats", type=int, default=10, help="timed calls (default: 10)")
    parser.add_argument("--warmup", type=int, default=2, help="untimed calls first (default: 2)")
    parser.add_argument(
        "--step", action="store_true", help="also time a whole Full-1 training step"
    )
    parser.add_argument(
        "--threads", type=int, default=0, help="torch CPU threads (default: torch's)"
    )


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _time(fn: Callable[[], object], device: torch.device, repeats: int, warmup: int) -> list[float]:
    times = []
    for i in range(warmup + repeats):
        _sync(device)
        start = time.perf_counter()
        fn()
        _sync(device)
        if i >= warmup:
            times.append(time.perf_counter() - start)
    return times


def _loss_and_grad(
    waypoints: torch.Tensor, trajectory: torch.Tensor, cfg: AwdaConfig, impl: str
) -> tuple[torch.Tensor, torch.Tensor]:
    w = waypoints.detach().requires_grad_(True)
    loss, _ = multi_waypoint_sdtw_loss(
        w,
        trajectory,
        num_sets=cfg.num_waypoint_sets,
        points_per_segment=cfg.points_per_segment,
        gamma=cfg.gamma,
        attribute_scale=cfg.attribute_scale,
        implementation=impl,
    )
    (grad,) = torch.autograd.grad(loss, w)
    return loss.detach(), grad


def run_soft_dtw_bench(args: argparse.Namespace) -> int:
    from awda_bench.training.columns import column_for
    from awda_bench.training.recipe import load_recipe
    from awda_bench.training.run import model_config

    if args.threads > 0:
        torch.set_num_threads(args.threads)
    device = resolve_device(args.device)
    recipe = load_recipe(args.recipe)
    if args.step and recipe.model.trunk.head in CELL_HEADS:
        raise UsageError(
            f"--step times a Full-1 step on random images; recipe {recipe.name}'s "
            f"{recipe.model.trunk.head} head votes along its training camera's rays and trains over "
            "cached features: time its step with `train --recipe ... --steps 20` instead, or drop "
            "--step"
        )
    # the loss's settings only: the identification loss (cell heads) needs a camera and labels
    # that random trajectories do not have, and is not part of the Soft-DTW loss timed here
    awda = {**recipe.model.awda, "identification_weight": 0.0}
    loss_only = replace(recipe, model=replace(recipe.model, awda=awda))
    cfg = model_config(loss_only, column_for("awda", None))
    assert isinstance(cfg, AwdaConfig)
    impls = [s for s in args.implementations.split(",") if s] or list(NATIVE[device.type])
    unknown = [s for s in impls if s not in IMPLEMENTATIONS]
    if unknown:
        raise UsageError(
            f"unknown soft-DTW implementation(s) {unknown}; choose from {', '.join(IMPLEMENTATIONS)}"
        )
    b, t = recipe.train.batch_size, recipe.data.trajectory_points
    gen = torch.Generator().manual_seed(0)
    waypoints = torch.randn(b, cfg.total_waypoints, cfg.waypoint_dim, generator=gen)
    trajectory = torch.rand(b, t, cfg.waypoint_dim, generator=gen)
    waypoints, trajectory = waypoints.to(device), trajectory.to(device)
    name = torch.cuda.get_device_name(device) if device.type == "cuda" else "CPU"
    print(
        f"multi-waypoint Soft-DTW loss, recipe {recipe.name}: batch {b}, "
        f"{cfg.num_waypoint_sets} sets x trajectory {t} points, gamma {cfg.gamma}; "
        f"device {name}, {torch.get_num_threads()} CPU threads"
    )
    reference, ref_grad = _loss_and_grad(waypoints.double(), trajectory.double(), cfg, "torch")
    medians: dict[str, float] = {}
    for impl in impls:
        value, grad = _loss_and_grad(waypoints.double(), trajectory.double(), cfg, impl)
        err = max(float((value - reference).abs()), float((grad - ref_grad).abs().max()))
        times = _time(
            lambda impl=impl: _loss_and_grad(waypoints, trajectory, cfg, impl),  # type: ignore[misc]
            device,
            args.repeats,
            args.warmup,
        )
        medians[impl] = statistics.median(times)
        print(
            f"  {impl:<7} {1e3 * medians[impl]:9.2f} ms fwd+bwd (median of {len(times)}; "
            f"min {1e3 * min(times):.2f})   float64 max |diff| vs torch: {err:.1e}"
        )
    fastest = min(medians, key=medians.__getitem__)
    for impl, ms in medians.items():
        if impl != fastest:
            print(f"  speed-up of {fastest} over {impl}: {ms / medians[fastest]:.1f}x")
    if not args.step:
        return 0
    model = AwdaNet(cfg, load_backbone_weights=False).to(device)
    trunk = cfg.trunk
    h, w = trunk.image_height_px, trunk.image_width_px
    batch = {
        "demo": torch.rand(b, trunk.demo_frames, 3, h, w, device=device),
        "first_frame": torch.rand(b, 3, h, w, device=device),
        "head": torch.zeros(b, dtype=torch.long, device=device),
        "trajectory": trajectory,
    }
    optimizer = torch.optim.Adam(model.parameters(), lr=recipe.train.learning_rate)

    def step() -> None:
        optimizer.zero_grad(set_to_none=True)
        loss, _ = model.compute_loss(batch)
        loss.backward()
        optimizer.step()

    step_times = _time(step, device, max(3, args.repeats // 2), 1)
    step_s = statistics.median(step_times)
    default = auto_implementation(device)  # what the step's loss ran
    print(f"  Full-1 training step at {h}x{w}, batch {b}: {step_s:.3f} s (loss: {default})")
    base = step_s - medians.get(default, 0.0)
    for impl, s in medians.items():
        print(f"  loss share of a step with {impl}: {100 * s / (base + s):.1f} %")
    return 0

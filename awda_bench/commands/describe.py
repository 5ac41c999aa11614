"""``python -m awda_bench describe [--model awda|tosvi|tosvi-depth] [--height H --width W]``.

Prints a learned model's configuration, the tensor shapes at each stage of one forward pass
(batch 1) and its parameter counts per part. Never downloads weights (``--backbone-weights``
defaults to none).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import torch
from torch import nn

from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.cli_options import add_model_args, model_from_args
from awda_bench.models.config import config_to_dict
from awda_bench.models.synthetic import random_forward_inputs

HELP = "shapes and parameter counts of a learned model (awda, tosvi, tosvi-depth)"
DESCRIPTION = "Build a model, run one batch-1 forward pass, print shapes and parameters."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_model_args(parser)


def _count(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def _shape(value: object) -> str:
    if isinstance(value, torch.Tensor):
        return "x".join(str(s) for s in value.shape)
    if isinstance(value, Sequence):
        return ", ".join(_shape(v) for v in value)
    return type(value).__name__


def run(args: argparse.Namespace) -> int:
    model = model_from_args(args).eval()
    print(f"model {model.arch}")
    for key, value in config_to_dict(model.config).items():
        print(f"  {key}: {value}")
    stages: dict[str, nn.Module] = {
        "backbone (per frame)": model.trunk.backbone,
        "positional encoding": model.trunk.positional,
        "attention": model.trunk.attention,
        "spatial softmax": model.trunk.spatial_softmax,
        "per-frame MLP": model.trunk.mlp,
    }
    if isinstance(model, AwdaNet):
        stages.update({f"head {i}": head for i, head in enumerate(model.heads)})
    else:
        stages.update({"policy head": model.policy_head, "inverse head": model.inverse_head})
        if model.depth_backbone is not None and model.depth_fusion is not None:
            stages.update(
                {"depth backbone": model.depth_backbone, "depth fusion": model.depth_fusion}
            )
    shapes: dict[str, str] = {}

    def recorder(name: str):  # type: ignore[no-untyped-def]
        def hook(_module: nn.Module, _inputs: object, output: object) -> None:
            shapes.setdefault(name, _shape(output))  # returning None keeps the output unchanged

        return hook

    hooks = [module.register_forward_hook(recorder(name)) for name, module in stages.items()]
    inputs = random_forward_inputs(model, 1, torch.device("cpu"))
    with torch.inference_mode():
        output = model(*inputs)
    for hook in hooks:
        hook.remove()
    print("shapes (batch 1):")
    print(f"  {'inputs':<22} {_shape(inputs)}")
    for name in stages:
        print(f"  {name:<22} {shapes.get(name, '-')}")
    print(f"  {'output':<22} {_shape(output)}")
    print("parameters:")
    for name, module in stages.items():
        if name in ("positional encoding", "spatial softmax"):
            continue
        print(f"  {name:<22} {_count(module):>12,}")
    print(f"  {'total':<22} {_count(model):>12,}")
    return 0

"""The space-time self-attention layer: what it computes, and that it takes PyTorch's fused path."""

from __future__ import annotations

import math

import torch
from torch.nn.attention import SDPBackend, sdpa_kernel

from awda_bench.models.attention import SelfAttention3d


def _reference(layer: SelfAttention3d, x: torch.Tensor) -> torch.Tensor:
    """softmax(Q K^T / sqrt(d)) V per head, written out, then output, residual and norm."""
    b, c, t, h, w = x.shape
    heads, d = layer.heads, layer.head_dim

    def tokens(y: torch.Tensor) -> torch.Tensor:
        return y.reshape(b, heads, d, t * h * w).transpose(2, 3)

    q, k, v = tokens(layer.query(x)), tokens(layer.key(x)), tokens(layer.value(x))
    weights = torch.softmax(q @ k.transpose(-1, -2) / math.sqrt(d), dim=-1)
    attended = (weights @ v).transpose(2, 3).reshape(b, heads * d, t, h, w)
    return layer.norm(x + layer.output(attended))


def test_the_layer_is_multi_head_softmax_attention_over_all_space_time_tokens() -> None:
    torch.manual_seed(0)
    layer = SelfAttention3d(channels=8, heads=2, head_dim=4, dropout=0.0).eval()
    x = torch.randn(2, 8, 3, 4, 5)
    torch.testing.assert_close(layer(x), _reference(layer, x), atol=1e-5, rtol=1e-4)
    # querying with the last frame only gives that frame's outputs (eval mode)
    torch.testing.assert_close(layer(x, queries_from=2), layer(x)[:, :, 2:], atol=1e-5, rtol=1e-4)


def test_training_runs_on_the_fused_flash_kernel_not_the_math_fallback() -> None:
    """The math fallback materializes every L x L weight matrix (3.7x slower for T-OSVI's 1,280
    tokens here); the fused kernel needs the tokens' last dimension at stride 1."""
    torch.manual_seed(0)
    layer = SelfAttention3d(channels=8, heads=2, head_dim=4, dropout=0.0).train()
    x = torch.randn(2, 8, 3, 4, 5, requires_grad=True)
    with sdpa_kernel(SDPBackend.FLASH_ATTENTION):  # raises "No available kernel" on a fallback
        y = layer(x)
        y.square().sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all()
    torch.testing.assert_close(y, _reference(layer, x), atol=1e-5, rtol=1e-4)

r"""The temporal part of the trunk: positional encoding, non-local self-attention, spatial softmax.

Feature volumes are laid out like video for ``Conv3d``: ``(B, C, T, h, w)``. Time and space are
flattened into one token axis of length :math:`L = T h w` (token :math:`p = (t h + y) w + x`), in
the T-OSVI order: demo frames first, then the agent frame(s).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from awda_bench.errors import UsageError


def sinusoidal_encoding(
    length: int, channels: int, device: torch.device, dtype: torch.dtype
) -> torch.Tensor:
    r"""Transformer sine/cosine table ``(channels, length)``.

    :math:`PE_{2i, p} = \sin(p / 10000^{2i/C})`, :math:`PE_{2i+1, p} = \cos(p / 10000^{2i/C})`.
    """
    position = torch.arange(length, device=device, dtype=torch.float64).unsqueeze(0)
    half = torch.arange(0, channels, 2, device=device, dtype=torch.float64)
    inv_freq = torch.exp(-math.log(10000.0) * half / channels).unsqueeze(1)
    angles = inv_freq * position
    table = torch.zeros(channels, length, device=device, dtype=torch.float64)
    table[0::2] = torch.sin(angles)
    table[1::2] = torch.cos(angles[: channels // 2])
    return table.to(dtype)


class SpaceTimePositionalEncoding(nn.Module):
    """Adds :func:`sinusoidal_encoding` over the flattened (time, space) axis of (B, C, T, h, w)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, t, h, w = x.shape
        table = sinusoidal_encoding(t * h * w, c, x.device, x.dtype).view(1, c, t, h, w)
        return x + table


class SelfAttention3d(nn.Module):
    """One non-local self-attention layer (T-OSVI): Q/K/V from 1x1x1 ``Conv3d``, multi-head scaled
    dot-product attention over all ``T*h*w`` tokens, a 1x1x1 output projection, then dropout,
    residual and ``BatchNorm3d``::

        y = BatchNorm3d(x + Dropout(W_o * Attention(W_q x, W_k x, W_v x)))

    ``queries_from = s`` computes ``y`` for the frames ``t >= s`` only (their tokens query all
    ``T*h*w`` keys): what a last layer costs when only the last frames' outputs are read. Exact in
    eval mode only (in training, BatchNorm's batch statistics would cover the queried tokens alone).
    """

    def __init__(self, channels: int, heads: int, head_dim: int, dropout: float) -> None:
        super().__init__()
        self.heads = heads
        self.head_dim = head_dim
        inner = heads * head_dim
        self.query = nn.Conv3d(channels, inner, kernel_size=1)
        self.key = nn.Conv3d(channels, inner, kernel_size=1)
        self.value = nn.Conv3d(channels, inner, kernel_size=1)
        self.output = nn.Conv3d(inner, channels, kernel_size=1)
        self.dropout = nn.Dropout(dropout)
        self.norm = nn.BatchNorm3d(channels)

    def _tokens(self, x: torch.Tensor) -> torch.Tensor:
        b = x.shape[0]
        # (B, heads*d, T, h, w) -> (B, heads, L, d), contiguous: PyTorch's fused (flash) attention
        # needs the last dimension at stride 1, else it falls back to the math path, which
        # materializes the L x L weights (T-OSVI, 1,280 tokens, batch 16, forward + backward on
        # 2 cores: 0.88 s per layer math, 0.24 s flash)
        return x.reshape(b, self.heads, self.head_dim, -1).transpose(2, 3).contiguous()

    def forward(self, x: torch.Tensor, queries_from: int = 0) -> torch.Tensor:
        """``(B, C, T, h, w)`` -> ``(B, C, T - queries_from, h, w)``."""
        if queries_from and self.training:
            raise UsageError("SelfAttention3d(queries_from > 0) is exact in eval mode only")
        b, _, t, h, w = x.shape
        kept = x[:, :, queries_from:]
        q, k, v = (
            self._tokens(self.query(kept)),
            self._tokens(self.key(x)),
            self._tokens(self.value(x)),
        )
        attended = F.scaled_dot_product_attention(q, k, v)  # (B, heads, L', d)
        shape = (b, self.heads * self.head_dim, t - queries_from, h, w)
        attended = attended.transpose(2, 3).reshape(shape)
        return self.norm(kept + self.dropout(self.output(attended)))


class SpatialSoftmax(nn.Module):
    r"""Per channel and frame, a softmax over the ``h x w`` grid and its expected image coordinates.

    ``(B, C, T, h, w) -> (B, T, 2C)``: for each channel the keypoint
    :math:`(\mathbb{E}[x], \mathbb{E}[y])` with x, y in [-1, 1] (x left to right, y top to bottom),
    channels' x first then y.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, t, h, w = x.shape
        weights = torch.softmax(x.reshape(b, c, t, h * w), dim=-1)
        ys = (
            torch.linspace(-1.0, 1.0, h, device=x.device, dtype=x.dtype)
            if h > 1
            else x.new_zeros(1)
        )
        xs = (
            torch.linspace(-1.0, 1.0, w, device=x.device, dtype=x.dtype)
            if w > 1
            else x.new_zeros(1)
        )
        grid_y, grid_x = torch.meshgrid(ys, xs, indexing="ij")
        ex = (weights * grid_x.reshape(-1)).sum(-1)  # (B, C, T)
        ey = (weights * grid_y.reshape(-1)).sum(-1)
        return torch.cat((ex, ey), dim=1).permute(0, 2, 1)  # (B, T, 2C)

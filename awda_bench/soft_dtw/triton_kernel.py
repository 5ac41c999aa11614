# mypy: disable-error-code="no-untyped-def"
r"""Fused Soft-DTW recursions as Triton kernels: one program per sample, every anti-diagonal inside.

The reference implementation (:func:`awda_bench.soft_dtw.tables.soft_dtw_forward_table`)
walks the ``N + M - 1`` anti-diagonals in a Python loop; on a GPU each diagonal is a handful of tiny
kernel launches, forward and backward, and the multi-waypoint loss of a paper-scale AWDA step spent
~348 ms of ~470 ms there (issue 13, one H100). Here each sample's whole recursion is **one**
program: its lanes hold one anti-diagonal (lane ``k`` is row ``i = k + 1``), read the two previous
diagonals from the sample's table in global memory, write the new one, and meet at a barrier before
the next (loads of the table being written bypass L1: ``cache_modifier=".cg"``) -- the wavefront
scheme of the CUDA soft-DTW kernels (Maghoumi et al.), written in Triton so no extra dependency
(Triton ships with torch) or hand-written CUDA is needed. ``gamma`` is passed as a one-element
tensor of the tables' dtype (a Python float argument would be float32 inside the kernel).

Only the recursions are fused; the squared-Euclidean cost and the chain rule from ``E`` back to
the sequences stay ordinary batched torch ops. The tables and their borders are set up exactly as
in the reference (same ``+inf``/``-inf`` conventions and ragged ``lengths`` seeding), so the two
agree to rounding; ``tests/test_soft_dtw.py`` checks values and gradients in float64 for
``gamma`` 1 and 0.001.

On a CPU tensor the kernels run in Triton's interpreter (numpy, one diagonal per vectorized step):
that is how the kernels are tested on machines without a GPU, not a fast path (use ``numpy``).
"""

import functools
from typing import Any

import torch
import triton
import triton.language as tl
from triton.runtime.interpreter import InterpretedFunction

from awda_bench.soft_dtw.tables import backward_tables


def _forward_kernel(cost_ptr, r_ptr, n, m, gamma_ptr, BLOCK: tl.constexpr):  # noqa: N803
    b = tl.program_id(0)
    gamma = tl.load(gamma_ptr)  # in the tables' dtype (a float argument would be float32)
    width = m + 2
    cost_b = cost_ptr + b * n * m
    r_b = r_ptr + b * (n + 2) * width
    i = tl.arange(0, BLOCK) + 1
    inv = 1.0 / gamma
    for d in range(2, n + m + 1):
        j = d - i
        mask = (i <= n) & (j >= 1) & (j <= m)
        p0 = tl.load(r_b + (i - 1) * width + (j - 1), mask=mask, other=0.0, cache_modifier=".cg")
        p1 = tl.load(r_b + (i - 1) * width + j, mask=mask, other=0.0, cache_modifier=".cg")
        p2 = tl.load(r_b + i * width + (j - 1), mask=mask, other=0.0, cache_modifier=".cg")
        low = tl.minimum(tl.minimum(p0, p1), p2)
        total = tl.exp((low - p0) * inv) + tl.exp((low - p1) * inv) + tl.exp((low - p2) * inv)
        c = tl.load(cost_b + (i - 1) * m + (j - 1), mask=mask, other=0.0)
        tl.store(r_b + i * width + j, c + low - gamma * tl.log(total), mask=mask)
        tl.debug_barrier()


def _backward_kernel(c_ptr, r_ptr, e_ptr, len_ptr, n, m, gamma_ptr, BLOCK: tl.constexpr):  # noqa: N803
    b = tl.program_id(0)
    gamma = tl.load(gamma_ptr)
    width = m + 2
    offset = b * (n + 2) * width
    c_b, r_b, e_b = c_ptr + offset, r_ptr + offset, e_ptr + offset
    rows = tl.load(len_ptr + b)
    i = tl.arange(0, BLOCK) + 1
    inv = 1.0 / gamma
    for step in range(0, n + m - 1):
        d = n + m - step
        j = d - i
        mask = (i <= rows) & (j >= 1) & (j <= m)
        r_ij = tl.load(r_b + i * width + j, mask=mask, other=0.0)
        down = (i + 1) * width + j
        right = i * width + j + 1
        diag = (i + 1) * width + j + 1
        a = tl.exp(
            (
                tl.load(r_b + down, mask=mask, other=0.0)
                - r_ij
                - tl.load(c_b + down, mask=mask, other=0.0)
            )
            * inv
        )
        bb = tl.exp(
            (
                tl.load(r_b + right, mask=mask, other=0.0)
                - r_ij
                - tl.load(c_b + right, mask=mask, other=0.0)
            )
            * inv
        )
        cc = tl.exp(
            (
                tl.load(r_b + diag, mask=mask, other=0.0)
                - r_ij
                - tl.load(c_b + diag, mask=mask, other=0.0)
            )
            * inv
        )
        value = (
            tl.load(e_b + down, mask=mask, other=0.0, cache_modifier=".cg") * a
            + tl.load(e_b + right, mask=mask, other=0.0, cache_modifier=".cg") * bb
            + tl.load(e_b + diag, mask=mask, other=0.0, cache_modifier=".cg") * cc
        )
        tl.store(e_b + i * width + j, value, mask=mask)
        tl.debug_barrier()


@functools.lru_cache(maxsize=2)
def _kernels(interpret: bool) -> tuple[Any, Any]:
    """The two kernels, compiled for the GPU or wrapped for Triton's CPU interpreter."""
    wrap = InterpretedFunction if interpret else triton.jit
    return wrap(_forward_kernel), wrap(_backward_kernel)


def _block(rows: int) -> int:
    return max(16, 1 << (rows - 1).bit_length())


def forward_table(cost: torch.Tensor, gamma: float) -> torch.Tensor:
    """Same table as :func:`~awda_bench.soft_dtw.tables.soft_dtw_forward_table`, in one
    launch."""
    cost = cost.contiguous()
    b, n, m = cost.shape
    r = torch.full((b, n + 2, m + 2), float("inf"), dtype=cost.dtype, device=cost.device)
    r[:, 0, 0] = 0.0
    forward, _ = _kernels(cost.device.type != "cuda")
    g = torch.tensor([gamma], dtype=cost.dtype, device=cost.device)
    forward[(b,)](cost, r, n, m, g, BLOCK=_block(n))
    return r


def backward_table(
    cost: torch.Tensor, r: torch.Tensor, gamma: float, lengths: torch.Tensor | None
) -> torch.Tensor:
    """Same ``E`` as :func:`~awda_bench.soft_dtw.tables.soft_dtw_backward_table`, in one
    launch."""
    b, n, m = cost.shape
    c, rr, e, lengths = backward_tables(cost, r, lengths)
    _, backward = _kernels(cost.device.type != "cuda")
    lens = lengths.to(torch.int32).contiguous()
    g = torch.tensor([gamma], dtype=cost.dtype, device=cost.device)
    backward[(b,)](c, rr.contiguous(), e, lens, n, m, g, BLOCK=_block(n))
    return e[:, 1 : n + 1, 1 : m + 1]

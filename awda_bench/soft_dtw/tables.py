r"""The Soft-DTW recursion tables in torch ops: the reference forward and backward recursions.

Both walk the anti-diagonals of the table in a Python loop (all cells with ``i + j = d`` are
independent), vectorized over the batch and the diagonal; the recursions themselves, the ragged
``lengths`` convention and the gradient are stated in :mod:`awda_bench.soft_dtw.core`, which
dispatches to them (``implementation="torch"``). :func:`backward_tables` sets up the padded
tables a backward recursion reads, shared with the fused kernel
(:mod:`awda_bench.soft_dtw.triton_kernel`), so the two agree to rounding.
"""

from __future__ import annotations

import torch


def _diagonal_indices(
    n: int, m: int, d: int, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor]:
    """1-based (i, j) of the cells with ``i + j == d``, ``1 <= i <= n``, ``1 <= j <= m``."""
    i = torch.arange(max(1, d - m), min(n, d - 1) + 1, device=device)
    return i, d - i


def soft_dtw_forward_table(cost: torch.Tensor, gamma: float) -> torch.Tensor:
    """The full table ``R``, ``(B, N + 2, M + 2)`` (rows/columns 0 and N+1/M+1 are borders)."""
    b, n, m = cost.shape
    r = torch.full((b, n + 2, m + 2), float("inf"), dtype=cost.dtype, device=cost.device)
    r[:, 0, 0] = 0.0
    for d in range(2, n + m + 1):
        i, j = _diagonal_indices(n, m, d, cost.device)
        prev = torch.stack((r[:, i - 1, j - 1], r[:, i - 1, j], r[:, i, j - 1]), dim=0)
        # softmin_gamma = -gamma * logsumexp(-prev / gamma); logsumexp shifts by the max itself and
        # gives -inf (not NaN) where all three are +inf, which never happens inside the table.
        soft = -gamma * torch.logsumexp(-prev / gamma, dim=0)
        r[:, i, j] = cost[:, i - 1, j - 1] + soft
    return r


def backward_tables(
    cost: torch.Tensor, r: torch.Tensor, lengths: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The padded tables the backward recursion reads, ``(c, rr, e, lengths)``, all
    ``(B, N + 2, M + 2)`` but ``lengths (B,)`` (every row where ``None`` was given).

    ``c``: the cost with a zero border. ``rr``: ``r`` with ``-inf`` in column ``M + 1`` and past
    each sample's last row, so border terms contribute ``exp(-inf) = 0``, except the corner
    ``(n_b + 1, M + 1)`` which holds ``R[n_b, M]``. ``e``: zeros but 1 at that corner (the seed).
    Shared by the torch loop and the fused Triton kernel.
    """
    b, n, m = cost.shape
    if lengths is None:
        lengths = torch.full((b,), n, dtype=torch.long, device=cost.device)
    c = torch.zeros((b, n + 2, m + 2), dtype=cost.dtype, device=cost.device)
    c[:, 1 : n + 1, 1 : m + 1] = cost
    rows = torch.arange(n + 2, device=cost.device)
    batch = torch.arange(b, device=cost.device)
    rr = r.clone()
    rr[:, :, m + 1] = -float("inf")
    rr[rows.view(1, -1) > lengths.view(-1, 1)] = -float("inf")
    rr[batch, lengths + 1, m + 1] = r[batch, lengths, m]
    e = torch.zeros((b, n + 2, m + 2), dtype=cost.dtype, device=cost.device)
    e[batch, lengths + 1, m + 1] = 1.0
    return c, rr, e, lengths


def soft_dtw_backward_table(
    cost: torch.Tensor, r: torch.Tensor, gamma: float, lengths: torch.Tensor | None = None
) -> torch.Tensor:
    """``E = dR[n_b, M] / dcost`` of shape ``(B, N, M)`` from the forward table ``r``.

    ``lengths (B,)``: rows each sample uses (default all ``N``); ``E`` is 0 on the other rows.
    """
    b, n, m = cost.shape
    c, rr, e, lengths = backward_tables(cost, r, lengths)
    rows = torch.arange(n + 2, device=cost.device)
    valid = rows.view(1, -1) <= lengths.view(-1, 1)  # (B, N + 2)
    for d in range(n + m, 1, -1):
        i, j = _diagonal_indices(n, m, d, cost.device)
        r_ij = rr[:, i, j]
        a = torch.exp((rr[:, i + 1, j] - r_ij - c[:, i + 1, j]) / gamma)
        bb = torch.exp((rr[:, i, j + 1] - r_ij - c[:, i, j + 1]) / gamma)
        cc = torch.exp((rr[:, i + 1, j + 1] - r_ij - c[:, i + 1, j + 1]) / gamma)
        value = e[:, i + 1, j] * a + e[:, i, j + 1] * bb + e[:, i + 1, j + 1] * cc
        # rows past n_b: -inf - -inf = NaN there, and E must be 0
        value = torch.where(valid[:, i], value, torch.zeros_like(value))
        e[:, i, j] = value
    return e[:, 1 : n + 1, 1 : m + 1]

r"""Batched, differentiable Soft-DTW (Cuturi & Blondel, 2017) in PyTorch.

For a cost matrix :math:`\Delta \in \mathbb{R}^{N \times M}` the soft-DTW value is the last cell of

.. math::

    R_{0,0} = 0,\quad R_{i,0} = R_{0,j} = +\infty,\qquad
    R_{i,j} = \Delta_{i,j} + \operatorname{softmin}_\gamma(R_{i-1,j-1}, R_{i-1,j}, R_{i,j-1}),

    \operatorname{softmin}_\gamma(a, b, c) = -\gamma \log\left(e^{-a/\gamma} + e^{-b/\gamma}
        + e^{-c/\gamma}\right),

which tends to plain DTW as :math:`\gamma \to 0`. The recursion is evaluated one anti-diagonal at a
time (all cells with :math:`i + j = d` are independent), vectorized over the batch and the diagonal.
The soft-min is a ``logsumexp`` (max-shifted), so :math:`\gamma = 10^{-3}` neither overflows nor
underflows.

The gradient :math:`E = \partial R_{N,M} / \partial \Delta` is the expected alignment matrix,
computed by the backward recursion of Cuturi & Blondel (Algorithm 2), again per anti-diagonal:

.. math::

    E_{i,j} = E_{i+1,j}\, e^{(R_{i+1,j} - R_{i,j} - \Delta_{i+1,j})/\gamma}
            + E_{i,j+1}\, e^{(R_{i,j+1} - R_{i,j} - \Delta_{i,j+1})/\gamma}
            + E_{i+1,j+1}\, e^{(R_{i+1,j+1} - R_{i,j} - \Delta_{i+1,j+1})/\gamma}.

Every exponent is :math:`\le 0` (a soft-min never exceeds its arguments), so the backward pass is
stable too. Gradients with respect to the sequences flow through the cost matrix by ordinary
autograd (:func:`soft_dtw` builds :math:`\Delta` from the sequences with differentiable torch ops).
"""

from __future__ import annotations

from typing import Any

import torch

from awda_bench.errors import UsageError


def squared_euclidean_cost(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    r"""Pairwise cost :math:`\Delta_{b,i,j} = \lVert x_{b,i} - y_{b,j} \rVert^2`.

    Args:
        x: ``(B, N, D)``.
        y: ``(B, M, D)``.

    Returns:
        ``(B, N, M)``; computed from differences (not the expanded square), so it is exactly 0 on
        identical points and never negative.
    """
    return (x.unsqueeze(2) - y.unsqueeze(1)).pow(2).sum(dim=-1)


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


def soft_dtw_backward_table(cost: torch.Tensor, r: torch.Tensor, gamma: float) -> torch.Tensor:
    """``E = dR[N, M] / dcost`` of shape ``(B, N, M)`` from the forward table ``r``."""
    b, n, m = cost.shape
    # Padded copies: cost gets a zero border, R gets -inf borders so border terms contribute
    # exp(-inf) = 0, except the corner (N+1, M+1) which seeds the recursion with E = 1.
    c = torch.zeros((b, n + 2, m + 2), dtype=cost.dtype, device=cost.device)
    c[:, 1 : n + 1, 1 : m + 1] = cost
    rr = r.clone()
    rr[:, :, m + 1] = -float("inf")
    rr[:, n + 1, :] = -float("inf")
    rr[:, n + 1, m + 1] = r[:, n, m]
    e = torch.zeros((b, n + 2, m + 2), dtype=cost.dtype, device=cost.device)
    e[:, n + 1, m + 1] = 1.0
    for d in range(n + m, 1, -1):
        i, j = _diagonal_indices(n, m, d, cost.device)
        r_ij = rr[:, i, j]
        a = torch.exp((rr[:, i + 1, j] - r_ij - c[:, i + 1, j]) / gamma)
        bb = torch.exp((rr[:, i, j + 1] - r_ij - c[:, i, j + 1]) / gamma)
        cc = torch.exp((rr[:, i + 1, j + 1] - r_ij - c[:, i + 1, j + 1]) / gamma)
        e[:, i, j] = e[:, i + 1, j] * a + e[:, i, j + 1] * bb + e[:, i + 1, j + 1] * cc
    return e[:, 1 : n + 1, 1 : m + 1]


class _SoftDtwFunction(torch.autograd.Function):
    """Soft-DTW of a batch of cost matrices, with the analytic (expected-alignment) gradient."""

    @staticmethod
    def forward(ctx: Any, cost: torch.Tensor, gamma: float) -> torch.Tensor:
        cost_d = cost.detach()
        r = soft_dtw_forward_table(cost_d, gamma)
        ctx.save_for_backward(cost_d, r)
        ctx.gamma = gamma
        n, m = cost.shape[1], cost.shape[2]
        return r[:, n, m].clone()

    @staticmethod
    def backward(ctx: Any, grad_output: torch.Tensor) -> tuple[torch.Tensor, None]:
        cost, r = ctx.saved_tensors
        e = soft_dtw_backward_table(cost, r, ctx.gamma)
        return grad_output.view(-1, 1, 1) * e, None


def soft_dtw_from_cost(cost: torch.Tensor, gamma: float) -> torch.Tensor:
    """Soft-DTW values ``(B,)`` of cost matrices ``(B, N, M)``; differentiable in ``cost``.

    Note: the first-order gradient is analytic; a second derivative (double backward) is not
    provided.
    """
    if cost.dim() != 3:
        raise UsageError(f"soft-DTW needs a (B, N, M) cost tensor, got shape {tuple(cost.shape)}")
    if not gamma > 0:
        raise UsageError(f"soft-DTW gamma must be > 0, got {gamma}")
    out: torch.Tensor = _SoftDtwFunction.apply(cost, float(gamma))
    return out


def soft_dtw(x: torch.Tensor, y: torch.Tensor, gamma: float = 1e-3) -> torch.Tensor:
    """Soft-DTW with squared-Euclidean cost between sequences ``x (B, N, D)`` and ``y (B, M, D)``.

    Returns ``(B,)``. Differentiable in both sequences.
    """
    if x.dim() != 3 or y.dim() != 3 or x.shape[0] != y.shape[0] or x.shape[2] != y.shape[2]:
        raise UsageError(
            f"soft-DTW needs x (B, N, D) and y (B, M, D); got {tuple(x.shape)} and {tuple(y.shape)}"
        )
    return soft_dtw_from_cost(squared_euclidean_cost(x, y), gamma)


def soft_dtw_divergence(x: torch.Tensor, y: torch.Tensor, gamma: float = 1e-3) -> torch.Tensor:
    r"""Soft-DTW divergence (Blondel et al., 2021): :math:`S(x,y) - \tfrac12 (S(x,x) + S(y,y))`.

    Non-negative and zero when ``x == y``; useful as a *metric* of fit because plain soft-DTW can be
    negative (its entropic term is about :math:`-\gamma \log(\text{number of near-optimal
    alignments})`).
    """
    return soft_dtw(x, y, gamma) - 0.5 * (soft_dtw(x, x, gamma) + soft_dtw(y, y, gamma))

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

Ragged batches (``lengths``): sample ``b`` may use only its first ``n_b <= N`` rows. The forward
recursion is causal (row ``i`` reads rows ``<= i``), so one table over the padded ``N`` rows holds
every sample's value at ``R[n_b, M]``; the backward recursion is seeded at ``(n_b + 1, M + 1)`` per
sample and rows past ``n_b`` get ``E = 0``. This is what lets the multi-waypoint loss evaluate its
5 polylines of different lengths in one call: 5x fewer anti-diagonal iterations (the Python loop
is the cost of this implementation, not the arithmetic). The torch recursions (the reference) are
:mod:`awda_bench.soft_dtw.tables`; ``implementation="triton"`` runs both recursions as one
fused Triton kernel launch each (:mod:`awda_bench.soft_dtw.triton_kernel`), tested against that
reference; the ``numpy`` implementation is this module's own.
"""

from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np
import torch

from awda_bench.errors import UsageError
from awda_bench.soft_dtw.tables import soft_dtw_backward_table, soft_dtw_forward_table


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


IMPLEMENTATIONS: tuple[str, ...] = ("auto", "torch", "numpy", "triton")
"""``torch``: the anti-diagonal loop in torch ops (any device; the reference); ``triton``: the
same recursions fused into one Triton kernel launch per pass (CUDA; on a CPU tensor Triton's
interpreter runs it, for testing only); ``numpy``: the
same recursion on the CPU, in the input's dtype, over a skewed table whose anti-diagonals are
contiguous slices with the batch innermost (no gathers; numpy's per-op overhead is ~4x below
torch's and its float32 ``exp`` is vectorized); ``auto``: :func:`auto_implementation` (numpy for
CPU tensors, triton for CUDA ones, torch on any other device). Triton became ``auto``'s CUDA choice
once it had run on a GPU (2026-12-04, one H200, ``bash scripts/gpu_checks.sh``): the CUDA cases of
``tests/test_soft_dtw.py`` pass, and at the ``paper`` recipe's batch (30 x 5 sets x 50 points,
gamma 0.001) the loss's forward + backward takes 3.45 ms against the torch loop's 65.75 ms (19x),
agreeing to 6.1e-11 in float64 (``reports/gpu-checks/``)."""


def auto_implementation(device: torch.device) -> str:
    """The implementation ``"auto"`` runs on ``device``: ``numpy`` on a CPU, ``triton`` on CUDA
    (Triton compiles for NVIDIA and AMD GPUs, which PyTorch both calls ``cuda``; PyTorch's Linux
    CUDA wheels bring it) where Triton is installed, ``torch`` elsewhere (MPS, XPU, CUDA without
    Triton)."""
    if device.type == "cpu":
        return "numpy"
    if device.type == "cuda" and importlib.util.find_spec("triton") is not None:
        return "triton"
    return "torch"


def _skew(cost: np.ndarray) -> np.ndarray:
    """``(B, N, M)`` -> ``(N + M + 3, N + 2, B)``: cell ``(i, j)`` (1-based) at ``[i + j, i]``,
    zero elsewhere (the zero border of the backward recursion)."""
    b, n, m = cost.shape
    out = np.zeros((n + m + 3, n + 2, b), dtype=cost.dtype)
    i, j = np.meshgrid(np.arange(1, n + 1), np.arange(1, m + 1), indexing="ij")
    out[i + j, i] = cost.transpose(1, 2, 0)
    return out


def _numpy_forward(cost: np.ndarray, gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """``(R, C)`` in skewed layout (:func:`_skew`): ``R[i + j, i, b] = R_{i,j}`` of sample b."""
    _, n, m = cost.shape
    c = _skew(cost)
    r = np.full_like(c, np.inf)
    r[0, 0] = 0.0
    inv = cost.dtype.type(1.0 / gamma)
    g = cost.dtype.type(gamma)
    for d in range(2, n + m + 1):
        lo, hi = max(1, d - m), min(n, d - 1)
        diag = r[d - 1]
        p0, p1, p2 = r[d - 2, lo - 1 : hi], diag[lo - 1 : hi], diag[lo : hi + 1]
        low = np.minimum(np.minimum(p0, p1), p2)
        total = np.exp((low - p0) * inv)
        total += np.exp((low - p1) * inv)
        total += np.exp((low - p2) * inv)
        np.log(total, out=total)
        r[d, lo : hi + 1] = c[d, lo : hi + 1] + low - g * total
    return r, c


def _numpy_backward(
    r: np.ndarray, c: np.ndarray, n: int, m: int, gamma: float, lengths: np.ndarray
) -> np.ndarray:
    """``E (B, N, M)`` seeded at ``(lengths + 1, M + 1)``; rows past a sample's length get 0."""
    b = r.shape[2]
    rows = np.arange(n + 2)
    batch = np.arange(b)
    d_idx, i_idx = np.meshgrid(np.arange(r.shape[0]), rows, indexing="ij")
    past = (i_idx[..., None] > lengths) | ((d_idx - i_idx) == m + 1)[..., None]
    rr = np.where(past, -np.inf, r).astype(r.dtype)  # rows past n_b, and column M + 1
    rr[lengths + 1 + m + 1, lengths + 1, batch] = r[lengths + m, lengths, batch]
    e = np.zeros_like(r)
    e[lengths + 1 + m + 1, lengths + 1, batch] = 1.0
    valid = rows[:, None] <= lengths  # (N + 2, B)
    inv = r.dtype.type(1.0 / gamma)
    with np.errstate(invalid="ignore", over="ignore"):
        for d in range(n + m, 1, -1):
            lo, hi = max(1, d - m), min(n, d - 1)
            r_ij = rr[d, lo : hi + 1]
            down, right = slice(lo + 1, hi + 2), slice(lo, hi + 1)  # (i + 1, j), (i, j + 1)
            value = e[d + 1, down] * np.exp((rr[d + 1, down] - r_ij - c[d + 1, down]) * inv)
            value += e[d + 1, right] * np.exp((rr[d + 1, right] - r_ij - c[d + 1, right]) * inv)
            value += e[d + 2, down] * np.exp((rr[d + 2, down] - r_ij - c[d + 2, down]) * inv)
            e[d, lo : hi + 1] = np.where(valid[lo : hi + 1], value, 0.0)
    i, j = np.meshgrid(np.arange(1, n + 1), np.arange(1, m + 1), indexing="ij")
    return np.ascontiguousarray(e[i + j, i].transpose(2, 0, 1))


class _SoftDtwFunction(torch.autograd.Function):
    """Soft-DTW of a batch of cost matrices, with the analytic (expected-alignment) gradient."""

    @staticmethod
    def forward(
        ctx: Any, cost: torch.Tensor, gamma: float, lengths: torch.Tensor | None, impl: str
    ) -> torch.Tensor:
        cost_d = cost.detach()
        b, n, m = cost.shape
        ctx.gamma, ctx.impl, ctx.shape = gamma, impl, (n, m)
        if impl == "numpy":
            lens = np.full(b, n) if lengths is None else lengths.cpu().numpy()
            r, c = _numpy_forward(cost_d.cpu().numpy(), gamma)
            ctx.numpy_tables = (r, c, lens)
            values = r[lens + m, lens, np.arange(b)]
            return torch.from_numpy(values).to(dtype=cost.dtype, device=cost.device)
        if impl == "triton":
            from awda_bench.soft_dtw import triton_kernel

            r_t = triton_kernel.forward_table(cost_d, gamma)
        else:
            r_t = soft_dtw_forward_table(cost_d, gamma)
        if lengths is None:
            ctx.save_for_backward(cost_d, r_t)
            return r_t[:, n, m].clone()
        ctx.save_for_backward(cost_d, r_t, lengths)
        return r_t[torch.arange(b, device=cost.device), lengths, m].clone()

    @staticmethod
    def backward(ctx: Any, grad_output: torch.Tensor) -> tuple[torch.Tensor, None, None, None]:
        if ctx.impl == "numpy":
            r, c, lens = ctx.numpy_tables
            n, m = ctx.shape
            e_np = _numpy_backward(r, c, n, m, ctx.gamma, lens)
            e = torch.from_numpy(e_np).to(dtype=grad_output.dtype, device=grad_output.device)
        else:
            cost, r_t, *rest = ctx.saved_tensors
            lengths = rest[0] if rest else None
            if ctx.impl == "triton":
                from awda_bench.soft_dtw import triton_kernel

                e = triton_kernel.backward_table(cost, r_t, ctx.gamma, lengths)
            else:
                e = soft_dtw_backward_table(cost, r_t, ctx.gamma, lengths)
        return grad_output.view(-1, 1, 1) * e, None, None, None


def _check_lengths(
    lengths: torch.Tensor | None, b: int, n: int, device: torch.device
) -> torch.Tensor | None:
    if lengths is None:
        return None
    lengths = torch.as_tensor(lengths, device=device).long()
    if lengths.shape != (b,) or bool(((lengths < 1) | (lengths > n)).any()):
        raise UsageError(f"soft-DTW lengths must be ({b},) ints in 1..{n}; got {lengths.tolist()}")
    return lengths


class _SoftDtwSqEuclideanNumpy(torch.autograd.Function):
    """Soft-DTW between sequences with the squared-Euclidean cost, all in numpy on the CPU.

    The cost and its chain rule are fused in, so no ``(B, N, M, D)`` torch tensor (and no autograd
    graph for it) exists: with ``E = dR / dcost``,
    ``dR/dx_i = 2 (x_i sum_j E_ij - sum_j E_ij y_j)`` and ``dR/dy_j = 2 (y_j sum_i E_ij - sum_i
    E_ij x_i)``.
    """

    @staticmethod
    def forward(
        ctx: Any, x: torch.Tensor, y: torch.Tensor, gamma: float, lengths: torch.Tensor | None
    ) -> torch.Tensor:
        xn, yn = x.detach().cpu().numpy(), y.detach().cpu().numpy()
        b, n, m = xn.shape[0], xn.shape[1], yn.shape[1]
        # |x|^2 + |y|^2 - 2 x.y (a matmul; clamped: rounding may dip below 0 near identical points)
        cost = (xn * xn).sum(-1)[:, :, None] + (yn * yn).sum(-1)[:, None, :]
        cost -= 2.0 * (xn @ yn.transpose(0, 2, 1))
        np.maximum(cost, 0.0, out=cost)
        lens = np.full(b, n) if lengths is None else lengths.cpu().numpy()
        r, c = _numpy_forward(cost, gamma)
        ctx.tables = (xn, yn, r, c, lens, gamma)
        return torch.from_numpy(r[lens + m, lens, np.arange(b)].copy()).to(x.device)

    @staticmethod
    def backward(
        ctx: Any, grad_output: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, None, None]:
        xn, yn, r, c, lens, gamma = ctx.tables
        n, m = xn.shape[1], yn.shape[1]
        e = _numpy_backward(r, c, n, m, gamma, lens)
        e *= grad_output.detach().cpu().numpy().astype(e.dtype)[:, None, None]
        grad_x = 2.0 * (xn * e.sum(axis=2)[..., None] - e @ yn)
        grad_y = 2.0 * (yn * e.sum(axis=1)[..., None] - e.transpose(0, 2, 1) @ xn)
        device = grad_output.device
        return torch.from_numpy(grad_x).to(device), torch.from_numpy(grad_y).to(device), None, None


def soft_dtw_from_cost(
    cost: torch.Tensor,
    gamma: float,
    lengths: torch.Tensor | None = None,
    implementation: str = "auto",
) -> torch.Tensor:
    """Soft-DTW values ``(B,)`` of cost matrices ``(B, N, M)``; differentiable in ``cost``.

    ``lengths (B,)`` int: sample ``b`` is the soft-DTW of ``cost[b, :lengths[b]]`` (its other
    rows are ignored and get zero gradient); default: every row. ``implementation``: one of
    :data:`IMPLEMENTATIONS` (same values and gradients). Note: the first-order gradient is
    analytic; a second derivative (double backward) is not provided.
    """
    if implementation not in IMPLEMENTATIONS:
        raise UsageError(
            f"unknown soft-DTW implementation {implementation!r}; choose one of: "
            f"{', '.join(IMPLEMENTATIONS)}"
        )
    if cost.dim() != 3:
        raise UsageError(f"soft-DTW needs a (B, N, M) cost tensor, got shape {tuple(cost.shape)}")
    if not gamma > 0:
        raise UsageError(f"soft-DTW gamma must be > 0, got {gamma}")
    lengths = _check_lengths(lengths, cost.shape[0], cost.shape[1], cost.device)
    impl = implementation
    if impl == "auto":
        impl = auto_implementation(cost.device)
    out: torch.Tensor = _SoftDtwFunction.apply(cost, float(gamma), lengths, impl)
    return out


def soft_dtw(
    x: torch.Tensor,
    y: torch.Tensor,
    gamma: float = 1e-3,
    lengths: torch.Tensor | None = None,
    implementation: str = "auto",
) -> torch.Tensor:
    """Soft-DTW with squared-Euclidean cost between sequences ``x (B, N, D)`` and ``y (B, M, D)``.

    Returns ``(B,)``. Differentiable in both sequences. ``lengths (B,)``: use only the first
    ``lengths[b]`` points of ``x[b]`` (ragged batches padded to ``N``).
    """
    if x.dim() != 3 or y.dim() != 3 or x.shape[0] != y.shape[0] or x.shape[2] != y.shape[2]:
        raise UsageError(
            f"soft-DTW needs x (B, N, D) and y (B, M, D); got {tuple(x.shape)} and {tuple(y.shape)}"
        )
    if implementation == "auto":
        implementation = auto_implementation(x.device)
    if implementation == "numpy":
        if x.dtype != y.dtype:
            raise UsageError(f"soft-DTW needs x and y of one dtype, got {x.dtype} and {y.dtype}")
        if not gamma > 0:
            raise UsageError(f"soft-DTW gamma must be > 0, got {gamma}")
        lens = _check_lengths(lengths, x.shape[0], x.shape[1], x.device)
        out: torch.Tensor = _SoftDtwSqEuclideanNumpy.apply(x, y, float(gamma), lens)
        return out
    return soft_dtw_from_cost(squared_euclidean_cost(x, y), gamma, lengths, implementation)


def soft_dtw_divergence(x: torch.Tensor, y: torch.Tensor, gamma: float = 1e-3) -> torch.Tensor:
    r"""Soft-DTW divergence (Blondel et al., 2021): :math:`S(x,y) - \tfrac12 (S(x,x) + S(y,y))`.

    Non-negative and zero when ``x == y``; useful as a *metric* of fit because plain soft-DTW can be
    negative (its entropic term is about :math:`-\gamma \log(\text{number of near-optimal
    alignments})`).
    """
    return soft_dtw(x, y, gamma) - 0.5 * (soft_dtw(x, x, gamma) + soft_dtw(y, y, gamma))

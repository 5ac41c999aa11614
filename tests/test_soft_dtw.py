"""Soft-DTW against a brute-force DP, plain DTW, gradcheck and small-gamma stability."""

from __future__ import annotations

import math

import pytest
import torch

from awda_bench.errors import UsageError
from awda_bench.soft_dtw.core import soft_dtw, soft_dtw_divergence, squared_euclidean_cost


def _reference(cost: list[list[float]], gamma: float) -> float:
    """Textbook recursion, one cell at a time in Python floats (gamma = 0: plain DTW)."""
    n, m = len(cost), len(cost[0])
    r = [[math.inf] * (m + 1) for _ in range(n + 1)]
    r[0][0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            prev = (r[i - 1][j - 1], r[i - 1][j], r[i][j - 1])
            low = min(prev)
            soft = (
                low
                if gamma == 0
                else low - gamma * math.log(sum(math.exp(-(v - low) / gamma) for v in prev))
            )
            r[i][j] = cost[i - 1][j - 1] + soft
    return r[n][m]


@pytest.mark.parametrize("gamma", [1.0, 1e-3])
def test_matches_brute_force_reference(gamma: float) -> None:
    g = torch.Generator().manual_seed(0)
    x = torch.randn(5, 9, 3, generator=g, dtype=torch.float64)
    y = torch.randn(5, 7, 3, generator=g, dtype=torch.float64)
    values = soft_dtw(x, y, gamma)
    cost = squared_euclidean_cost(x, y)
    expected = torch.tensor(
        [_reference(cost[b].tolist(), gamma) for b in range(5)], dtype=torch.float64
    )
    assert torch.max(torch.abs(values - expected)) <= 1e-5


def test_tends_to_plain_dtw_as_gamma_goes_to_zero() -> None:
    g = torch.Generator().manual_seed(1)
    x = torch.randn(4, 8, 2, generator=g, dtype=torch.float64)
    y = torch.randn(4, 11, 2, generator=g, dtype=torch.float64)
    cost = squared_euclidean_cost(x, y)
    dtw = torch.tensor([_reference(cost[b].tolist(), 0.0) for b in range(4)], dtype=torch.float64)
    gaps = [
        torch.max(torch.abs(soft_dtw(x, y, gamma) - dtw)).item() for gamma in (1e-1, 1e-2, 1e-4)
    ]
    # soft-DTW <= DTW and DTW - soft-DTW <= gamma * log(3) * (n + m): the gap shrinks with gamma.
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[2] <= 1e-4 * math.log(3) * (8 + 11)


def test_identical_sequences_cost_nothing_with_hard_dtw_limit() -> None:
    x = torch.rand(2, 6, 3, dtype=torch.float64)
    assert torch.allclose(soft_dtw(x, x, 1e-6), torch.zeros(2, dtype=torch.float64), atol=1e-4)
    assert torch.all(soft_dtw_divergence(x, x + 0.1, 1e-3) > 0)


@pytest.mark.parametrize("gamma", [1.0, 0.1, 1e-3])
def test_gradients_pass_gradcheck(gamma: float) -> None:
    g = torch.Generator().manual_seed(2)
    x = torch.randn(2, 5, 3, generator=g, dtype=torch.float64, requires_grad=True)
    y = torch.randn(2, 4, 3, generator=g, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b: soft_dtw(a, b, gamma), (x, y))


def test_gamma_0001_on_60_by_50_is_finite_with_finite_gradients() -> None:
    g = torch.Generator().manual_seed(3)
    x = torch.rand(3, 60, 4, generator=g, requires_grad=True)
    y = torch.rand(3, 50, 4, generator=g, requires_grad=True)
    value = soft_dtw(x, y, 1e-3)
    value.sum().backward()
    assert torch.isfinite(value).all()
    assert x.grad is not None and y.grad is not None
    assert torch.isfinite(x.grad).all() and torch.isfinite(y.grad).all()
    assert x.grad.abs().sum() > 0


def test_bad_shapes_and_gamma_are_refused() -> None:
    with pytest.raises(UsageError, match="gamma"):
        soft_dtw(torch.rand(1, 3, 2), torch.rand(1, 3, 2), 0.0)
    with pytest.raises(UsageError, match="soft-DTW needs"):
        soft_dtw(torch.rand(1, 3, 2), torch.rand(1, 3, 3))


# ------------------------------------------------------- ragged; numpy and fused triton paths
# The triton kernels run in Triton's interpreter on a CPU tensor, and compiled on a GPU if present.
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.mark.parametrize(
    ("impl", "device"),
    [("numpy", "cpu")] + [("triton", device) for device in DEVICES],
)
@pytest.mark.parametrize("gamma", [1.0, 1e-3])
def test_fast_paths_match_torch_reference_with_ragged_lengths(
    gamma: float, impl: str, device: str
) -> None:
    g = torch.Generator().manual_seed(4)
    x = torch.rand(6, 13, 4, generator=g, dtype=torch.float64).to(device).requires_grad_(True)
    y = torch.rand(6, 9, 4, generator=g, dtype=torch.float64).to(device).requires_grad_(True)
    lengths = torch.tensor([13, 1, 5, 7, 13, 2], device=device)
    weights = torch.arange(1, 7, dtype=torch.float64, device=device)
    results = []
    for name in ("torch", impl):
        x.grad = y.grad = None
        values = soft_dtw(x, y, gamma, lengths=lengths, implementation=name)
        (values * weights).sum().backward()
        assert x.grad is not None and y.grad is not None
        results.append((values.detach(), x.grad.clone(), y.grad.clone()))
    for ours, reference in zip(*results, strict=True):
        assert torch.max(torch.abs(ours - reference)) <= 1e-6
    # each ragged row is the soft-DTW of the truncated sequence, and padding gets no gradient
    for i, n in enumerate(lengths.tolist()):
        alone = soft_dtw(x[i : i + 1, :n], y[i : i + 1], gamma, implementation="torch")
        assert alone.device.type == device
        assert abs(float(alone.detach()) - float(results[0][0][i])) <= 1e-9
        assert torch.all(results[1][1][i, n:] == 0)


def test_auto_picks_numpy_on_cpu_triton_on_cuda_torch_elsewhere(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import importlib.util

    from awda_bench.soft_dtw.core import auto_implementation

    assert auto_implementation(torch.device("cpu")) == "numpy"
    assert auto_implementation(torch.device("cuda")) == "triton"  # torch's wheels bring triton
    assert auto_implementation(torch.device("mps")) == "torch"
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name == "triton" else real_find_spec(name, *a),
    )
    assert auto_implementation(torch.device("cuda")) == "torch"  # CUDA without Triton


def test_bad_lengths_and_implementation_are_refused() -> None:
    x, y = torch.rand(2, 5, 3), torch.rand(2, 4, 3)
    with pytest.raises(UsageError, match="lengths"):
        soft_dtw(x, y, lengths=torch.tensor([0, 5]))
    with pytest.raises(UsageError, match="implementation"):
        soft_dtw(x, y, implementation="cuda-kernel")


@pytest.mark.parametrize("gamma", [1.0, 1e-3])
def test_multi_waypoint_loss_in_one_call_equals_one_call_per_set(gamma: float) -> None:
    from awda_bench.models.waypoint_loss import multi_waypoint_sdtw_loss

    g = torch.Generator().manual_seed(5)
    waypoints = (0.3 * torch.rand(4, 15, 4, generator=g, dtype=torch.float64)).requires_grad_()
    trajectory = 0.3 * torch.rand(4, 50, 4, generator=g, dtype=torch.float64)
    trajectory[..., 3] = (trajectory[..., 3] > 0.15).double()
    out = []
    for one_call, impl in ((True, "auto"), (False, "auto"), (False, "torch")):
        waypoints.grad = None
        loss, per_set = multi_waypoint_sdtw_loss(
            waypoints,
            trajectory,
            num_sets=5,
            points_per_segment=12,
            gamma=gamma,
            attribute_scale=0.2,
            one_call=one_call,
            implementation=impl,
        )
        loss.backward()
        assert waypoints.grad is not None
        out.append((per_set.detach(), waypoints.grad.clone()))
    for per_set, grad in out[:2]:
        assert torch.max(torch.abs(per_set - out[2][0])) <= 1e-6
        assert torch.max(torch.abs(grad - out[2][1])) <= 1e-6


def test_bench_soft_dtw_times_native_implementations_side_by_side(
    capsys: pytest.CaptureFixture[str],
) -> None:
    import argparse

    from awda_bench.benchmarks.soft_dtw import add_soft_dtw_args, run_soft_dtw_bench

    parser = argparse.ArgumentParser()
    add_soft_dtw_args(parser)
    args = ["--recipe", "small", "--repeats", "1", "--device", "cpu"]  # also on a GPU machine
    assert run_soft_dtw_bench(parser.parse_args(args)) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line for line in lines if "fwd+bwd" in line}
    assert set(rows) == {"numpy", "torch"}  # the CPU's native implementations, nothing else
    for row in rows.values():
        assert float(row.rsplit(":", 1)[1]) <= 1e-6  # agreement with the torch reference
    assert any(line.startswith("  speed-up of") for line in lines)
    with pytest.raises(UsageError, match="implementation"):
        run_soft_dtw_bench(parser.parse_args(["--implementations", "cuda-kernel"]))
    # small's demo-pointer head needs its training camera: a random-image step is refused
    with pytest.raises(UsageError, match="train --recipe"):
        run_soft_dtw_bench(parser.parse_args(["--recipe", "small", "--step"]))

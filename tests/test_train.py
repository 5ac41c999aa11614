"""Training loop: snapshots every N steps, resume continues the uninterrupted loss curve exactly."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch

from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig, TrainConfig, TrunkConfig
from awda_bench.models.snapshot import list_snapshots, load_snapshot
from awda_bench.models.synthetic import SyntheticWaypointDataset
from awda_bench.training.loop import batch_indices, learning_rate_at, resolve_device, train

torch.set_num_threads(1)


def _model(seed: int) -> AwdaNet:
    torch.manual_seed(seed)
    trunk = TrunkConfig(
        image_height_px=64, image_width_px=64, demo_frames=1, backbone_weights="none", dropout=0.1
    )
    return AwdaNet(AwdaConfig(trunk=trunk))


def test_batch_order_covers_each_epoch_once_and_depends_only_on_seed_and_step() -> None:
    epoch = [i for step in range(3) for i in batch_indices(step, 2, 6, seed=4)]
    assert sorted(epoch) == list(range(6))
    assert batch_indices(5, 2, 6, seed=4) == batch_indices(5, 2, 6, seed=4)
    assert [batch_indices(s, 2, 6, seed=4) for s in range(3)] != [
        batch_indices(s, 2, 6, seed=5) for s in range(3)
    ]


def test_resume_continues_the_same_loss_curve(tmp_path: Path) -> None:
    data = SyntheticWaypointDataset(6, height_px=64, width_px=64, demo_frames=1)
    cfg = TrainConfig(batch_size=2, max_steps=4, snapshot_every_steps=2, seed=3, device="cpu")
    full = train(_model(0), data, cfg, tmp_path / "full")
    assert [p.name for p in list_snapshots(tmp_path / "full")] == [
        "snapshot-000000002.pt",
        "snapshot-000000004.pt",
    ]

    first = train(
        _model(0), data, TrainConfig(**{**cfg.__dict__, "max_steps": 2}), tmp_path / "split"
    )
    torch.manual_seed(123)  # disturb the global RNG: the snapshot's RNG state must win
    resumed = train(
        _model(99), data, cfg, tmp_path / "split"
    )  # different init: weights come from the snapshot
    assert resumed.start_step == 2 and resumed.resumed_from is not None
    assert first.losses + resumed.losses == full.losses  # bit-identical floats
    assert len(set(full.losses)) == 4  # dropout active and weights changing: a real curve


def test_device_auto_picks_what_exists() -> None:
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert resolve_device("auto").type == expected


def test_ema_snapshots_hold_the_average_and_resume_bit_identically(tmp_path: Path) -> None:
    data = SyntheticWaypointDataset(6, height_px=64, width_px=64, demo_frames=1)
    cfg = TrainConfig(
        batch_size=2, max_steps=4, snapshot_every_steps=2, seed=3, device="cpu", ema_decay=0.5
    )
    # the average by hand: the first step's weights, then ema = 0.5 ema + 0.5 w after each step
    plain = TrainConfig(**{**cfg.__dict__, "ema_decay": 0.0, "snapshot_every_steps": 1})
    train(_model(0), data, plain, tmp_path / "plain")
    steps = [load_snapshot(p).model_state for p in list_snapshots(tmp_path / "plain")]
    expected = {k: v.clone() for k, v in steps[0].items()}
    for state in steps[1:]:
        for k, v in state.items():
            if v.is_floating_point():
                expected[k] = 0.5 * expected[k] + 0.5 * v
    full = train(_model(0), data, cfg, tmp_path / "full")
    last = load_snapshot(list_snapshots(tmp_path / "full")[-1])
    assert last.training_state is not None
    moved = 0
    for k, v in last.model_state.items():
        if v.is_floating_point():
            torch.testing.assert_close(v, expected[k], rtol=1e-5, atol=1e-6)
            torch.testing.assert_close(last.training_state[k], steps[-1][k], rtol=0, atol=0)
            moved += int(not torch.equal(v, steps[-1][k]))
    assert moved > 0  # the average is not the last weights

    first = train(
        _model(0), data, TrainConfig(**{**cfg.__dict__, "max_steps": 2}), tmp_path / "split"
    )
    resumed = train(_model(99), data, cfg, tmp_path / "split")
    assert first.losses + resumed.losses == full.losses
    again = load_snapshot(list_snapshots(tmp_path / "split")[-1])
    assert again.training_state is not None
    for k, v in last.model_state.items():
        assert torch.equal(v, again.model_state[k]) and torch.equal(
            last.training_state[k], again.training_state[k]
        )
    with pytest.raises(CorruptFileError, match="holds a moving average"):
        train(
            _model(0), data, TrainConfig(**{**plain.__dict__, "max_steps": 6}), tmp_path / "split"
        )
    with pytest.raises(CorruptFileError, match="holds raw weights"):
        train(_model(0), data, TrainConfig(**{**cfg.__dict__, "max_steps": 6}), tmp_path / "plain")


def test_cosine_schedule_sets_each_steps_step_size_and_resumes_on_the_same_curve(
    tmp_path: Path,
) -> None:
    data = SyntheticWaypointDataset(6, height_px=64, width_px=64, demo_frames=1)
    cfg = TrainConfig(
        batch_size=2,
        max_steps=4,
        snapshot_every_steps=2,
        seed=3,
        device="cpu",
        lr_schedule="cosine",
    )
    seen: list[float] = []
    full = train(_model(0), data, cfg, tmp_path / "full", on_step=lambda s, i: seen.append(i["lr"]))
    # half a cosine from 5e-4 at step 0 down towards 0 at max_steps
    assert seen == pytest.approx([5e-4, 5e-4 * (1 + 2**-0.5) / 2, 2.5e-4, 5e-4 * (1 - 2**-0.5) / 2])
    assert [learning_rate_at(cfg, s) for s in range(4)] == seen
    constant = TrainConfig(**{**cfg.__dict__, "lr_schedule": "constant"})
    assert learning_rate_at(constant, 3) == 5e-4
    assert train(_model(0), data, constant, tmp_path / "constant").losses[2:] != full.losses[2:]

    # an interrupted run (its step-2 snapshot) resumed to max_steps: the same curve, bit for bit
    (tmp_path / "split").mkdir()
    shutil.copy(list_snapshots(tmp_path / "full")[0], tmp_path / "split")
    resumed = train(_model(99), data, cfg, tmp_path / "split")
    assert resumed.start_step == 2 and resumed.losses == full.losses[2:]
    with pytest.raises(UsageError, match="lr_schedule"):
        TrainConfig(lr_schedule="linear")


def test_bf16_precision_runs_the_forward_in_bfloat16_and_keeps_weights_and_losses_float32(
    tmp_path: Path,
) -> None:
    data = SyntheticWaypointDataset(6, height_px=64, width_px=64, demo_frames=1)
    cfg = TrainConfig(batch_size=2, max_steps=3, snapshot_every_steps=3, seed=3, device="cpu")
    low = TrainConfig(**{**cfg.__dict__, "precision": "bf16"})
    # what the forward pass ran in: the waypoints the pointer emits before the float32 cast
    model = _model(0)
    seen: list[torch.dtype] = []
    for module in model.modules():
        if isinstance(module, torch.nn.Linear):
            module.register_forward_hook(lambda _m, _i, out: seen.append(out.dtype))
    low_run = train(model, data, low, tmp_path / "bf16")
    assert seen and set(seen) == {torch.bfloat16}
    full_run = train(_model(0), data, cfg, tmp_path / "fp32")
    assert all(torch.isfinite(torch.tensor(low_run.losses)))
    # the same first step to bfloat16's precision (the curves then drift apart), not bit-identical
    assert low_run.losses[0] == pytest.approx(full_run.losses[0], rel=0.02)
    assert low_run.losses != full_run.losses
    snap = load_snapshot(list_snapshots(tmp_path / "bf16")[-1])
    assert {v.dtype for v in snap.model_state.values() if v.is_floating_point()} == {torch.float32}
    # resuming a bf16 run continues its own curve bit for bit
    first = train(_model(0), data, TrainConfig(**{**low.__dict__, "max_steps": 2}), tmp_path / "s")
    resumed = train(_model(99), data, low, tmp_path / "s")
    assert first.losses + resumed.losses == low_run.losses
    with pytest.raises(UsageError, match="precision"):
        TrainConfig(precision="fp16")


def test_bf16_precision_trains_tosvi_with_a_bfloat16_forward_and_float32_losses(
    tmp_path: Path,
) -> None:
    from awda_bench.models.config import TosviConfig
    from awda_bench.models.synthetic import SyntheticActionDataset
    from awda_bench.models.tosvi_net import TosviNet

    def tosvi(seed: int) -> TosviNet:
        torch.manual_seed(seed)
        trunk = TrunkConfig(
            image_height_px=64, image_width_px=64, demo_frames=1, backbone_weights="none"
        )
        return TosviNet(TosviConfig(trunk=trunk, frame_stack=2))

    data = SyntheticActionDataset(4, height_px=64, width_px=64, demo_frames=1, frame_stack=2)
    cfg = TrainConfig(batch_size=2, max_steps=2, snapshot_every_steps=2, seed=1, device="cpu")
    model = tosvi(0)
    seen: list[torch.dtype] = []
    for module in model.modules():
        if isinstance(module, torch.nn.Linear):
            module.register_forward_hook(lambda _m, _i, out: seen.append(out.dtype))
    low = train(model, data, TrainConfig(**{**cfg.__dict__, "precision": "bf16"}), tmp_path / "a")
    assert seen and set(seen) == {torch.bfloat16}
    full = train(tosvi(0), data, cfg, tmp_path / "b")
    assert all(torch.isfinite(torch.tensor(low.losses)))
    assert low.losses[0] == pytest.approx(full.losses[0], rel=0.02) and low.losses != full.losses

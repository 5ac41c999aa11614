"""Training loop: snapshots every N steps, resume continues the uninterrupted loss curve exactly."""

from __future__ import annotations

from pathlib import Path

import torch

from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig, TrainConfig, TrunkConfig
from awda_bench.models.snapshot import list_snapshots
from awda_bench.models.synthetic import SyntheticWaypointDataset
from awda_bench.training.loop import batch_indices, resolve_device, train

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

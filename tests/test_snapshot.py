"""Snapshot files: bit-exact round trip, order by step, refusal of other archs and corrupt files."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
import torch
from torch.utils.data import default_collate

from awda_bench.errors import CorruptFileError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig, TosviConfig, TrunkConfig
from awda_bench.models.snapshot import (
    list_snapshots,
    load_snapshot,
    restore,
    save_snapshot,
    snapshot_path,
)
from awda_bench.models.synthetic import SyntheticWaypointDataset
from awda_bench.models.tosvi_net import TosviNet

torch.set_num_threads(1)
TRUNK = TrunkConfig(image_height_px=64, image_width_px=64, demo_frames=1, backbone_weights="none")


def _trained_awda() -> tuple[AwdaNet, torch.optim.Optimizer, dict[str, torch.Tensor]]:
    torch.manual_seed(0)
    model = AwdaNet(AwdaConfig(trunk=TRUNK))
    optimizer = torch.optim.Adam(model.parameters(), lr=5e-4)
    data = SyntheticWaypointDataset(2, height_px=64, width_px=64, demo_frames=1)
    batch = default_collate([data[i] for i in range(2)])
    loss, _ = model.compute_loss(batch)
    loss.backward()
    optimizer.step()
    return model, optimizer, batch


def test_round_trip_is_bit_exact(tmp_path: Path) -> None:
    model, optimizer, batch = _trained_awda()
    path = save_snapshot(snapshot_path(tmp_path, 7), model, step=7, optimizer=optimizer)
    snap = load_snapshot(path)
    assert snap.arch == "awda" and snap.step == 7 and snap.config == model.config
    assert snap.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    for key, value in model.state_dict().items():
        assert torch.equal(snap.model_state[key], value), key
    rebuilt = snap.build_model()
    model.eval()
    with torch.no_grad():
        expected = model(batch["demo"], batch["first_frame"], batch["head"])
        got = rebuilt(batch["demo"], batch["first_frame"], batch["head"])
    assert torch.equal(expected, got)
    fresh = AwdaNet(AwdaConfig(trunk=TRUNK))
    fresh_opt = torch.optim.Adam(fresh.parameters(), lr=5e-4)
    restore(fresh, snap, fresh_opt)
    for (_, a), (_, b) in zip(
        optimizer.state_dict()["state"].items(),
        fresh_opt.state_dict()["state"].items(),
        strict=True,
    ):
        assert torch.equal(a["exp_avg"], b["exp_avg"]) and torch.equal(
            a["exp_avg_sq"], b["exp_avg_sq"]
        )


def test_snapshots_listed_by_step_and_other_files_ignored(tmp_path: Path) -> None:
    model = AwdaNet(AwdaConfig(trunk=TRUNK))
    for step in (20000, 500, 10000):
        save_snapshot(snapshot_path(tmp_path, step), model, step=step)
    (tmp_path / "notes.txt").write_text("not a snapshot")
    assert [p.name for p in list_snapshots(tmp_path)] == [
        "snapshot-000000500.pt",
        "snapshot-000010000.pt",
        "snapshot-000020000.pt",
    ]
    assert list_snapshots(tmp_path / "missing") == []


def test_other_architecture_is_refused(tmp_path: Path) -> None:
    tosvi = TosviNet(TosviConfig(trunk=TRUNK, frame_stack=2))
    path = save_snapshot(tmp_path / "snapshot-000000001.pt", tosvi, step=1)
    with pytest.raises(CorruptFileError, match="holds a 'tosvi' model, not 'awda'") as info:
        restore(AwdaNet(AwdaConfig(trunk=TRUNK)), load_snapshot(path))
    assert "\n" not in str(info.value)
    other_size = AwdaNet(
        AwdaConfig(
            trunk=TrunkConfig(
                image_height_px=96, image_width_px=64, demo_frames=1, backbone_weights="none"
            )
        )
    )
    awda_path = save_snapshot(
        tmp_path / "snapshot-000000002.pt", AwdaNet(AwdaConfig(trunk=TRUNK)), step=2
    )
    with pytest.raises(CorruptFileError, match="trunk.image_height_px"):
        restore(other_size, load_snapshot(awda_path))


@pytest.mark.parametrize("damage", ["garbage", "truncated", "foreign"])
def test_corrupt_file_raises_one_line_corrupt_file_error(tmp_path: Path, damage: str) -> None:
    path = tmp_path / "snapshot-000000001.pt"
    if damage == "garbage":
        path.write_bytes(b"\x00not a torch file" * 10)
    elif damage == "truncated":
        save_snapshot(path, AwdaNet(AwdaConfig(trunk=TRUNK)), step=1)
        path.write_bytes(path.read_bytes()[:50_000])
    else:
        torch.save({"weights": torch.zeros(3)}, path)
    with pytest.raises(CorruptFileError) as info:
        load_snapshot(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)

"""The learned ``awda`` method through the harness: snapshots from a (tiny) training run are
evaluated one by one, each with its demo video, first frame, predicted waypoints and primitives."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from awda_bench.models.architectures import build_model
from awda_bench.models.config import AwdaConfig, TrainConfig, TrunkConfig
from awda_bench.models.synthetic import SyntheticWaypointDataset
from awda_bench.training.loop import train

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("ckpt")
    trunk = TrunkConfig(
        image_height_px=64, image_width_px=80, demo_frames=2, backbone_weights="none"
    )
    config = AwdaConfig(trunk=trunk)
    data = SyntheticWaypointDataset(4, height_px=64, width_px=80, demo_frames=2)
    train(
        build_model(config),
        data,
        TrainConfig(batch_size=2, max_steps=2, snapshot_every_steps=1, device="cpu"),
        directory,
    )
    return directory


def test_run_evaluates_every_snapshot_with_predicted_waypoints(
    checkpoints: Path, tmp_path: Path
) -> None:
    out = tmp_path / "runs"
    command = [
        sys.executable, "-m", "awda_bench", "run", "--suite", "pick_place", "--method", "awda",
        "--checkpoints", str(checkpoints), "--snapshots", "2", "--episodes", "1", "--task", "14",
        "--workers", "1", "--out", str(out),
    ]  # fmt: skip
    result = subprocess.run(command, capture_output=True, text=True, timeout=900, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    with sqlite3.connect(out / "results.sqlite") as db:
        rows = db.execute(
            "SELECT snapshot, status, waypoints FROM episodes WHERE method = 'awda'"
        ).fetchall()
    assert len(rows) == 2 and len({r[0] for r in rows}) == 2  # one episode per snapshot
    assert all(status == "ok" for _, status, _ in rows)
    for _, _, waypoints in rows:
        points = json.loads(waypoints)
        assert len(points) == 5 and all(len(p) == 4 for p in points)
        assert all(p[3] in (0.0, 1.0) for p in points)  # attribute thresholded into a flag


def test_a_tosvi_snapshot_is_refused_in_one_line(tmp_path: Path) -> None:
    from awda_bench.errors import CorruptFileError
    from awda_bench.models.config import TosviConfig
    from awda_bench.models.snapshot import save_snapshot
    from awda_bench.policies.awda_policy import AwdaPolicy

    trunk = TrunkConfig(
        image_height_px=64, image_width_px=80, demo_frames=2, backbone_weights="none"
    )
    model = build_model(TosviConfig(trunk=trunk))
    path = tmp_path / "snapshot-000000001.pt"
    save_snapshot(path, model, step=1)
    with pytest.raises(CorruptFileError, match="not 'awda'"):
        AwdaPolicy(path)

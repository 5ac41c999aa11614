"""``study offline``: a trained snapshot's waypoints against the ground truth on collected pairs,
per task, and a one-line refusal of what it cannot read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from training_helpers import FROZEN_LITE0, TINY_NET, recipe_toml

from awda_bench.cli import main
from awda_bench.data.datasets import AwdaPairDataset, CollectedData
from awda_bench.models.agent_cameras import camera_fields
from awda_bench.models.config import AwdaConfig, TrunkConfig
from awda_bench.models.snapshot import list_snapshots
from awda_bench.training.offline_waypoints import (
    axis_bias_cm,
    on_model_cameras,
    other_task_partners,
    per_task_table,
)

POINTER = {**TINY_NET, **FROZEN_LITE0, "head": "demo-pointer", "identification_weight": 1.0}
HEIGHTS = {**POINTER, "demo_heights": True}


@pytest.mark.slow
def test_study_offline_measures_every_pair_per_task(
    tiny_copy: Path, tmp_path: Path, capsys
) -> None:
    recipe = tmp_path / "pointer.toml"
    recipe.write_text(recipe_toml("tiny-pointer", HEIGHTS))
    out = tmp_path / "ckpt"
    argv = ["train", "--method", "awda", "--data", str(tiny_copy), "--recipe", str(recipe)]
    assert main([*argv, "--steps", "2", "--no-progress", "--threads", "1", "--out", str(out)]) == 0
    snapshot = list_snapshots(out)[-1]
    capsys.readouterr()
    csv = tmp_path / "study" / "offline.csv"
    assert main(["study", "offline", str(snapshot), str(tiny_copy), "--csv", str(csv)]) == 0
    lines = csv.read_text().splitlines()
    header = lines[0].split(",")
    assert header[:4] == ["task", "pairs", "wp_err_cm", "end_err_cm"] and "object_near" in header
    effect = header.index("demo_effect_cm")
    data = CollectedData(tiny_copy)
    pairs = AwdaPairDataset(data, include_synthesized=False, image_size=(64, 80))
    tasks = {ref.task for ref, _, _ in pairs.pairs}
    rows = {line.split(",")[0]: line.split(",") for line in lines[1:]}
    assert len(rows) == len(tasks) + 1 and rows["all"][1] == str(len(pairs))
    assert all(float(row[2]) > 0.0 for row in rows.values())  # cm, every task and over all
    # the demo-swap measure needs another task's demo: none in a one-task collection
    assert len(tasks) > 1 or rows["all"][effect] == ""
    copy, shift = header.index("demo_copy_cm"), header.index("true_shift_cm")
    assert float(rows["all"][copy]) > 0.0 and float(rows["all"][shift]) > 0.0
    assert all(f"bias_{axis}_cm" in header for axis in "xyz")
    height = header.index("hand_height_cm")  # demo_heights: the hand heights' error per task
    assert all(float(row[height]) > 0.0 for name, row in rows.items() if name != "all")
    assert "wp_err_cm" in capsys.readouterr().out
    # only these tasks
    one = min(tasks)
    argv = ["study", "offline", str(snapshot), str(tiny_copy), "--task", str(one)]
    assert main([*argv, "--csv", str(csv)]) == 0
    only = [line.split(",") for line in csv.read_text().splitlines()[1:]]
    assert len(only) == 2 and only[0][0] in rows and only[1][0] == "all"
    assert only[0] == rows[only[0][0]] or only[0][1] == only[1][1]  # that task's pairs alone


def test_study_offline_refuses_what_it_cannot_read(tmp_path: Path, capsys) -> None:
    missing = tmp_path / "snapshot-000000001.pt"
    missing.write_bytes(b"not a snapshot")
    assert main(["study", "offline", str(missing), str(tmp_path)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")


def test_demo_swap_partners_are_of_another_task() -> None:
    tasks = [3, 3, 3, 5, 5, 8]
    partners = other_task_partners(tasks)
    assert list(partners) == [3, 3, 3, 5, 5, 0]  # the nearest of another task after each, cyclic
    assert all(tasks[j] != t for t, j in zip(tasks, partners, strict=True))
    assert list(other_task_partners([4, 4])) == [-1, -1]  # one task: no partner


def test_axis_bias_is_the_signed_mean_offset_per_world_axis() -> None:
    true = np.zeros((5, 3))
    high = {"predicted": true + [0.0, 0.0, 0.08], "true": true}  # every waypoint 8 cm up
    left = {"predicted": true + [-0.02, 0.0, 0.0], "true": true}
    np.testing.assert_allclose(axis_bias_cm([high]), [0.0, 0.0, 8.0])
    np.testing.assert_allclose(axis_bias_cm([high, left]), [-1.0, 0.0, 4.0])
    one = {"predicted": true.copy(), "true": true.copy()}
    one["predicted"][2] = [0.0, 0.05, -0.05]  # one of five waypoints off
    np.testing.assert_allclose(axis_bias_cm([one]), [0.0, 1.0, -1.0])


def test_per_task_table_prints_each_tasks_axis_bias() -> None:
    def row(task: int, dz: float) -> dict:
        true = np.zeros((5, 3))
        return {
            "task": task, "task_name": f"t{task}", "wp_err_cm": abs(dz) * 100, "end_err_cm": 0.0,
            "grasp_pred": False, "grasp_true": False, "grasp_err_cm": np.nan,
            "demo_copy_cm": 0.0, "true_shift_cm": 0.0, "demo_effect_cm": np.nan,
            "object_near": np.nan, "moved_near": np.nan, "target_near": float(task == 6),
            "put_near": np.nan, "hand_height_cm": 3.0 + task, "predicted": true + [0.0, 0.0, dz],
            "true": true,
        }  # fmt: skip

    table = per_task_table([row(6, 0.09), row(6, 0.07), row(7, -0.01)])
    assert table.loc["t6", "bias_z_cm"] == pytest.approx(8.0)
    assert table.loc["t7", "bias_z_cm"] == pytest.approx(-1.0)
    assert table.loc["t6", "bias_x_cm"] == pytest.approx(0.0)
    assert table.loc["t6", "target_near"] == 1.0 and table.loc["t7", "target_near"] == 0.0
    assert table.loc["t6", "hand_height_cm"] == 9.0 and table.loc["t7", "hand_height_cm"] == 10.0


def test_the_pairs_index_their_cameras_among_the_snapshots() -> None:
    """Pairs that were all filmed by the snapshot's second camera (MOSAIC's stack block: door and
    drawer are filmed from the other side) take index 1, the rays they were trained on, not 0."""
    first = (np.eye(3) * 200.0, np.hstack((np.eye(3), np.zeros((3, 1)))))
    second = (first[0], np.hstack((np.eye(3), np.array([[0.0], [0.1], [0.8]]))))

    class Pairs:  # AwdaPairDataset's camera bookkeeping over two pairs of one scene camera
        data = None
        _filmed = [second, second]
        cameras, pair_camera = [second], [0, 0]
        index_cameras = AwdaPairDataset.index_cameras  # the real indexing

    pairs = Pairs()
    pointer = TrunkConfig(
        backbone="efficientnet-lite0", backbone_stride=16, freeze_backbone=True,
        head="demo-pointer", attention_head_dim=8,
    )  # fmt: skip
    config = AwdaConfig(trunk=pointer, **camera_fields([first, second], (240, 320)))
    on_model_cameras(pairs, config)  # type: ignore[arg-type]
    assert pairs.pair_camera == [1, 1]
    on_model_cameras(pairs, AwdaConfig(trunk=pointer))  # no cameras: left as they are
    assert pairs.pair_camera == [1, 1]

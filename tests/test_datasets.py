"""Torch datasets and ``dataset info`` over the tiny collection (see ``test_collect.py``)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from test_collect import tiny_collection_dir
from torch.utils.data import default_collate

from awda_bench.cli import main
from awda_bench.data.datasets import (
    AwdaPairDataset,
    CollectedData,
    Selection,
    TosviDataset,
    resample_trajectory,
)
from awda_bench.data.info import contact_sheet, dataset_info
from awda_bench.episode import demo_frame_indices
from awda_bench.errors import UsageError


# ----------------------------------------------------------------------------- pure functions
def test_demo_frame_indices_include_first_and_last() -> None:
    idx = demo_frame_indices(57, 10)
    assert idx[0] == 0 and idx[-1] == 57 and len(idx) == 10
    assert np.all(np.diff(idx) > 0)
    # a demo shorter than the frames asked for repeats frames: always ``count`` of them (MOSAIC's
    # "door 1 close" renders 9 demo frames; evaluation gave the network 9 and it refused)
    short = demo_frame_indices(8, 10)
    assert len(short) == 10 and short[0] == 0 and short[-1] == 8
    assert np.all(np.diff(short) >= 0) and set(short) == set(range(9))


def test_resample_trajectory_keeps_ends_and_flags() -> None:
    tcp = np.stack([np.linspace(0, 1, 11), np.zeros(11), np.full(11, 0.2)], axis=1)
    flags = np.zeros((10, 1), np.float32)
    flags[4:8] = 1.0
    out = resample_trajectory(tcp, flags, 21)
    assert out.shape == (21, 4)
    np.testing.assert_allclose(out[0, :3], tcp[0])
    np.testing.assert_allclose(out[-1, :3], tcp[-1])
    np.testing.assert_allclose(out[:, 0], np.linspace(0, 1, 21), atol=1e-6)
    assert out[:, 3].max() == 1.0 and out[0, 3] == 0.0 and out[-1, 3] == 0.0
    assert out[10, 3] == 1.0  # state 5 lies inside the flagged steps 4..7


# ----------------------------------------------------------------------------- tiny collection
@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_collection_dir(tmp_path_factory)


@pytest.fixture(scope="module")
def data(tiny: Path):
    collected = CollectedData(tiny)
    yield collected
    collected.close()


@pytest.mark.slow
def test_awda_pairs_stay_within_a_task_and_match_the_files(data: CollectedData) -> None:
    ds = AwdaPairDataset(data)
    assert len(ds) == 2 * 2 + 1  # agents x demonstrators of task 0, + 1 synthesized
    heads = [int(ds[i]["head"]) for i in range(len(ds))]
    assert heads.count(0) == 4 and heads.count(1) == 1
    for agent, demo, head in ds.pairs:
        assert agent.task == demo.task
        assert (agent is demo) == (head == 1)
        assert agent.role == ("synthesized" if head else "agent")
    sample = ds[0]
    agent, demo, _ = ds.pairs[0]
    assert sample["demo"].shape == (10, 3, 64, 80) and sample["demo"].dtype == torch.float32
    assert sample["first_frame"].shape == (3, 64, 80)
    assert 0.0 <= float(sample["demo"].min()) and float(sample["demo"].max()) <= 1.0
    first_last = data.frames(demo, [0, demo.steps])
    np.testing.assert_allclose(
        sample["demo"][[0, -1]].permute(0, 2, 3, 1).numpy(), first_last / 255.0, atol=1e-6
    )
    tcp = data.tcp_pos(agent)
    trajectory = sample["trajectory"].numpy()
    assert trajectory.shape == (50, 4)
    np.testing.assert_allclose(trajectory[0, :3], tcp[0], atol=1e-6)
    np.testing.assert_allclose(trajectory[-1, :3], tcp[-1], atol=1e-6)
    assert trajectory[:, 3].max() == 1.0  # the expert's grasp is in the label
    synthesized = ds[len(ds) - 1]
    assert int(synthesized["head"]) == 1 and synthesized["trajectory"][:, 3].max() == 0.0
    resized = AwdaPairDataset(data, image_size=(96, 128))[0]
    assert resized["demo"].shape == (10, 3, 96, 128)


@pytest.mark.slow
def test_awda_batch_trains_the_network(data: CollectedData) -> None:
    from awda_bench.models.awda_net import AwdaNet
    from awda_bench.models.config import AwdaConfig, TrunkConfig

    trunk = TrunkConfig(
        image_height_px=64, image_width_px=80, backbone_weights="none", attention_layers=1
    )
    net = AwdaNet(AwdaConfig(trunk=trunk), load_backbone_weights=False)
    ds = AwdaPairDataset(data)
    loss, info = net.compute_loss(default_collate([ds[0], ds[4]]))
    assert torch.isfinite(loss) and info["loss"] > 0
    loss.backward()


@pytest.mark.slow
def test_tosvi_samples_are_agent_steps_with_depth(data: CollectedData) -> None:
    from awda_bench.models.config import TosviConfig, TrunkConfig
    from awda_bench.models.tosvi_net import TosviNet

    ds = TosviDataset(data, with_depth=True)
    agents = data.select("agent")
    assert len(ds) == sum(a.steps for a in agents)
    first = ds[0]
    assert first["frames"].shape == (6, 3, 64, 80)
    assert first["actions"].shape == (6, 4) and first["depth"].shape == (6, 1, 128, 128)
    assert torch.equal(first["frames"][0], first["frames"][-1])  # t = 0: frame 0 repeated
    agent, demo, t = ds.samples[10]
    sample = ds[10]
    assert agent.task == demo.task and demo.role == "demonstrator" and t == 10
    np.testing.assert_array_equal(sample["actions"].numpy(), data.actions(agent)[5:11])
    depth = sample["depth"].numpy()
    assert 0.05 < float(np.median(depth)) < 1.5  # metres, the table below the hand
    trunk = TrunkConfig(
        image_height_px=64, image_width_px=80, backbone_weights="none", attention_layers=1
    )
    net = TosviNet(TosviConfig(trunk=trunk, use_depth=True), load_backbone_weights=False)
    loss, _ = net.compute_loss(default_collate([ds[0], ds[10]]))
    assert torch.isfinite(loss)


@pytest.mark.slow
def test_held_out_data_and_empty_selections_are_refused(tiny: Path, tmp_path: Path) -> None:
    copy = tmp_path / "test_split"
    shutil.copytree(tiny, copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    manifest["definition"]["split"] = "test"
    (copy / "manifest.json").write_text(json.dumps(manifest))
    held_out = CollectedData(copy)
    with pytest.raises(UsageError, match="test-split collection"):
        AwdaPairDataset(held_out)
    with pytest.raises(UsageError, match="test-split collection"):
        TosviDataset(held_out)
    assert len(AwdaPairDataset(held_out, allow_test=True)) == 5  # a validation set
    held_out.close()
    data = CollectedData(tiny)
    with pytest.raises(UsageError, match="no AWDA pairs"):
        AwdaPairDataset(data, selection=Selection(exclude_families=("pick_place",)))
    assert len(AwdaPairDataset(data, selection=Selection(tasks=(0,)))) == 5
    data.close()


@pytest.mark.slow
def test_dataset_info_counts_and_contact_sheet(data: CollectedData, tmp_path: Path) -> None:
    import cv2

    info = dataset_info(data)
    assert info.complete and info.split == "train"
    rows = {(r.role, r.task): r for r in info.rows}
    assert rows[("agent", 0)].episodes == 2 and rows[("synthesized", 0)].episodes == 1
    assert all(r.steps_min > 0 and r.bytes > 0 for r in info.rows)
    assert info.disk_bytes >= sum(r.bytes for r in info.rows)
    sheet = contact_sheet(data, tmp_path / "sheet.png")
    image = cv2.imread(str(sheet))
    assert image.shape == (5 * 64, 5 * 80, 3)  # 2 + 2 + 1 episodes, 5 frames each


@pytest.mark.slow
def test_dataset_info_cli_and_a_corrupt_file(
    tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sheet = tmp_path / "sheet.png"
    assert main(["dataset", "info", str(tiny), "--verify", "--sheet", str(sheet)]) == 0
    out = capsys.readouterr().out
    assert "agent: 2 episodes (0 discarded)" in out and "verified:" in out and sheet.is_file()
    copy = tmp_path / "corrupt"
    shutil.copytree(tiny, copy)
    h5_path = copy / "agent/pick_place/task_00.h5"
    with h5py.File(h5_path, "r") as f:
        assert "traj_0" in f
    h5_path.write_bytes(h5_path.read_bytes()[:5000])
    assert main(["dataset", "info", str(copy), "--verify"]) == 2
    err = capsys.readouterr().err.strip()
    assert "task_00.h5 is unreadable" in err and len(err.splitlines()) == 1
    assert main(["dataset", "info", str(tmp_path / "nothing")]) == 2
    assert "not a collect directory" in capsys.readouterr().err


@pytest.mark.slow
def test_fig_s6_draws_each_synthesized_path_where_the_camera_sees_it(
    data: CollectedData, tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import cv2

    from awda_bench.reporting.figures import project_points
    from awda_bench.reporting.synthesis_figure import synthesized_panel

    (ref,) = data.select("synthesized")
    frame = data.frames(ref, [0])[0]
    panel = synthesized_panel(data, ref)
    assert panel.shape == frame.shape
    pixels = project_points(data.tcp_pos(ref), *data.camera(ref))
    inside = [
        (int(round(u)), int(round(v)))
        for u, v in pixels
        if 16 <= v < frame.shape[0] and 0 <= u < frame.shape[1]  # below the label
    ]
    assert inside, "the synthesized path should be in view"
    changed = np.abs(panel.astype(int) - frame.astype(int)).sum(-1) > 0
    assert all(changed[v, u] for u, v in inside)  # drawn on every point of the path
    # far from the path (and from the label) the frame is untouched
    far = np.ones_like(changed)
    for u, v in inside:
        far[max(0, v - 8) : v + 9, max(0, u - 8) : u + 9] = False
    far[:18] = False
    assert not changed[far].any()
    out = tmp_path / "s6.png"
    assert main(["dataset", "fig-s6", str(tiny), "--out", str(out)]) == 0
    assert "Fig. S6" in capsys.readouterr().out
    assert cv2.imread(str(out)).shape == frame.shape  # one synthesized episode: one panel
    assert main(["dataset", "fig-s6", str(tiny), "--out", str(out), "--episodes", "0"]) == 2
    assert "--episodes" in capsys.readouterr().err

"""Suites filmed from more than one place (MOSAIC: door and drawer from one side, its other
families from another): the network lists every agent camera, each sample and each live scene
names its own, and the cell heads vote on that camera's rays."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from test_collect import tiny_collection_dir

from awda_bench.data.config import ROLE_AGENT
from awda_bench.data.datasets import AwdaPairDataset, CollectedData
from awda_bench.errors import UsageError
from awda_bench.models.agent_cameras import camera_fields, camera_index, config_cameras
from awda_bench.models.cell_readout import CellHeadShape, CellReadout
from awda_bench.models.config import AwdaConfig, TrunkConfig
from awda_bench.models.identification_loss import (
    grasp_cells,
    grasp_cells_per_camera,
    release_cells,
    release_cells_per_camera,
)
from awda_bench.policies.awda_policy import check_camera
from awda_bench.training.run import agent_cameras

K = np.array([[219.66, 0.0, 160.0], [0.0, 219.66, 120.0], [0.0, 0.0, 1.0]])
TABLE = np.array(  # MOSAIC's pick-and-place, stack block, basketball ... camera
    [[0.0, 1.0, 0.0, 0.0], [0.8396, 0.0, -0.5433, 0.1007], [-0.5433, 0.0, -0.8396, 0.7447]]
)
SIDE = np.array(  # MOSAIC's door and drawer camera
    [[0.0, -1.0, 0.0, 0.0], [-0.4962, 0.0, -0.8682, 0.1536], [0.8682, 0.0, -0.4962, 0.6180]]
)
GRID = (15, 20)


def _camera(extrinsic: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, tuple[int, int]]:
    return torch.tensor(K), torch.tensor(extrinsic), (240, 320)


def _readout(*extrinsics: np.ndarray, offset_m: float = 0.05) -> CellReadout:
    shape = CellHeadShape(
        channels=8, grid=GRID, demo_frames=4, dim=16, dropout=0.0, hidden=32, waypoints=5,
        waypoint_dim=4, num_heads=2, cameras=tuple(_camera(e) for e in extrinsics),
        offset_m=offset_m,
    )  # fmt: skip
    return CellReadout(shape).eval()


def _weights(readout: CellReadout) -> dict[str, torch.Tensor]:
    return {k: v for k, v in readout.state_dict().items() if not k.startswith("ray_")}


def test_each_sample_votes_on_the_rays_of_its_own_camera() -> None:
    torch.manual_seed(0)
    both = _readout(TABLE, SIDE)
    table, side = _readout(TABLE), _readout(SIDE)
    for one in (table, side):
        one.load_state_dict(_weights(both), strict=False)
    x = torch.randn(3, GRID[0] * GRID[1], 16)
    head = torch.tensor([0, 0, 1])
    with torch.no_grad():
        out = both(x, head, camera=torch.tensor([1, 0, 1]))
        torch.testing.assert_close(out[[0, 2]], side(x[[0, 2]], head[[0, 2]]))
        torch.testing.assert_close(out[[1]], table(x[[1]], head[[1]]))
        # the two cameras' rays put the same votes in different places
        assert float((out[0] - both(x[:1], head[:1])[0]).abs().max()) > 0.05
        # no camera index: every sample on the first camera's rays, as before cameras were listed
        torch.testing.assert_close(both(x, head), table(x, head))


def test_a_vote_sits_at_most_offset_m_beside_its_ray() -> None:
    """A saturated horizontal vote moves the point offset_m off its cell's ray (5 cm unless the
    config widens it: ray_offset_m), the height untouched."""
    votes = torch.zeros(1, GRID[0] * GRID[1], 5, 4)
    votes[..., 1] = 20.0  # dx: tanh -> 1
    camera = torch.zeros(1, dtype=torch.long)
    for offset_m in (0.05, 0.25):
        readout = _readout(TABLE, offset_m=offset_m)
        on_ray = readout._ray_points(torch.zeros_like(votes), 0, camera)
        moved = readout._ray_points(votes, 0, camera)
        shift = moved[..., :3] - on_ray[..., :3]
        torch.testing.assert_close(shift[..., 0], torch.full_like(shift[..., 0], offset_m))
        assert float(shift[..., 1:].abs().max()) < 1e-6
    with pytest.raises(UsageError, match="ray_offset_m"):
        AwdaConfig(trunk=TrunkConfig(), ray_offset_m=0.0)


def test_a_snapshot_from_before_cameras_were_listed_loads() -> None:
    torch.manual_seed(1)
    new = _readout(TABLE)
    old = dict(new.state_dict())
    old["ray_origin"], old["ray_direction"] = old["ray_origin"][0], old["ray_direction"][0]
    assert old["ray_origin"].shape == (3,)  # the single-camera layout snapshots hold
    loaded = _readout(TABLE)
    loaded.load_state_dict(old)
    x, head = torch.randn(2, GRID[0] * GRID[1], 16), torch.tensor([0, 1])
    with torch.no_grad():
        torch.testing.assert_close(loaded(x, head), new(x, head))


def test_the_config_lists_cameras_and_the_policy_finds_the_scenes() -> None:
    fields = camera_fields([(K, TABLE), (K, SIDE)], (240, 320))
    config = AwdaConfig(trunk=TrunkConfig(head="demo-pointer"), **fields)
    assert config.num_cameras == 2
    assert check_camera(config, (K, SIDE)) == 1 and check_camera(config, (K, TABLE)) == 0
    elsewhere = SIDE.copy()
    elsewhere[0, 3] += 0.05
    with pytest.raises(UsageError, match="none of them"):
        check_camera(config, (K, elsewhere))
    assert check_camera(AwdaConfig(), (K, elsewhere)) == 0  # free votes: any camera
    with pytest.raises(UsageError, match="9 and 12 numbers per camera"):
        AwdaConfig(**{**fields, "camera_extrinsic": fields["camera_extrinsic"][:12]})
    np.testing.assert_allclose(config_cameras(config)[1][1], SIDE)


def test_the_identification_labels_project_each_row_through_its_camera() -> None:
    trajectory = torch.zeros(3, 6, 4)
    trajectory[:, :, :3] = torch.tensor([-0.05, 0.05, 0.03])
    trajectory[:, 2:, 3] = 1.0
    cameras = (_camera(TABLE), _camera(SIDE))
    cells, ok = grasp_cells_per_camera(trajectory, cameras, torch.tensor([1, 0, 1]), GRID)
    side_cells, _ = grasp_cells(trajectory, cameras[1], GRID)
    table_cells, _ = grasp_cells(trajectory, cameras[0], GRID)
    assert cells.tolist() == [int(side_cells[0]), int(table_cells[1]), int(side_cells[2])]
    assert int(side_cells[0]) != int(table_cells[0]) and bool(ok.all())
    # where each row lets go (the place target's labels), through its camera too
    trajectory[:, 5, 3] = 0.0
    trajectory[:, 4, :3] = torch.tensor([0.05, -0.05, 0.08])
    cells, ok = release_cells_per_camera(trajectory, cameras, torch.tensor([0, 1, 1]), GRID)
    side_cells, _ = release_cells(trajectory, cameras[1], GRID)
    table_cells, _ = release_cells(trajectory, cameras[0], GRID)
    assert cells.tolist() == [int(table_cells[0]), int(side_cells[1]), int(side_cells[2])]
    assert int(side_cells[0]) != int(table_cells[0]) and bool(ok.all())


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> CollectedData:
    collected = CollectedData(tiny_collection_dir(tmp_path_factory))
    yield collected
    collected.close()


@pytest.mark.slow
def test_pairs_name_the_camera_their_agent_was_filmed_with(
    data: CollectedData, monkeypatch: pytest.MonkeyPatch
) -> None:
    recorded = data.camera(data.select(ROLE_AGENT)[0])
    train = AwdaPairDataset(data, include_synthesized=False)  # the tiny collection: one camera
    assert len(train.cameras) == 1
    second = data.select(ROLE_AGENT)[1]  # as if its family were filmed from the side
    real = data.camera
    monkeypatch.setattr(
        data, "camera", lambda ref: (recorded[0], SIDE) if ref == second else real(ref)
    )
    pairs = AwdaPairDataset(data, include_synthesized=False)
    assert len(pairs.cameras) == 2 and camera_index(pairs.cameras, recorded) == 0
    for i, (agent, _, _) in enumerate(pairs.pairs):
        assert int(pairs[i]["camera"]) == (1 if agent == second else 0)
    # a validation set filmed by a camera the training pairs never were: listed after theirs
    monkeypatch.setattr(data, "camera", lambda ref: (recorded[0], SIDE))
    val = AwdaPairDataset(data, include_synthesized=False)
    with pytest.raises(UsageError, match="not among the 1 listed"):
        val.index_cameras([recorded])
    fields = agent_cameras(data, train, val)
    assert len(fields["camera_intrinsic"]) == 9 * 2
    assert {int(val[i]["camera"]) for i in range(len(val))} == {1}
    assert {int(train[i]["camera"]) for i in range(len(train))} == {0}
    assert tuple(fields["camera_size"]) == tuple(data.manifest["definition"]["image_size"])


def test_one_camera_is_what_every_single_camera_suite_records() -> None:
    fields = camera_fields([(K, TABLE)], (240, 320))
    assert (len(fields["camera_intrinsic"]), len(fields["camera_extrinsic"])) == (9, 12)
    assert AwdaConfig(**fields).num_cameras == 1

"""AWDA network: shapes at both paper image sizes, head choice, loss geometry, backbone weights,
config validation, inference output, and overfitting a tiny synthetic batch."""

from __future__ import annotations

import urllib.error

import numpy as np
import pytest
import torch
import torchvision
from torch.utils.data import default_collate
from training_helpers import fit_batch

from awda_bench.errors import UsageError
from awda_bench.models.awda_net import HEAD_NAMES, AwdaNet
from awda_bench.models.backbone import BackboneWeightsUnavailableError, build_resnet18_features
from awda_bench.models.config import AwdaConfig, TrunkConfig
from awda_bench.models.predict import predict_waypoints
from awda_bench.models.synthetic import SyntheticWaypointDataset
from awda_bench.models.waypoint_loss import interpolate_polyline, split_waypoint_sets

torch.set_num_threads(1)


def _config(h: int = 64, w: int = 64, demo_frames: int = 2, **kw: object) -> AwdaConfig:
    trunk = TrunkConfig(
        image_height_px=h, image_width_px=w, demo_frames=demo_frames, backbone_weights="none"
    )
    return AwdaConfig(trunk=trunk, **kw)  # type: ignore[arg-type]


@pytest.mark.parametrize(("h", "w"), [(224, 224), (240, 320)])
def test_forward_shape_at_paper_image_sizes(h: int, w: int) -> None:
    torch.manual_seed(0)
    model = AwdaNet(_config(h, w)).eval()
    with torch.no_grad():
        out = model(torch.rand(1, 2, 3, h, w), torch.rand(1, 3, h, w), torch.tensor([0]))
    assert out.shape == (1, 15, 4)
    assert [s.shape[1] for s in model.waypoint_sets(out)] == [1, 2, 3, 4, 5]


def test_each_sample_uses_the_head_its_index_names() -> None:
    torch.manual_seed(0)
    model = AwdaNet(_config()).eval()
    demo, first = torch.rand(1, 2, 3, 64, 64), torch.rand(1, 3, 64, 64)
    with torch.no_grad():
        both = model(
            demo.expand(2, -1, -1, -1, -1), first.expand(2, -1, -1, -1), torch.tensor([0, 1])
        )
        only0 = model(demo, first, torch.tensor([0]))
        only1 = model(demo, first, torch.tensor([1]))
    assert torch.allclose(both[0], only0[0], atol=1e-5) and torch.allclose(
        both[1], only1[0], atol=1e-5
    )
    assert not torch.allclose(only0, only1)
    with pytest.raises(UsageError, match="head indices"):
        model(demo, first, torch.tensor([2]))


def test_wrong_image_size_is_refused_with_the_config_field() -> None:
    model = AwdaNet(_config())
    with pytest.raises(UsageError, match="image_height_px"):
        model(torch.rand(1, 2, 3, 64, 80), torch.rand(1, 3, 64, 80), torch.tensor([0]))


def test_polyline_starts_at_start_passes_every_waypoint_and_is_linear() -> None:
    start = torch.tensor([[0.0, 0.0, 0.0, 0.0]])
    wps = torch.tensor([[[1.0, 0.0, 0.0, 1.0], [1.0, 2.0, 0.0, 1.0]]])
    line = interpolate_polyline(start, wps, points_per_segment=4)
    assert line.shape == (1, 2 * 4 + 1, 4)
    assert (
        torch.equal(line[0, 0], start[0])
        and torch.equal(line[0, 4], wps[0, 0])
        and torch.equal(line[0, -1], wps[0, 1])
    )
    assert torch.allclose(line[0, 2], torch.tensor([0.5, 0.0, 0.0, 0.5]))
    sets = split_waypoint_sets(torch.arange(15.0).view(1, 15, 1), 5)
    assert [s.flatten().tolist() for s in sets][2] == [3.0, 4.0, 5.0]


def test_imagenet_weights_offline_raise_one_line_error_naming_the_alternative(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def offline(*args: object, **kwargs: object) -> None:
        raise urllib.error.URLError("[Errno -3] Temporary failure in name resolution")

    monkeypatch.setattr(torch.hub, "load_state_dict_from_url", offline)
    with pytest.raises(BackboneWeightsUnavailableError) as info:
        build_resnet18_features("imagenet")
    message = str(info.value)
    assert "\n" not in message and "--backbone-weights none" in message and "local .pth" in message


def test_local_weights_file_is_loaded_and_missing_file_is_refused(tmp_path) -> None:  # type: ignore[no-untyped-def]
    torch.manual_seed(5)
    reference = torchvision.models.resnet18(weights=None)
    path = tmp_path / "r18.pth"
    torch.save(reference.state_dict(), path)
    features = build_resnet18_features(str(path))
    assert torch.equal(features[0].weight, reference.conv1.weight)
    assert torch.equal(features[7][1].conv2.weight, reference.layer4[1].conv2.weight)
    depth = build_resnet18_features(str(path), in_channels=1)
    assert torch.allclose(depth[0].weight[:, 0], reference.conv1.weight.sum(dim=1))
    with pytest.raises(BackboneWeightsUnavailableError, match="neither 'imagenet', 'none'"):
        build_resnet18_features(str(tmp_path / "missing.pth"))


def test_config_errors_name_the_field() -> None:
    with pytest.raises(UsageError, match=r"TrunkConfig\.image_height_px = 16"):
        TrunkConfig(image_height_px=16)
    with pytest.raises(UsageError, match=r"AwdaConfig\.gamma"):
        AwdaConfig(gamma=0.0)


def test_predict_waypoints_returns_five_positions_and_probabilities() -> None:
    torch.manual_seed(0)
    model = AwdaNet(_config())
    rng = np.random.default_rng(0)
    demo = rng.integers(0, 256, size=(2, 64, 64, 3), dtype=np.uint8)
    first = rng.integers(0, 256, size=(64, 64, 3), dtype=np.uint8)
    out = predict_waypoints(model, demo, first)
    assert out.shape == (5, 4) and out.dtype == np.float64
    assert np.all((out[:, 3] >= 0) & (out[:, 3] <= 1))
    assert model.training  # restored after the eval-mode pass
    with pytest.raises(UsageError, match="render the camera"):
        predict_waypoints(model, demo[:, :32], first[:32])


@pytest.mark.slow
def test_overfits_a_tiny_batch_and_predicts_its_waypoints() -> None:
    """Straight-line targets (start -> one grasp waypoint): every set of 1..5 waypoints can fit them
    exactly, so the whole multi-set loss can fall to its floor (~0; soft-DTW may go slightly
    negative). Paper optimizer settings (Adam, lr 5e-4); dropout off to overfit.

    At lr 5e-4 the loss reaches its floor by step ~120 but the end point keeps jittering about the
    goal there (measured, seeds 0-2, worst sample of the five sets: 1.1-2.2 cm at step 120, up to
    2.3 cm at step 200, 0.8-1.2 cm at step 250; a CI machine's CPU gave 2.15 cm at step 120 where
    this one gave 1.2), so the fit is checked at step 250 with a 2.5 cm bound."""
    torch.manual_seed(0)
    cfg = AwdaConfig(
        trunk=TrunkConfig(
            image_height_px=64,
            image_width_px=64,
            demo_frames=1,
            backbone_weights="none",
            dropout=0.0,
        )
    )
    model = AwdaNet(cfg)
    data = SyntheticWaypointDataset(
        2, height_px=64, width_px=64, demo_frames=1, num_waypoints=1, grasped=(0,)
    )
    batch = default_collate([data[i] for i in range(2)])
    losses = fit_batch(model, batch)
    assert losses[-1] <= 0.1 * losses[0], (losses[0], losses[-1])
    goals = batch["waypoints"][:, 0]
    with torch.no_grad():  # training mode: the fit itself (measured: 0.8-1.2 cm)
        raw = model(batch["demo"], batch["first_frame"], batch["head"])
    for waypoint_set in model.waypoint_sets(raw):
        assert torch.all((waypoint_set[:, -1, :3] - goals[:, :3]).norm(dim=-1) < 0.025)
    for i in range(2):  # inference (eval mode): BatchNorm running statistics of a 2-sample batch
        head = HEAD_NAMES[int(batch["head"][i])]  # sample i was trained through this head
        predicted = predict_waypoints(model, batch["demo"][i], batch["first_frame"][i], head=head)
        assert np.linalg.norm(predicted[-1, :3] - goals[i, :3].numpy()) < 0.05  # measured: 2-4 cm
        assert predicted[-1, 3] > 0.5  # the goal waypoint's grasp attribute

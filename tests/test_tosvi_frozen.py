"""T-OSVI and T-OSVI +depth on the frozen, ImageNet-pretrained trunk (issue 24 item 5).

- the network over cached (pooled) maps gives exactly its forward pass over the images;
- the frozen backbone gets no gradient and no optimizer state (+depth's depth ResNet does: it is
  trained);
- the closed-loop policy, encoding each live frame once, acts as the whole stack re-encoded;
- ``train --method tosvi`` on a frozen recipe caches every agent frame and demo frame once, trains
  from the cache and resumes the identical loss curve; its snapshot rebuilds the trunk exactly;
- AWDA's and T-OSVI's datasets sharing one cache file never evict each other.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from test_tosvi_policy import _Frames, _small
from training_helpers import FROZEN_LITE0, TINY_NET, CountingEncoder, recipe_toml

from awda_bench.cli import main
from awda_bench.data.datasets import AwdaPairDataset, CollectedData, TosviDataset
from awda_bench.errors import UsageError
from awda_bench.models.config import TosviConfig, TrainConfig, TrunkConfig
from awda_bench.models.snapshot import list_snapshots, load_snapshot, save_snapshot
from awda_bench.models.tosvi_net import TosviNet, pool_feature_maps
from awda_bench.training.feature_cache import episode_name, load_or_build
from awda_bench.training.feature_datasets import (
    CachedTosviSamples,
    frames_needed,
    tosvi_frames_needed,
)
from awda_bench.training.logbook import read_metrics

H, W = 64, 80


def _trunk(pretrained: bool = False) -> TrunkConfig:
    return TrunkConfig(
        image_height_px=H,
        image_width_px=W,
        demo_frames=2,
        backbone="efficientnet-lite0",
        backbone_stride=16,
        freeze_backbone=True,
        backbone_weights="imagenet" if pretrained else "none",
        attention_layers=1,
        attention_heads=2,
        attention_head_dim=16,
        hidden_dim=32,
        feature_dim=32,
    )


def _config(depth: bool = False, pool: int = 2) -> TosviConfig:
    return TosviConfig(
        trunk=_trunk(),
        frame_stack=3,
        feature_pool=pool,
        head_hidden_dim=32,
        use_depth=depth,
        depth_height_px=32,
        depth_width_px=40,
    )


# ----------------------------------------------------------------------------- fast
def test_pooled_maps_average_their_windows_and_edges_average_what_they_cover() -> None:
    maps = torch.arange(15.0).view(1, 1, 15, 1).expand(2, 3, 4, 15, 20).contiguous()
    pooled = pool_feature_maps(maps, 2)
    assert tuple(pooled.shape) == (2, 3, 4, 8, 10)
    edge = torch.tensor([0.5, 2.5, 4.5, 6.5, 8.5, 10.5, 12.5, 14.0])  # the last row alone
    torch.testing.assert_close(pooled[0, 0, 0, :, 0], edge)
    assert pool_feature_maps(maps, 1) is maps
    with pytest.raises(UsageError, match="feature_pool"):
        TosviConfig(trunk=_trunk(), feature_pool=0)


@pytest.mark.parametrize("depth", [False, True])
def test_cached_maps_give_the_forward_pass(depth: bool) -> None:
    torch.manual_seed(0)
    net = TosviNet(_config(depth), load_backbone_weights=False).eval()
    g = torch.Generator().manual_seed(1)
    demo, frames = torch.rand(2, 2, 3, H, W, generator=g), torch.rand(2, 3, 3, H, W, generator=g)
    d = torch.rand(2, 3, 1, 32, 40, generator=g) if depth else None
    with torch.no_grad():
        want = net(demo, frames, d)
        demo_maps, frame_maps = net.frame_features(demo), net.frame_features(frames)
        got = net.forward_features(demo_maps, frame_maps, d)
    assert tuple(frame_maps.shape) == (2, 3, 112, 2, 3)  # 4x5 cells at stride 16, pooled by 2
    for a, b in zip(want, got, strict=True):
        torch.testing.assert_close(a, b)
    with pytest.raises(UsageError, match="feature maps must be"):
        net.forward_features(demo_maps, frame_maps[:, :2], d)


@pytest.mark.parametrize("depth", [False, True])
def test_the_policy_path_equals_the_full_heads_and_refuses_training_mode(depth: bool) -> None:
    torch.manual_seed(0)
    net = TosviNet(_config(depth), load_backbone_weights=False).eval()
    g = torch.Generator().manual_seed(2)
    maps = torch.randn(2, 5, 112, 2, 3, generator=g)
    vectors = torch.randn(2, 3, 512, generator=g) if depth else None
    with torch.no_grad():
        want, _ = net.heads_from_features(maps, vectors)
        frames = maps
        if vectors is not None:  # fused frame by frame, demo frames with zero vectors
            zeros = torch.zeros(2, 2, 512)
            frames = torch.cat(
                [net.fuse_depth(maps[:, :2], zeros)]
                + [
                    net.fuse_depth(maps[:, i : i + 1], vectors[:, i - 2 : i - 1]) for i in (2, 3, 4)
                ],
                dim=1,
            )
        got = net.policy_from_frames(frames)
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)
    with pytest.raises(UsageError, match="eval mode"):
        net.train().policy_from_frames(maps)


def test_a_run_recorded_before_tosvi_feature_pool_existed_still_resumes() -> None:
    from awda_bench.training.recipe import load_recipe
    from awda_bench.training.run import identity

    recipe = load_recipe("small").to_dict()
    column = {"slug": "tosvi", "arch": "tosvi"}
    record = {"column": column, "recipe": recipe, "data": {"fingerprint": "f"}, "hold_out": None}
    older = json.loads(json.dumps(record))
    del older["recipe"]["model"]["tosvi_feature_pool"]  # counts as the default, 1
    assert identity(older) != identity(record)  # small pools T-OSVI's maps by 2
    record["recipe"]["model"]["tosvi_feature_pool"] = 1
    assert identity(older) == identity(record)
    # an AWDA run started before the field existed resumes under today's small (pool 2)
    awda = {**record, "column": {"slug": "awda", "arch": "awda"}, "recipe": recipe}
    awda["recipe"]["model"]["tosvi_feature_pool"] = 2
    assert identity({**older, "column": awda["column"]}) == identity(awda)


def test_a_tosvi_run_resumes_whatever_the_awda_only_fields_say() -> None:
    """Meta-World's recipe gained the contact label while a T-OSVI run was under way: T-OSVI
    reads neither it nor the ray heights, so the run resumes; an AWDA run does not."""
    from awda_bench.training.recipe import load_recipe
    from awda_bench.training.run import identity

    today = load_recipe("small").for_suite("metaworld").to_dict()
    before = json.loads(json.dumps(today))
    before["model"]["identification_contact"] = False
    before["model"]["ray_height_offset_m"] = 0.05
    for arch, resumes in (("tosvi", True), ("tosvi-depth", True), ("awda", False)):
        column = {"slug": arch, "arch": arch}
        old, new = ({"column": column, "recipe": r, "data": {"fingerprint": "f"}, "hold_out": None}
                    for r in (before, today))  # fmt: skip
        assert (identity(old) == identity(new)) == resumes, arch


def test_frozen_backbone_gets_no_gradient_and_no_optimizer_state_depth_resnet_does(
    tmp_path: Path,
) -> None:
    from awda_bench.training.loop import train

    torch.manual_seed(0)
    model = TosviNet(_config(depth=True), load_backbone_weights=False)
    before = {k: v.clone() for k, v in model.trunk.backbone.state_dict().items()}
    depth_before = [p.detach().clone() for p in model.depth_backbone.parameters()]  # type: ignore[union-attr]
    assert not any(p.requires_grad for p in model.trunk.backbone.parameters())
    g = torch.Generator().manual_seed(1)
    samples = [
        {
            "demo_features": torch.randn(2, 112, 2, 3, generator=g),
            "frame_features": torch.randn(3, 112, 2, 3, generator=g),
            "actions": torch.rand(3, 4, generator=g) * 2 - 1,
            "depth": torch.rand(3, 1, 32, 40, generator=g),
        }
        for _ in range(4)
    ]
    config = TrainConfig(batch_size=2, max_steps=3, snapshot_every_steps=3, device="cpu")
    train(model, samples, config, tmp_path)
    assert all(p.grad is None for p in model.trunk.backbone.parameters())
    after = model.trunk.backbone.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before)  # BN statistics included
    moved = [
        not torch.equal(a, b)
        for a, b in zip(depth_before, model.depth_backbone.parameters(), strict=True)  # type: ignore[union-attr]
    ]
    assert any(moved)  # +depth's depth ResNet is trained
    snap = torch.load(list_snapshots(tmp_path)[-1], weights_only=False)
    trainable = sum(1 for p in model.parameters() if p.requires_grad)
    assert len(snap["optimizer_state"]["state"]) == trainable
    assert len(snap["optimizer_state"]["param_groups"][0]["params"]) == trainable


@pytest.mark.parametrize("depth", [False, True])
def test_policy_encodes_each_frame_once_and_acts_as_the_whole_stack_re_encoded(
    tmp_path: Path, depth: bool
) -> None:
    from awda_bench.data.trajectory_file import as_stored
    from awda_bench.episode import EpisodeContext, EpisodeSpec
    from awda_bench.policies.tosvi_policy import TosviPolicy

    torch.manual_seed(0)
    path = save_snapshot(
        tmp_path / "snapshot-000000001.pt", TosviNet(_config(depth), False), step=1
    )
    demo = np.random.default_rng(1).integers(0, 256, (2, 120, 160, 3), dtype=np.uint8)
    camera = _Frames(demo)
    policy = TosviPolicy(path, "mode")
    spec = EpisodeSpec(suite="pick_place", task=14, episode=0, seed=1, demo_seed=2)
    policy.reset(EpisodeContext(env=None, spec=spec, observations=camera))  # type: ignore[arg-type]
    encoded: list[int] = []
    backbone = policy.model.trunk.backbone
    backbone.register_forward_hook(lambda _m, args, _out: encoded.append(len(args[0])))
    for step in range(5):
        action = policy.act(None)
        index = np.clip(np.arange(step - 2, step + 1), 0, None)
        # the policy sees its frames as the collection stores them (JPEG), and so does the check
        stored = as_stored(np.stack([camera.shown[i] for i in index]), policy.jpeg_quality)
        stack = _small(stored)
        d = None
        if depth:
            d = torch.from_numpy(np.stack([camera.depths[i] for i in index]))[None, :, None]
        expected = policy.model.predict_action(
            _small(as_stored(demo, policy.jpeg_quality)), stack, d, statistic="mode"
        )
        np.testing.assert_allclose(action[0, :3], expected[0, :3].numpy(), atol=1e-5)
        assert action[0, 3] == (1.0 if expected[0, 3] > 0 else -1.0)
    # per step: one live frame through the backbone, then the check's whole demo + stack
    assert encoded == [1, 2 + 3] * 5


# ----------------------------------------------------------------------------- tiny collection
FROZEN_TOSVI_RECIPE = recipe_toml(
    "tiny-tosvi-frozen",
    {
        **TINY_NET,
        "hidden_dim": 32,
        "feature_dim": 32,
        "frame_stack": 3,
        **FROZEN_LITE0,
        "tosvi_feature_pool": 2,
    },
)


@pytest.mark.slow
def test_tosvi_trains_from_the_cache_resumes_the_identical_curve_and_rebuilds_its_trunk(
    tiny_copy: Path, tmp_path: Path
) -> None:
    data_dir = tiny_copy
    recipe = tmp_path / "frozen.toml"
    recipe.write_text(FROZEN_TOSVI_RECIPE)
    common = ["--data", str(data_dir), "--recipe", str(recipe), "--no-progress", "--threads", "1"]
    tosvi = ["--method", "tosvi", *common, "--steps", "6", "--snapshot-every", "2"]
    assert main(["train", *tosvi, "--out", str(tmp_path / "full")]) == 0
    caches = list((data_dir / "features").glob("*.h5"))
    assert len(caches) == 1
    built = caches[0].stat().st_mtime_ns
    part = tmp_path / "part"
    assert main(["train", *tosvi, "--out", str(part)]) == 0
    (part / "snapshot-000000006.pt").unlink()
    assert main(["train", *tosvi, "--out", str(part)]) == 0
    assert caches[0].stat().st_mtime_ns == built  # reused, not encoded again
    full = read_metrics(tmp_path / "full" / "metrics.csv")
    resumed = read_metrics(part / "metrics.csv")
    assert resumed[("train", "loss")] == full[("train", "loss")]

    # the cache holds every agent frame 0..T-1 (pooled), and serves what the network computes
    snap = load_snapshot(list_snapshots(part)[-1])
    model = snap.build_model()
    assert isinstance(model, TosviNet)
    trunk = model.config.trunk
    assert (trunk.backbone, trunk.freeze_backbone, model.config.feature_pool) == (
        "efficientnet-lite0",
        True,
        2,
    )
    from awda_bench.models.efficientnet_lite import EfficientNetLiteFeatures

    package = EfficientNetLiteFeatures(16, pretrained=True).state_dict()
    rebuilt = model.trunk.backbone.state_dict()
    assert all(torch.equal(package[k], rebuilt[k]) for k in package)  # the exact trunk
    data = CollectedData(data_dir)
    samples = TosviDataset(data, demo_frames=10, frame_stack=3, image_size=(H, W))
    needed = {episode_name(data, ref): idx for ref, idx in tosvi_frames_needed(samples)}
    for agent in data.select("agent"):
        np.testing.assert_array_equal(needed[episode_name(data, agent)], np.arange(agent.steps))
    # a subset (the validator's samples) needs only its own stacks
    agent, demo, t = samples.samples[5]
    assert t == 5
    few = {episode_name(data, r): i for r, i in tosvi_frames_needed(samples.subset([5]))}
    np.testing.assert_array_equal(few[episode_name(data, agent)], [3, 4, 5])
    assert len(few) == 2 and len(few[episode_name(data, demo)]) == 10

    def no_encoding(images: torch.Tensor) -> torch.Tensor:
        raise AssertionError("the cache is complete: nothing is encoded again")

    from awda_bench.training.run import cache_variant

    cache = load_or_build(
        data,
        trunk,
        tosvi_frames_needed(samples),
        no_encoding,
        variant=cache_variant(2),
        progress=False,
    )
    assert cache.path == caches[0]
    cached = CachedTosviSamples(samples, cache)
    for index in (0, len(samples) - 1):
        plain, served = samples[index], cached[index]
        with torch.no_grad():
            want = model.frame_features(plain["frames"][None])[0]
        torch.testing.assert_close(served["frame_features"], want, atol=2e-2, rtol=1e-2)  # fp16
        torch.testing.assert_close(served["actions"], plain["actions"])
    data.close()

    # +depth and the no-waypoints ablation (ADM on the cached stacks, synthesized episodes added
    # to the same file) train from the same cache
    depth = ["--method", "tosvi-depth", *common, "--steps", "2", "--val-data", str(data_dir)]
    assert main(["train", *depth, "--out", str(tmp_path / "depth")]) == 0
    no_wp = ["--method", "awda", "--ablation", "no-waypoints", *common, "--steps", "2"]
    assert main(["train", *no_wp, "--out", str(tmp_path / "no-wp")]) == 0
    assert list((data_dir / "features").glob("*.h5")) == caches
    for run in ("depth", "no-wp"):
        steps, losses = read_metrics(tmp_path / run / "metrics.csv")[("train", "loss")]
        assert steps == [1, 2] and np.all(np.isfinite(losses))
    steps, losses = read_metrics(tmp_path / "depth" / "metrics.csv")[("val", "loss")]
    assert steps == [0, 2] and np.all(np.isfinite(losses))


@pytest.mark.slow
def test_awda_and_tosvi_share_an_unpooled_cache_without_evicting_each_other(
    tiny_copy: Path,
) -> None:
    data_dir = tiny_copy
    data = CollectedData(data_dir)
    trunk = _trunk()
    pairs = AwdaPairDataset(data, image_size=(H, W))
    samples = TosviDataset(data, demo_frames=10, frame_stack=3, image_size=(H, W))
    encoder = CountingEncoder()
    awda_needed, tosvi_needed = frames_needed(pairs), tosvi_frames_needed(samples)
    first = load_or_build(data, trunk, awda_needed, encoder, progress=False)
    awda_frames = encoder.frames
    load_or_build(data, trunk, tosvi_needed, encoder, progress=False)
    # T-OSVI re-encodes each agent episode whole (o_1 included) and reuses the demo frames
    agents = sum(a.steps for a in data.select("agent"))
    assert encoder.frames == awda_frames + agents
    again = load_or_build(data, trunk, awda_needed, encoder, progress=False)
    load_or_build(data, trunk, tosvi_needed, encoder, progress=False)
    assert encoder.frames == awda_frames + agents  # neither evicted the other
    assert again.path == first.path and len(list((data_dir / "features").glob("*.h5"))) == 1
    name = episode_name(data, data.select("agent")[0])  # sample 0: its stack is all frame 0
    with torch.no_grad():
        want = encoder.conv(samples[0]["frames"][:1]).half().float()
    torch.testing.assert_close(again.features(name, np.zeros(1, np.int64)), want)
    data.close()

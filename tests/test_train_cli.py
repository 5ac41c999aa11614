"""``train``: every Table S3 column from a tiny collection, resume, logs, and bad input.

The tiny collection is ``test_collect``'s (pick_place task 0, 2 episodes per embodiment + 1
synthesized, 64x80 frames; recorded once per session). Training uses a tiny recipe written
here (1 attention layer, narrow MLPs, batch 2): a step costs well under a second on one core.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from test_collect import tiny_collection_dir

from awda_bench.cli import main
from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.models.snapshot import list_snapshots, load_snapshot
from awda_bench.training.augment import BatchTreatment, step_generator
from awda_bench.training.columns import ABLATIONS, COLUMNS, TRAINABLE, column_for
from awda_bench.training.logbook import read_metrics
from awda_bench.training.recipe import AugmentRecipe, TrainRecipe, load_recipe

TINY_RECIPE = """
name = "tiny"
suites = ["pick_place", "mosaic"]
[model]
image_height_px = {h}
image_width_px = 80
attention_layers = 1
attention_heads = 2
attention_head_dim = 16
hidden_dim = 32
feature_dim = 32
frame_stack = 3
[train]
batch_size = 2
max_steps = 20
snapshot_every_steps = 10
validate_every_steps = 5
validation_batches = 1
[augment]
shift_px = 2
"""


def write_recipe(directory: Path, height: int = 64, name: str = "tiny.toml") -> Path:
    path = directory / name
    path.write_text(TINY_RECIPE.format(h=height))
    return path


# ----------------------------------------------------------------------------- fast
def test_every_column_is_one_method_ablation_pair() -> None:
    pairs = {(c.method, c.ablation) for c in TRAINABLE}
    assert len(COLUMNS) == 8 and len(pairs) == len(TRAINABLE) == 9
    assert {a for _, a in pairs} - {None} == set(ABLATIONS)
    stack = column_for("tosvi", "no-frame-stack")  # the §S3 analysis's network
    assert (stack.arch, stack.frame_stack, stack.adm, stack.synthesized) == (
        "tosvi",
        1,
        False,
        False,
    )
    assert all(c.frame_stack is None for c in COLUMNS)
    with pytest.raises(UsageError, match="ablation of tosvi"):
        column_for("awda", "no-frame-stack")
    full = column_for("awda", None)
    assert (full.name, full.num_heads, full.adm, full.synthesized) == ("Full-1", 2, True, True)
    assert column_for("awda", "no-waypoints").arch == "tosvi"
    only = column_for("awda", "only-waypoints")
    assert not only.adm and not only.synthesized and only.arch == "awda"
    assert column_for("tosvi-depth", None).arch == "tosvi-depth"
    with pytest.raises(UsageError, match="ablation of awda"):
        column_for("tosvi", "no-adm")
    with pytest.raises(UnknownChoiceError, match="awda, tosvi, tosvi-depth"):
        column_for("daml", None)


def test_paper_recipe_is_table_s2_and_recipes_refuse_unknown_fields(tmp_path: Path) -> None:
    paper = load_recipe("paper")
    m, t = paper.model, paper.train
    assert (m.trunk.image_height_px, m.trunk.image_width_px, m.trunk.demo_frames) == (240, 320, 10)
    assert (m.trunk.attention_layers, m.trunk.attention_heads, m.trunk.hidden_dim) == (2, 4, 256)
    assert m.awda["gamma"] == 1e-3
    assert (t.batch_size, t.learning_rate, t.snapshot_every_steps) == (30, 5e-4, 10_000)
    small = load_recipe("small")
    assert small.train.max_steps >= 10 * small.train.snapshot_every_steps  # 10 to evaluate
    assert small.sha256 != paper.sha256
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\nsuites = ["pick_place"]\n[train]\nbatchsize = 3\n')
    with pytest.raises(UsageError, match="batchsize"):
        load_recipe(str(bad))
    with pytest.raises(UnknownChoiceError, match="paper"):
        load_recipe("huge")


def test_a_variant_extends_its_base_and_overrides_only_what_it_names(tmp_path: Path) -> None:
    from dataclasses import replace

    small = load_recipe("small")
    seed1 = load_recipe("small-seed1")  # extends = "small", [train] seed = 1
    assert seed1.name == "small-seed1" and seed1.train.seed == 1 != small.train.seed
    assert seed1.model == small.model and seed1.augment == small.augment
    assert replace(seed1, name="small", path=small.path, train=small.train) == small
    # chained, by path, a [suite.*.model] table merged field by field
    (tmp_path / "base.toml").write_text(
        'name = "base"\nsuites = ["pick_place", "metaworld"]\n[model]\ndropout = 0.3\n'
        "[suite.metaworld.model]\nimage_height_px = 224\nimage_width_px = 224\n"
    )
    (tmp_path / "mid.toml").write_text(
        'extends = "base.toml"\nname = "mid"\n[train]\nseed = 5\n'
        "[suite.metaworld.model]\nimage_width_px = 200\n"
    )
    (tmp_path / "leaf.toml").write_text('extends = "mid.toml"\nname = "leaf"\n')
    leaf = load_recipe(str(tmp_path / "leaf.toml"))
    assert (leaf.name, leaf.model.trunk.dropout, leaf.train.seed) == ("leaf", 0.3, 5)
    assert leaf.suite_models == {"metaworld": {"image_height_px": 224, "image_width_px": 200}}
    # a [suite.*.train] table: that suite's schedule, inherited beside a variant's own model table
    (tmp_path / "steps.toml").write_text(
        'extends = "base.toml"\nname = "steps"\n[suite.metaworld.train]\nmax_steps = 6000\n'
    )
    (tmp_path / "steps-leaf.toml").write_text(
        'extends = "steps.toml"\nname = "steps-leaf"\n[suite.metaworld.model]\ndropout = 0.2\n'
    )
    steps = load_recipe(str(tmp_path / "steps-leaf.toml"))
    on_mw, on_pp = steps.for_suite("metaworld"), steps.for_suite("pick_place")
    assert (on_mw.train.max_steps, on_pp.train.max_steps) == (6000, TrainRecipe().max_steps)
    assert (on_mw.model.trunk.image_height_px, on_mw.model.trunk.dropout) == (224, 0.2)
    assert on_mw.with_schedule(50, None).train.max_steps == 50  # --steps wins
    assert "suite_trains" in steps.to_dict() and "suite_trains" not in on_mw.to_dict()
    assert "suite_trains" not in load_recipe(str(tmp_path / "leaf.toml")).to_dict()
    (tmp_path / "bad-steps.toml").write_text(
        'extends = "base.toml"\nname = "bad"\n[suite.metaworld.train]\nmax_step = 6000\n'
    )
    with pytest.raises(UsageError, match="max_step"):
        load_recipe(str(tmp_path / "bad-steps.toml"))
    (tmp_path / "bad-table.toml").write_text(
        'extends = "base.toml"\nname = "bad"\n[suite.metaworld.augment]\nshift_px = 0\n'
    )
    with pytest.raises(UsageError, match=r"only \[suite.<name>.model\] and"):
        load_recipe(str(tmp_path / "bad-table.toml"))
    # a missing base, a cycle and a nameless variant are one-line errors
    (tmp_path / "lost.toml").write_text('extends = "nowhere"\nname = "lost"\n')
    with pytest.raises(UsageError, match="extends 'nowhere', which does not exist"):
        load_recipe(str(tmp_path / "lost.toml"))
    (tmp_path / "a.toml").write_text('extends = "b.toml"\nname = "a"\n')
    (tmp_path / "b.toml").write_text('extends = "a.toml"\nname = "b"\n')
    with pytest.raises(UsageError, match="cycle"):
        load_recipe(str(tmp_path / "a.toml"))
    (tmp_path / "nameless.toml").write_text('extends = "base.toml"\n')
    with pytest.raises(UsageError, match="needs a name"):
        load_recipe(str(tmp_path / "nameless.toml"))


def test_the_model_table_loads_into_the_model_configs(tmp_path: Path) -> None:
    from dataclasses import asdict

    from awda_bench.models.config import ModelSpec, TrunkConfig

    small = load_recipe("small")
    assert isinstance(small.model.trunk, TrunkConfig)
    assert ModelSpec.from_table(small.model.to_table()) == small.model
    assert set(small.to_dict()["model"]) == {*ModelSpec.table_keys(), *asdict(small.data)}
    tosvi = small.model.tosvi_config(frame_stack=1, use_depth=True)  # a column's settings
    assert (tosvi.frame_stack, tosvi.use_depth, tosvi.trunk.head) == (1, True, "self-attention")
    assert tosvi.feature_pool == small.to_dict()["model"]["tosvi_feature_pool"]
    for body, message in (
        ("dropout = 1.5", r"\[model\]: TrunkConfig.dropout = 1.5 is invalid; expected a float"),
        ("tosvi_feature_pool = 0", r"TosviConfig.feature_pool \(tosvi_feature_pool\) = 0"),
        ("trajectory_points = 1", r"DataRecipe.trajectory_points = 1 is invalid; expected an int"),
        ("gammma = 1", r"\[model\] has no field\(s\) \['gammma'\]; valid: image_height_px"),
    ):
        bad = tmp_path / "bad.toml"
        bad.write_text(f'name = "bad"\nsuites = ["pick_place"]\n[model]\n{body}\n')
        with pytest.raises(UsageError, match=message):
            load_recipe(str(bad))


def test_adm_blends_with_the_partners_first_frame_and_never_touches_labels() -> None:
    g = torch.Generator().manual_seed(0)
    batch = {
        "demo": torch.rand(3, 4, 3, 8, 8, generator=g),
        "first_frame": torch.rand(3, 3, 8, 8, generator=g),
        "trajectory": torch.rand(3, 5, 4, generator=g),
        "head": torch.tensor([0, 1, 0]),
    }
    plain = AugmentRecipe(shift_px=0, brightness=0.0, contrast=0.0, saturation=0.0)
    treat = BatchTreatment(plain, adm=True, seed=3)
    out = treat(batch, step=7)
    lam = 0.3 + 0.7 * torch.rand(3, generator=step_generator(3, 7))  # the only draw
    assert torch.all((lam >= 0.3) & (lam <= 1.0))
    for i in range(3):
        p = (i + 1) % 3
        expected_agent = lam[i] * batch["first_frame"][i] + (1 - lam[i]) * batch["first_frame"][p]
        expected_demo = lam[i] * batch["demo"][i] + (1 - lam[i]) * batch["demo"][p, 0]
        assert torch.allclose(out["first_frame"][i], expected_agent, atol=1e-6)
        assert torch.allclose(out["demo"][i], expected_demo, atol=1e-6)
    assert out["trajectory"] is batch["trajectory"] and out["head"] is batch["head"]
    assert torch.equal(treat(batch, 7)["demo"], out["demo"])  # a function of (seed, step)
    assert not torch.equal(treat(batch, 8)["demo"], out["demo"])
    off = BatchTreatment(plain, adm=False, seed=3)(batch, 7)
    assert torch.equal(off["demo"], batch["demo"])
    # adm_mix_agent = false: the same demo mix, o_1 left as it is (images and cached features)
    demo_only = BatchTreatment(replace(plain, adm_mix_agent=False), adm=True, seed=3)
    kept = demo_only(batch, 7)
    assert torch.equal(kept["demo"], out["demo"])
    assert torch.equal(kept["first_frame"], batch["first_frame"])
    features = {"demo_features": batch["demo"], "first_frame_features": batch["first_frame"]}
    mixed, kept = treat(features, 7), demo_only(features, 7)
    assert torch.allclose(mixed["first_frame_features"], out["first_frame"], atol=1e-6)
    assert torch.equal(kept["demo_features"], mixed["demo_features"])
    assert kept["first_frame_features"] is batch["first_frame"]
    # shifts and jitter keep images in [0, 1] and shapes; T-OSVI stacks are treated alike
    stack = {
        "demo": batch["demo"],
        "frames": torch.rand(3, 6, 3, 8, 8),
        "actions": torch.zeros(3, 6, 4),
    }
    full = BatchTreatment(AugmentRecipe(shift_px=2), adm=True, seed=0)(stack, 0)
    assert full["frames"].shape == (3, 6, 3, 8, 8) and torch.equal(
        full["actions"], stack["actions"]
    )
    assert 0.0 <= float(full["frames"].min()) and float(full["frames"].max()) <= 1.0


def test_logbook_resumes_at_the_snapshot_step_and_a_fresh_start_keeps_nothing(
    tmp_path: Path,
) -> None:
    from awda_bench.training.logbook import Logbook

    log = Logbook(tmp_path, 0, tensorboard=False)
    log.log(0, "val", {"loss": 2.0})
    for step in range(1, 5):
        log.log(step, "train", {"loss": 1.0 / step})
    log.close()
    Logbook(tmp_path, 2, tensorboard=False).close()  # resumed from the snapshot at step 2
    series = read_metrics(tmp_path / "metrics.csv")
    assert series[("train", "loss")][0] == [1, 2] and series[("val", "loss")][0] == [0]
    Logbook(tmp_path, 0, tensorboard=False).close()  # killed before its first snapshot
    assert read_metrics(tmp_path / "metrics.csv") == {}


# ----------------------------------------------------------------------------- tiny collection
@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_collection_dir(tmp_path_factory)


@pytest.fixture(scope="module")
def recipe(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_recipe(tmp_path_factory.mktemp("recipes"))


def _train(*args: str) -> int:
    return main(["train", *args, "--no-progress", "--threads", "1"])


@pytest.mark.slow
@pytest.mark.parametrize("column", TRAINABLE, ids=[c.slug for c in TRAINABLE])
def test_every_column_trains_20_steps_into_loadable_snapshots(
    column, tiny: Path, recipe: Path, tmp_path: Path
) -> None:
    from awda_bench.data.datasets import CollectedData

    out = tmp_path / "ckpt"
    args = ["--method", column.method, "--data", str(tiny), "--out", str(out)]
    if column.ablation:
        args += ["--ablation", column.ablation]
    assert _train(*args, "--recipe", str(recipe)) == 0
    snapshots = list_snapshots(out)
    assert [p.name for p in snapshots] == ["snapshot-000000010.pt", "snapshot-000000020.pt"]
    snap = load_snapshot(snapshots[-1])
    assert snap.arch == column.arch and snap.step == 20
    assert snap.training is not None
    data = CollectedData(tiny)
    assert snap.training["data"]["fingerprint"] == data.fingerprint != ""
    assert snap.training["column"]["name"] == column.name
    assert snap.training["recipe"]["name"] == "tiny"
    losses = read_metrics(out / "metrics.csv")[("train", "loss")][1]
    assert len(losses) == 20 and all(np.isfinite(losses))
    assert (out / "learning_curve.png").stat().st_size > 0
    assert any((out / "tensorboard").iterdir())
    if column.arch == "awda":
        from awda_bench.models.predict import predict_waypoints
        from awda_bench.policies.awda_policy import AwdaPolicy

        policy = AwdaPolicy(snapshots[-1])  # what the `awda` evaluation method loads
        assert policy.model.config.num_heads == column.num_heads
        agent = data.select("agent")[0]
        demo = data.select("demonstrator")[0]
        frames = data.frames(demo, np.linspace(0, demo.steps, 10).round().astype(int))
        waypoints = predict_waypoints(policy.model, frames, data.frames(agent, [0])[0])
        assert waypoints.shape == (5, 4) and np.all(np.isfinite(waypoints))
    else:
        from awda_bench.models.tosvi_net import TosviNet

        model = snap.build_model()
        assert isinstance(model, TosviNet) and model.arch == column.arch
        assert model.config.frame_stack == (column.frame_stack or 3)  # the tiny recipe's: 3
    data.close()


def test_an_ema_recipe_snapshots_the_average_and_the_policy_plays_it(
    tiny: Path, recipe: Path, tmp_path: Path
) -> None:
    from awda_bench.policies.awda_policy import AwdaPolicy

    ema = recipe.parent / "tiny-ema.toml"
    ema.write_text(f'extends = "{recipe.name}"\nname = "tiny-ema"\n[train]\nema_decay = 0.9\n')
    out = tmp_path / "ckpt"
    args = ["--method", "awda", "--data", str(tiny), "--out", str(out), "--recipe", str(ema)]
    assert _train(*args, "--steps", "4", "--snapshot-every", "2") == 0
    snap = load_snapshot(list_snapshots(out)[-1])
    assert snap.training is not None and snap.training["recipe"]["train"]["ema_decay"] == 0.9
    assert snap.training_state is not None
    assert any(not torch.equal(v, snap.training_state[k]) for k, v in snap.model_state.items())
    policy = AwdaPolicy(list_snapshots(out)[-1])  # plays the average
    for k, v in policy.model.state_dict().items():
        assert torch.equal(v, snap.model_state[k])
    assert _train(*args, "--steps", "6", "--snapshot-every", "2") == 0  # resumes from step 4
    assert load_snapshot(list_snapshots(out)[-1]).step == 6
    bad = recipe.parent / "tiny-ema-bad.toml"
    bad.write_text(f'extends = "{recipe.name}"\nname = "bad"\n[train]\nema_decay = 1.0\n')
    with pytest.raises(UsageError, match="ema_decay"):
        load_recipe(str(bad))


def test_a_cosine_recipe_reaches_the_loop_and_logs_its_step_size(
    tiny: Path, recipe: Path, tmp_path: Path
) -> None:
    cosine = recipe.parent / "tiny-cosine.toml"
    cosine.write_text(
        f'extends = "{recipe.name}"\nname = "tiny-cosine"\n[train]\nlr_schedule = "cosine"\n'
    )
    out = tmp_path / "ckpt"
    args = ["--method", "awda", "--data", str(tiny), "--out", str(out), "--recipe", str(cosine)]
    assert _train(*args, "--steps", "4", "--snapshot-every", "2") == 0
    snap = load_snapshot(list_snapshots(out)[-1])
    assert snap.training is not None
    assert snap.training["recipe"]["train"]["lr_schedule"] == "cosine"
    steps, lr = read_metrics(out / "metrics.csv")[("train", "lr")]
    assert steps == [1, 2, 3, 4]
    base = load_recipe(str(cosine)).train.learning_rate
    assert lr == pytest.approx([base * (1 + math.cos(math.pi * s / 4)) / 2 for s in range(4)])
    bad = recipe.parent / "tiny-cosine-bad.toml"
    bad.write_text(f'extends = "{recipe.name}"\nname = "bad"\n[train]\nlr_schedule = "step"\n')
    with pytest.raises(UsageError, match="lr_schedule"):
        load_recipe(str(bad))


def test_a_bf16_recipe_reaches_the_loop_and_its_record(
    tiny: Path, recipe: Path, tmp_path: Path
) -> None:
    low = recipe.parent / "tiny-bf16.toml"
    low.write_text(f'extends = "{recipe.name}"\nname = "tiny-bf16"\n[train]\nprecision = "bf16"\n')
    out = tmp_path / "ckpt"
    args = ["--method", "awda", "--data", str(tiny), "--out", str(out), "--recipe", str(low)]
    assert _train(*args, "--steps", "2", "--snapshot-every", "2") == 0
    snap = load_snapshot(list_snapshots(out)[-1])
    assert snap.training is not None and snap.training["recipe"]["train"]["precision"] == "bf16"
    steps, loss = read_metrics(out / "metrics.csv")[("train", "loss")]
    assert steps == [1, 2] and all(math.isfinite(v) for v in loss)
    bad = recipe.parent / "tiny-bf16-bad.toml"
    bad.write_text(f'extends = "{recipe.name}"\nname = "bad"\n[train]\nprecision = "fp16"\n')
    with pytest.raises(UsageError, match="precision"):
        load_recipe(str(bad))


@pytest.mark.slow
def test_resume_after_a_kill_continues_the_identical_curve(
    tiny: Path, recipe: Path, tmp_path: Path
) -> None:
    common = ["--method", "awda", "--data", str(tiny), "--recipe", str(recipe), "--steps", "6"]
    assert _train(*common, "--snapshot-every", "2", "--out", str(tmp_path / "full")) == 0
    part = tmp_path / "part"
    assert _train(*common, "--snapshot-every", "2", "--out", str(part)) == 0
    # as if killed after step 5: snapshot 6 never written, metrics past step 4 left behind
    (part / "snapshot-000000006.pt").unlink()
    assert _train(*common, "--snapshot-every", "2", "--out", str(part)) == 0
    full = read_metrics(tmp_path / "full" / "metrics.csv")
    resumed = read_metrics(part / "metrics.csv")
    assert resumed[("train", "loss")] == full[("train", "loss")]  # same steps, same values
    assert resumed[("train", "loss")][0] == [1, 2, 3, 4, 5, 6]
    assert len(set(full[("train", "loss")][1])) == 6


@pytest.mark.slow
def test_validation_on_a_held_out_family_and_on_val_data(
    tiny: Path, recipe: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a two-family collection: the tiny files listed a second time as family "door", task 99
    two = tmp_path / "two_families"
    shutil.copytree(tiny, two)
    manifest = json.loads((two / "manifest.json").read_text())
    manifest["units"] += [
        {**u, "family": "door", "task": 99} for u in manifest["units"] if u["role"] != "synthesized"
    ]
    (two / "manifest.json").write_text(json.dumps(manifest))
    out = tmp_path / "held_out"
    common = ["--method", "awda", "--recipe", str(recipe), "--steps", "10"]
    assert _train(*common, "--data", str(two), "--out", str(out), "--hold-out", "door") == 0
    val = read_metrics(out / "metrics.csv")[("val", "loss")]
    assert val[0] == [0, 5, 10] and all(np.isfinite(val[1]))
    record = json.loads((out / "train.json").read_text())
    assert record["hold_out"] == "door" and record["validation"]["source"] == "hold-out family"
    assert record["data"]["samples"] == 5  # the pick_place pairs only: door is held out
    assert "validation loss" in capsys.readouterr().out

    test_split = tmp_path / "test_split"
    shutil.copytree(tiny, test_split)
    manifest = json.loads((test_split / "manifest.json").read_text())
    manifest["definition"]["split"] = "test"
    (test_split / "manifest.json").write_text(json.dumps(manifest))
    out2 = tmp_path / "val_data"
    args = [*common, "--data", str(tiny), "--out", str(out2), "--val-data", str(test_split)]
    assert _train(*args) == 0
    assert read_metrics(out2 / "metrics.csv")[("val", "loss")][0] == [0, 5, 10]
    assert _train(*common, "--data", str(test_split), "--out", str(tmp_path / "x")) == 2
    assert "test'-split collection" in capsys.readouterr().err


@pytest.mark.slow
def test_bad_input_is_one_line_and_leaves_snapshots_untouched(
    tiny: Path, recipe: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ckpt"
    base = ["--method", "awda", "--data", str(tiny), "--out", str(out), "--recipe", str(recipe)]
    assert _train(*base, "--steps", "2", "--snapshot-every", "1") == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    capsys.readouterr()

    other_size = write_recipe(tmp_path, height=96, name="tiny96.toml")
    mosaic_only = tmp_path / "mosaic_only.toml"
    mosaic_only.write_text(recipe.read_text().replace('["pick_place", "mosaic"]', '["mosaic"]'))
    corrupt = tmp_path / "corrupt"
    shutil.copytree(tiny, corrupt)
    h5 = corrupt / "agent/pick_place/task_00.h5"
    h5.write_bytes(h5.read_bytes()[:5000])
    broken_manifest = tmp_path / "broken_manifest"
    shutil.copytree(tiny, broken_manifest)
    (broken_manifest / "manifest.json").write_text("{not json")
    cases = {
        "recorded at 64x80": [*base[:6], "--recipe", str(other_size)],
        "'pick_place' collection": [*base[:6], "--recipe", str(mosaic_only)],
        "does not exist": ["--method", "awda", "--data", str(tmp_path / "none"), *base[4:]],
        "task_00.h5 is unreadable": ["--method", "awda", "--data", str(corrupt), *base[4:]],
        "manifest.json is unreadable": [
            "--method",
            "awda",
            "--data",
            str(broken_manifest),
            *base[4:],
        ],
        "unknown --hold-out family 'drawer'": [*base, "--hold-out", "drawer"],
        "holds another training run (it trains awda, not awda+no-adm": [
            *base,
            "--ablation",
            "no-adm",
        ],
        "recipe 'tiny', not 'tiny96'": [
            *base[:6],
            "--recipe",
            str(other_size.with_name("tiny96b.toml")),
        ],
        "recipe 'tiny' with [train] seed = 0, not 1": [*base, "--seed", "1"],
        "--seed must be >= 0": [*base, "--seed", "-1"],
        "unknown method 'daml'": ["--method", "daml", *base[2:]],
        "unknown device 'tpu'": [*base, "--device", "tpu"],
    }
    # another recipe of the right size: same data, same column, other name and trunk
    (tmp_path / "tiny96b.toml").write_text(
        recipe.read_text().replace('name = "tiny"', 'name = "tiny96"').replace("= 32", "= 48")
    )
    if not torch.cuda.is_available():
        cases["torch sees no CUDA device"] = [*base, "--device", "cuda"]
    for needle, args in cases.items():
        code = _train(*args)
        err = capsys.readouterr().err.strip()
        assert code != 0, needle
        assert needle in err and len(err.splitlines()) == 1, (needle, err)
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert after == before
    # --seed trains a replicate of the same recipe: recorded, and it resumes under the same seed
    replicate = [*base[:4], "--out", str(tmp_path / "seed3"), *base[6:], "--seed", "3"]
    assert _train(*replicate, "--steps", "1") == 0
    assert json.loads((tmp_path / "seed3/train.json").read_text())["recipe"]["train"]["seed"] == 3
    assert _train(*replicate, "--steps", "2") == 0

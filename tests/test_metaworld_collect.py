"""``collect --suite metaworld``: the plan and its refusals (fast), and a tiny real collection in
``.venv-metaworld`` workers (slow): ManiSkill-format trajectory files that the training datasets
read unchanged, deterministic, resumable.

The tiny collection: train tasks 30 (pick-place-v3: a grasp) and 43 (reach-v3), one episode per
role and one synthesized trajectory per task, 64x64 frames and 32x32 wrist depth, recorded once
per module with 2 workers. Tests marked
``needs_metaworld`` are skipped without ``.venv-metaworld`` (except under CI, where set-up made it).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from metaworld_env import needs_metaworld

from awda_bench.cli import main
from awda_bench.data.collect import MANIFEST, run_collect
from awda_bench.data.config import METAWORLD_SYNTHESIS, CollectConfig
from awda_bench.data.datasets import AwdaPairDataset, CollectedData, TosviDataset
from awda_bench.data.plan import make_plan
from awda_bench.errors import UsageError

PICK, REACH = 30, 43
"""pick-place-v3 and reach-v3: indices in tasks/metaworld.toml (both train tasks)."""


def tiny_config(out: Path, workers: int = 2) -> CollectConfig:
    return CollectConfig(
        suite="metaworld",
        split="train",
        embodiment="both",
        episodes_per_task=1,
        out=out,
        workers=workers,
        image_size=(64, 64),
        depth_size=(32, 32),
        tasks=(PICK, REACH),
        synthesize=2,
        progress=False,
    )


def arrays_of(root: Path) -> dict[str, np.ndarray]:
    """Every dataset of every unit file, by path (JPEG blobs as their bytes)."""
    out: dict[str, np.ndarray] = {}
    for h5 in sorted(root.rglob("task_*.h5")):
        with h5py.File(h5, "r") as f:

            def take(name: str, obj: object, prefix: str = str(h5.relative_to(root))) -> None:
                if isinstance(obj, h5py.Dataset):
                    value = obj[()]
                    if obj.dtype.kind == "O":
                        value = np.concatenate([np.asarray(v) for v in value])
                    out[f"{prefix}/{name}"] = np.asarray(value)

            f.visititems(take)
    return out


# ----------------------------------------------------------------------------- plan (fast)
def test_plan_is_the_45_train_tasks_at_the_suite_camera_size(tmp_path: Path) -> None:
    config = CollectConfig(
        suite="metaworld", split="train", embodiment="both", episodes_per_task=2, out=tmp_path
    )
    plan = make_plan(config)
    assert len({u.task for u in plan.units}) == 45
    assert {u.role for u in plan.units} == {"agent", "demonstrator"}
    assert plan.definition["image_size"] == [224, 224]  # tasks/metaworld.toml's camera
    test_plan = make_plan(CollectConfig(**{**config.__dict__, "split": "test"}))
    assert sorted(u.task for u in test_plan.units if u.role == "agent") == [6, 16, 28, 46, 48]
    # pick_place's default stays its camera's 240x320
    pick_place = CollectConfig(
        suite="pick_place", split="train", embodiment="agent", episodes_per_task=1, out=tmp_path
    )
    assert make_plan(pick_place).definition["image_size"] == [240, 320]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--workers", "0"], "--workers >= 1"),
        (["--task", "30", "--split", "test"], "not in the 'test' split"),
        (["--image-size", "32x32"], "use at least 64x64"),
    ],
)
def test_bad_input_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    out = tmp_path / "data"
    code = main(["collect", "--suite", "metaworld", *args, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert needle in err and len(err.splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize("backend", ["local", "ray"])
def test_collecting_in_this_process_is_refused_in_one_line(tmp_path: Path, backend: str) -> None:
    config = tiny_config(tmp_path / "data")
    with pytest.raises(UsageError, match="--workers >= 1") as err:
        make_plan(CollectConfig(**{**config.__dict__, "backend": backend, "workers": 0}))
    assert "\n" not in str(err.value)


def test_a_missing_second_environment_is_one_line_and_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("AWDA_METAWORLD_PYTHON", str(tmp_path / "no-venv" / "bin" / "python"))
    out = tmp_path / "data"
    code = main(["collect", "--suite", "metaworld", "--task", "43", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "bash scripts/setup.sh" in err
    assert not out.exists()


# ----------------------------------------------------------------------------- tiny collection
@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.getbasetemp() / "mw_tiny"
    result = run_collect(tiny_config(out, workers=2))
    assert result.complete and result.errors == 0, result.error_messages
    return out


@pytest.mark.slow
@needs_metaworld
def test_collection_is_maniskill_trajectory_files(tiny: Path) -> None:
    manifest = json.loads((tiny / MANIFEST).read_text())
    assert manifest["complete"] and manifest["counts"]["kept"] == 6
    for unit in manifest["units"]:
        if unit["role"] == "synthesized":
            continue  # test_synthesized_trajectories_are_feasible_free_space_motion
        h5_path = tiny / unit["file"]
        meta = json.loads(h5_path.with_suffix(".json").read_text())
        name = "pick-place-v3" if unit["task"] == PICK else "reach-v3"
        assert meta["env_info"]["env_id"] == name
        kwargs = meta["env_info"]["env_kwargs"]
        assert kwargs["sensor_configs"]["third_person"] == {
            "camera": "corner4",
            "height": 64,
            "width": 64,
        }
        (episode,) = meta["episodes"]
        T = episode["elapsed_steps"]
        # kept: success at some step; the episode ends 5 steps after the first
        assert episode["info"]["success_once"] and T == episode["success_step"] + 5
        assert episode["robot_uid"] == "sawyer" and episode["role"] == unit["role"]
        with h5py.File(h5_path, "r") as f:
            g = f["traj_0"]
            assert g["actions"].shape == (T, 4) and g["actions"].dtype == np.float32
            assert np.all(np.abs(g["actions"][:]) <= 1.0)
            assert g["success"][:].any()
            assert g["obs/extra/tcp_pose"].shape == (T + 1, 7)
            assert g["obs/agent/qpos"].shape == (T + 1, 9)
            assert g["obs/sensor_data/third_person/rgb_jpeg"].shape == (T + 1,)
            assert g["obs/sensor_param/third_person/intrinsic_cv"].shape == (T + 1, 3, 3)
            assert g["obs/sensor_param/third_person/extrinsic_cv"].shape == (T + 1, 3, 4)
            assert g["env_states/qpos"].shape[0] == T + 1
            assert g["attributes/grasp"].shape == g["attributes/press"].shape == (T,)
            assert not g["attributes/press"][:].any()
            has_depth = "wrist_depth" in g["obs/sensor_data"]
            assert has_depth == (unit["role"] == "agent")
            if has_depth:
                depth = g["obs/sensor_data/wrist_depth/depth"]
                assert depth.shape == (T + 1, 32, 32, 1) and depth.dtype == np.uint16
                assert 0 < np.median(depth[0]) < 2000  # millimetres: the table within 2 m
            grasp = g["attributes/grasp"][:]
            if unit["task"] == PICK:
                assert grasp.any()  # the expert picks the puck: mined with the Sawyer's miner
            else:
                assert not grasp.any()  # reaching never closes on anything


@pytest.mark.slow
@needs_metaworld
def test_the_training_datasets_read_it(tiny: Path) -> None:
    data = CollectedData(tiny)
    pairs = AwdaPairDataset(data)
    assert len(pairs) == 4  # one agent x one demonstrator episode per task, 2 synthesized
    sample = pairs[0]
    assert sample["demo"].shape == (10, 3, 64, 64) and sample["first_frame"].shape == (3, 64, 64)
    assert sample["trajectory"].shape == (50, 4)
    # the trajectory's first point is the TCP of the first frame, and the frame shows it: the
    # TCP projects inside the image through the stored camera
    ref = data.select("agent")[0]
    intrinsic, extrinsic = data.camera(ref)
    tcp = data.tcp_pos(ref)[0]
    u, v, w = intrinsic @ (extrinsic @ np.append(tcp, 1.0))
    assert w > 0 and 0 <= u / w < 64 and 0 <= v / w < 64
    pick = next(p for p in pairs.pairs if p[0].task == PICK)
    assert pairs.trajectory(pick[0])[:, 3].any()  # the grasp attribute reaches the label
    tosvi = TosviDataset(data, with_depth=True, depth_size=(32, 32))
    item = tosvi[0]
    assert item["frames"].shape == (6, 3, 64, 64) and item["actions"].shape == (6, 4)
    assert item["depth"].shape == (6, 1, 32, 32)
    data.close()


@needs_metaworld
def test_contact_points_label_where_the_hand_first_moves_the_object(tiny: Path) -> None:
    """The identification label of episodes without a grasp (``contact_points=True``): on
    pick-place the hand first moves the puck where it grasps it; reach moves nothing; a
    synthesized path's touches label nothing."""
    data = CollectedData(tiny)
    pairs = AwdaPairDataset(data, contact_points=True)
    by_origin = {(agent.task, agent.role): i for i, (agent, _, _) in enumerate(pairs.pairs)}
    pick = pairs[by_origin[(PICK, "agent")]]
    assert pick["contact"][3] == 1.0 and pick["demo_contact"][3] == 1.0
    agent = pairs.pairs[by_origin[(PICK, "agent")]][0]
    grasping = np.flatnonzero(data.attributes(agent, ("grasp",))[:, 0])
    first_grasp = data.tcp_pos(agent)[grasping[0]]
    assert np.linalg.norm(pick["contact"][:3].numpy() - first_grasp) < 0.02
    assert pairs[by_origin[(REACH, "agent")]]["contact"].tolist() == [0.0] * 4
    assert pairs[by_origin[(PICK, "synthesized")]]["contact"].tolist() == [0.0] * 4
    assert "contact" not in AwdaPairDataset(data)[0]  # off unless asked for
    data.close()


@pytest.mark.slow
@needs_metaworld
def test_synthesized_trajectories_are_feasible_free_space_motion(tiny: Path) -> None:
    """The Sawyer reaches every drawn waypoint (within the motion's 2 mm), inside the Meta-World
    box, with the hand open: no grasp is mined; head 1, and the wrist depth of an agent episode."""
    box = METAWORLD_SYNTHESIS
    synthesized = [u for u in json.loads((tiny / MANIFEST).read_text())["units"]
                   if u["role"] == "synthesized"]  # fmt: skip
    assert sorted(u["task"] for u in synthesized) == [PICK, REACH]
    for unit in synthesized:
        h5_path = tiny / unit["file"]
        (episode,) = json.loads(h5_path.with_suffix(".json").read_text())["episodes"]
        waypoints = np.asarray(episode["waypoints"])
        assert 1 <= len(waypoints) <= 3 and all(episode["waypoints_reached"])
        assert np.all(waypoints >= box.low_m) and np.all(waypoints <= box.high_m)
        assert episode["head"] == 1 and episode["role"] == "synthesized"
        with h5py.File(h5_path, "r") as f:
            g = f["traj_0"]
            tcp = g["obs/extra/tcp_pose"][:, :3]
            for waypoint in waypoints:  # the recorded path passes through each waypoint
                assert np.linalg.norm(tcp - waypoint, axis=1).min() < 0.003
            assert not g["attributes/grasp"][:].any()  # the hand never closed
            assert np.all(g["actions"][:, 3] < 0)  # Meta-World's "open" every step
            assert np.all(g["obs/extra/gripper_opening_m"][:] > 0.035)
            assert g["obs/sensor_data/wrist_depth/depth"].shape[0] == len(tcp)
    # the plan's definition names Meta-World's box, not pick-and-place's
    definition = json.loads((tiny / MANIFEST).read_text())["definition"]
    assert definition["synthesis"]["low_m"] == list(box.low_m)


@pytest.mark.slow
@needs_metaworld
def test_a_training_batch_mixes_both_heads_by_origin(tiny: Path) -> None:
    """Head 0 for the task-driven pairs, head 1 for the synthesized (self-paired) ones, in one
    batch, and the network's waypoints for each sample come from that sample's head."""
    import torch

    from awda_bench.models.awda_net import AwdaNet
    from awda_bench.models.config import AwdaConfig, TrunkConfig

    data = CollectedData(tiny)
    pairs = AwdaPairDataset(data)
    batch = torch.utils.data.default_collate([pairs[i] for i in range(len(pairs))])
    origin = [agent.role for agent, _demo, _head in pairs.pairs]
    assert batch["head"].tolist() == [1 if r == "synthesized" else 0 for r in origin]
    assert sorted(batch["head"].tolist()) == [0, 0, 1, 1]
    for agent, demo, head in pairs.pairs:  # a synthesized trajectory is its own demonstration
        assert (agent == demo) == (head == 1)
    torch.manual_seed(0)
    trunk = TrunkConfig(image_height_px=64, image_width_px=64, backbone_weights="none")
    model = AwdaNet(AwdaConfig(trunk=trunk)).eval()
    with torch.no_grad():
        mixed = model(batch["demo"], batch["first_frame"], batch["head"])
        flipped = model(batch["demo"], batch["first_frame"], 1 - batch["head"])
        for i, head in enumerate(batch["head"].tolist()):
            alone = model(batch["demo"][i : i + 1], batch["first_frame"][i : i + 1],
                          torch.tensor([head]))  # fmt: skip
            torch.testing.assert_close(mixed[i], alone[0], rtol=1e-4, atol=1e-4)
    assert float((mixed - flipped).abs().max()) > 1e-3  # the heads differ
    data.close()


@pytest.mark.slow
@needs_metaworld
def test_same_command_again_is_the_same_data_and_one_worker_too(tiny: Path, tmp_path: Path) -> None:
    again = tmp_path / "again"
    result = run_collect(tiny_config(again, workers=1))
    assert result.complete
    ours, theirs = arrays_of(tiny), arrays_of(again)
    assert ours.keys() == theirs.keys()
    for key, value in ours.items():
        assert np.array_equal(value, theirs[key]), key
    first = json.loads((tiny / MANIFEST).read_text())
    second = json.loads((again / MANIFEST).read_text())
    assert first["fingerprint"] == second["fingerprint"]


@pytest.mark.slow
@needs_metaworld
def test_collecting_on_ray_actors_from_the_second_environment_is_the_same_data(
    tiny: Path, tmp_path: Path
) -> None:
    on_ray = tmp_path / "ray"
    result = run_collect(CollectConfig(**{**tiny_config(on_ray).__dict__, "backend": "ray"}))
    assert result.complete and result.errors == 0, result.error_messages
    ours, theirs = arrays_of(tiny), arrays_of(on_ray)
    assert ours.keys() == theirs.keys()
    assert all(np.array_equal(v, theirs[k]) for k, v in ours.items())


@pytest.mark.slow
@needs_metaworld
def test_a_killed_collection_resumes_only_what_is_missing(tiny: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(tiny, copy)
    lost = copy / "agent" / "pick-place" / f"task_{PICK:02d}"
    lost.with_suffix(".h5").unlink()  # killed before this unit was consolidated
    lost.with_suffix(".json").unlink()
    result = run_collect(tiny_config(copy, workers=1))
    assert result.complete and result.already == 5 and result.kept == 1
    ours, theirs = arrays_of(tiny), arrays_of(copy)
    assert ours.keys() == theirs.keys()
    assert all(np.array_equal(v, theirs[k]) for k, v in ours.items())

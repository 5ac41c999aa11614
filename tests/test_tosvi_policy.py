"""The learned closed-loop ``tosvi`` method: per-frame features (RGB, and +depth's wrist-depth
vectors) computed once per frame give the same action distribution as the network's full forward
pass on the same stack; the stack pads with
the first frame as training samples do; actions are valid (gripper binarized); wrong snapshots
and options are refused in one line."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from awda_bench.data.trajectory_file import as_stored  # the frames as the policy sees them
from awda_bench.episode import EpisodeContext, EpisodeSpec, WristDepth
from awda_bench.models.architectures import build_model
from awda_bench.models.config import AwdaConfig, TosviConfig, TrunkConfig
from awda_bench.models.snapshot import save_snapshot

H, W = 64, 80


def _trunk() -> TrunkConfig:
    return TrunkConfig(image_height_px=H, image_width_px=W, demo_frames=2, backbone_weights="none")


@pytest.fixture
def snapshot(tmp_path: Path) -> Path:
    torch.manual_seed(0)
    model = build_model(TosviConfig(trunk=_trunk(), frame_stack=3))
    path = tmp_path / "snapshot-000000001.pt"
    save_snapshot(path, model, step=1)
    return path


@pytest.fixture
def depth_snapshot(tmp_path: Path) -> Path:
    torch.manual_seed(0)
    config = TosviConfig(
        trunk=_trunk(), frame_stack=3, use_depth=True, depth_height_px=32, depth_width_px=40
    )
    path = tmp_path / "depth" / "snapshot-000000001.pt"
    path.parent.mkdir()
    save_snapshot(path, build_model(config), step=1)
    return path


class _Frames:
    """Stands in for the episode's observations: the demo, and a new random 120x160 frame (and a
    64x80 wrist depth image, nearest-resized by the policy) per capture."""

    num_envs = 1

    def __init__(self, demo: np.ndarray) -> None:
        self.rng = np.random.default_rng(0)
        self.demo = demo
        self.shown: list[np.ndarray] = []
        self.depths: list[np.ndarray] = []

    def demo_frames(self, count: int = 10) -> np.ndarray:
        assert count == len(self.demo)
        return self.demo

    def rgb(self) -> np.ndarray:
        frame = self.rng.integers(0, 256, (1, 120, 160, 3), dtype=np.uint8)
        self.shown.append(frame[0])
        return frame

    def wrist_depth(self) -> WristDepth:
        depth = self.rng.uniform(0.05, 1.5, (1, 64, 80)).astype(np.float32)
        self.depths.append(depth[0, ::2, ::2])  # what nearest-resizing to 32x40 keeps
        return WristDepth(depth, np.eye(3)[None], np.eye(4)[None])


def _policy(snapshot: Path, monkeypatch: pytest.MonkeyPatch, select: str):
    from awda_bench.policies.tosvi_policy import TosviPolicy

    demo = np.random.default_rng(1).integers(0, 256, (2, 120, 160, 3), dtype=np.uint8)
    camera = _Frames(demo)
    policy = TosviPolicy(snapshot, select)
    spec = EpisodeSpec(suite="pick_place", task=14, episode=0, seed=1, demo_seed=2)
    policy.reset(EpisodeContext(env=None, spec=spec, observations=camera))  # type: ignore[arg-type]
    return policy, camera, demo


def _small(frames: np.ndarray) -> torch.Tensor:
    import cv2

    out = np.stack([cv2.resize(f, (W, H), interpolation=cv2.INTER_AREA) for f in frames])
    return torch.from_numpy(out).permute(0, 3, 1, 2).float()[None] / 255.0


def test_cached_stack_equals_the_full_forward_pass(
    snapshot: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    policy, camera, demo = _policy(snapshot, monkeypatch, "mode")
    for step in range(5):
        action = policy.act(None)
        shown = camera.shown
        # training's stack: o_{t-2} .. o_t, indices below 0 repeat frame 0
        index = np.clip(np.arange(step - 2, step + 1), 0, None)
        expected = policy.model.predict_action(
            _small(as_stored(demo, policy.jpeg_quality)),
            _small(as_stored(np.stack([shown[i] for i in index]), policy.jpeg_quality)),
            statistic="mode",
        )[0].numpy()
        assert action.shape == (1, 4) and action.dtype == np.float32
        np.testing.assert_allclose(action[0, :3], expected[:3], atol=1e-5)
        assert action[0, 3] == (1.0 if expected[3] > 0 else -1.0)
    assert policy.steps == 5 and policy.inference_s > 0 and not policy.done
    assert 0 < policy.encode_s < policy.inference_s  # frames through the trunk, then attention


def test_cached_depth_vectors_equal_the_full_forward_pass(
    depth_snapshot: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    policy, camera, demo = _policy(depth_snapshot, monkeypatch, "mode")
    assert policy.name == "tosvi-depth"
    for step in range(5):
        action = policy.act(None)
        index = np.clip(np.arange(step - 2, step + 1), 0, None)
        depth = torch.from_numpy(np.stack([camera.depths[i] for i in index]))[None, :, None]
        expected = policy.model.predict_action(
            _small(as_stored(demo, policy.jpeg_quality)),
            _small(as_stored(np.stack([camera.shown[i] for i in index]), policy.jpeg_quality)),
            depth,
            statistic="mode",
        )[0].numpy()
        np.testing.assert_allclose(action[0, :3], expected[:3], atol=1e-5)
        assert action[0, 3] == (1.0 if expected[3] > 0 else -1.0)


def test_sampled_actions_are_valid_and_follow_torch_seed(
    snapshot: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    runs = []
    for _ in range(2):
        torch.manual_seed(7)
        policy, _, _ = _policy(snapshot, monkeypatch, "sample")
        runs.append(np.concatenate([policy.act(None) for _ in range(4)]))
    assert np.array_equal(runs[0], runs[1])
    assert np.all(np.abs(runs[0][:, :3]) <= 1.0) and set(runs[0][:, 3]) <= {-1.0, 1.0}


def test_wrong_snapshots_and_selections_are_refused(tmp_path: Path, snapshot: Path) -> None:
    from awda_bench.errors import CorruptFileError, UnknownChoiceError
    from awda_bench.policies.tosvi_policy import TosviPolicy, tosvi_method_name

    awda = tmp_path / "awda" / "snapshot-000000001.pt"
    awda.parent.mkdir()
    save_snapshot(awda, build_model(AwdaConfig(trunk=_trunk())), step=1)
    with pytest.raises(CorruptFileError, match="holds a 'awda' model"):
        TosviPolicy(awda)
    with pytest.raises(CorruptFileError, match="not 'tosvi-depth'"):
        TosviPolicy(snapshot, arch="tosvi-depth")
    with pytest.raises(UnknownChoiceError):
        TosviPolicy(snapshot, "argmax")
    assert tosvi_method_name("tosvi", "sample") == "tosvi"
    assert tosvi_method_name("tosvi-depth", "mean") == "tosvi-depth-mean"


def test_action_select_is_folded_into_the_method(tmp_path: Path, capsys) -> None:

    from awda_bench.cli import build_parser, main
    from awda_bench.commands.run import config_from_args

    parser = build_parser()

    def method(*extra: str) -> str:
        args = parser.parse_args(["run", "--suite", "pick_place", "--out", str(tmp_path), *extra])
        return config_from_args(args).method

    assert method("--method", "tosvi") == "tosvi"
    assert method("--method", "tosvi", "--action-select", "mode") == "tosvi-mode"
    assert method("--method", "tosvi-depth", "--action-select", "mean") == "tosvi-depth-mean"
    code = main(
        ["run", "--suite", "pick_place", "--method", "awda", "--action-select", "mean",
         "--out", str(tmp_path / "runs")]
    )  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--action-select" in err
    assert not (tmp_path / "runs").exists()


@pytest.mark.slow
def test_run_plays_tosvi_snapshots_closed_loop_on_the_real_env(
    snapshot: Path, tmp_path: Path
) -> None:
    checkpoints = snapshot.parent
    save_snapshot(
        checkpoints / "snapshot-000000002.pt",
        build_model(TosviConfig(trunk=_trunk(), frame_stack=3)),
        step=2,
    )
    out = tmp_path / "runs"
    command = [
        sys.executable, "-m", "awda_bench", "run", "--suite", "pick_place", "--method", "tosvi",
        "--action-select", "mode", "--checkpoints", str(checkpoints), "--snapshots", "2",
        "--episodes", "1", "--task", "14", "--workers", "1", "--out", str(out), "--no-progress",
    ]  # fmt: skip
    result = subprocess.run(command, capture_output=True, text=True, timeout=900, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    with sqlite3.connect(out / "results.sqlite") as db:
        rows = db.execute("SELECT snapshot, status, steps, method FROM episodes").fetchall()
    assert len(rows) == 2 and len({r[0] for r in rows}) == 2
    # closed loop: never done, so every episode runs the whole horizon
    assert all(r[1] == "ok" and r[2] == 180 and r[3] == "tosvi-mode" for r in rows)

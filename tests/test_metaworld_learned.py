"""The learned methods on Meta-World: ``awda`` (and ``awda-centre``) drive the Sawyer with its own
executor and localization parameters and its mocap-lead actions
(:mod:`awda_bench.metaworld.sawyer_interface`), the Panda elsewhere as before; ``tosvi``'s action
goes to Meta-World as it is; a snapshot voting on another camera's rays is refused in one line;
both play short episodes through the harness in ``.venv-metaworld`` workers.

The snapshots are untrained (random weights, nothing learned): these tests check the plumbing,
not success. Tests marked ``needs_metaworld`` start workers from ``.venv-metaworld`` and are
skipped without it (outside CI), as in ``tests/test_metaworld_suite.py``.
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from metaworld_env import needs_metaworld

from awda_bench.episode import EpisodeContext, EpisodeSpec, Proprioception, WristDepth
from awda_bench.errors import UsageError
from awda_bench.evaluation.results_store import ResultsStore
from awda_bench.evaluation.sweep import SweepConfig, run_sweep
from awda_bench.metaworld.sawyer import (
    SAWYER_EXECUTOR,
    SAWYER_LOCALIZATION,
    STEP_M,
    TRACKING_GAIN,
    lead_action,
)
from awda_bench.metaworld.sawyer_interface import SawyerInterface
from awda_bench.models.architectures import build_model
from awda_bench.models.config import AwdaConfig, TosviConfig, TrunkConfig
from awda_bench.models.snapshot import save_snapshot
from awda_bench.policies.awda_policy import AwdaPolicy, awda
from awda_bench.primitives.config import ExecutorConfig
from awda_bench.primitives.executor import WaypointExecutor
from awda_bench.primitives.wrist_camera import WRIST_LOCALIZATION
from awda_bench.suites import SUITES_DIR, load_suite

TESTS = Path(__file__).resolve().parent
SIZE = 224
"""Meta-World's third-person frames (Table S2)."""
MW_K = np.array([[270.0, 0.0, 112.0], [0.0, 270.0, 112.0], [0.0, 0.0, 1.0]])
MW_E = np.array([[1.0, 0.0, 0.0, 0.1], [0.0, -1.0, 0.0, 0.6], [0.0, 0.0, -1.0, 1.2]])
PANDA_K = np.array([[277.0, 0.0, 160.0], [0.0, 277.0, 120.0], [0.0, 0.0, 1.0]])
"""A ManiSkill-like 240 x 320 camera: a snapshot trained with it must refuse Meta-World's."""


def _trunk(head: str = "self-attention") -> TrunkConfig:
    return TrunkConfig(
        image_height_px=64, image_width_px=64, demo_frames=2, backbone_weights="none", head=head
    )


def _camera(k: np.ndarray, size: tuple[int, int]) -> dict[str, tuple]:
    return {
        "camera_intrinsic": tuple(float(v) for v in k.ravel()),  # plain floats: weights_only
        "camera_extrinsic": tuple(float(v) for v in MW_E.ravel()),
        "camera_size": size,
    }


def _awda(path: Path, **config: object) -> Path:
    """An untrained AWDA snapshot (random weights) at ``path``."""
    torch.manual_seed(0)
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_snapshot(path, build_model(AwdaConfig(**config)), step=1)  # type: ignore[arg-type]


def _tosvi(path: Path) -> Path:
    torch.manual_seed(0)
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_snapshot(path, build_model(TosviConfig(trunk=_trunk(), frame_stack=3)), step=2)


class _PandaView:
    """An observation-only episode's observations (no robot of its own: the Panda)."""

    num_envs = 1

    def __init__(self) -> None:
        rng = np.random.default_rng(0)
        self.frames = rng.integers(0, 256, (3, SIZE, SIZE, 3), dtype=np.uint8)
        self.tcp = np.array([0.0, 0.6, 0.2])

    def demo_frames(self, count: int = 10) -> np.ndarray:
        return self.frames[:count]

    def first_frame(self) -> np.ndarray:
        return self.frames[-1]

    def rgb(self) -> np.ndarray:
        return self.frames[-1:]

    def wrist_depth(self) -> WristDepth:
        depth = np.full((1, 128, 128), 0.3, dtype=np.float32)
        return WristDepth(depth, np.eye(3)[None] * 64, np.eye(4)[None])

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        return MW_K, MW_E

    def proprio(self) -> Proprioception:
        return Proprioception(
            tcp_pos=self.tcp.reshape(1, 3),
            tcp_quat=np.array([[1.0, 0.0, 0.0, 0.0]]),
            gripper_opening_m=np.array([0.08]),
            qpos=np.zeros((1, 9)),
        )


class _SawyerView(_PandaView):
    """Meta-World's observations: the hand's mocap target (5 mm ahead of the TCP in y, 12 cm
    above it) and the Sawyer as the robot."""

    mocap_ahead_m = np.array([0.0, 0.005, 0.12])

    def hand_target(self) -> np.ndarray:
        return (self.tcp + self.mocap_ahead_m).reshape(1, 3)

    def robot_interface(self) -> SawyerInterface:
        return SawyerInterface(self)


def _context(view: _PandaView) -> EpisodeContext:
    spec = EpisodeSpec(suite="metaworld", task=6, episode=0, seed=1, demo_seed=2)
    return EpisodeContext(env=None, spec=spec, observations=view)  # type: ignore[arg-type]


def test_the_sawyer_interface_runs_the_sawyers_parameters_and_leads_the_mocap() -> None:
    view = _SawyerView()
    robot = SawyerInterface(view)
    assert robot.executor_config(ExecutorConfig()) is SAWYER_EXECUTOR
    centre = replace(WRIST_LOCALIZATION, select="centre")
    assert robot.localization_config(centre) == replace(SAWYER_LOCALIZATION, select="centre")
    np.testing.assert_allclose(robot.offset, view.mocap_ahead_m)  # measured when built
    state = robot.robot_states()[0]
    np.testing.assert_array_equal(state.tcp_pos, view.tcp)
    assert state.gripper_opening_m == pytest.approx(0.08)
    assert np.all(robot.env_actions(np.array([[0.0, 0.0, 0.0, -1.0]]))[0, :3] == 0.0)  # at rest
    command = np.array([[0.1, -0.1, 0.04, 1.0]])
    action = robot.env_actions(command)
    assert action.shape == (1, 4) and action.dtype == np.float32
    want = TRACKING_GAIN * STEP_M * command[0, :3] / STEP_M  # the mocap's lead, in 1 cm units
    np.testing.assert_allclose(action[0, :3], want / max(1.0, np.abs(want).max()), rtol=1e-6)
    assert action[0, 3] == 1.0


@pytest.mark.parametrize("centre", [False, True], ids=["awda", "awda-centre"])
def test_awda_drives_the_sawyer_on_meta_world_and_the_panda_elsewhere(
    tmp_path: Path, centre: bool
) -> None:
    snapshot = _awda(tmp_path / "snapshot-000000001.pt", trunk=_trunk())
    for view in (_SawyerView(), _PandaView()):
        policy = awda(snapshot, "centre") if centre else AwdaPolicy(snapshot)
        policy.reset(_context(view))
        waypoints = policy.waypoints
        assert waypoints is not None and waypoints.shape == (5, 4)
        select = "centre" if centre else "waypoint"
        config = policy.episode_config
        if isinstance(view, _SawyerView):
            robot = SawyerInterface(view)
            assert config.executor is SAWYER_EXECUTOR
            assert config.localization == replace(SAWYER_LOCALIZATION, select=select)
        else:
            assert config == policy.config  # the Panda's parameters, as before
            assert config.executor == ExecutorConfig() and config.localization.select == select
        twin = WaypointExecutor(
            waypoints,
            SawyerInterface(_SawyerView()).locator(0, config.localization),
            config.executor,
        )
        for _ in range(6):
            action = policy.act(view)
            command = twin.step(policy._robot.robot_states()[0])  # type: ignore[union-attr]
            assert action.shape == (1, 4) and action.dtype == np.float32
            assert np.isfinite(action).all() and np.abs(action).max() <= 1.0
            if isinstance(view, _SawyerView):  # the command as the mocap action that leads to it
                want = lead_action(view.tcp, view.hand_target()[0], command, robot.offset)
                np.testing.assert_array_equal(action[0], want)
            else:  # the Panda's controller takes the command as it is
                np.testing.assert_array_equal(action[0], command.astype(np.float32))


def test_a_snapshot_for_another_camera_is_refused_in_one_line(tmp_path: Path) -> None:
    head = _trunk("demo-to-scene")
    foreign = _awda(
        tmp_path / "a" / "snapshot-000000001.pt", trunk=head, **_camera(PANDA_K, (240, 320))
    )
    policy = AwdaPolicy(foreign)
    with pytest.raises(UsageError, match="camera") as err:
        policy.reset(_context(_SawyerView()))
    assert "\n" not in str(err.value)
    # trained with Meta-World's 224 x 224 camera: its rays fit, it predicts (64 x 64 net input)
    own = _awda(tmp_path / "b" / "snapshot-000000001.pt", trunk=head, **_camera(MW_K, (SIZE, SIZE)))
    policy = AwdaPolicy(own)
    policy.reset(_context(_SawyerView()))
    assert policy.waypoints is not None and np.isfinite(policy.waypoints).all()


# ------------------------------------------------------------------ through the harness
SHORT_HORIZON = 30
"""Steps per episode in the harness tests (the suite's 500 are for measuring)."""


def _short_suites(directory: Path) -> Path:
    """The ``metaworld`` suite file with a :data:`SHORT_HORIZON`-step horizon."""
    text = (SUITES_DIR / "metaworld.toml").read_text()
    assert "horizon_steps = 500" in text
    directory.mkdir()
    short = text.replace("horizon_steps = 500", f"horizon_steps = {SHORT_HORIZON}")
    (directory / "metaworld.toml").write_text(short)
    return directory


def _sweep(out: Path, method: str, checkpoints: Path, suites: Path, snapshots: int = 1) -> object:
    suite = load_suite("metaworld")
    button = next(t for t in suite.held_out if suite.task(t).name == "button-press-v3")
    return run_sweep(
        SweepConfig(
            suite="metaworld",
            method=method,
            out=out,
            checkpoints=checkpoints,
            snapshots=snapshots,
            episodes=1,
            workers=1,
            tasks=(button,),
            suites_dir=suites,
            progress=False,
        )
    )


def _rows(out: Path) -> list[tuple]:
    with ResultsStore(out, create=False) as store:
        return store.raw(
            "SELECT method, snapshot, status, error, steps, waypoints FROM episodes ORDER BY rowid"
        )


@pytest.mark.slow
@needs_metaworld
def test_awda_and_tosvi_play_meta_world_episodes_through_the_harness(tmp_path: Path) -> None:
    suites = _short_suites(tmp_path / "suites")
    awda = tmp_path / "awda"
    _awda(awda / "snapshot-000000001.pt", trunk=_trunk())
    head = _trunk("demo-to-scene")
    _awda(awda / "snapshot-000000002.pt", trunk=head, **_camera(PANDA_K, (240, 320)))
    _sweep(tmp_path / "ra", "awda", awda, suites, snapshots=2)
    (_, _, ok, _, steps, waypoints), (_, _, refused, error, _, _) = _rows(tmp_path / "ra")
    assert ok == "ok" and 0 < steps <= SHORT_HORIZON
    points = np.asarray(json.loads(waypoints))
    assert points.shape == (5, 4) and set(points[:, 3]) <= {0.0, 1.0}
    assert refused == "error"  # the foreign camera: one line, naming the fix
    last = error.strip().splitlines()[-1]
    assert last.startswith("awda_bench.errors.UsageError: this AWDA snapshot votes waypoints")
    assert "evaluate it on the suite it was trained on" in last

    tosvi = tmp_path / "tosvi"
    _tosvi(tosvi / "snapshot-000000002.pt")
    _sweep(tmp_path / "rt", "tosvi", tosvi, suites)
    [(method, _, status, error, steps, waypoints)] = _rows(tmp_path / "rt")
    assert (method, status, error) == ("tosvi", "ok", None)
    assert steps == SHORT_HORIZON and waypoints is None  # closed loop: it never stops early


@pytest.mark.slow
@needs_metaworld
def test_the_workers_act_in_meta_worlds_action_space_without_mink_or_maniskill(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])
    )
    suites = _short_suites(tmp_path / "suites")
    checkpoints = tmp_path / "both"
    _awda(checkpoints / "snapshot-000000001.pt", trunk=_trunk())
    _tosvi(checkpoints / "snapshot-000000002.pt")
    _sweep(tmp_path / "r", "metaworld_learned_probe:LearnedProbe", checkpoints, suites, 2)
    rows = _rows(tmp_path / "r")
    assert [r[2] for r in rows] == ["ok", "ok"], [r[3] for r in rows]
    for arch, (_, _, _, _, steps, waypoints) in zip(("awda", "tosvi"), rows, strict=True):
        probe = np.asarray(json.loads(waypoints))
        count, finite, largest, n_rows, n_cols, float32 = probe[0]
        assert count == steps > 0 and finite == 1.0 and largest <= 1.0
        assert (n_rows, n_cols, float32) == (1, 4, 1.0)  # Meta-World's (1, 4) float32 action
        sawyer, localization, robot, foreign = probe[1, :4]
        if arch == "awda":
            assert (sawyer, localization, robot) == (1.0, 1.0, 1.0)
        else:
            assert (sawyer, localization, robot) == (-1.0, -1.0, -1.0)
        assert foreign == 0.0  # the worker imported none of mink, ManiSkill, SAPIEN

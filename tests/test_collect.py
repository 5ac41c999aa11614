"""``collect``: the plan (fast), bad input (fast), and a tiny real collection (slow).

The tiny collection: pick_place train task 0, 2 episodes per embodiment + 1 synthesized, 64x80
frames. It is recorded once per session (``tiny_collection``) with 2 workers; a second copy is
recorded with 1 worker, killed with SIGKILL after its first shard, and resumed: both must be
identical, frame for frame.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from awda_bench.cli import main
from awda_bench.data.collect import MANIFEST, run_collect
from awda_bench.data.config import CollectConfig, parse_image_size
from awda_bench.data.plan import job_seed, make_plan, split_tasks
from awda_bench.data.trajectory_file import PARTIAL_DIR, decode_jpeg
from awda_bench.episode import derive_seed
from awda_bench.errors import CorruptFileError, UsageError
from awda_bench.suites import load_suite


def tiny_collect_argv(embodiment: str = "both", episodes_per_task: int = 2) -> list[str]:
    """A tiny collection's command line (without ``--out`` and ``--workers``): pick_place's
    task 0, ``episodes_per_task`` of ``embodiment``, one synthesized episode, 64 x 80 images."""
    return [
        "collect",
        "--suite",
        "pick_place",
        "--split",
        "train",
        "--embodiment",
        embodiment,
        "--episodes-per-task",
        str(episodes_per_task),
        "--task",
        "0",
        "--synthesize",
        "1",
        "--image-size",
        "64x80",
        "--no-progress",
    ]


TINY_ARGS = tiny_collect_argv()
"""The tiny collection's command line (without ``--out`` and ``--workers``)."""


def tiny_config(out: Path, workers: int = 2) -> CollectConfig:
    return CollectConfig(
        suite="pick_place",
        split="train",
        embodiment="both",
        episodes_per_task=2,
        out=out,
        workers=workers,
        image_size=(64, 80),
        synthesize=1,
        tasks=(0,),
        progress=False,
    )


def tiny_collection_dir(factory: pytest.TempPathFactory) -> Path:
    """Record the tiny collection once per session (a complete one is simply resumed: no work)."""
    out = factory.getbasetemp() / "tiny_collection"
    result = run_collect(tiny_config(out, workers=2))
    assert result.complete and result.errors == 0
    return out


def tree_digest(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


# ----------------------------------------------------------------------------- plan (fast)
def test_plan_units_seeds_and_splits(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, workers=1)
    plan = make_plan(config)
    assert [(u.role, u.task, u.planned) for u in plan.units] == [
        ("agent", 0, 2),
        ("demonstrator", 0, 2),
        ("synthesized", 0, 1),
    ]
    # seeds depend on (suite, seed, task, attempt, role) only, and differ between roles
    assert job_seed(config, 0, 1, "agent") == job_seed(tiny_config(tmp_path, 2), 0, 1, "agent")
    assert job_seed(config, 0, 1, "agent") != job_seed(config, 0, 1, "demonstrator")
    # disjoint from the evaluation's scenes of the same tasks
    collected = {
        job_seed(config, t, i, r)
        for t in range(16)
        for i in range(20)
        for r in ("agent", "demonstrator")
    }
    evaluated = {
        derive_seed("pick_place", 0, t, i, r)
        for t in range(16)
        for i in range(20)
        for r in ("agent", "demo")
    }
    assert not collected & evaluated
    suite = load_suite("pick_place")
    assert [t.index for t in split_tasks(suite, "train")] == list(range(14))
    assert [t.index for t in split_tasks(suite, "test")] == [14, 15]
    mosaic = load_suite("mosaic")
    train_families = {t.family for t in split_tasks(mosaic, "train")}
    assert len(train_families) == 7  # every family: leave-one-out is a selection
    # the fingerprint follows the definition, not the output directory or worker count
    assert make_plan(tiny_config(tmp_path / "x", workers=2)).fingerprint == plan.fingerprint
    other = CollectConfig(**{**config.__dict__, "seed": 1})
    assert make_plan(other).fingerprint != plan.fingerprint


def test_synthesized_count_is_spread_over_tasks(tmp_path: Path) -> None:
    config = CollectConfig(
        suite="pick_place",
        split="train",
        embodiment="agent",
        episodes_per_task=0,
        out=tmp_path,
        synthesize=30,
    )
    units = make_plan(config).units
    assert {u.role for u in units} == {"synthesized"}
    assert sum(u.planned for u in units) == 30
    assert {u.planned for u in units} == {2, 3}


# ----------------------------------------------------------------------------- bad input (fast)
@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--suite", "nope"], "unknown suite 'nope'"),
        (["--suite", "pick_place", "--split", "val"], "unknown split 'val'"),
        (["--suite", "pick_place", "--embodiment", "sawyer"], "unknown embodiment 'sawyer'"),
        (["--suite", "pick_place", "--image-size", "32x32"], "use at least 64x64"),
        (["--suite", "pick_place", "--image-size", "big"], "is not HxW"),
        (["--suite", "pick_place", "--task", "15"], "not in the 'train' split"),
        (["--suite", "pick_place", "--episodes-per-task", "0"], "nothing to collect"),
    ],
)
def test_bad_input_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    out = tmp_path / "data"
    code = main(["collect", *args, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert needle in err and len(err.splitlines()) == 1
    assert not out.exists()  # refused before writing anything


def test_foreign_and_unwritable_dirs_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    assert main([*TINY_ARGS, "--out", str(foreign)]) == 2
    assert "not a collect directory" in capsys.readouterr().err
    assert (foreign / "notes.txt").read_text() == "mine" and len(list(foreign.iterdir())) == 1
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main([*TINY_ARGS, "--out", str(blocker)]) == 2
    assert "is a file" in capsys.readouterr().err
    assert main([*TINY_ARGS, "--out", str(blocker / "sub")]) == 2
    err = capsys.readouterr().err.strip()
    assert "cannot write to --out" in err and len(err.splitlines()) == 1


def test_parse_image_size() -> None:
    assert parse_image_size("240x320") == (240, 320)
    assert parse_image_size(" 64X80 ") == (64, 80)
    with pytest.raises(UsageError, match="at least 64x64"):
        parse_image_size("63x80")


# ----------------------------------------------------------------------------- tiny collection
@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_collection_dir(tmp_path_factory)


@pytest.mark.slow
def test_collection_is_maniskill_trajectory_files(tiny: Path) -> None:
    manifest = json.loads((tiny / MANIFEST).read_text())
    assert manifest["complete"] is True
    assert manifest["counts"]["planned"] == manifest["counts"]["kept"] == 5
    assert manifest["fingerprint"] == make_plan(tiny_config(tiny)).fingerprint
    assert len(manifest["code_sha256"]) == 1  # (other files may change during a long session)
    assert not (tiny / PARTIAL_DIR).exists() or not any((tiny / PARTIAL_DIR).rglob("*.h5"))
    for unit in manifest["units"]:
        h5_path = tiny / unit["file"]
        meta = json.loads(h5_path.with_suffix(".json").read_text())
        assert meta["env_info"]["env_id"] == "AWDA-PickPlace-v1"
        assert meta["env_info"]["env_kwargs"]["sensor_configs"]["third_person"] == {
            "height": 64,
            "width": 80,
        }
        assert len(meta["episodes"]) == unit["planned"]
        seeds = [e["episode_seed"] for e in meta["episodes"]]
        assert len(set(seeds)) == len(seeds)  # no episode twice
        with h5py.File(h5_path, "r") as f:
            assert sorted(f.keys()) == [f"traj_{i}" for i in range(unit["planned"])]
            for episode in meta["episodes"]:
                g = f[f"traj_{episode['episode_id']}"]
                T = episode["elapsed_steps"]
                assert episode["reset_kwargs"]["seed"] == episode["episode_seed"]
                assert episode["reset_kwargs"]["options"] == {"task": 0}
                assert g["actions"].shape == (T, 4) and g["actions"].dtype == np.float32
                assert g["env_states/actors/milk"].shape == (T + 1, 13)
                assert g["obs/extra/tcp_pose"].shape == (T + 1, 7)
                assert g["obs/sensor_data/third_person/rgb_jpeg"].shape == (T + 1,)
                frame = decode_jpeg(g["obs/sensor_data/third_person/rgb_jpeg"][T])
                assert frame.shape == (64, 80, 3)
                assert g["attributes/grasp"].shape == g["truth/grasp"].shape == (T,)
                has_depth = "wrist_depth" in g["obs/sensor_data"]
                assert has_depth == (unit["role"] != "demonstrator")
                if unit["role"] == "synthesized":
                    assert episode["head"] == 1 and all(episode["waypoints_reached"])
                    assert not g["attributes/grasp"][:].any()
                else:
                    assert episode["success"] is True and episode["head"] == 0
                    # the expert grasped: mined attribute and simulator truth both saw it
                    assert g["attributes/grasp"][:].any() and g["truth/grasp"][:].any()


@pytest.mark.slow
def test_same_command_again_does_nothing(tiny: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = tree_digest(tiny)
    assert main([*TINY_ARGS, "--out", str(tiny), "--workers", "2"]) == 0
    assert "5 already kept, 0 kept" in capsys.readouterr().out
    assert tree_digest(tiny) == before


@pytest.mark.slow
def test_other_definition_in_same_dir_is_refused(
    tiny: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = tree_digest(tiny)
    assert main([*TINY_ARGS, "--out", str(tiny), "--seed", "7"]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds another collection" in err and "differs in seed" in err
    assert len(err.splitlines()) == 1
    assert tree_digest(tiny) == before


@pytest.mark.slow
def test_corrupt_shard_is_named_and_nothing_is_lost(tiny: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(tiny, copy)
    # make the agent unit unfinished, with a damaged shard of its attempt 0
    (copy / "agent/pick_place/task_00.json").unlink()
    shard = copy / PARTIAL_DIR / "agent/pick_place/task_00/a00000.h5"
    shard.parent.mkdir(parents=True)
    shard.write_bytes(b"not hdf5")
    before = tree_digest(copy)
    with pytest.raises(CorruptFileError, match="a00000.h5 is unreadable.*delete it"):
        run_collect(tiny_config(copy, workers=0))
    assert tree_digest(copy) == before


def _frames_and_arrays(root: Path) -> dict[str, object]:
    """Every dataset of every unit file, JPEG frames decoded (for equality checks)."""
    out: dict[str, object] = {}
    for h5_path in sorted(root.rglob("*.h5")):
        with h5py.File(h5_path, "r") as f:

            def visit(name: str, obj: object, h5_path: Path = h5_path) -> None:
                if isinstance(obj, h5py.Dataset):
                    if name.endswith("rgb_jpeg"):
                        out[f"{h5_path.relative_to(root)}:{name}"] = [
                            decode_jpeg(b).tobytes() for b in obj[:]
                        ]
                    else:
                        out[f"{h5_path.relative_to(root)}:{name}"] = obj[()].tobytes()

            f.visititems(visit)
    return out


@pytest.mark.slow
def test_sigkill_then_resume_equals_two_worker_run(tiny: Path, tmp_path: Path) -> None:
    """1 worker, one episode per job, killed after its first shard and resumed == 2 workers,
    five episodes per job, uninterrupted."""
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "awda_bench", *TINY_ARGS, "--out", str(out), "--workers", "1"]
    cmd += ["--chunk-episodes", "1"]  # a shard stays unconsolidated until its unit's next job
    proc = subprocess.Popen(
        cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        deadline = time.monotonic() + 600
        while not any((out / PARTIAL_DIR).rglob("a*.h5")) and time.monotonic() < deadline:
            assert proc.poll() is None, "collect finished before it could be killed"
            time.sleep(0.1)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the collect process and its worker
        proc.wait()
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["complete"] is False
    assert main([*TINY_ARGS, "--out", str(out), "--workers", "1"]) == 0
    ours = json.loads((out / MANIFEST).read_text())
    theirs = json.loads((tiny / MANIFEST).read_text())
    if ours["code_sha256"] != theirs["code_sha256"]:
        pytest.skip("the recording code changed between the two collections (shared tree)")
    assert ours == theirs
    assert _frames_and_arrays(out) == _frames_and_arrays(tiny)
    for unit in ours["units"]:
        meta = json.loads((out / unit["file"]).with_suffix(".json").read_text())
        assert len(meta["episodes"]) == unit["planned"]


@pytest.mark.slow
def test_stored_env_state_reproduces_frame_and_tcp(tiny: Path) -> None:
    """set_state_dict(state of step t) -> the same TCP pose and the same (JPEG) frame."""
    import torch
    from mani_skill.trajectory import utils as trajectory_utils
    from mani_skill.utils import common

    from awda_bench.data.recorder import EpisodeRecorder, encode_jpeg
    from awda_bench.robot.cameras import capture_rgb

    recorder = EpisodeRecorder(tiny_config(tiny))
    try:
        for role in ("agent", "demonstrator"):
            env, _ = recorder.env_for(0, role)
            episode = json.loads((tiny / f"{role}/pick_place/task_00.json").read_text())[
                "episodes"
            ][1]
            env.reset(**episode["reset_kwargs"])
            with h5py.File(tiny / f"{role}/pick_place/task_00.h5", "r") as f:
                g = f["traj_1"]
                states = trajectory_utils.dict_to_list_of_dicts(g["env_states"])
                for t in (len(states) // 2, len(states) - 1):
                    env.unwrapped.set_state_dict(common.to_tensor(common.batch(states[t])))
                    tcp = env.unwrapped.agent.tcp_pose.raw_pose[0].cpu().numpy()
                    np.testing.assert_allclose(tcp, g["obs/extra/tcp_pose"][t], atol=1e-5)
                    jpeg = encode_jpeg(capture_rgb(env)[0], 90)
                    assert jpeg == g["obs/sensor_data/third_person/rgb_jpeg"][t].tobytes()
                    assert isinstance(env.unwrapped.agent.tcp_pose.raw_pose, torch.Tensor)
    finally:
        recorder.close()


def _replay(path: Path, *extra: str) -> str:
    proc = subprocess.run(
        [sys.executable, "-m", "awda_bench", "replay", "--traj-path", str(path), *extra],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


@pytest.mark.slow
def test_maniskill_replay_by_actions_reaches_the_recorded_outcome(tiny: Path) -> None:
    out = _replay(tiny / "agent/pick_place/task_00.h5")
    assert "Replayed 2 episodes, 2/2=100.00% demos saved" in out
    out = _replay(tiny / "demonstrator/pick_place/task_00.h5")
    assert "Replayed 2 episodes, 2/2=100.00% demos saved" in out


@pytest.mark.slow
def test_maniskill_replay_by_env_states_reaches_the_recorded_outcome(tiny: Path) -> None:
    out = _replay(tiny / "agent/pick_place/task_00.h5", "--use-env-states")
    assert "Replayed 2 episodes, 2/2=100.00% demos saved" in out


@pytest.mark.slow
def test_maniskill_replay_of_the_demonstrator_by_env_states(tiny: Path) -> None:
    out = _replay(tiny / "demonstrator/pick_place/task_00.h5", "--use-env-states")
    assert "Replayed 2 episodes, 2/2=100.00% demos saved" in out


def test_replay_without_a_trajectory_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["replay", "--traj-path", str(tmp_path / "none.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert "need an existing .h5 trajectory file" in err and len(err.splitlines()) == 1
    assert main(["replay"]) == 2
    assert "replay needs --traj-path" in capsys.readouterr().err


# ----------------------------------------------------------------------------- scheduling (fast)
def _fake_episode(job, success: bool):
    from awda_bench.data.recorder import EpisodeData, encode_jpeg

    T = 3
    frame = np.full((64, 80, 3), job.attempt * 10 % 255, dtype=np.uint8)
    return EpisodeData(
        job=job,
        success=success,
        actions=np.zeros((T, 4), np.float32),
        success_steps=np.full(T, success),
        rgb_jpeg=[encode_jpeg(frame, 90)] * (T + 1),
        obs={"extra": {"tcp_pose": np.zeros((T + 1, 7), np.float32)}},
        env_states={"actors": {"cube": np.zeros((T + 1, 13), np.float32)}},
        attributes={"grasp": np.zeros(T, bool), "press": np.zeros(T, bool)},
        truth={"grasp": np.zeros(T, bool)},
        meta={
            "episode_seed": job.seed,
            "attempt": job.attempt,
            "elapsed_steps": T,
            "success": success,
            "code_sha256": "0" * 64,  # "older code" than the tree's
        },
        env_info={"env_id": "AWDA-PickPlace-v1", "env_kwargs": {}, "max_episode_steps": 300},
    )


class FakeRunner:
    """Runs the real attempt sequence (run_unit_job) without simulation: attempts in ``fail``
    are discarded, attempts in ``error`` raise."""

    def __init__(self, fail: set[int] = frozenset(), error: set[int] = frozenset()) -> None:
        self.fail, self.error = fail, error
        self.played: list[tuple[str, int]] = []
        self.replayed: list[tuple[str, int]] = []

    def run(self, jobs, on_result) -> None:
        from collections import deque

        from awda_bench.data.pool import run_unit_job

        def record(attempt):
            self.played.append((attempt.role, attempt.attempt))
            if attempt.attempt in self.error:
                raise RuntimeError("boom")
            return _fake_episode(attempt, attempt.attempt not in self.fail)

        def replay(attempt):
            self.replayed.append((attempt.role, attempt.attempt))

        queue = deque(jobs)
        while queue:
            job = queue.popleft()
            config = tiny_config(Path("unused"))
            queue.extend(on_result(run_unit_job(job, config, record, replay)))


def _fake_config(out: Path, **kw) -> CollectConfig:
    base = dict(
        suite="pick_place",
        split="train",
        embodiment="agent",
        episodes_per_task=3,
        out=out,
        tasks=(0,),
        progress=False,
    )
    return CollectConfig(**{**base, **kw})


def test_failed_attempts_are_replaced_and_counted(tmp_path: Path) -> None:
    runner = FakeRunner(fail={1, 3})
    result = run_collect(_fake_config(tmp_path), runner=runner)
    assert result.complete and result.kept == 3 and result.discarded == 2 and result.errors == 0
    # attempts 0, 1, 2 first; 1 failed -> 3; 3 failed -> 4
    assert runner.played == [("agent", 0), ("agent", 1), ("agent", 2), ("agent", 3), ("agent", 4)]
    meta = json.loads((tmp_path / "agent/pick_place/task_00.json").read_text())
    assert [e["episode_id"] for e in meta["episodes"]] == [0, 1, 2]
    assert [d["attempt"] for d in meta["discarded"]] == [1, 3]
    manifest = json.loads((tmp_path / MANIFEST).read_text())
    assert manifest["counts"]["discarded"] == 2 and manifest["counts"]["kept"] == 3
    with h5py.File(tmp_path / "agent/pick_place/task_00.h5", "r") as f:
        assert sorted(f.keys()) == ["traj_0", "traj_1", "traj_2"]
        # traj_1 is attempt 2 (attempt 1 was discarded)
        assert decode_jpeg(f["traj_1/obs/sensor_data/third_person/rgb_jpeg"][0])[0, 0, 0] in range(
            15, 26
        )


def test_errors_are_kept_apart_and_retried_on_rerun(tmp_path: Path) -> None:
    first = run_collect(_fake_config(tmp_path), runner=FakeRunner(error={1}))
    assert first.errors == 1 and first.kept == 1 and first.discarded == 0 and not first.complete
    assert "agent/pick_place/task_00: RuntimeError: boom" in first.error_messages[0]
    assert json.loads((tmp_path / MANIFEST).read_text())["complete"] is False
    again = FakeRunner()
    second = run_collect(_fake_config(tmp_path), runner=again)
    # attempt 0 is replayed (the env's history), only the missing ones are recorded
    assert again.replayed == [("agent", 0)] and again.played == [("agent", 1), ("agent", 2)]
    assert second.complete and second.already == 1 and second.kept == 2
    # resumed under other code than the first episodes': completed, with a warning
    assert "partly recorded by other code (code_sha256 000000000000)" in second.warnings[0]
    assert json.loads((tmp_path / MANIFEST).read_text())["code_sha256"] == ["0" * 64]


def test_chunks_replay_the_units_history(tmp_path: Path) -> None:
    runner = FakeRunner(fail={1})
    result = run_collect(_fake_config(tmp_path, chunk_episodes=1), runner=runner)
    assert result.complete and result.kept == 3 and result.discarded == 1
    assert runner.played == [("agent", 0), ("agent", 1), ("agent", 2), ("agent", 3)]
    # every chunk starts in a fresh env and replays the unit's earlier attempts in order
    assert runner.replayed == [("agent", 0), ("agent", 0), ("agent", 1), ("agent", 2)]


def _unit_contents(root: Path) -> tuple[dict, dict[str, list]]:
    """A finished unit's JSON and its arrays (JPEG frames as bytes), traj by traj."""
    meta = json.loads((root / "agent/pick_place/task_00.json").read_text())
    arrays: dict[str, list] = {}

    def read(key: str, obj: object) -> None:
        if isinstance(obj, h5py.Dataset):
            values = obj[()]
            arrays[key] = [bytes(v) for v in values] if obj.dtype.kind == "O" else values.tolist()

    with h5py.File(root / "agent/pick_place/task_00.h5", "r") as f:
        f.visititems(read)
    return meta, arrays


def test_a_larger_collection_extends_a_finished_smaller_one(tmp_path: Path) -> None:
    small = tmp_path / "small"
    assert run_collect(_fake_config(small, episodes_per_task=2), runner=FakeRunner(fail={1}))
    four = {"episodes_per_task": 4}
    fresh = run_collect(_fake_config(tmp_path / "fresh", **four), runner=FakeRunner(fail={1, 4}))
    runner = FakeRunner(fail={1, 4})
    big = run_collect(_fake_config(tmp_path / "big", extend_from=small, **four), runner=runner)
    # attempts 0 and 2 kept, 1 discarded in the small one: only 3, 4 (failed) and 5 are recorded
    assert big.complete and big.extended == 2 and big.already == 2 and big.kept == 2
    assert runner.replayed == [("agent", 0), ("agent", 1), ("agent", 2)]
    assert runner.played == [("agent", 3), ("agent", 4), ("agent", 5)]
    assert fresh.complete and _unit_contents(tmp_path / "big") == _unit_contents(tmp_path / "fresh")
    manifest = json.loads((tmp_path / "big" / MANIFEST).read_text())
    assert manifest["fingerprint"] == make_plan(_fake_config(tmp_path, **four)).fingerprint
    # done: a re-run seeds and records nothing
    again = run_collect(_fake_config(tmp_path / "big", extend_from=small, **four), FakeRunner())
    assert again.extended == 0 and again.kept == 0 and again.already == 4


def test_an_extension_only_from_a_finished_smaller_collection_of_the_same_options(
    tmp_path: Path,
) -> None:
    small = tmp_path / "small"
    run_collect(_fake_config(small, episodes_per_task=2), runner=FakeRunner())
    unfinished = tmp_path / "unfinished"
    run_collect(_fake_config(unfinished, episodes_per_task=2), runner=FakeRunner(error={1}))
    cases = {
        "differs in seed": _fake_config(tmp_path / "a", seed=3, extend_from=small),
        "holds more than this collection plans (episodes_per_task 2 > 1)": _fake_config(
            tmp_path / "b", episodes_per_task=1, extend_from=small
        ),
        "that collection is unfinished": _fake_config(tmp_path / "c", extend_from=unfinished),
        "no manifest.json there": _fake_config(tmp_path / "d", extend_from=tmp_path / "none"),
    }
    for needle, config in cases.items():
        with pytest.raises(UsageError, match=re.escape(needle)):
            run_collect(config, runner=FakeRunner())
        assert not config.out.exists()  # refused before anything is written


def test_a_task_the_expert_always_fails_gives_up(tmp_path: Path) -> None:
    config = _fake_config(tmp_path, episodes_per_task=1, max_attempts_factor=1)
    result = run_collect(config, runner=FakeRunner(fail=set(range(100))))
    assert not result.complete and result.kept == 0 and result.discarded == 11
    assert result.errors == 1 and "gave up after 11 attempts" in result.error_messages[0]


def test_quick_is_two_tasks_two_episodes(tmp_path: Path) -> None:
    from awda_bench.cli import build_parser
    from awda_bench.commands.collect import config_from_args

    args = build_parser().parse_args(
        ["collect", "--suite", "pick_place", "--quick", "--synthesize", "9", "--out", str(tmp_path)]
    )
    config = config_from_args(args)
    assert config.tasks == (0, 1) and config.episodes_per_task == 2 and config.synthesize == 2

"""The Meta-World suites (``tasks/metaworld.toml``, ``tasks/metaworld_ml45.toml``): the suite
files, the second environment's workers, seeded layouts, "any step" success and the one-line
errors.

Tests marked ``needs_metaworld`` start workers from ``.venv-metaworld`` (made by
``bash scripts/setup.sh``); without it they are skipped, except under CI (``CI`` set), where
set-up has made it and they must run.
"""

from __future__ import annotations

import json
import os
import subprocess
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from metaworld_env import metaworld_python, needs_metaworld

from awda_bench.episode import EpisodeContext, EpisodeSpec
from awda_bench.errors import CorruptFileError, UnknownChoiceError, UsageError
from awda_bench.evaluation.episode_runner import run_episode
from awda_bench.evaluation.results_store import ResultsStore
from awda_bench.evaluation.sweep import SweepConfig, prepare_sweep, run_sweep
from awda_bench.metaworld_tasks import ALL_TASKS, ML45_TEST, REFERENCE_HELD_OUT
from awda_bench.runtimes import MissingEnvironmentError
from awda_bench.suites import SUITES_DIR, load_suite

TESTS = Path(__file__).resolve().parent


def test_suite_files_hold_out_the_reference_five_and_ml45_test_set() -> None:
    suite = load_suite("metaworld")
    assert suite.simulator == "metaworld"
    assert [t.name for t in suite.tasks] == list(ALL_TASKS)
    assert sorted(t.name for t in suite.eval_tasks) == sorted(REFERENCE_HELD_OUT)
    assert len(suite.train_tasks) == 45
    assert {t.name for t in suite.eval_tasks} == {
        "sweep-into-v3",
        "window-open-v3",
        "button-press-v3",
        "door-unlock-v3",
        "pick-place-wall-v3",
    }
    assert suite.camera.name is not None and (suite.camera.height, suite.camera.width) == (224, 224)
    ml45 = load_suite("metaworld_ml45")
    assert sorted(t.name for t in ml45.eval_tasks) == sorted(ML45_TEST)
    assert [t.name for t in ml45.tasks] == list(ALL_TASKS)
    assert ml45.horizon_steps == suite.horizon_steps


def test_every_metaworld_task_carries_its_published_difficulty(tmp_path: Path) -> None:
    # the grouping both suite files cite: 28 easy, 11 medium, 6 hard, 5 very hard
    for name in ("metaworld", "metaworld_ml45"):
        counts = Counter(t.difficulty for t in load_suite(name).tasks)
        assert counts == {"easy": 28, "medium": 11, "hard": 6, "very_hard": 5}
    held_out = {t.name: t.difficulty for t in load_suite("metaworld").eval_tasks}
    assert held_out["pick-place-wall-v3"] == "very_hard" and held_out["sweep-into-v3"] == "medium"
    text = (SUITES_DIR / "metaworld.toml").read_text().replace('"very_hard"', '"brutal"', 1)
    (tmp_path / "metaworld.toml").write_text(text)
    with pytest.raises(CorruptFileError, match="difficulty 'brutal', not one of"):
        load_suite("metaworld", tmp_path)


def test_a_bad_task_name_is_one_line_naming_the_valid_ones(tmp_path: Path) -> None:
    text = (
        (SUITES_DIR / "metaworld.toml").read_text().replace('"door-unlock-v3"', '"door-unlok-v3"')
    )
    (tmp_path / "metaworld.toml").write_text(text)
    config = SweepConfig(
        suite="metaworld", method="random", out=tmp_path / "runs", suites_dir=tmp_path
    )
    with pytest.raises(UnknownChoiceError) as err:
        prepare_sweep(config)
    message = str(err.value)
    assert "\n" not in message
    assert "door-unlok-v3" in message and "door-unlock-v3" in message and "sweep-into-v3" in message
    assert not (tmp_path / "runs").exists()


def test_a_missing_second_environment_is_one_line_naming_setup(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from awda_bench.cli import main

    monkeypatch.setenv("AWDA_METAWORLD_PYTHON", str(tmp_path / "no-venv" / "bin" / "python"))
    with pytest.raises(MissingEnvironmentError, match="bash scripts/setup.sh"):
        prepare_sweep(SweepConfig(suite="metaworld", method="random", out=tmp_path / "runs"))
    code = main(["run", "--suite", "metaworld", "--method", "random", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "bash scripts/setup.sh" in err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("backend", ["local", "ray"])
def test_playing_in_this_process_is_refused(tmp_path: Path, backend: str) -> None:
    config = SweepConfig(
        suite="metaworld", method="random", out=tmp_path / "r", workers=0, backend=backend
    )
    with pytest.raises(UsageError, match="--workers >= 1") as err:
        prepare_sweep(config)
    assert "\n" not in str(err.value)


def test_ray_actors_need_ray_at_the_drivers_version_in_the_second_environment(
    tmp_path: Path,
) -> None:
    from awda_bench.runtimes import check_worker_ray

    no_ray = tmp_path / "python"  # an interpreter whose `import ray` fails
    no_ray.write_text("#!/bin/sh\nexit 1\n")
    no_ray.chmod(0o755)
    with pytest.raises(UsageError, match="has no Ray.*bash scripts/setup.sh") as err:
        check_worker_ray(str(no_ray), "2.60.0")
    assert "\n" not in str(err.value)
    other = tmp_path / "python-other"
    other.write_text("#!/bin/sh\nprintf 1.2.3\n")
    other.chmod(0o755)
    with pytest.raises(UsageError, match="has ray 1.2.3, this environment ray 2.60.0"):
        check_worker_ray(str(other), "2.60.0")


def test_videos_are_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from awda_bench.cli import main

    code = main(["run", "--suite", "metaworld", "--videos", "1", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--videos" in err
    assert not (tmp_path / "r").exists()


class _FlagEnv:
    """An env whose per-step success flag is up at step 3 only (Meta-World's is not sticky)."""

    def __init__(self) -> None:
        self.t = 0
        self.unwrapped = self

    def reset(self, *, seed: int, options: dict[str, Any]) -> tuple[np.ndarray, dict[str, Any]]:
        self.t = 0
        return np.zeros(3), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.t += 1
        return np.zeros(3), 0.0, False, False, {"success": float(self.t == 3)}

    def episode_observations(self, spec: EpisodeSpec, extras: dict[str, Any]) -> Any:
        class _Obs:
            num_envs = 1

            def mark_stepped(self) -> None:
                pass

        return _Obs()


class _Still:
    name = "still"
    privileged = True

    def reset(self, ctx: EpisodeContext) -> None:
        pass

    def act(self, obs: Any) -> np.ndarray:
        return np.zeros((1, 4), dtype=np.float32)

    done = False
    waypoints = None


def test_success_is_any_step_not_the_last() -> None:
    suite = load_suite("metaworld")
    task = suite.held_out[0]
    spec = EpisodeSpec(suite.name, task, 0, seed=1, demo_seed=2)
    record = run_episode(_FlagEnv(), _Still(), spec, suite, method="still", snapshot="builtin")
    assert record.steps == suite.horizon_steps
    assert record.success_once is True
    assert record.success_at_end is False


def _records(out: Path) -> dict[tuple[int, int], tuple[Any, ...]]:
    with ResultsStore(out, create=False) as store:
        rows = store.raw(
            "SELECT task, episode, seed, status, error, success_once, steps, waypoints FROM episodes"
        )
    return {(r[0], r[1]): r[2:] for r in rows}


@pytest.fixture
def probes_importable(monkeypatch: pytest.MonkeyPatch) -> None:
    """The probe policies (tests/metaworld_probe.py) must import in the workers too."""
    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])
    )


def _sweep(
    out: Path,
    method: str,
    workers: int,
    tasks: tuple[int, ...],
    episodes: int,
    backend: str = "local",
) -> Any:
    return run_sweep(
        SweepConfig(
            suite="metaworld",
            method=method,
            out=out,
            episodes=episodes,
            workers=workers,
            tasks=tasks,
            progress=False,
            backend=backend,
        )
    )


@pytest.mark.slow
@needs_metaworld
def test_layouts_are_seeded_identical_across_workers_backends_and_different_across_seeds(
    tmp_path: Path, probes_importable: None
) -> None:
    suite = load_suite("metaworld")
    tasks = (suite.held_out[0], suite.held_out[4])
    first = _sweep(tmp_path / "a", "metaworld_probe:ProbePolicy", 1, tasks, 2)
    second = _sweep(tmp_path / "b", "metaworld_probe:ProbePolicy", 2, tasks, 2)
    assert first.errors == second.errors == 0 and first.ran == second.ran == 4
    a, b = _records(tmp_path / "a"), _records(tmp_path / "b")
    assert a == b  # same spec, other worker process (and another run): the same observations
    # Ray actors started from .venv-metaworld's interpreter (runtime_env py_executable)
    on_ray = _sweep(tmp_path / "ray", "metaworld_probe:ProbePolicy", 2, tasks, 2, "ray")
    assert on_ray.errors == 0 and on_ray.ran == 4
    assert _records(tmp_path / "ray") == a
    probes = {key: np.array(json.loads(row[-1])) for key, row in a.items()}
    for task in tasks:
        assert not np.array_equal(probes[(task, 0)], probes[(task, 1)])  # another seed
    for probe in probes.values():
        tcp, opening = probe[0, :3], probe[0, 3]
        assert 0.0 < tcp[2] < 0.4 and 0.0 < opening < 0.2  # metres, above the table
        assert probe[1, 4:].tolist() == [224, 224]
        assert 0.5 < probe[1, 3] <= 1.0  # the wrist camera sees something almost everywhere
        point = probe[1, :3]
        # below the hand, on the table or an object on it: intrinsics and pose agree with the scene
        assert np.linalg.norm(point[:2] - tcp[:2]) < 0.1 and -0.05 < point[2] < tcp[2]
        u, v = probe[2, :2]
        assert 0 < u < 224 and 0 < v < 224  # the gripper is in the third-person frame


@pytest.mark.slow
@needs_metaworld
def test_the_demo_is_the_expert_in_another_layout_and_leaves_the_episode_as_it_was(
    tmp_path: Path, probes_importable: None
) -> None:
    suite = load_suite("metaworld")
    task = suite.held_out[0]  # button-press: the button goes in, the frame changes
    result = _sweep(tmp_path / "d", "metaworld_probe:DemoProbePolicy", 1, (task,), 1)
    row = _records(tmp_path / "d")[(task, 0)]
    assert result.errors == 0, row[2]
    probe = np.array(json.loads(row[-1]))
    count, first_mean, last_mean, unchanged = probe[3, :4]
    assert count == 10 and first_mean != last_mean
    assert unchanged == 1.0  # the episode's scene is back in its own layout after the demo


@pytest.mark.slow
@needs_metaworld
def test_a_worker_that_dies_is_recorded_and_replaced(
    tmp_path: Path, probes_importable: None
) -> None:
    task = load_suite("metaworld").held_out[1]
    result = _sweep(tmp_path / "c", "metaworld_probe:CrashingPolicy", 1, (task,), 2)
    rows = _records(tmp_path / "c")
    assert result.respawns == 1 and result.errors == 1
    assert rows[(task, 0)][1] == "error" and "exit code 7" in rows[(task, 0)][2]
    assert rows[(task, 1)][1] == "ok"  # the replacement worker played the next episode


@pytest.mark.slow
@needs_metaworld
def test_scripted_and_random_through_the_harness(tmp_path: Path) -> None:
    suite = load_suite("metaworld")
    task = suite.held_out[2]
    scripted = _sweep(tmp_path / "s", "scripted", 1, (task,), 3)
    random = _sweep(tmp_path / "r", "random", 1, (task,), 2)
    assert scripted.errors == random.errors == 0
    assert scripted.successes == 3 and random.successes == 0
    rows = _records(tmp_path / "s")
    assert all(row[4] < suite.horizon_steps for row in rows.values())  # stops at its success
    assert all(row[4] == suite.horizon_steps for row in _records(tmp_path / "r").values())
    # the grasp analysis on Meta-World's object (the puck): the primitives reach it before they
    # close, close on it and lift it (the scripted experts start closing 5-8 cm away, or at once:
    # the analysis reads the grasp primitive's way); random actions never lift it
    gt = _sweep(tmp_path / "g", "gt-waypoints-centre", 1, (task,), 2)
    assert gt.errors == 0 and gt.successes == 2
    with ResultsStore(tmp_path / "g", create=False) as store:
        grasps = store.raw("SELECT reached, grasped, first_grip FROM episodes")
    assert grasps == [(1, 1, "target")] * 2
    with ResultsStore(tmp_path / "r", create=False) as store:
        grasps = store.raw("SELECT grasped, first_grip FROM episodes")
    assert all(g == 0 and f in ("target", "nothing", "never") for g, f in grasps)
    with ResultsStore(tmp_path / "s", create=False) as store:
        versions = json.loads(store.raw("SELECT versions FROM runs")[0][0])
    assert versions[".venv-metaworld mujoco"] == "3.3.0"  # the MuJoCo that played, not .venv's
    assert versions[".venv-metaworld metaworld"] == "3.1.1"


@needs_metaworld
def test_task_names_match_the_package() -> None:
    python = metaworld_python()
    assert python is not None
    code = (
        "import json; from metaworld.env_dict import ALL_V3_ENVIRONMENTS as A, ML45_V3 as M; "
        "print(json.dumps([list(A), list(M['test'])]))"
    )
    out = subprocess.run([python, "-c", code], capture_output=True, text=True, check=True).stdout
    names, ml45 = json.loads(out.strip().splitlines()[-1])
    assert tuple(names) == ALL_TASKS and tuple(ml45) == ML45_TEST

"""Served policies (``serve`` + ``run --method remote``): the same episodes and records as
in-process, the actions and observations crossing unchanged, and every failure (wrong shape, NaN,
a policy that raises, a timeout, a server killed mid-run) one line, recorded as that episode's
error, retried by a re-run."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from harness_fakes import SkillPolicy, fake_sweep_config, learned_method, write_snapshots

from awda_bench.cli import main
from awda_bench.commands.serve import build_server
from awda_bench.episode import EpisodeContext, EpisodeSpec, Proprioception, WristDepth
from awda_bench.errors import RemotePolicyError, UsageError
from awda_bench.evaluation.methods import (
    get_method,
    register_method,
    select_snapshots,
    served_method,
    unregister_method,
)
from awda_bench.evaluation.results_store import STORE_NAME, ResultsStore
from awda_bench.evaluation.sweep import SweepConfig, run_sweep
from awda_bench.policies.random_policy import RandomPolicy
from awda_bench.serving.protocol import ServerInfo
from awda_bench.serving.remote_policy import RemotePolicy, ServedMethod
from awda_bench.serving.server import PolicyServer

TESTS = Path(__file__).resolve().parent
LEARNED = learned_method("served-learned")


@pytest.fixture(autouse=True)
def learned_method():
    register_method(LEARNED)
    yield
    unregister_method(LEARNED.name)


@contextmanager
def serving(server: PolicyServer) -> Iterator[str]:
    """Run ``server`` on a thread; yield its URL."""
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server.url
    finally:
        server.shutdown()
        thread.join(timeout=10)


def _served(make: Any, method: str) -> PolicyServer:
    info = ServerInfo(method, "builtin", "builtin", 0, learned=False)
    return PolicyServer(make, info)


def _sweep(suites: Path, out: Path, method: str, **kw: Any):
    return run_sweep(fake_sweep_config(suites, out, method, **kw))


def _rows(out: Path) -> list[tuple]:
    with ResultsStore(out, create=False) as store:
        return store.raw(
            "SELECT method, snapshot, task, episode, seed, demo_seed, status, success_once, "
            "success_at_end, reached, grasped, steps, waypoints FROM episodes "
            "ORDER BY method, snapshot, task, episode"
        )


def _errors(out: Path) -> dict[tuple[int, int], str]:
    with ResultsStore(out, create=False) as store:
        rows = store.raw("SELECT task, episode, error FROM episodes WHERE status='error'")
    return {(t, e): msg.strip().splitlines()[-1] for t, e, msg in rows}


# ---------------------------------------------------------------------------- same episodes


def test_a_served_policy_plays_the_same_episodes_as_in_process(suites, tmp_path) -> None:
    local = _sweep(suites, tmp_path / "local", "random")
    with serving(build_server("random")) as url:
        remote = _sweep(suites, tmp_path / "remote", "remote", policy_url=url)
    assert (remote.ran, remote.errors) == (local.ran, local.errors) == (8, 0)
    rows = _rows(tmp_path / "remote")
    assert rows == _rows(tmp_path / "local")
    assert {r[0] for r in rows} == {"random"}  # labelled with the served method's name
    assert {r[7] for r in rows} == {0, 1}  # the outcomes depend on the actions


def test_run_method_remote_from_the_command_line_with_a_worker_process(suites, tmp_path) -> None:
    out = tmp_path / "cli"
    with serving(build_server("random")) as url:
        code = main(
            ["run", "--suite", "fake", "--tasks-dir", str(suites), "--out", str(out),
             "--method", "remote", "--policy-url", url, "--policy-timeout", "30",
             "--workers", "1", "--episodes", "2", "--no-progress"]
        )  # fmt: skip
    assert code == 0
    _sweep(suites, tmp_path / "local", "random", episodes=2)
    assert _rows(out) == _rows(tmp_path / "local")


class _RecordingObservations:
    """Observations of a fake episode that log every call (what the served policy asked for)."""

    num_envs = 1

    def __init__(self) -> None:
        self.calls: list[str] = []
        self._rng = np.random.default_rng(3)

    def demo_frames(self, count: int = 10) -> np.ndarray:
        self.calls.append(f"demo_frames({count})")
        return self._rng.integers(0, 255, (count, 240, 320, 3), dtype=np.uint8)

    def first_frame(self) -> np.ndarray:
        self.calls.append("first_frame")
        return self._rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)

    def rgb(self) -> np.ndarray:
        self.calls.append("rgb")
        return self._rng.integers(0, 255, (1, 240, 320, 3), dtype=np.uint8)

    def wrist_depth(self) -> WristDepth:
        self.calls.append("wrist_depth")
        return WristDepth(
            self._rng.random((1, 128, 128), dtype=np.float32),
            np.eye(3)[None] * 64.0,
            np.eye(4)[None],
        )

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        self.calls.append("camera")
        return np.eye(3) * 200.0, np.eye(4)[:3]

    def proprio(self) -> Proprioception:
        self.calls.append("proprio")
        return Proprioception(
            self._rng.random((1, 3)), self._rng.random((1, 4)), self._rng.random(1), np.ones((1, 9))
        )


class _ObservingPolicy:
    """Asks for every observation and folds them all into its actions (float64, to check that
    the dtype crosses too)."""

    name = "observing"

    def reset(self, ctx: EpisodeContext) -> None:
        obs = ctx.observations
        assert obs is not None
        demo, first = obs.demo_frames(4), obs.first_frame()
        intrinsic, extrinsic = obs.camera()
        assert demo.shape == (4, 240, 320, 3) and demo.dtype == np.uint8
        self.total = float(demo.sum()) + float(first.sum()) + intrinsic[0, 0] + extrinsic[0, 0]

    def act(self, obs: Any) -> np.ndarray:
        depth, proprio = obs.wrist_depth(), obs.proprio()
        assert isinstance(depth, WristDepth) and isinstance(proprio, Proprioception)
        assert depth.depth_m.dtype == np.float32 and depth.cam2world_cv.shape == (1, 4, 4)
        value = float(obs.rgb().mean()) + float(depth.depth_m.sum()) + proprio.tcp_pos.sum()
        return np.array([[value, self.total % 1.0, proprio.gripper_opening_m[0], -1.0]])

    done = False
    waypoints = None


def _play(policy: Any, steps: int, observations: Any) -> list[np.ndarray]:
    spec = EpisodeSpec(suite="fake", task=2, episode=0, seed=1234, demo_seed=99)
    policy.reset(EpisodeContext(None, spec, observations=observations))
    return [policy.act(observations) for _ in range(steps)]


@pytest.mark.parametrize("make", [RandomPolicy, _ObservingPolicy], ids=["random", "observing"])
def test_actions_and_observations_cross_unchanged(make: Any) -> None:
    here, there = _RecordingObservations(), _RecordingObservations()
    expected = _play(make(), 20, here)
    with serving(_served(make, "m")) as url:
        remote = RemotePolicy(ServedMethod(url, ServerInfo("m", "builtin", "builtin", 0, False)))
        got = _play(remote, 20, there)
        remote.close()
    assert there.calls == here.calls  # the same observations, asked for in the same order
    assert all(
        a.dtype == b.dtype and np.array_equal(a, b) for a, b in zip(got, expected, strict=True)
    )


def test_a_served_learned_method_is_keyed_by_its_snapshot(suites, tmp_path) -> None:
    written = write_snapshots(tmp_path / "ckpt", [0.2, 0.9])
    newest = select_snapshots(LEARNED, tmp_path / "ckpt", last_n=1)[0]
    _sweep(suites, tmp_path / "local", LEARNED.name, checkpoints=tmp_path / "ckpt", snapshots=1)
    with serving(build_server(LEARNED.name, tmp_path / "ckpt")) as url:
        assert served_method(url).served.info.snapshot == newest.sha256  # type: ignore[union-attr]
        _sweep(suites, tmp_path / "remote", "remote", policy_url=url)
    assert _rows(tmp_path / "remote") == _rows(tmp_path / "local")
    with ResultsStore(tmp_path / "remote", create=False) as store:
        plan = store.raw("SELECT method, snapshot, name, learned FROM snapshots")
    assert plan == [(LEARNED.name, newest.sha256, written[-1].name, 1)]

    with pytest.raises(UsageError, match="no snapshot 'step_5.json'.*step_10000.json, step_20000"):
        build_server(LEARNED.name, tmp_path / "ckpt", "step_5.json")
    older = build_server(LEARNED.name, tmp_path / "ckpt", written[0].name)
    assert older.info.snapshot_name == written[0].name and older.info.snapshot_order == 0
    older.shutdown()


# ---------------------------------------------------------------------------- failures


class _BadActionPolicy(SkillPolicy):
    """Episode 1: an action of shape (1, 3); episode 2: NaN; otherwise fine."""

    def act(self, obs: Any) -> np.ndarray:
        action = super().act(obs)
        assert self.spec is not None
        if self.spec.episode == 1:
            return action[:, :3]
        if self.spec.episode == 2:
            return np.full_like(action, np.nan)
        return action


def test_a_wrong_shape_or_nan_is_that_episodes_one_line_error(suites, tmp_path) -> None:
    with serving(_served(_BadActionPolicy, "bad-action")) as url:
        result = _sweep(suites, tmp_path / "out", "remote", policy_url=url)
    assert (result.ran, result.errors) == (8, 4)  # episodes 1 and 2 of each task; the run goes on
    errors = _errors(tmp_path / "out")
    assert sorted(errors) == [(2, 1), (2, 2), (3, 1), (3, 2)]
    assert "RemotePolicyError" in errors[(2, 1)]
    assert "returned an action of shape (1, 3), expected (1, 4)" in errors[(2, 1)]
    assert "returned an action with NaN or inf" in errors[(3, 2)]


def test_a_served_policy_that_raises_fails_its_episode_only(suites, tmp_path) -> None:
    from harness_fakes import RaisingPolicy

    with serving(_served(RaisingPolicy, "raising")) as url:
        result = _sweep(suites, tmp_path / "out", "remote", policy_url=url)
    assert (result.ran, result.errors) == (8, 2)
    message = _errors(tmp_path / "out")[(2, 1)]
    assert "the served policy raised during step 1: RuntimeError: boom in act" in message


class _StallingPolicy(SkillPolicy):
    """Stalls in episode 1's first act until released (a stuck server)."""

    release = threading.Event()

    def act(self, obs: Any) -> np.ndarray:
        assert self.spec is not None
        if self.spec.episode == 1 and self.spec.task == 2:
            self.release.wait(30)
        return super().act(obs)


def test_a_timeout_is_an_error_and_the_next_episode_reconnects(suites, tmp_path) -> None:
    with serving(_served(_StallingPolicy, "stalling")) as url:
        try:
            result = _sweep(
                suites, tmp_path / "out", "remote", policy_url=url, policy_timeout_s=0.5
            )
        finally:
            _StallingPolicy.release.set()
    assert (result.ran, result.errors) == (8, 1)
    message = _errors(tmp_path / "out")[(2, 1)]
    assert "sent nothing for 0.5 s during step 1" in message and "--policy-timeout" in message


def _start_server(method: str, **env: str) -> tuple[subprocess.Popen[str], str]:
    command = [sys.executable, "-m", "awda_bench", "serve", "--method", method, "--port", "0"]
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), *sys.path]), **env}
    process = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=environment
    )
    assert process.stdout is not None
    line = process.stdout.readline()
    assert " on ws://" in line, process.stderr.read() if process.stderr else line
    return process, line.split(" on ")[1].split(";")[0]


def test_a_server_killed_mid_run_leaves_errors_that_a_re_run_retries(suites, tmp_path) -> None:
    out = tmp_path / "out"
    server, url = _start_server("harness_fakes:CrashingPolicy")  # exits in episode 1
    try:
        first = _sweep(suites, out, "remote", policy_url=url)
    finally:
        server.kill()
        server.wait()
    assert server.returncode == 7
    assert (first.ran, first.errors) == (8, 7)  # task 2 episode 0 played; then no server
    errors = _errors(out)
    assert "lost the connection to the policy server" in errors[(2, 1)]
    assert "cannot reach the policy server" in errors[(3, 0)]
    assert "re-run" in errors[(2, 1)] and "serve" in errors[(3, 0)]

    server, url = _start_server("harness_fakes:CrashingPolicy", AWDA_FAKE_NO_CRASH="1")
    try:
        second = _sweep(suites, out, "remote", policy_url=url)  # restarted on another port
    finally:
        server.kill()
        server.wait()
    assert (second.skipped, second.ran, second.errors) == (1, 7, 0)
    with ResultsStore(out, create=False) as store:
        attempts = store.raw("SELECT task, episode, attempts, status FROM episodes ORDER BY 1, 2")
    assert attempts[0] == (2, 0, 1, "ok")
    assert all(a == 2 and s == "ok" for _, _, a, s in attempts[1:])


# ---------------------------------------------------------------------------- refusals


def test_serving_a_privileged_method_is_refused_in_one_line(capsys) -> None:
    assert main(["serve", "--method", "scripted", "--port", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "'scripted' is privileged" in err and "cannot be served" in err


def test_remote_needs_a_reachable_server_and_is_checked_before_writing(suites, tmp_path) -> None:
    with pytest.raises(UsageError, match="--method remote needs --policy-url"):
        get_method("remote")
    with pytest.raises(UsageError, match="--policy-url applies to --method remote"):
        _sweep(suites, tmp_path / "a", "random", policy_url="ws://127.0.0.1:9")
    with pytest.raises(RemotePolicyError, match="cannot reach the policy server") as caught:
        _sweep(suites, tmp_path / "b", "remote", policy_url="ws://127.0.0.1:9", policy_timeout_s=2)
    assert len(str(caught.value).splitlines()) == 1
    assert not (tmp_path / "b" / STORE_NAME).exists()
    with serving(build_server("random")) as url:
        with pytest.raises(UsageError, match="drop --checkpoints"):
            _sweep(suites, tmp_path / "c", "remote", policy_url=url, checkpoints=tmp_path)


# ---------------------------------------------------------------------------- real episodes


@pytest.mark.slow
def test_a_served_example_policy_plays_real_episodes_as_in_process(tmp_path, monkeypatch) -> None:
    """The example's wrist-descend policy reads wrist depth and proprioception every step, so
    this covers observations rendered on the harness's side at the served policy's request."""
    monkeypatch.syspath_prepend(str(TESTS.parent / "examples"))
    method = "awda_example_policies.wrist_descend:WristDescendPolicy"

    def sweep(out: Path, **kw: Any) -> None:
        config = SweepConfig(
            suite="pick_place", out=out, progress=False, command="test", workers=0, episodes=1, **kw
        )
        result = run_sweep(config)
        assert (result.ran, result.errors) == (2, 0)

    sweep(tmp_path / "local", method=method)
    with serving(build_server(method)) as url:
        sweep(tmp_path / "remote", method="remote", policy_url=url)
    rows = _rows(tmp_path / "remote")
    assert rows == _rows(tmp_path / "local") and len(rows) == 2
    assert all(0 < r[11] < 180 for r in rows)  # the policy ended them (done), not the horizon

"""openpi's websocket policy protocol, both ways: ``run --method remote --protocol openpi``
against openpi's own server (``openpi_server.WebsocketPolicyServer``, not ours) plays the same
episodes as in-process, chunks included; ``serve --protocol openpi`` answers openpi's own client
(``openpi_client.websocket_client_policy.WebsocketClientPolicy``) with the in-process actions; and
every failure is one line, recorded as that episode's error, the run going on.

openpi-client 0.1.2 declares numpy < 2 (it runs on 2: these tests), so the pair is installed
without dependencies: ``pip install --no-deps openpi-client==0.1.2 openpi-server==0.1.0`` (tox's
``py`` env does it)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from openpi_fakes import (
    NO_OBSERVATIONS,
    ChunkPolicy,
    MisbehavingPolicy,
    free_port,
    openpi_serving,
    wait_until_listening,
)

from awda_bench.cli import main
from awda_bench.commands.serve import build_server
from awda_bench.episode import EpisodeContext, EpisodeSpec, Proprioception, WristDepth
from awda_bench.errors import RemotePolicyError, UsageError
from awda_bench.evaluation.methods import (
    MethodSpec,
    register_method,
    served_method,
    unregister_method,
)
from awda_bench.evaluation.results_store import STORE_NAME, ResultsStore
from awda_bench.evaluation.sweep import SweepConfig, run_sweep
from awda_bench.policies.random_policy import RandomPolicy
from awda_bench.serving import openpi_schema as schema
from awda_bench.serving.openpi_adapter import OpenpiAdapter
from awda_bench.serving.wire import decode, pack_openpi

msgpack_numpy = pytest.importorskip(
    "openpi_client.msgpack_numpy",
    reason="pip install --no-deps openpi-client==0.1.2 openpi-server==0.1.0",
)
from openpi_client.websocket_client_policy import WebsocketClientPolicy  # noqa: E402

pytestmark = pytest.mark.filterwarnings(  # openpi_client 0.1.2 on websockets 17
    "ignore:connect\\(\\) must be used as a context manager:DeprecationWarning"
)

TESTS = Path(__file__).resolve().parent
STEP_METHOD = MethodSpec("seeded-step", "openpi_fakes:SeededStepPolicy")


@pytest.fixture(autouse=True)
def step_method():
    register_method(STEP_METHOD)
    yield
    unregister_method(STEP_METHOD.name)


def _sweep(suites: Path, out: Path, method: str, **kw: Any):
    config = SweepConfig(
        suite="fake", out=out, suites_dir=suites, progress=False, command="test", method=method,
        workers=0, **kw,
    )  # fmt: skip
    return run_sweep(config)


def _openpi_sweep(suites: Path, out: Path, url: str, **kw: Any):
    return _sweep(suites, out, "remote", policy_url=url, policy_protocol="openpi", **kw)


def _rows(out: Path) -> list[tuple]:
    with ResultsStore(out, create=False) as store:
        return store.raw(
            "SELECT task, episode, seed, demo_seed, status, success_once, success_at_end, "
            "reached, grasped, steps, waypoints FROM episodes ORDER BY task, episode"
        )


def _server_notes(out: Path) -> dict[tuple[int, int], dict]:
    with ResultsStore(out, create=False) as store:
        rows = store.raw("SELECT task, episode, server FROM episodes WHERE status='ok'")
    return {(t, e): json.loads(s) for t, e, s in rows}


def _errors(out: Path) -> dict[tuple[int, int], str]:
    with ResultsStore(out, create=False) as store:
        rows = store.raw("SELECT task, episode, error FROM episodes WHERE status='error'")
    return {(t, e): msg.strip().splitlines()[-1] for t, e, msg in rows}


# ---------------------------------------------------------------------------- the wire


def test_arrays_cross_between_openpis_codec_and_ours() -> None:
    arrays = {
        "u8": np.arange(24, dtype=np.uint8).reshape(2, 3, 4),
        "f32": np.linspace(0, 1, 6, dtype=np.float32).reshape(3, 2),
        "f64": np.eye(4)[:3],
        "b": np.array([True, False]),
    }
    theirs = decode(msgpack_numpy.packb({**arrays, "n": np.float32(2.5)}), peer="p", hint="h")
    ours = msgpack_numpy.unpackb(pack_openpi(arrays))
    for got in (theirs, ours):
        for key, value in arrays.items():
            assert got[key].dtype == value.dtype and np.array_equal(got[key], value)
    assert theirs["n"] == np.float32(2.5) and theirs["n"].dtype == np.float32
    hostile = {b"__ndarray__": True, b"data": b"\0" * 8, b"dtype": "|O", b"shape": [1]}
    with pytest.raises(RemotePolicyError, match="refusing an array of dtype object"):
        decode(msgpack.packb(hostile), peer="p", hint="h")


# ---------------------------------------------------------------------------- chunks


@pytest.mark.parametrize(
    ("horizon", "metadata_horizon", "requests"),
    [(0, None, 6), (1, None, 6), (4, None, 2), (10, None, 1), (10, 4, 2), (4, 1, 6)],
    ids=["(4,)", "H=1", "H=4", "H=10", "H=10-horizon-4", "H=4-horizon-1"],
)
def test_chunks_play_step_by_step_like_in_process(
    suites, tmp_path, horizon, metadata_horizon, requests
) -> None:
    local = _sweep(suites, tmp_path / "local", STEP_METHOD.name)
    policy = ChunkPolicy(horizon)
    metadata = {**NO_OBSERVATIONS, "method": STEP_METHOD.name, "snapshot": "builtin"}
    if metadata_horizon is not None:
        metadata["action_horizon"] = metadata_horizon
    with openpi_serving(policy, metadata) as url:
        remote = _openpi_sweep(suites, tmp_path / "remote", url)
    assert (remote.ran, remote.errors) == (local.ran, local.errors) == (8, 0)
    assert _rows(tmp_path / "remote") == _rows(tmp_path / "local")  # the fake horizon: 6 steps
    assert {r[5] for r in _rows(tmp_path / "local")} == {0, 1}  # the outcomes follow the actions
    played = metadata_horizon or max(horizon, 1)
    by_episode: dict[str, list[int]] = {}
    for episode, step in policy.requests:
        by_episode.setdefault(episode, []).append(step)
    assert len(by_episode) == 8
    assert all(steps == list(range(0, 6, played)) for steps in by_episode.values())
    notes = _server_notes(tmp_path / "remote")
    assert {n["requests"] for n in notes.values()} == {requests}
    note = notes[(2, 0)]
    assert note["protocol"] == "openpi" and note["metadata"] == metadata
    assert set(note["server_timing"]) == {"infer_ms", "prev_total_ms"} or requests == 1
    assert note["server_timing"]["infer_ms"]["max"] >= note["server_timing"]["infer_ms"]["mean"]


def test_run_protocol_openpi_from_the_command_line_with_a_worker_process(suites, tmp_path) -> None:
    metadata = {**NO_OBSERVATIONS, "method": STEP_METHOD.name, "snapshot": "builtin"}
    with openpi_serving(ChunkPolicy(4), metadata) as url:
        code = main(
            ["run", "--suite", "fake", "--tasks-dir", str(suites), "--out", str(tmp_path / "cli"),
             "--method", "remote", "--protocol", "openpi", "--policy-url", url,
             "--policy-timeout", "30", "--workers", "1", "--episodes", "2", "--no-progress"]
        )  # fmt: skip
    assert code == 0
    _sweep(suites, tmp_path / "local", STEP_METHOD.name, episodes=2)
    assert (
        _rows(tmp_path / "cli") == _rows(tmp_path / "local") and len(_rows(tmp_path / "cli")) == 4
    )
    assert {n["requests"] for n in _server_notes(tmp_path / "cli").values()} == {2}


def test_rows_take_the_metadatas_name_or_openpi_and_a_hash_of_it(suites, tmp_path) -> None:
    with openpi_serving(ChunkPolicy(0), NO_OBSERVATIONS) as url:
        spec = served_method(url, protocol="openpi")
        _openpi_sweep(suites, tmp_path / "out", url, label="mine")
    assert spec.name == "openpi" and spec.served is not None
    assert len(spec.served.info.snapshot) == 16 and spec.served.info.snapshot_name == "metadata"
    with ResultsStore(tmp_path / "out", create=False) as store:
        assert store.raw("SELECT DISTINCT method, snapshot FROM episodes") == [
            ("mine", spec.served.info.snapshot)
        ]


# ---------------------------------------------------------------------------- failures


def test_a_raise_wrong_shape_nan_missing_actions_or_stall_is_one_line_and_the_run_goes_on(
    suites, tmp_path
) -> None:
    with openpi_serving(MisbehavingPolicy(stall_s=1.6), NO_OBSERVATIONS) as url:
        result = _openpi_sweep(suites, tmp_path / "out", url, policy_timeout_s=1.0)
    assert (result.ran, result.errors) == (8, 6)
    errors = _errors(tmp_path / "out")
    assert sorted(errors) == [(2, 1), (2, 2), (2, 3), (3, 1), (3, 2), (3, 3)]
    assert all(m.startswith("awda_bench.errors.RemotePolicyError: ") for m in errors.values())
    assert "the served policy raised during step 1" in errors[(2, 1)]
    assert "RuntimeError: boom in infer" in errors[(2, 1)]
    assert "returned an action of shape (2, 3), expected (4,) or (H, 4)" in errors[(2, 2)]
    assert "returned an action with NaN or inf" in errors[(2, 3)]
    assert "replied without 'actions'" in errors[(3, 1)] and "['action'" in errors[(3, 1)]
    assert "returned a str as the action" in errors[(3, 2)]
    assert "sent nothing for 1 s during step 3" in errors[(3, 3)]
    assert "--policy-timeout" in errors[(3, 3)]


@contextmanager
def _server_process(name: str) -> Iterator[tuple[subprocess.Popen, str]]:
    port = free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), *sys.path])}
    process = subprocess.Popen(
        [sys.executable, str(TESTS / "openpi_fakes.py"), name, str(port)],
        env=env,
        stderr=subprocess.DEVNULL,
    )
    url = f"ws://127.0.0.1:{port}"
    try:
        wait_until_listening(url)
        yield process, url
    finally:
        process.kill()
        process.wait()


def test_a_server_that_dies_mid_run_leaves_errors_that_a_re_run_retries(suites, tmp_path) -> None:
    out = tmp_path / "out"
    with _server_process("exiting") as (process, url):
        first = _openpi_sweep(suites, out, url, policy_timeout_s=5)
        assert process.wait(timeout=10) == 7
    assert (first.ran, first.errors) == (8, 7)
    errors = _errors(out)
    assert "lost the connection to the policy server" in errors[(2, 1)]
    assert "re-run" in errors[(2, 1)]
    assert "cannot reach the policy server" in errors[(3, 0)]
    with _server_process("chunk") as (_, url):
        second = _openpi_sweep(suites, out, url)
    assert (second.skipped, second.ran, second.errors) == (1, 7, 0)


def test_refusals_are_one_line_before_the_store_is_touched(suites, tmp_path, capsys) -> None:
    def cli(*extra: str) -> tuple[int, str]:
        code = main(
            ["run", "--suite", "fake", "--tasks-dir", str(suites), "--out", str(tmp_path / "c"),
             "--no-progress", "--workers", "0", *extra]
        )  # fmt: skip
        return code, capsys.readouterr().err.strip()

    code, err = cli("--method", "remote", "--protocol", "openpi")
    assert code == 2 and len(err.splitlines()) == 1 and "needs --policy-url" in err
    code, err = cli("--method", "random", "--protocol", "openpi")
    assert code == 2 and len(err.splitlines()) == 1
    assert "--protocol openpi applies to --method remote" in err
    with pytest.raises(RemotePolicyError, match="cannot reach the policy server"):
        _openpi_sweep(suites, tmp_path / "a", "ws://127.0.0.1:9", policy_timeout_s=2)
    with openpi_serving(ChunkPolicy(0), {"observation_keys": ["observation/depth"]}) as url:
        with pytest.raises(RemotePolicyError, match=r"observation keys \['observation/depth'\]"):
            _openpi_sweep(suites, tmp_path / "b", url)
    with openpi_serving(ChunkPolicy(0), {"action_horizon": 0}) as url:
        with pytest.raises(RemotePolicyError, match="action_horizon is 0, not a positive"):
            _openpi_sweep(suites, tmp_path / "b", url)
        with pytest.raises(RemotePolicyError, match="not a hello.*--protocol openpi"):
            _sweep(suites, tmp_path / "b", "remote", policy_url=url)
    server = build_server("random")
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        with pytest.raises(RemotePolicyError, match="own protocol.*drop --protocol openpi"):
            _openpi_sweep(suites, tmp_path / "b", server.url)
    finally:
        server.shutdown()
        thread.join(timeout=10)
    assert not (tmp_path / "a" / STORE_NAME).exists() and not (tmp_path / "b").exists()
    with pytest.raises(UsageError, match="unknown --protocol 'grpc'"):
        _sweep(suites, tmp_path / "d", "remote", policy_url="ws://x:1", policy_protocol="grpc")


# ---------------------------------------------------------------------------- serve --protocol openpi


class _StepObservations:
    """Observations that depend on the step only (``t``, set by the test), so that the order of
    the calls does not matter; small frames."""

    num_envs = 1

    def __init__(self) -> None:
        self.t = 0

    def _rng(self, salt: int) -> np.random.Generator:
        return np.random.default_rng(1000 * salt + self.t)

    def demo_frames(self, count: int = 10) -> np.ndarray:
        return np.random.default_rng(7).integers(0, 255, (count, 24, 32, 3), dtype=np.uint8)

    def first_frame(self) -> np.ndarray:
        return np.random.default_rng(0).integers(0, 255, (1, 24, 32, 3), dtype=np.uint8)[0]

    def rgb(self) -> np.ndarray:
        return self._rng(0).integers(0, 255, (1, 24, 32, 3), dtype=np.uint8)

    def wrist_depth(self) -> WristDepth:
        rng = self._rng(1)
        return WristDepth(
            rng.random((1, 16, 16), dtype=np.float32), rng.random((1, 3, 3)), rng.random((1, 4, 4))
        )

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        return np.eye(3) * 200.0, np.eye(4)[:3]

    def proprio(self) -> Proprioception:
        rng = self._rng(2)
        return Proprioception(
            rng.random((1, 3)), rng.random((1, 4)), rng.random(1), rng.random((1, 9))
        )


class ReadingEverythingPolicy:
    """Reads every observation; its actions fold them all in (float64, so the dtype crosses)."""

    name = "reading-everything"

    def __init__(self) -> None:
        self.steps = 0

    def reset(self, ctx: EpisodeContext) -> None:
        obs = ctx.observations
        assert obs is not None
        demo, first = obs.demo_frames(), obs.first_frame()
        intrinsic, extrinsic = obs.camera()
        assert demo.shape == (10, 24, 32, 3) and demo.dtype == np.uint8
        self.total = float(demo.sum()) + float(first.sum()) + intrinsic[0, 0] + extrinsic[0, 0]
        self.steps = 0

    def act(self, obs: Any) -> np.ndarray:
        depth, proprio = obs.wrist_depth(), obs.proprio()
        assert depth.depth_m.dtype == np.float32 and depth.cam2world_cv.shape == (1, 4, 4)
        self.steps += 1
        value = float(obs.rgb().mean()) + float(depth.depth_m.sum()) + depth.intrinsic_cv.sum()
        return np.array(
            [[value, self.total % 1.0, proprio.gripper_opening_m[0], proprio.qpos.sum()]]
        )

    @property
    def done(self) -> bool:
        return self.steps >= 15

    @property
    def waypoints(self) -> np.ndarray:
        return np.full((2, 4), float(self.steps))


@pytest.mark.parametrize(
    "make", [RandomPolicy, ReadingEverythingPolicy], ids=["random", "reading-everything"]
)
def test_openpis_client_gets_the_in_process_actions_from_serve(make: Any) -> None:
    spec = EpisodeSpec(suite="fake", task=2, episode=0, seed=1234, demo_seed=99)
    here = _StepObservations()
    policy = make()
    policy.reset(EpisodeContext(None, spec, observations=here))
    expected = []
    while not policy.done and len(expected) < 20:
        expected.append((policy.act(here), bool(policy.done), policy.waypoints))
        here.t += 1

    name = f"{__name__}:{make.__name__}"
    server = build_server(name if make is not RandomPolicy else "random", protocol="openpi")
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    there = _StepObservations()
    try:
        client = WebsocketClientPolicy(server.url)
        metadata = client.get_server_metadata()
        assert metadata["method"] == ("random" if make is RandomPolicy else name)
        assert metadata["snapshot"] == "builtin"
        reads = [] if make is RandomPolicy else list(schema.OBSERVATION_KEYS)
        assert metadata["observation_keys"] == reads
        options = schema.OpenpiOptions.from_metadata(metadata, "server")
        got = []
        for step in range(len(expected)):
            there.t = step
            reply = client.infer(schema.observation_request(there, spec, step, options))
            assert set(reply["server_timing"]) >= {"infer_ms"}
            got.append((reply["actions"], reply["done"], reply.get("waypoints")))
    finally:
        server.shutdown()
        thread.join(timeout=10)
    assert len(got) == len(expected) == (20 if make is RandomPolicy else 15)
    for (action, done, waypoints), (want, want_done, want_waypoints) in zip(
        got, expected, strict=True
    ):
        assert action.shape == (4,) and action.dtype == want.dtype
        assert np.array_equal(action, want[0]) and done == want_done
        assert (waypoints is None) == (want_waypoints is None)
        assert want_waypoints is None or np.array_equal(waypoints, want_waypoints)


def test_serve_openpi_sends_the_policys_traceback_as_text() -> None:
    server = build_server("harness_fakes:RaisingPolicy", protocol="openpi")
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        client = WebsocketClientPolicy(server.url)
        spec = EpisodeSpec(suite="fake", task=2, episode=1, seed=5, demo_seed=6)
        request = schema.observation_request(
            _StepObservations(), spec, 0, schema.OpenpiOptions(observation_keys=())
        )
        with pytest.raises(RuntimeError, match="RuntimeError: boom in act"):
            client.infer(request)
    finally:
        server.shutdown()
        thread.join(timeout=10)


def test_an_adapter_refuses_requests_out_of_step() -> None:
    adapter = OpenpiAdapter(RandomPolicy())
    spec = EpisodeSpec(suite="fake", task=2, episode=0, seed=1, demo_seed=2)
    options = schema.OpenpiOptions(observation_keys=())
    adapter.infer(schema.observation_request(_StepObservations(), spec, 0, options))
    with pytest.raises(ValueError, match="request for step 3, expected step 1"):
        adapter.infer(schema.observation_request(_StepObservations(), spec, 3, options))
    with pytest.raises(KeyError, match="no episode_id"):
        adapter.infer({"observation/image": np.zeros((2, 2, 3), np.uint8)})


# ---------------------------------------------------------------------------- real episodes


@pytest.mark.slow
def test_a_policy_served_by_openpis_server_plays_real_episodes_as_in_process(
    tmp_path, monkeypatch, capsys
) -> None:
    """The example's wrist-descend policy (it reads wrist depth and proprioception), wrapped as an
    openpi policy and served by ``openpi_server.WebsocketPolicyServer``, evaluated by ``run
    --method remote --protocol openpi``: the records equal the in-process run's."""
    monkeypatch.syspath_prepend(str(TESTS.parent / "examples"))
    from awda_example_policies.wrist_descend import WristDescendPolicy

    method = "awda_example_policies.wrist_descend:WristDescendPolicy"

    class Reading(WristDescendPolicy):
        observation_keys = (
            schema.WRIST_DEPTH, schema.WRIST_INTRINSICS, schema.WRIST_CAM2WORLD, schema.STATE
        )  # fmt: skip

    common = ["--suite", "pick_place", "--episodes", "2", "--task", "14", "--workers", "0",
              "--no-progress"]  # fmt: skip
    assert main(["run", *common, "--method", method, "--out", str(tmp_path / "local")]) == 0
    adapter = OpenpiAdapter(Reading(), method=method)
    with openpi_serving(adapter, adapter.metadata) as url:
        code = main(
            ["run", *common, "--method", "remote", "--protocol", "openpi", "--policy-url", url,
             "--out", str(tmp_path / "remote")]
        )  # fmt: skip
    assert code == 0, capsys.readouterr().err
    with ResultsStore(tmp_path / "local", create=False) as local:
        query = (
            "SELECT method, snapshot, task, episode, seed, demo_seed, status, success_once, "
            "success_at_end, reached, grasped, first_grip, steps, waypoints FROM episodes "
            "ORDER BY task, episode"
        )
        expected = local.raw(query)
    with ResultsStore(tmp_path / "remote", create=False) as remote:
        got = remote.raw(query)
        notes = [json.loads(n) for (n,) in remote.raw("SELECT server FROM episodes")]
    assert got == expected and len(got) == 2
    assert all(0 < r[12] < 180 for r in got)  # the policy ended them (done), not the horizon
    assert [n["requests"] for n in notes] == [r[12] for r in got]  # one action per request
    assert notes[0]["metadata"]["observation_keys"] == list(Reading.observation_keys)

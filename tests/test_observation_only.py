"""Observation-only episodes: a method that is not privileged gets a context without the
simulator; reaching for ``ctx.env`` fails that episode as an *error* naming the rule, and the run
goes on. A privileged method reads it."""

from __future__ import annotations

from pathlib import Path

import pytest
from harness_fakes import fake_suites_dir, fake_sweep_config

from awda_bench.episode import EpisodeContext, EpisodeSpec, is_privileged
from awda_bench.errors import PrivilegedAccessError
from awda_bench.evaluation.methods import MethodSpec, register_method, unregister_method
from awda_bench.evaluation.results_store import ResultsStore
from awda_bench.evaluation.sweep import run_sweep

METHODS = (
    MethodSpec("env-reading", "harness_fakes:EnvReadingPolicy"),
    MethodSpec(
        "privileged-env-reading", "harness_fakes:PrivilegedEnvReadingPolicy", privileged=True
    ),
)


@pytest.fixture(autouse=True)
def fake_methods():
    for spec in METHODS:
        register_method(spec)
    yield
    for spec in METHODS:
        unregister_method(spec.name)


def _sweep(tmp_path: Path, method: str, out: Path | None = None):
    out = out or tmp_path / method
    suites = fake_suites_dir(tmp_path / "tasks")
    return run_sweep(fake_sweep_config(suites, out, method, episodes=3)), out


def test_reading_the_env_is_an_error_naming_the_rule_and_the_run_goes_on(tmp_path: Path) -> None:
    result, out = _sweep(tmp_path, "env-reading")
    assert (result.ran, result.errors) == (6, 2)  # episode 1 of each held-out task
    with ResultsStore(out, create=False) as store:
        rows = store.raw("SELECT task, episode, status, error, success_once FROM episodes")
    errors = [(t, e, msg) for t, e, status, msg, _ in rows if status == "error"]
    assert [(t, e) for t, e, _ in errors] == [(2, 1), (3, 1)]
    for *_, msg in errors:
        assert "PrivilegedAccessError" in msg
        assert "'env-reading' is not privileged" in msg and "ctx.observations" in msg
    ok = [r for r in rows if r[2] == "ok"]
    assert len(ok) == 4 and all(r[4] is not None for r in ok)  # played to the end, judged


def test_a_privileged_method_reads_the_env(tmp_path: Path) -> None:
    result, _ = _sweep(tmp_path, "privileged-env-reading")
    assert (result.ran, result.errors) == (6, 0)


def test_the_tables_mark_the_privileged_rows(tmp_path: Path) -> None:
    from awda_bench.reporting.report import write_report

    out = tmp_path / "store"
    _sweep(tmp_path, "privileged-env-reading", out)
    _sweep(tmp_path, "env-reading", out)
    write_report(out, tmp_path / "report")
    header = (tmp_path / "report" / "s3.md").read_text().splitlines()[0]
    columns = [c.strip() for c in header.strip("|").split("|")]
    assert columns[1:] == ["env-reading", "privileged-env-reading (privileged)"]


def test_a_declaration_that_disagrees_with_the_registration_is_refused() -> None:
    from awda_bench.errors import UsageError
    from awda_bench.evaluation.methods import BUILTIN_SNAPSHOT, SnapshotRef, make_policy

    snapshot = SnapshotRef(BUILTIN_SNAPSHOT, BUILTIN_SNAPSHOT, None, 0)
    unflagged = MethodSpec("unflagged", "harness_fakes:PrivilegedEnvReadingPolicy")
    with pytest.raises(UsageError, match="declares privileged = True but the method is regis"):
        make_policy(unflagged, snapshot)


def test_the_builtin_methods_declare_what_they_are() -> None:
    from awda_bench.policies.gt_waypoints import GtWaypointsPolicy
    from awda_bench.policies.random_policy import RandomPolicy
    from awda_bench.policies.scripted import ScriptedPolicy
    from awda_bench.policies.tosvi_policy import TosviPolicy

    assert is_privileged(GtWaypointsPolicy) and is_privileged(ScriptedPolicy)
    assert not is_privileged(RandomPolicy) and not is_privileged(TosviPolicy)
    from awda_bench.policies.awda_policy import AwdaPolicy

    assert not is_privileged(AwdaPolicy)


def test_a_context_without_the_env_says_so_in_one_line() -> None:
    spec = EpisodeSpec(suite="fake", task=0, episode=0, seed=1, demo_seed=2)
    ctx = EpisodeContext(env=None, spec=spec, method="mine")
    assert not ctx.privileged
    with pytest.raises(PrivilegedAccessError) as caught:
        _ = ctx.env
    message = str(caught.value)
    assert len(message.splitlines()) == 1
    assert "'mine' is not privileged" in message and "privileged = True" in message
    assert EpisodeContext(env=object(), spec=spec).privileged


@pytest.mark.slow
def test_the_observations_have_the_documented_shapes_on_the_real_env() -> None:
    import numpy as np

    from awda_bench.evaluation.env_factory import make_env
    from awda_bench.evaluation.episode_runner import fresh_scene_options
    from awda_bench.evaluation.observations import SimObservations
    from awda_bench.suites import load_suite

    suite = load_suite("pick_place")
    env = make_env(suite)
    try:
        spec = EpisodeSpec(suite="pick_place", task=14, episode=0, seed=5, demo_seed=6)
        env.reset(seed=spec.seed, options=fresh_scene_options(suite, spec.task))
        extras: dict = {}
        obs = SimObservations(env.unwrapped, spec, suite, extras)
        first = obs.first_frame()
        assert first.shape == (240, 320, 3) and first.dtype == np.uint8
        assert obs.rgb().shape == (1, 240, 320, 3)
        depth = obs.wrist_depth()
        assert depth.depth_m.shape == (1, 128, 128) and depth.depth_m.dtype == np.float32
        assert depth.intrinsic_cv.shape == (1, 3, 3) and depth.cam2world_cv.shape == (1, 4, 4)
        intrinsic, extrinsic = obs.camera()
        assert intrinsic.shape == (3, 3) and extrinsic.shape == (3, 4)
        proprio = obs.proprio()
        assert proprio.tcp_pos.shape == (1, 3) and proprio.tcp_quat.shape == (1, 4)
        assert proprio.qpos.shape == (1, 9) and proprio.gripper_opening_m.shape == (1,)
        np.testing.assert_allclose(proprio.gripper_opening_m, proprio.qpos[:, -2:].sum(1))
        assert 0.0 < proprio.tcp_pos[0, 2] < 0.6  # above the table, in reach
        env.step(np.zeros((1, 4), np.float32))
        obs.mark_stepped()
        assert obs.first_frame() is extras["first_frame"]  # kept from reset, not re-rendered
    finally:
        env.close()


def test_the_first_frame_is_the_one_at_reset(monkeypatch: pytest.MonkeyPatch) -> None:
    from types import SimpleNamespace

    import numpy as np

    from awda_bench.evaluation.observations import SimObservations

    renders = iter(np.full((1, 2, 2, 3), i, np.uint8) for i in range(10))
    monkeypatch.setattr("awda_bench.robot.cameras.capture_rgb", lambda env: next(renders))
    spec = EpisodeSpec(suite="fake", task=0, episode=0, seed=1, demo_seed=2)
    extras: dict = {}
    obs = SimObservations(SimpleNamespace(num_envs=1), spec, None, extras)  # type: ignore[arg-type]
    assert obs.first_frame()[0, 0, 0] == 0 and extras["first_frame"][0, 0, 0] == 0
    obs.mark_stepped()
    assert obs.first_frame()[0, 0, 0] == 0  # kept, not rendered again
    assert obs.rgb()[0, 0, 0, 0] == 1  # now
    late = SimObservations(SimpleNamespace(num_envs=1), spec, None, {})  # type: ignore[arg-type]
    late.mark_stepped()
    with pytest.raises(RuntimeError, match="call it in reset"):
        late.first_frame()

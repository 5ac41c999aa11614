"""A tiny env and policies for testing the harness without a simulator.

Importing this module registers ``AWDA-Fake-v0``; a suite names it as
``"harness_fakes:AWDA-Fake-v0"`` so gymnasium imports this module inside spawned workers too.

The env succeeds at a step when the last action's x exceeds a threshold fixed by the seed
(``(seed % 1000) / 1000``), so outcomes depend on the seed and the policy's ``skill`` only.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from awda_bench.episode import EpisodeContext
from awda_bench.errors import CorruptFileError
from awda_bench.evaluation.methods import MethodSpec

FAKE_SUITE_TOML = """
name = "fake"
env_id = "harness_fakes:AWDA-Fake-v0"
display_name = "Fake suite"
control_freq_hz = 10
horizon_steps = 6
held_out = [2, 3]
episodes_per_task = 4
[[tasks]]
index = 0
name = "t0"
family = "door"
[[tasks]]
index = 1
name = "t1"
family = "door"
[[tasks]]
index = 2
name = "t2"
family = "drawer"
[[tasks]]
index = 3
name = "t3"
family = "press_button"
"""


def write_fake_suite(directory: Path, name: str = "fake", **overrides: str) -> Path:
    text = FAKE_SUITE_TOML.replace('name = "fake"', f'name = "{name}"')
    for key, value in overrides.items():
        lines = [line for line in text.splitlines() if not line.startswith(f"{key} =")]
        text = "\n".join([f"{key} = {value}", *lines])
    path = directory / f"{name}.toml"
    path.write_text(text)
    return path


def fake_suites_dir(directory: Path) -> Path:
    """``directory`` (created if missing) holding the fake suite, for ``--tasks-dir`` /
    ``suites_dir``."""
    directory.mkdir(parents=True, exist_ok=True)
    write_fake_suite(directory)
    return directory


def fake_sweep_config(suites: Path, out: Path, method: str = "fake", **overrides: Any) -> Any:
    """A :class:`~awda_bench.evaluation.sweep.SweepConfig` of the fake suite (another suite of
    ``suites`` with ``suite=``) into ``out``: inline (``workers=0``), no progress bars, unless
    ``overrides`` say otherwise."""
    from awda_bench.evaluation.sweep import SweepConfig

    fields: dict[str, Any] = {"suite": "fake", "workers": 0, **overrides}
    return SweepConfig(
        out=out, suites_dir=suites, method=method, progress=False, command="test", **fields
    )


class FakeEnv(gym.Env):
    """Deterministic in (seed, actions); latches ``reached``/``grasped`` like the real envs."""

    metadata = {"render_modes": ["rgb_array"]}
    observation_space = gym.spaces.Box(-1, 1, (1, 3), np.float32)
    action_space = gym.spaces.Box(-1, 1, (1, 4), np.float32)

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        self.render_mode = render_mode
        self.kwargs = kwargs
        self.threshold = 0.0
        self.t = 0
        self.reached = False

    def reset(self, *, seed: int | None = None, options: dict | None = None):  # type: ignore[override]
        super().reset(seed=seed)
        assert seed is not None and options is not None and "task" in options
        self.task = int(options["task"])
        self.threshold = (seed % 1000) / 1000
        self.t = 0
        self.reached = False
        self.last_x = 0.0
        return self._obs(), {"success": np.array([False])}

    def _obs(self) -> np.ndarray:
        return np.array([[self.threshold, self.t, self.task]], np.float32)

    def step(self, action):  # type: ignore[override]
        self.t += 1
        self.last_x = float(np.asarray(action).reshape(-1)[0])
        success = self.t >= 3 and self.last_x > self.threshold
        self.reached = self.reached or self.last_x > self.threshold / 2
        info = {
            "success": np.array([success]),
            "reached": np.array([self.reached]),
            "grasped": np.array([self.reached and self.threshold < 0.5]),
        }
        return self._obs(), np.zeros(1), np.array([False]), np.array([False]), info

    def render(self):  # type: ignore[override]
        frame = np.zeros((48, 64, 3), np.uint8)
        frame[:, : int(64 * min(self.last_x, 1.0) if self.t else 0)] = 255
        return frame[None]


gym.register("AWDA-Fake-v0", entry_point=FakeEnv)


class SkillPolicy:
    """Pushes x = ``skill`` every step; predicts two waypoints."""

    name = "fake"
    skill = 0.5

    def __init__(self, snapshot_path: str | None = None) -> None:
        if snapshot_path is not None:
            self.skill = float(json.loads(Path(snapshot_path).read_text())["skill"])
        self.spec = None

    def reset(self, ctx: EpisodeContext) -> None:
        self.spec = ctx.spec
        self.t = 0

    def act(self, obs: Any) -> np.ndarray:
        self.t += 1
        return np.array([[self.skill, 0.0, 0.0, 0.0]], np.float32)

    @property
    def done(self) -> bool:
        return False

    @property
    def waypoints(self) -> np.ndarray | None:
        return np.array([[0.1, 0.2, 0.3, 0.0], [0.4, 0.5, 0.6, 1.0]])


class RaisingPolicy(SkillPolicy):
    """Raises inside ``act`` on episode 1."""

    name = "raising"

    def act(self, obs: Any) -> np.ndarray:
        assert self.spec is not None
        if self.spec.episode == 1:
            raise RuntimeError("boom in act")
        return super().act(obs)


class EnvReadingPolicy(SkillPolicy):
    """Reaches for the simulator (``ctx.env``) on episode 1, as an observation-only method must
    not; records what ``act`` is handed."""

    name = "env-reading"

    def reset(self, ctx: EpisodeContext) -> None:
        super().reset(ctx)
        self.observations = ctx.observations
        if ctx.spec.episode == 1:
            self.env_name = type(ctx.env).__name__

    def act(self, obs: Any) -> np.ndarray:
        if obs is not self.observations:
            raise AssertionError(f"act got {type(obs).__name__}, not the episode's observations")
        return super().act(obs)


class PrivilegedEnvReadingPolicy(SkillPolicy):
    """Declares itself privileged and reads ``ctx.env`` every episode (allowed)."""

    name = "privileged-env-reading"
    privileged = True

    def reset(self, ctx: EpisodeContext) -> None:
        super().reset(ctx)
        self.env_name = type(ctx.env).__name__


class _FaultOnEpisodeOne(SkillPolicy):
    """Misbehaves (:meth:`fault`) on episode 1 unless the environment variable ``disarm_env`` is
    set."""

    disarm_env = ""

    def fault(self) -> None:
        raise NotImplementedError

    def act(self, obs: Any) -> np.ndarray:
        assert self.spec is not None
        if self.spec.episode == 1 and not os.environ.get(self.disarm_env):
            self.fault()
        return super().act(obs)


class HangingPolicy(_FaultOnEpisodeOne):
    """Hangs (like a stuck renderer) on episode 1 unless AWDA_FAKE_NO_HANG is set."""

    name = "hanging"
    disarm_env = "AWDA_FAKE_NO_HANG"

    def fault(self) -> None:
        time.sleep(3600)


class CrashingPolicy(_FaultOnEpisodeOne):
    """Kills its own process on episode 1 (a segfaulting simulator) unless AWDA_FAKE_NO_CRASH
    is set."""

    name = "crashing"
    disarm_env = "AWDA_FAKE_NO_CRASH"

    def fault(self) -> None:
        os._exit(7)


class SlowPolicy(SkillPolicy):
    """Sleeps ``AWDA_FAKE_SLEEP_S`` per step (to kill a run mid-sweep)."""

    name = "slow"

    def act(self, obs: Any) -> np.ndarray:
        time.sleep(float(os.environ.get("AWDA_FAKE_SLEEP_S", "0.05")))
        return super().act(obs)


def learned_method(name: str = "learned") -> MethodSpec:
    """A learned method: :class:`SkillPolicy` on snapshots written by :func:`write_snapshots`
    (register it with ``awda_bench.evaluation.methods.register_method``)."""
    return MethodSpec(
        name,
        "harness_fakes:SkillPolicy",
        learned=True,
        list_snapshots="harness_fakes:list_snapshots",
        load_snapshot="harness_fakes:load_snapshot",
    )


def fake_suite_argv(suites: Path, out: Path, *extra: str) -> list[str]:
    """``awda run`` of the fake suite in ``suites`` into ``out``, no progress bars, then
    ``extra``."""
    return [
        "run",
        "--suite",
        "fake",
        "--tasks-dir",
        str(suites),
        "--out",
        str(out),
        "--no-progress",
        *extra,
    ]


def slow_run_command(suites: Path, out: Path, *extra: str) -> list[str]:
    """``python -m awda_bench run`` of the fake suite with :class:`SlowPolicy` (a run to kill,
    or to start twice at once); run it with :func:`slow_run_env`."""
    argv = fake_suite_argv(suites, out, "--method", "harness_fakes:SlowPolicy", *extra)
    return [sys.executable, "-m", "awda_bench", *argv]


def slow_run_env(sleep_s: float) -> dict[str, str]:
    """The environment of a :func:`slow_run_command` process: its workers import this module,
    :class:`SlowPolicy` sleeps ``sleep_s`` per step, one OpenMP thread."""
    tests = str(Path(__file__).resolve().parent)
    return {
        **os.environ,
        "PYTHONPATH": tests,
        "AWDA_FAKE_SLEEP_S": str(sleep_s),
        "OMP_NUM_THREADS": "1",
    }


def report_runs(root: Path, *names: str) -> list[Path]:
    """``awda report`` of each run directory ``root/name`` into ``root/rep-name`` (each must
    succeed); returns the report directories."""
    from awda_bench.cli import main

    reports = []
    for name in names:
        report = root / f"rep-{name}"
        assert main(["report", "--runs", str(root / name), "--out", str(report)]) == 0, name
        reports.append(report)
    return reports


def run_fake_suite(suites: Path, out: Path, *extra: str) -> int:
    """:func:`fake_suite_argv` through the CLI; returns its exit code."""
    from awda_bench.cli import main

    return main(fake_suite_argv(suites, out, *extra))


def list_snapshots(directory: Path) -> list[Path]:
    """Snapshot files ``step_<N>.json``, oldest first."""
    return sorted(Path(directory).glob("step_*.json"), key=lambda p: int(p.stem.split("_")[1]))


def load_snapshot(path: Path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        raise CorruptFileError(f"snapshot {path} is not valid JSON; replace it") from exc


def write_snapshots(directory: Path, skills: list[float]) -> list[Path]:
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, skill in enumerate(skills):
        p = directory / f"step_{(i + 1) * 10000}.json"
        p.write_text(json.dumps({"skill": skill, "step": (i + 1) * 10000}))
        paths.append(p)
    return paths

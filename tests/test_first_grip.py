"""The first-grip analysis: what a policy's first grip command closed on (§S3's "wrong object").

The harness asks the env's ``grip_outcome`` before each step until an action closes the gripper,
records it in the episode, the store keeps it and ``grasp.csv`` rates it. These tests run a fake
env; the pick-place env's own answer is tested in test_pick_place_env.py.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from harness_fakes import FakeEnv, SkillPolicy, write_fake_suite

from awda_bench.episode import EpisodeSpec
from awda_bench.evaluation.episode_runner import run_episode
from awda_bench.reporting.aggregate import FIRST_GRIP_COLUMNS, grasp_analysis
from awda_bench.suites import load_suite


class GripEnv(FakeEnv):
    """Tells what a grip closes on: another object while x > 0.5 (the policy's push), else the
    target; it records the actions it was asked about."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.asked: list[np.ndarray] = []

    def object_distances(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((1, 2)), np.zeros(1, dtype=np.int64)

    def grip_outcome(self, action: Any) -> np.ndarray:
        a = np.asarray(action).reshape(-1)
        self.asked.append(a)
        if a[3] <= 0:
            return np.array([-1])
        return np.array([1 if a[0] > 0.5 else 0])


class GripAt(SkillPolicy):
    """Pushes x = ``skill``; closes the gripper from step ``at`` on (never when ``at`` is None)."""

    def __init__(self, skill: float, at: int | None) -> None:
        super().__init__()
        self.skill, self.at = skill, at

    def act(self, obs: Any) -> np.ndarray:
        action = super().act(obs)
        if self.at is not None and self.t >= self.at:
            action[0, 3] = 1.0
        return action


def _play(tmp_path: Path, env: FakeEnv, policy: SkillPolicy) -> Any:
    write_fake_suite(tmp_path)
    suite = load_suite("fake", tmp_path)
    spec = EpisodeSpec("fake", 0, 0, 1100, 2100)
    return run_episode(env, policy, spec, suite, method="m", snapshot="builtin")


def test_the_record_says_what_the_first_grip_closed_on(tmp_path: Path) -> None:
    env = GripEnv()
    record = _play(tmp_path, env, GripAt(0.9, at=3))
    assert record.first_grip == "other"
    # asked before each step until the first grip (steps 1..3), then no more
    assert len(env.asked) == 3 and env.asked[-1][3] == 1.0
    assert _play(tmp_path, GripEnv(), GripAt(0.2, at=2)).first_grip == "target"
    assert _play(tmp_path, GripEnv(), GripAt(0.9, at=None)).first_grip == "never"
    # an env that does not tell: no first grip at all, not "never"
    assert _play(tmp_path, FakeEnv(), GripAt(0.9, at=3)).first_grip is None


def test_grasp_csv_rates_each_first_grip_over_the_episodes_that_recorded_one() -> None:
    outcomes = ["target", "other", "other", "never", None]
    episodes = pd.DataFrame(
        {
            "suite": "pick_place", "method": "tosvi", "status": "ok", "snapshot": "s",
            "task": 14, "waypoints": None, "reached": [1, 0, 1, 0, 0], "grasped": 0,
            "success_once": 0, "first_grip": outcomes,
        }
    )  # fmt: skip
    row = grasp_analysis(episodes, "success_once").iloc[0]
    rates = {outcome: row[column] for outcome, column in FIRST_GRIP_COLUMNS.items()}
    assert rates == {"target": 0.25, "other": 0.5, "nothing": 0.0, "never": 0.25}
    assert row["episodes"] == 5 and row["reached"] == 0.4
    # a store from before the analysis: every rate unknown, the rest as before
    old = grasp_analysis(episodes.drop(columns="first_grip"), "success_once").iloc[0]
    assert all(pd.isna(old[c]) for c in FIRST_GRIP_COLUMNS.values()) and old["reached"] == 0.4

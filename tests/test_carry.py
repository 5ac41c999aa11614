"""The carry analysis: what became of a grasped target on a task that carries it to a place.

Fast: the tally's rules on a scripted fake scene, the episode record, the report's table (the
store's columns: test_results_store.py). Slow: the stacking scene with its scripted expert as
is (placed), told to open its gripper as soon as it has lifted cube A (off target) and never to
open it (held); Meta-World's pick-place-wall placed and let go early, button-press untallied
(through ``.venv-metaworld``'s interpreter).
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import torch
from harness_fakes import FakeEnv, SkillPolicy, write_fake_suite
from metaworld_env import metaworld_python, needs_metaworld
from task_env_helpers import make_task_env, run_expert, task_env_fixture

from awda_bench.episode import EpisodeSpec
from awda_bench.evaluation.carry import CARRY_OUTCOMES, RELEASE_STEPS, CarryTally
from awda_bench.evaluation.episode_runner import run_episode
from awda_bench.experts.stack_block import StackBlockExpert
from awda_bench.reporting.aggregate import carry_analysis
from awda_bench.runtimes import PROJECT_ROOT
from awda_bench.suites import load_suite


class Scene:
    """A fake carry scene: the goal at the origin, 2 cm tolerance; the test moves the target and
    says whether the fingers hold it."""

    def __init__(self) -> None:
        self.held = True
        self.target = torch.tensor([[0.3, 0.0, 0.1]])

    def place_goal(self) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.zeros(1, 3), torch.tensor([0.02])

    def is_grasping_target(self) -> torch.Tensor:
        return torch.tensor([self.held])

    def target_position(self) -> torch.Tensor:
        return self.target

    def grip_commanded(self, action: Any) -> torch.Tensor:
        return torch.tensor([float(np.asarray(action).reshape(-1)[3]) > 0])


CLOSED, OPEN = np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, -1.0])


def _carry(scene: Scene, steps: list[tuple[bool, Any, bool]]) -> CarryTally:
    """Play ``(held, action, grasped)`` steps on a tally of ``scene``."""
    tally = CarryTally(scene)
    for held, action, grasped in steps:
        scene.held = held
        tally.after_step(action, grasped)
    return tally


def test_the_release_is_where_the_fingers_let_go_for_good() -> None:
    scene = Scene()
    # not yet grasped: nothing is asked of the scene, whatever it says
    tally = _carry(scene, [(False, OPEN, False)] * 5)
    assert tally.release is None and tally.outcome(grasped=False, success=False) is None
    # grasped and carried: a one-step miss of the contact query is no release
    steps = [(True, CLOSED, True)] * 3 + [(False, CLOSED, True)] + [(True, CLOSED, True)] * 2
    tally = _carry(scene, steps)
    assert tally.release is None and tally.outcome(grasped=True, success=False) == "held"
    # let go over the goal, 5 cm up: the position of the first free step is the release's
    scene.target = torch.tensor([[0.01, 0.0, 0.05]])
    tally = _carry(scene, [(True, CLOSED, True), (False, OPEN, True)])
    scene.target = torch.tensor([[0.5, 0.5, 0.0]])  # where it rolls on to does not count
    for _ in range(RELEASE_STEPS - 1):
        tally.after_step(OPEN, True)
    assert tally.release is not None
    assert tally.release.xy_m == pytest.approx(0.01) and tally.release.dz_m == pytest.approx(0.05)
    assert tally.outcome(grasped=True, success=False) == "on_target"
    assert tally.outcome(grasped=True, success=True) == "placed"


def test_far_from_the_goal_is_off_target_and_with_the_gripper_closed_a_drop() -> None:
    scene = Scene()  # the target 30 cm from over the goal
    off = _carry(scene, [(True, CLOSED, True)] + [(False, OPEN, True)] * RELEASE_STEPS)
    assert off.outcome(grasped=True, success=False) == "off_target"
    dropped = _carry(scene, [(True, CLOSED, True)] + [(False, CLOSED, True)] * RELEASE_STEPS)
    assert dropped.outcome(grasped=True, success=False) == "dropped"
    assert set(CARRY_OUTCOMES) == {"placed", "on_target", "off_target", "dropped", "held"}


class CarryFakeEnv(FakeEnv):
    """The harness's fake env with a place goal: the target is held at steps 1 and 2 (the suite's
    horizon is 6: released for good at step 3)."""

    def place_goal(self) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.zeros(1, 3), torch.tensor([0.02])

    def is_grasping_target(self) -> torch.Tensor:
        return torch.tensor([1 <= self.t <= 2])

    def target_position(self) -> torch.Tensor:
        return torch.tensor([[0.1, 0.0, 0.2]])

    def grip_commanded(self, action: Any) -> torch.Tensor:
        return torch.tensor([False])


def test_the_episode_record_and_the_report_table_carry_it(tmp_path: Path) -> None:
    write_fake_suite(tmp_path)
    suite = load_suite("fake", tmp_path)
    spec = EpisodeSpec("fake", 0, 0, 1100, 2100)  # threshold 0.1: grasped from step 1 on
    policy = SkillPolicy()
    policy.skill = 0.06  # reaches (> threshold / 2), no success (< threshold)
    record = run_episode(CarryFakeEnv(), policy, spec, suite, method="m", snapshot="builtin")
    assert record.grasped and record.carry == "off_target"
    assert record.release_xy_m == pytest.approx(0.1) and record.release_dz_m == pytest.approx(0.2)
    assert record.place_goal == [0.0, 0.0, 0.0]
    plain = run_episode(FakeEnv(), SkillPolicy(), spec, suite, method="m", snapshot="builtin")
    assert plain.carry is None and plain.release_xy_m is None  # no place goal: not analysed

    def episode(carry: str | None, xy: float | None) -> dict[str, Any]:
        # meant to put it 3 cm (x) and 4 cm (y) from over the goal: held at waypoint 2, not 3
        waypoints = "[[0.5, 0.5, 0.1, 0.0], [0.0, 0.0, 0.0, 1.0], [0.13, 0.24, 0.2, 1.0], [0.9, 0.9, 0.2, 0.0]]"
        return {
            "suite": "mosaic", "method": "awda", "family": "stack_block", "status": "ok",
            "carry": carry, "release_xy_m": xy, "release_dz_m": None if xy is None else 0.1,
            "waypoints": waypoints, "place_goal": "[0.1, 0.2, 0.05]",
        }  # fmt: skip

    rows = [episode("placed", 0.0), episode("held", None), episode("off_target", 0.2)]
    rows += [episode("off_target", 0.3), episode(None, None)]
    table = carry_analysis(pd.DataFrame(rows))
    got = table.iloc[0]
    assert got["grasped"] == 4 and got["off_target"] == 0.5 and got["held"] == 0.25
    assert got["release_xy_cm"] == pytest.approx(20.0) and got["release_dz_cm"] == 10.0
    assert got["place_wp_xy_cm"] == pytest.approx(5.0)
    assert carry_analysis(pd.DataFrame(rows).drop(columns="carry")).empty  # an older store


# ----------------------------------------------------------------------------- slow
env = task_env_fixture("AWDA-StackBlock-v1")


class Overridden(StackBlockExpert):
    """The scripted expert with its gripper forced open or closed from the moment A is lifted."""

    def __init__(self, grip: float) -> None:
        super().__init__()
        self.grip = grip
        self.env: Any = None

    def reset(self, ctx: Any) -> None:
        super().reset(ctx)
        self.env = ctx.env

    def act(self, obs: Any) -> np.ndarray:
        action = np.array(super().act(obs), dtype=np.float32)
        if bool(self.env.grasped[0]):  # from the lift on
            action[0, 3] = self.grip
        return action


def _tallied_run(env: Any, expert: Any, task: int, seed: int) -> tuple[CarryTally, str | None]:
    """``expert``'s episode on ``env`` with a carry tally beside it: the tally and its outcome."""
    base = env.unwrapped
    tally = CarryTally.for_env(base)
    assert tally is not None
    played: list[Any] = []
    act = expert.act
    expert.act = lambda obs: played.append(act(obs)) or played[-1]
    run = run_expert(
        env, expert, task, seed, 260, on_step=lambda: tally.after_step(played[-1], base.grasped[0])
    )
    outcome = tally.outcome(bool(run.info["grasped"][0]), bool(run.info["success_once"][0]))
    return tally, outcome


@pytest.mark.slow
@pytest.mark.parametrize(
    ("env_id", "task", "seed"),
    [
        ("AWDA-StackBlock-v1", 0, 0),
        ("AWDA-Basketball-v1", 5, 2),
        ("AWDA-NutAssembly-v1", 4, 2),
        ("AWDA-PickPlace-v1", 4, 2),
    ],
)
def test_every_carry_familys_expert_releases_over_its_goal(
    env_id: str, task: int, seed: int
) -> None:
    from awda_bench.experts import FAMILY_EXPERTS

    carry_env = make_task_env(env_id)
    try:
        tally, outcome = _tallied_run(
            carry_env, FAMILY_EXPERTS[carry_env.unwrapped.family](), task, seed
        )
    finally:
        carry_env.close()
    assert outcome == "placed" and tally.release is not None
    assert tally.release.over_goal and not tally.release.closed
    assert -0.01 < tally.release.dz_m < 0.06  # at the goal's height or a little above it


@pytest.mark.slow
@pytest.mark.parametrize(("grip", "outcome"), [(-1.0, "off_target"), (1.0, "held")])
def test_the_stacking_expert_told_to_let_go_early_or_never(env, grip: float, outcome: str) -> None:
    tally, got = _tallied_run(env, Overridden(grip), task=0, seed=0)
    assert got == outcome
    if outcome == "off_target":  # let go right after the lift, where A was picked up
        assert tally.release is not None and tally.release.xy_m > env.unwrapped.layout.edge_m
        assert not tally.release.closed


METAWORLD_CARRIES = r"""
import json
import numpy as np
from awda_bench.evaluation.carry import CarryTally
from awda_bench.metaworld.env import MetaWorldEnv
from awda_bench.metaworld.expert import expert_action, task_policy
from awda_bench.suites import load_suite

suite = load_suite("metaworld")
index = {suite.task(t).name: t for t in suite.held_out}
env, out = MetaWorldEnv(suite), {}
for name, let_go in (("pick-place-wall-v3", False), ("pick-place-wall-v3", True),
                     ("button-press-v3", False)):
    obs, info = env.reset(seed=3, options={"task": index[name]})
    tally, policy, success, after = CarryTally.for_env(env), task_policy(name), False, 0
    if tally is None:
        out[name] = None
        continue
    # the expert closes its hand on the way down, so the env's latch (reached before the first
    # grip) stays off: the carry starts here once the puck is 5 cm up
    start_z, lifted = float(env.target_position()[0, 2]), False
    for _step in range(suite.horizon_steps):
        action = expert_action(policy, obs)[0]
        if let_go and lifted:
            after += 1
            action = np.array([0.0, 0.0, 0.0, -1.0]) if after > 5 else action
        obs, _, _, _, info = env.step(action)
        lifted |= float(env.target_position()[0, 2]) - start_z > 0.05
        tally.after_step(action, lifted)
        success |= bool(info["success"])
        if success or after > 20:
            break
    release = tally.release
    out[f"{name} {let_go}"] = {
        "goal": tally.goal, "outcome": tally.outcome(lifted, success),
        "release": None if release is None else [release.xy_m, release.dz_m, release.closed],
    }
env.close()
print(json.dumps(out))
"""


@pytest.mark.slow
@needs_metaworld
def test_metaworld_carries_are_tallied_and_its_pushes_are_not() -> None:
    """Meta-World answers the tally's questions too (numpy, a finger pad's touch as the hold):
    the expert places pick-place-wall's puck; told to open its hand five steps after the lift it
    lets go where it picked the puck up, off target; button-press has no place goal."""
    python = metaworld_python()
    assert python is not None
    env = {**os.environ, "PYTHONPATH": str(PROJECT_ROOT), "MUJOCO_GL": "egl"}
    done = subprocess.run(
        [python, "-c", METAWORLD_CARRIES], capture_output=True, text=True, env=env, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["button-press-v3"] is None
    placed, dropped = out["pick-place-wall-v3 False"], out["pick-place-wall-v3 True"]
    assert placed["outcome"] == "placed" and len(placed["goal"]) == 3
    assert dropped["outcome"] == "off_target"
    xy_m, _, closed = dropped["release"]
    assert xy_m > 0.07 and not closed  # Meta-World's success radius for pick-place-wall

"""AWDA-Basketball-v1: layout invariants (fast), basketball-specific env checks and the scripted
expert on the agent (slow). The contract every env keeps (the expert on the demonstrator included)
is in ``test_env_contract.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from task_env_helpers import run_expert, task_env_fixture

from awda_bench.envs.basketball import BALLS, HOOPS, BallSpec, BasketballLayout
from awda_bench.envs.layouts import sample_separated_xy
from awda_bench.envs.static_props import HoopSpec
from awda_bench.experts.basketball import BasketballExpert

PANDA_OPEN_M = 0.08
"""Panda finger gap when open [m]."""

# ---------------------------------------------------------------------------- fast


def test_balls_fit_the_gripper_and_the_rings() -> None:
    for ball in BALLS:
        assert 2 * ball.radius_m <= PANDA_OPEN_M - 0.02  # >= 1 cm clearance per finger
        for hoop in HOOPS:
            assert hoop.inner_radius_m - ball.radius_m >= 0.015


def test_hoops_and_balls_are_distinct() -> None:
    assert len({h.color for h in HOOPS}) == 4 and len({b.color for b in BALLS}) == 3
    assert not {h.color for h in HOOPS} & {b.color for b in BALLS}
    goals = np.array([h.goal_m for h in HOOPS])
    gaps = np.linalg.norm(goals[:, None, :2] - goals[None, :, :2], axis=-1) + np.eye(4)
    assert gaps.min() > 2 * max(h.outer_radius_m for h in HOOPS)  # rings do not overlap
    assert len({h.goal_m[2] for h in HOOPS}) == 4


def test_a_ball_resting_in_the_net_is_a_success() -> None:
    lay = BasketballLayout()
    for hoop in lay.hoops:
        for ball in lay.balls:
            # at rest on the net floor, centred or touching the cage: within the success radius
            depth = hoop.goal_m[2] - (hoop.net_floor_z_m + ball.rest_height_m)
            off_axis = hoop.inner_radius_m - ball.radius_m
            assert 0 < depth < lay.success_radius_m
            assert np.hypot(depth, off_axis) <= lay.success_radius_m
    deep = HoopSpec(goal_m=(0.0, 0.0, 0.15), color=(1, 1, 1, 1), net_depth_m=0.08)
    with pytest.raises(ValueError, match="success_radius_m"):
        BasketballLayout(hoops=(deep,) * 4)


def test_hoop_heights_derive_from_the_goal() -> None:
    hoop = HoopSpec(goal_m=(0.0, 0.0, 0.15), color=(1, 1, 1, 1))
    assert hoop.rim_top_z_m == pytest.approx(0.155)
    assert hoop.net_floor_z_m == pytest.approx(0.15 - hoop.net_depth_m)
    assert hoop.outer_radius_m == pytest.approx(0.06)
    assert BallSpec(name="b", color=(1, 1, 1, 1)).rest_height_m == pytest.approx(0.028)


def test_spawn_sampler_keeps_separation_and_the_middle_band_free() -> None:
    lay = BasketballLayout()
    torch.manual_seed(0)
    xy = sample_separated_xy(
        64,
        3,
        center_xy_m=lay.spawn_center_xy_m,
        half_size_m=lay.spawn_half_size_m,
        min_separation_m=lay.min_separation_m,
        min_abs_y_m=lay.spawn_min_abs_y_m,
    )
    assert xy.shape == (64, 3, 2)
    d = torch.linalg.norm(xy[:, :, None] - xy[:, None], dim=-1) + torch.eye(3)
    assert float(d.min()) >= lay.min_separation_m
    assert float(xy[..., 1].abs().min()) >= lay.spawn_min_abs_y_m
    dx = (xy[..., 0] - lay.spawn_center_xy_m[0]).abs()
    assert float(dx.max()) <= lay.spawn_half_size_m[0] + 1e-6
    with pytest.raises(ValueError, match="min_abs_y_m"):
        sample_separated_xy(
            1, 2, center_xy_m=(0, 0), half_size_m=(0.1, 0.1), min_separation_m=0.0, min_abs_y_m=0.2
        )
    with pytest.raises(RuntimeError, match="apart"):
        sample_separated_xy(
            1, 3, center_xy_m=(0, 0), half_size_m=(0.01, 0.01), min_separation_m=0.5, candidates=16
        )


# ---------------------------------------------------------------------------- slow (simulation)


env = task_env_fixture("AWDA-Basketball-v1")


def _ball_state(env) -> np.ndarray:
    return torch.stack([b.pose.raw_pose for b in env.unwrapped.balls], dim=1).cpu().numpy()


@pytest.mark.slow
def test_balls_stay_put_at_rest(env) -> None:
    env.reset(seed=3)
    before = _ball_state(env)[..., :3]
    for _ in range(20):
        env.step(np.zeros(4, dtype=np.float32))
    assert np.abs(_ball_state(env)[..., :3] - before).max() < 1e-3


@pytest.mark.slow
def test_success_only_near_the_target_hoop(env) -> None:
    from mani_skill.utils.structs.pose import Pose

    base = env.unwrapped
    env.reset(seed=1, options={"task": 6})  # yellow ball, cyan hoop
    ball = base.balls[1]
    for j, hoop in enumerate(base.layout.hoops):
        ball.set_pose(
            Pose.create_from_pq(torch.tensor([hoop.goal_m]) - torch.tensor([[0, 0, 0.01]]))
        )
        assert bool(base.evaluate()["success"][0]) == (j == 2)
    goal = torch.tensor([base.layout.hoops[2].goal_m])
    ball.set_pose(Pose.create_from_pq(goal + torch.tensor([[0.0, 0.0, 0.05]])))  # above the ring
    assert not bool(base.evaluate()["success"][0])
    base.balls[0].set_pose(Pose.create_from_pq(goal))  # the wrong ball in the right hoop
    ball.set_pose(Pose.create_from_pq(torch.tensor([[-0.2, 0.25, 0.028]])))
    assert not bool(base.evaluate()["success"][0])


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [(0, 3), (11, 7)])
def test_expert_puts_the_ball_in_the_hoop_with_the_agent(env, task: int, seed: int) -> None:
    run = run_expert(env, BasketballExpert(), task, seed, horizon=300)
    assert run.done and run.steps < 250
    for key in ("success", "success_once", "reached", "grasped"):
        assert bool(run.info[key][0]), key
    # the ball rests in the net: still a success a second later
    for _ in range(20):
        _, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
    assert bool(info["success"][0])

"""AWDA-Basketball-v1: layout invariants (fast), basketball-specific env checks and the scripted
expert (slow). The contract every env keeps is in ``test_env_contract.py``."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from awda_bench.envs.basketball import BALLS, HOOPS, BallSpec, BasketballLayout
from awda_bench.envs.layouts import sample_separated_xy
from awda_bench.envs.static_props import HoopSpec
from awda_bench.episode import EpisodeContext, EpisodeSpec
from awda_bench.experts.basketball import BasketballExpert, BasketballExpertConfig

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


def test_expert_config_rejects_non_positive_values() -> None:
    with pytest.raises(ValueError, match="release_clearance_m"):
        BasketballExpertConfig(release_clearance_m=0.0)
    with pytest.raises(ValueError, match="close_steps"):
        BasketballExpertConfig(close_steps=0)
    with pytest.raises(RuntimeError, match="reset"):
        BasketballExpert().act(None)


# ---------------------------------------------------------------------------- slow (simulation)


@pytest.fixture(scope="module")
def env():
    import awda_bench.envs  # noqa: F401

    e = gym.make("AWDA-Basketball-v1", obs_mode="state", reward_mode="none", num_envs=1)
    yield e
    e.close()


def _ball_state(env) -> np.ndarray:
    return torch.stack([b.pose.raw_pose for b in env.unwrapped.balls], dim=1).cpu().numpy()


@pytest.mark.slow
def test_make_reset_step(env) -> None:
    base = env.unwrapped
    assert base.family == "basketball" and base.num_variations == 12 and base.has_grasp_target
    obs, info = env.reset(seed=0, options={"task": 7})
    assert torch.isfinite(obs).all()
    assert int(info["task"][0]) == 7 and not bool(info["success"][0])
    assert int(base.target_ball_index[0]) == 1 and int(base.target_hoop_index[0]) == 3
    obs, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
    assert torch.isfinite(obs).all()
    assert set(info) >= {"success", "success_once", "reached", "grasped", "goal_distance_m"}
    assert set(base.truth_signals()) == {"grasp"}


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


def _rollout(env, task: int, seed: int, horizon: int = 300) -> tuple[int, dict]:
    expert = BasketballExpert()
    obs, _ = env.reset(seed=seed, options={"task": task})
    spec = EpisodeSpec(suite="mosaic", task=task, episode=0, seed=seed, demo_seed=seed)
    expert.reset(EpisodeContext(env=env.unwrapped, spec=spec))
    info: dict = {}
    for t in range(horizon):
        action = expert.act(obs)
        assert action.shape == (1, 4) and np.abs(action).max() <= 1.0
        obs, _, _, _, info = env.step(action)
        if expert.done:
            return t + 1, info
    return horizon, info


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [(0, 3), (11, 7)])
def test_expert_puts_the_ball_in_the_hoop_with_the_agent(env, task: int, seed: int) -> None:
    steps, info = _rollout(env, task, seed)
    assert steps < 250
    for key in ("success", "success_once", "reached", "grasped"):
        assert bool(info[key][0]), key
    # the ball rests in the net: still a success a second later
    for _ in range(20):
        _, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
    assert bool(info["success"][0])


@pytest.mark.slow
def test_expert_drives_the_demonstrator() -> None:
    import awda_bench.envs  # noqa: F401

    e = gym.make(
        "AWDA-Basketball-v1", robot_uids="awda_demonstrator", obs_mode="state", reward_mode="none"
    )
    try:
        steps, info = _rollout(e, task=5, seed=2)
        assert steps < 250 and bool(info["success"][0])
    finally:
        e.close()

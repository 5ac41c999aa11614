"""gt-waypoints, random and scripted policies (the sim tests are marked slow; CI runs them)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from awda_bench.episode import EpisodeContext, EpisodeSpec, Policy
from awda_bench.policies.random_policy import RandomPolicy


def _ctx(seed: int, num_envs: int = 2) -> EpisodeContext:
    spec = EpisodeSpec(suite="pick_place", task=14, episode=0, seed=seed, demo_seed=seed + 1)
    observations = SimpleNamespace(num_envs=num_envs)  # all RandomPolicy reads
    return EpisodeContext(env=None, spec=spec, observations=observations)  # type: ignore[arg-type]


def test_random_policy_is_uniform_in_bounds_and_seeded_per_episode() -> None:
    policy = RandomPolicy()
    assert isinstance(policy, Policy)
    policy.reset(_ctx(3))
    a = np.stack([policy.act(None) for _ in range(500)])
    assert a.shape == (500, 2, 4) and a.dtype == np.float32
    assert a.min() >= -1.0 and a.max() <= 1.0
    assert abs(a.mean()) < 0.05 and a.std() > 0.5
    policy.reset(_ctx(3))
    assert np.array_equal(policy.act(None), a[0])
    policy.reset(_ctx(4))
    assert not np.array_equal(policy.act(None), a[0])
    assert not policy.done and policy.waypoints is None


@pytest.fixture(scope="module")
def pick_place_env():
    gym = pytest.importorskip("gymnasium")
    import awda_bench.envs  # noqa: F401

    env = gym.make("AWDA-PickPlace-v1", obs_mode="state", num_envs=1, reward_mode="none")
    yield env
    env.close()


def _run(env, policy, task: int, seed: int, horizon: int = 200):
    from awda_bench.policies.gt_waypoints import episode_spec_for

    obs, info = env.reset(seed=seed, options={"task": task})
    policy.reset(EpisodeContext(env=env.unwrapped, spec=episode_spec_for("pick_place", task, seed)))
    steps = 0
    while steps < horizon and not policy.done:
        obs, _, _, _, info = env.step(policy.act(obs))
        steps += 1
    return info, steps


@pytest.mark.slow
def test_gt_waypoints_plans_restores_the_start_and_succeeds(pick_place_env) -> None:
    from awda_bench.policies.gt_waypoints import (
        GtWaypointsConfig,
        GtWaypointsPolicy,
        episode_spec_for,
    )

    env = pick_place_env
    base = env.unwrapped
    env.reset(seed=123, options={"task": 14})
    qpos0 = base.agent.robot.get_qpos().clone()
    objects0, _ = base.object_poses()
    policy = GtWaypointsPolicy(GtWaypointsConfig(record_truth=True))
    policy.reset(EpisodeContext(env=base, spec=episode_spec_for("pick_place", 14, 123)))
    # planning ran the expert on this very scene and put everything back
    assert float((base.agent.robot.get_qpos() - qpos0).abs().max()) < 1e-6
    assert float((base.object_poses()[0] - objects0).abs().max()) < 1e-6
    assert not bool(base.grip_attempted[0])
    traj = policy.stats.trajectories[0]
    assert traj.meta["expert_done"] and traj.truth["grasp"].any()
    W = policy.waypoints
    assert W is not None and W.shape == (5, 5)  # xyz, grasped, pressing
    assert not W[:, 4].any()  # nothing is pressed in pick-and-place
    assert W[:, 3].tolist() == [0, 1, 1, 1, 0]

    steps = 0
    obs = base.get_obs()
    info = {}
    while steps < 200 and not policy.done:
        obs, _, _, _, info = env.step(policy.act(obs))
        steps += 1
    assert policy.done
    assert bool(info["success"][0]) and bool(info["reached"][0]) and bool(info["grasped"][0])
    ex = policy.executors[0]
    grasp = ex.grasp_primitives[0]
    assert [e.kind for e in ex.log] == ["move", "grasp", "carry", "carry", "drop+move"]
    # wrist depth frames only during the grasp's hover: one per hover step, plus the final check
    assert policy.stats.frames == grasp.localizations > 0
    assert grasp.localization_misses == 0
    assert policy.stats.overhead_per_step_ms < 5.0  # generous bound for shared CI machines
    # evaluating (the default) plans without the contact-force truth: only the miner is used
    env.reset(seed=124, options={"task": 14})
    plain = GtWaypointsPolicy()
    plain.reset(EpisodeContext(env=base, spec=episode_spec_for("pick_place", 14, 124)))
    assert plain.stats.trajectories[0].truth == {} and plain.waypoints is not None


@pytest.mark.slow
def test_scripted_policy_wraps_the_expert(pick_place_env) -> None:
    from awda_bench.policies.scripted import ScriptedPolicy

    policy = ScriptedPolicy()
    info, steps = _run(pick_place_env, policy, task=15, seed=7)
    assert policy.done and steps < 200
    assert bool(info["success"][0])


@pytest.mark.slow
def test_wrist_localization_in_the_sim_finds_the_target_below(pick_place_env) -> None:
    from awda_bench.policies.gt_waypoints import robot_states
    from awda_bench.primitives.config import FreeSpaceConfig
    from awda_bench.primitives.free_space import FreeSpace
    from awda_bench.primitives.wrist_camera import WristLocator

    env = pick_place_env
    base = env.unwrapped
    env.reset(seed=11, options={"task": 13})  # the can
    target = base.target_pose()[0][0].cpu().numpy()
    goal = target + np.array([0.0, 0.0, 0.04 + 0.2])
    move = FreeSpace(goal, FreeSpaceConfig(reach_tol_m=0.003))
    while (a := move.step(robot_states(base)[0])) is not None:
        env.step(a[None].astype(np.float32))
    locator = WristLocator(base)
    loc = locator()
    assert loc is not None and locator.frames == 1
    assert np.linalg.norm(loc.position_world[:2] - target[:2]) < 0.015
    assert loc.position_world[2] == pytest.approx(target[2] + 0.04, abs=0.01)  # the can's top


@pytest.mark.slow
def test_physics_only_planning_gives_the_same_rollout_as_full_env_steps() -> None:
    gym = pytest.importorskip("gymnasium")
    import awda_bench.envs  # noqa: F401
    from awda_bench.policies.gt_waypoints import (
        GtWaypointsConfig,
        GtWaypointsPolicy,
        episode_spec_for,
    )

    rollouts = []
    for physics_only in (False, True):
        # A fresh env each: PhysX keeps contact state across resets, so a shared env's earlier
        # episodes (other tests) can change later rollouts by a fraction of a millimetre.
        env = gym.make("AWDA-PickPlace-v1", obs_mode="state", num_envs=1, reward_mode="none")
        env.reset(seed=7, options={"task": 15})
        policy = GtWaypointsPolicy(GtWaypointsConfig(physics_only_planning=physics_only))
        (traj,) = policy.plan(
            EpisodeContext(env=env.unwrapped, spec=episode_spec_for("pick_place", 15, 7))
        )
        env.close()
        rollouts.append(traj)
    full, physics = rollouts
    assert full.meta["expert_done"] and len(full) > 20
    np.testing.assert_array_equal(physics.tcp_pos, full.tcp_pos)
    np.testing.assert_array_equal(physics.actions, full.actions)
    np.testing.assert_array_equal(physics.gripper_opening_m, full.gripper_opening_m)

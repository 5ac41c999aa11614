"""AWDA-StackBlock-v1: variation table (fast), stacking-specific env checks (slow). The contract
every env keeps is in ``test_env_contract.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from task_env_helpers import assert_spread_out, run_expert, task_env_fixture

from awda_bench.envs.stack_block import STACK_ORDERS, StackBlockLayout
from awda_bench.experts.stack_block import StackBlockExpert

# ---------------------------------------------------------------------------- fast


def test_six_ordered_pairs_of_three_distinct_cubes() -> None:
    assert len(STACK_ORDERS) == 6 and len(set(STACK_ORDERS)) == 6
    assert all(a != b and {a, b} <= {0, 1, 2} for a, b in STACK_ORDERS)
    cubes = StackBlockLayout().cubes
    assert len({c.color for c in cubes}) == 3
    assert all(c.size_m == (0.045, 0.045, 0.045) for c in cubes)
    # the open Panda fingers (8 cm) fit around a cube at any yaw
    assert max(c.footprint_radius_m for c in cubes) * 2 < 0.08


# ---------------------------------------------------------------------------- slow (simulation)


env = task_env_fixture("AWDA-StackBlock-v1")


def _cube_state(env) -> np.ndarray:
    pos, quat = env.unwrapped.cube_poses()
    return torch.cat([pos, quat], dim=2).cpu().numpy()


def _place(cube, xyz) -> None:
    from mani_skill.utils.structs.pose import Pose

    cube.set_pose(Pose.create_from_pq(torch.tensor([xyz], dtype=torch.float32)))
    cube.set_linear_velocity(torch.zeros((1, 3)))


@pytest.mark.slow
def test_same_seed_same_layout_and_layouts_respect_the_rules(env) -> None:
    lay = env.unwrapped.layout
    env.reset(seed=11, options={"task": 1})
    first = _cube_state(env)
    env.reset(seed=12, options={"task": 1})
    other = _cube_state(env)
    env.reset(seed=11, options={"task": 1})
    np.testing.assert_array_equal(first, _cube_state(env))
    assert np.abs(first - other).max() > 1e-3
    center = np.array(lay.spawn_center_xy_m)
    (x_lo, x_hi), (y_lo, y_hi) = lay.hidden_box_xy_m
    for seed in range(8):
        env.reset(seed=seed)
        xy = env.unwrapped.cube_poses()[0][0, :, :2].cpu().numpy()
        assert_spread_out(xy, center, lay.spawn_half_size_m, lay.min_separation_m)
        hidden = (xy[:, 0] > x_lo) & (xy[:, 0] < x_hi) & (xy[:, 1] > y_lo) & (xy[:, 1] < y_hi)
        assert not hidden.any()


@pytest.mark.slow
def test_success_needs_a_resting_on_b_not_on_c_not_above(env) -> None:
    base = env.unwrapped
    edge = base.layout.edge_m
    env.reset(seed=3, options={"task": 4})  # A = blue, B = red, C = green
    a, b = (base.cubes[i] for i in STACK_ORDERS[4])
    c = base.cubes[3 - sum(STACK_ORDERS[4])]
    _place(b, [-0.10, 0.20, edge / 2])
    _place(c, [-0.10, -0.20, edge / 2])
    cases = {
        "on B": ([-0.10, 0.20, 1.5 * edge], True),
        "on B, 1.5 cm off centre": ([-0.085, 0.20, 1.5 * edge], True),
        "beside B": ([-0.10 + 0.9 * edge, 0.20, 1.5 * edge], False),
        "3 cm above B": ([-0.10, 0.20, 1.5 * edge + 0.03], False),
        "on C": ([-0.10, -0.20, 1.5 * edge], False),
        "on the table": ([0.0, 0.25, edge / 2], False),
    }
    for name, (xyz, expected) in cases.items():
        _place(a, xyz)
        assert bool(base.evaluate()["success"][0]) == expected, name
    # a falling A is not resting
    _place(a, [-0.10, 0.20, 1.5 * edge])
    a.set_linear_velocity(torch.tensor([[0.0, 0.0, -0.2]]))
    assert not bool(base.evaluate()["success"][0])


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [(0, 0), (5, 2)])
def test_expert_stacks_with_the_agent(env, task: int, seed: int) -> None:
    run = run_expert(env, StackBlockExpert(), task, seed, horizon=220)
    for _ in range(5):
        _, _, _, _, info = env.step(np.zeros(4, dtype=np.float32))
    assert run.done and bool(info["success"][0])
    assert bool(info["reached"][0]) and bool(info["grasped"][0])
    assert run.signals["grasp"] > 10

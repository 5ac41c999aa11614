"""AWDA-Drawer-v1: geometry and layout checks (fast), drawer-specific env checks and the scripted
expert on the agent (slow). The contract every env keeps (the expert on the demonstrator included)
is in ``test_env_contract.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from task_env_helpers import run_expert, task_env_fixture

from awda_bench.envs.articulated import DrawerCabinetSpec, rotate_z
from awda_bench.envs.drawer import DrawerLayout
from awda_bench.experts.drawer import DrawerExpert

REST_HAND_HALF_LENGTH_M = 0.104
"""The Panda hand at the agent's rest pose spans |y| <= this around y = 0 [m]."""
HAND_HALF_DEPTH_M = 0.032
"""Half extent of the Panda hand body along world x when pointing down [m]."""
REACH_M = 0.75
"""The agent reaches targets within this horizontal distance of its base axis [m]."""
BASE_X_M = -0.615
"""Agent base x [m]."""

# ---------------------------------------------------------------------------- fast


def test_cabinets_differ_and_handles_are_reachable_and_clear() -> None:
    lay = DrawerLayout()
    a, b = lay.cabinets
    assert a.front_color != b.front_color
    for spec in lay.cabinets:
        # both drawer handles below the Panda's top-down reach height
        assert max(spec.drawer_center_z_m) + spec.handle_head_size_m[2] / 2 <= 0.35
        # the fingers (8 cm apart when open) fit around the head with room to spare
        assert spec.handle_head_size_m[1] <= 0.08 - 0.02
        # the hand grasping a head stays in front of the cabinet's face
        assert spec.handle_stem_m + spec.handle_head_size_m[0] / 2 - HAND_HALF_DEPTH_M > 0.01
        # the carcass stands behind the hand resting at x = 0, and the drawer fronts (which come
        # out toward the robot) beside it
        yaw_shift = spec.width_m / 2 * np.sin(lay.placement.yaw_rad)
        assert spec.center_xy_m[0] - lay.placement.xy_m[0] - yaw_shift > HAND_HALF_DEPTH_M
        front_edge = abs(spec.center_xy_m[1]) - spec.width_m / 2 + spec.wall_m + spec.gap_m
        assert front_edge - lay.placement.xy_m[1] > REST_HAND_HALF_LENGTH_M
        for y, z in zip(spec.handle_y_m, spec.drawer_center_z_m, strict=True):
            x = spec.center_xy_m[0] + spec.handle_center_x_m + lay.placement.xy_m[0]
            y_world = abs(spec.center_xy_m[1] + y) + lay.placement.xy_m[1]
            assert np.hypot(x - BASE_X_M, y_world) < REACH_M
            assert z > 0


def test_spec_and_layout_validate() -> None:
    with pytest.raises(ValueError, match="apart"):
        DrawerCabinetSpec(name="c", center_xy_m=(0, 0), front_color=(1, 0, 0, 1), handle_y_m=(0, 0))
    with pytest.raises(ValueError, match="beyond the drawer front"):
        DrawerCabinetSpec(
            name="c", center_xy_m=(0, 0), front_color=(1, 0, 0, 1), handle_y_m=(0.12, -0.07)
        )
    with pytest.raises(ValueError, match="close_start_m"):
        DrawerLayout(close_start_m=(0.05, 0.10))
    with pytest.raises(ValueError, match="close_success_m"):
        DrawerLayout(close_success_m=0.0)


# ---------------------------------------------------------------------------- slow (simulation)


env = task_env_fixture("AWDA-Drawer-v1")


@pytest.mark.slow
def test_drawers_start_shut_to_be_opened_and_out_to_be_closed(env) -> None:
    base = env.unwrapped
    env.reset(seed=0, options={"task": 6})  # open cabinet 1's upper drawer
    np.testing.assert_allclose(base.drawer_slides().cpu().numpy(), 0.0, atol=1e-6)
    lo, hi = base.layout.close_start_m
    for seed in range(4):  # close: the target and one drawer of the other cabinet start out
        env.reset(seed=seed, options={"task": 3})  # cabinet 0, upper drawer
        slides = base.drawer_slides()[0].cpu().numpy()
        assert lo - 1e-6 <= slides[1] <= hi + 1e-6 and slides[0] == pytest.approx(0, abs=1e-6)
        assert int((slides[2:] > 1e-3).sum()) == 1


@pytest.mark.slow
def test_handle_position_follows_the_drawer_link(env) -> None:
    base = env.unwrapped
    for task in range(0, 8, 2):
        env.reset(seed=task, options={"task": task})
        drawer = int(base.target_drawer[0])
        cabinet = base.cabinets[drawer // 2]
        slides = torch.zeros((1, 2))
        slides[0, drawer % 2] = 0.1
        cabinet.set_qpos(slides)
        spec = base.target_spec(0)
        link = base.drawer_links[drawer]
        yaw = 2 * torch.atan2(link.pose.q[:, 3], link.pose.q[:, 0])
        local = torch.tensor([[spec.handle_center_x_m, spec.handle_y_m[drawer % 2], 0.0]])
        np.testing.assert_allclose(
            base.handle_position().numpy(), (link.pose.p + rotate_z(local, yaw)).numpy(), atol=1e-5
        )
        # the slide axis points from the shut handle to the pulled one
        shut = base.handle_position(torch.zeros(1))
        moved = base.handle_position() - shut
        np.testing.assert_allclose(moved.numpy(), (0.1 * base.slide_axis()).numpy(), atol=1e-5)
        assert float(base.slide_axis()[0, 0]) < -0.99  # toward the robot


@pytest.mark.slow
def test_success_thresholds_and_drawer_stays_where_left(env) -> None:
    base = env.unwrapped
    lay = base.layout
    env.reset(seed=0, options={"task": 2})  # open cabinet 0 upper drawer
    base.cabinets[0].set_qpos(torch.tensor([[0.0, lay.open_success_m - 0.01]]))
    assert not bool(base.evaluate()["success"][0])
    base.cabinets[0].set_qpos(torch.tensor([[0.0, lay.open_success_m + 0.01]]))
    assert bool(base.evaluate()["success"][0])
    for _ in range(10):  # passive, damped slide: no drift
        env.step(np.zeros(4, dtype=np.float32))
    assert float(base.target_slide()[0]) == pytest.approx(lay.open_success_m + 0.01, abs=0.003)
    env.reset(seed=0, options={"task": 5})  # close cabinet 1 lower drawer
    assert not bool(base.evaluate()["success"][0])
    base.cabinets[1].set_qpos(torch.tensor([[lay.close_success_m - 0.002, 0.0]]))
    assert bool(base.evaluate()["success"][0])
    base.cabinets[1].set_qpos(torch.tensor([[lay.close_success_m + 0.004, 0.0]]))
    assert not bool(base.evaluate()["success"][0])


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [(2, 0), (7, 1)])
def test_expert_succeeds_on_the_agent(env, task: int, seed: int) -> None:
    run = run_expert(env, DrawerExpert(), task, seed, horizon=200)
    assert run.done and bool(run.info["success"][0])
    assert run.signals["grasp" if task % 2 == 0 else "push"] > 0

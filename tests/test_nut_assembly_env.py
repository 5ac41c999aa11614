"""AWDA-NutAssembly-v1: geometry invariants (fast), nut-specific env checks and the scripted expert
on the agent (slow). The contract every env keeps (the expert on the demonstrator included) is in
``test_env_contract.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from task_env_helpers import run_expert, task_env_fixture

from awda_bench.envs.nut_assembly import NUTS, PEGS, NutAssemblyLayout, NutSpec
from awda_bench.envs.static_props import PegSpec
from awda_bench.experts.nut_assembly import NutAssemblyExpert

PANDA_OPEN_M = 0.08
"""Panda finger gap when open [m]."""
PANDA_FINGER_HALF_WIDTH_M = 0.00875
"""Half a Panda fingertip's extent along the handle (x) [m]."""

# ---------------------------------------------------------------------------- fast


def test_nut_geometry_fits_peg_and_gripper() -> None:
    for nut in NUTS:
        assert 2 * nut.handle_half_width_m <= PANDA_OPEN_M - 0.04
        # fingers around the handle's centre stay clear of the nut body
        assert nut.handle_length_m / 2 > PANDA_FINGER_HALF_WIDTH_M + 0.005
        gx, gy, gz = nut.grasp_point_m
        assert gx == pytest.approx(-(nut.outer_half_m + nut.handle_length_m / 2)) and gy == gz == 0
        lo, hi = nut.bounds_m
        assert lo[0] < gx < hi[0] and hi[0] == pytest.approx(nut.outer_half_m)
        for peg in PEGS:
            assert nut.hole_half_m - peg.half_width_m >= 0.005  # >= 5 mm play per side
            assert peg.height_m >= 0.08


def test_layout_rejects_a_hole_smaller_than_the_peg_diagonal() -> None:
    tight = NutSpec(name="tight", color=(1, 1, 1, 1), hole_half_m=0.013)
    with pytest.raises(ValueError, match="diagonal"):
        NutAssemblyLayout(nuts=(tight,) * 3)


def test_nuts_and_pegs_are_distinct() -> None:
    assert len({n.color for n in NUTS}) == 3 and len({p.color for p in PEGS}) == 3
    assert not {n.color for n in NUTS} & {p.color for p in PEGS}
    xy = np.array([p.center_xy_m for p in PEGS])
    gaps = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.eye(3)
    assert gaps.min() > 2 * max(p.plate_half_m for p in PEGS)
    peg = PegSpec(center_xy_m=(0.0, 0.0), color=(1, 1, 1, 1))
    assert peg.base_z_m == pytest.approx(0.006) and peg.top_z_m == pytest.approx(0.096)


# ---------------------------------------------------------------------------- slow (simulation)


env = task_env_fixture("AWDA-NutAssembly-v1")


@pytest.mark.slow
def test_nuts_start_with_their_handles_roughly_towards_the_robot(env) -> None:
    base = env.unwrapped
    env.reset(seed=0, options={"task": 5})
    env.step(np.zeros(4, dtype=np.float32))
    # nuts lie flat, handles roughly towards the robot
    lay = base.layout
    _, quat = base.nut_poses()
    yaw = 2 * torch.atan2(quat[0, :, 3], quat[0, :, 0])
    assert float(yaw.abs().max()) <= lay.max_yaw_rad + 1e-3


@pytest.mark.slow
def test_success_needs_the_right_peg_the_bottom_and_the_gripper_away(env) -> None:
    from mani_skill.utils.structs.pose import Pose

    base = env.unwrapped
    env.reset(seed=1, options={"task": 4})  # yellow nut, magenta peg
    nut, spec = base.nuts[1], base.layout.nuts[1]
    for j, peg in enumerate(base.layout.pegs):
        x, y = peg.center_xy_m
        nut.set_pose(Pose.create_from_pq(torch.tensor([[x, y, peg.base_z_m + spec.height_m / 2]])))
        assert bool(base.evaluate()["success"][0]) == (j == 1)
    x, y = base.layout.pegs[1].center_xy_m
    z = base.layout.pegs[1].base_z_m + spec.height_m / 2
    nut.set_pose(Pose.create_from_pq(torch.tensor([[x, y, z + 0.05]])))  # halfway up the peg
    assert not bool(base.evaluate()["success"][0])
    # down on the peg but the TCP at its handle (still held): not a success
    tcp = base.agent.tcp_pose.p
    grasp = torch.tensor([spec.grasp_point_m])
    nut.set_pose(Pose.create_from_pq(tcp - grasp))
    info = base.evaluate()
    assert float(info["tcp_clearance_m"][0]) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [(0, 3), (8, 6)])
def test_expert_puts_the_nut_on_the_peg_with_the_agent(env, task: int, seed: int) -> None:
    run = run_expert(env, NutAssemblyExpert(), task, seed, horizon=300)
    assert run.done and run.steps < 250
    for key in ("success", "success_once", "reached", "grasped"):
        assert bool(run.info[key][0]), key
    assert float(run.info["height_m"][0]) < 0.005


def test_rotate_matches_mani_skill_quaternion_apply() -> None:
    from mani_skill.utils.geometry.rotation_conversions import (
        quaternion_apply,
        quaternion_invert,
    )

    from awda_bench.envs.nut_assembly import rotate

    torch.manual_seed(0)
    quat = torch.nn.functional.normalize(torch.randn(8, 4), dim=1)
    vec = torch.randn(8, 3)
    torch.testing.assert_close(rotate(quat, vec), quaternion_apply(quat, vec))
    torch.testing.assert_close(
        rotate(quat, vec, inverse=True), quaternion_apply(quaternion_invert(quat), vec)
    )

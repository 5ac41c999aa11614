"""AWDA-Door-v1: geometry and layout checks (fast), door-specific env checks and the scripted expert
on the agent (slow). The contract every env keeps (the expert on the demonstrator included) is in
``test_env_contract.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from task_env_helpers import run_expert, task_env_fixture

from awda_bench.envs.articulated import DoorCabinetSpec, hinge_joint_quat, rotate_z
from awda_bench.envs.door import DoorLayout
from awda_bench.experts.door import DoorExpert

REST_HAND_HALF_LENGTH_M = 0.104
"""The Panda hand at the agent's rest pose spans |y| <= this around y = 0 [m]."""

# ---------------------------------------------------------------------------- fast


def _rotate(q: list[float], v: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    return r @ v


@pytest.mark.parametrize("sign", [-1, 1])
def test_hinge_joint_frame_turns_about_vertical_axis(sign: int) -> None:
    axis = _rotate(hinge_joint_quat(sign), np.array([1.0, 0.0, 0.0]))
    np.testing.assert_allclose(axis, [0.0, 0.0, sign], atol=1e-12)


def test_rotate_z_quarter_turn() -> None:
    v = torch.tensor([[1.0, 0.0, 0.3]])
    np.testing.assert_allclose(
        rotate_z(v, torch.tensor([np.pi / 2])).numpy(), [[0, 1, 0.3]], atol=1e-6
    )


def test_two_doors_differ_and_clear_the_resting_hand() -> None:
    lay = DoorLayout()
    a, b = lay.doors
    assert a.panel_color != b.panel_color and a.hinge_side == -b.hinge_side
    for spec in lay.doors:
        # doors open toward the robot: the opening sign turns the panel's free edge to -x
        free_edge = rotate_z(
            torch.tensor([[0.0, -spec.hinge_side * spec.panel_width_m, 0.0]]),
            torch.tensor([spec.opening_sign * 0.5]),
        )
        assert float(free_edge[0, 0]) < 0
        # the handle's top is flush with the panel top; the bar stands clear of the face
        assert spec.handle_top_z_m == pytest.approx(spec.height_m - spec.panel_gap_m)
        assert spec.handle_standoff_m - spec.handle_radius_m > 0.03
        # the handle (and the panel edge) never under the hand resting at y = 0
        handle_y = spec.center_xy_m[1] + spec.hinge_side * spec.width_m / 2
        handle_y -= spec.hinge_side * spec.handle_from_hinge_m
        assert (
            abs(handle_y) - spec.handle_radius_m - lay.placement.xy_m[1] > REST_HAND_HALF_LENGTH_M
        )


def test_layout_and_spec_validate() -> None:
    with pytest.raises(ValueError, match="hinge_side"):
        DoorCabinetSpec(name="d", center_xy_m=(0, 0), hinge_side=0, panel_color=(1, 0, 0, 1))
    with pytest.raises(ValueError, match="handle_standoff_m"):
        DoorCabinetSpec(
            name="d",
            center_xy_m=(0, 0),
            hinge_side=1,
            panel_color=(1, 0, 0, 1),
            handle_standoff_m=0.005,
        )
    with pytest.raises(ValueError, match="close_start_rad"):
        DoorLayout(close_start_rad=(0.3, 0.5))
    with pytest.raises(ValueError, match="open_success_rad"):
        DoorLayout(open_success_rad=2.0)


# ---------------------------------------------------------------------------- slow (simulation)


env = task_env_fixture("AWDA-Door-v1")


@pytest.mark.slow
def test_doors_start_shut_to_be_opened_and_open_to_be_closed(env) -> None:
    base = env.unwrapped
    env.reset(seed=0, options={"task": 2})  # open door 1
    np.testing.assert_allclose(base.door_angles().cpu().numpy(), 0.0, atol=1e-6)
    # close variations: both doors start open inside close_start_rad
    env.reset(seed=0, options={"task": 1})
    lo, hi = base.layout.close_start_rad
    angles = base.door_angles().cpu().numpy()
    assert ((angles >= lo - 1e-6) & (angles <= hi + 1e-6)).all()


@pytest.mark.slow
def test_placement_noise_stays_in_bounds(env) -> None:
    base = env.unwrapped
    noise = base.layout.placement
    for seed in range(6):
        env.reset(seed=seed, options={"task": 0})
        for cabinet, spec in zip(base.cabinets, base.layout.doors, strict=True):
            p = cabinet.pose.p[0].cpu().numpy()
            q = cabinet.pose.q[0].cpu().numpy()
            assert abs(p[0] - spec.center_xy_m[0]) <= noise.xy_m[0] + 1e-6
            assert abs(p[1] - spec.center_xy_m[1]) <= noise.xy_m[1] + 1e-6
            assert abs(2 * np.arctan2(q[3], q[0])) <= noise.yaw_rad + 1e-6


@pytest.mark.slow
def test_handle_position_follows_the_door_link(env) -> None:
    base = env.unwrapped
    for task, angle in ((0, 0.0), (1, 0.7), (2, 0.3), (3, 1.0)):
        env.reset(seed=task, options={"task": task})
        cabinet = base.cabinets[int(base.target_door[0])]
        cabinet.set_qpos(torch.tensor([[angle]]))
        spec = base.target_spec(0)
        link = base.door_links[int(base.target_door[0])]
        yaw = 2 * torch.atan2(link.pose.q[:, 3], link.pose.q[:, 0])
        local = torch.tensor([spec.handle_from_hinge_local_m()])
        expected = link.pose.p + rotate_z(local, yaw)
        got = base.handle_position()
        np.testing.assert_allclose(got[:, :2].numpy(), expected[:, :2].numpy(), atol=1e-5)
        assert float(got[0, 2]) == pytest.approx(spec.handle_top_z_m)
        assert float(base.target_angle()[0]) == pytest.approx(angle, abs=1e-5)


@pytest.mark.slow
def test_success_thresholds_and_door_stays_where_left(env) -> None:
    base = env.unwrapped
    lay = base.layout
    env.reset(seed=0, options={"task": 0})  # open door 0
    base.cabinets[0].set_qpos(torch.tensor([[lay.open_success_rad - 0.05]]))
    assert not bool(base.evaluate()["success"][0])
    base.cabinets[0].set_qpos(torch.tensor([[lay.open_success_rad + 0.05]]))
    assert bool(base.evaluate()["success"][0])
    for _ in range(10):  # passive, damped hinge: no drift
        env.step(np.zeros(4, dtype=np.float32))
    assert float(base.target_angle()[0]) == pytest.approx(lay.open_success_rad + 0.05, abs=0.01)
    env.reset(seed=0, options={"task": 3})  # close door 1 (starts open)
    assert not bool(base.evaluate()["success"][0])
    base.cabinets[1].set_qpos(torch.tensor([[lay.close_success_rad - 0.02]]))
    assert bool(base.evaluate()["success"][0])
    base.cabinets[0].set_qpos(torch.tensor([[0.0]]))  # the other door does not count
    base.cabinets[1].set_qpos(torch.tensor([[0.5]]))
    assert not bool(base.evaluate()["success"][0])


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [(0, 0), (3, 1)])
def test_expert_succeeds_on_the_agent(env, task: int, seed: int) -> None:
    run = run_expert(env, DoorExpert(), task, seed, horizon=200)
    assert run.done and bool(run.info["success"][0])
    assert run.signals["grasp" if task % 2 == 0 else "push"] > 0


def test_hand_holds_a_handle_it_drags_with_one_finger_but_not_one_it_pushes_or_touches() -> None:
    from awda_bench.envs.articulated import HOLD_MIN_FORCE_N, hand_holds

    strong = 10 * HOLD_MIN_FORCE_N
    cases = [  # (two-finger test, finger forces [N], opening [m], commanded closed) -> holds
        ((True, (strong, strong), 0.016, True), True),
        (
            (False, (0.0, strong), 0.020, True),
            True,
        ),  # dragging along the arc: the trailing finger lost contact
        ((False, (0.0, strong), 0.007, True), False),  # closed fingers pushing a panel
        ((False, (strong, 0.0), 0.08, False), False),  # an open hand bumping into the handle
        ((False, (0.0, 0.5 * HOLD_MIN_FORCE_N), 0.02, True), False),  # a light touch
        # fingers opening after a closed-hand push, passing 3 cm with one still on the handle
        ((False, (0.0, strong), 0.030, False), False),
    ]
    grasping = torch.tensor([c[0][0] for c in cases])
    forces = torch.tensor([c[0][1] for c in cases])
    opening = torch.tensor([c[0][2] for c in cases])
    closed = torch.tensor([c[0][3] for c in cases])
    assert hand_holds(grasping, forces, opening, closed).tolist() == [c[1] for c in cases]

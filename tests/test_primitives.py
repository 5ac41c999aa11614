"""Free-space, carry, drop and grasp primitives against the kinematic fake robot."""

from __future__ import annotations

import numpy as np
import pytest

from awda_bench.errors import UsageError
from awda_bench.primitives import (
    Carry,
    Drop,
    DropConfig,
    FreeSpace,
    FreeSpaceConfig,
    Grasp,
    GraspConfig,
    localize_object,
)
from awda_bench.primitives.base import RobotState
from awda_bench.primitives.free_space import straight_line_action
from awda_bench.primitives.grasp import GraspPhase
from awda_bench.primitives.kinematic_fake import Box, KinematicRobot


def _run(primitive, robot: KinematicRobot, limit: int = 500) -> list[np.ndarray]:
    actions = []
    state = robot.state
    while (a := primitive.step(state)) is not None:
        assert a.shape == (4,) and np.all(np.abs(a) <= 1.0 + 1e-12)
        actions.append(a)
        state = robot.step(a)
        assert len(actions) < limit, "primitive did not terminate"
    return actions


def _locator(robot: KinematicRobot):
    return lambda: localize_object(*robot.depth_frame())


def test_straight_line_action_keeps_direction_and_scales_to_unit_box() -> None:
    a = straight_line_action(np.zeros(3), np.array([0.3, -0.1, 0.05]), 0.02, grip=-1.0)
    assert np.max(np.abs(a[:3])) == pytest.approx(1.0)
    assert np.allclose(np.cross(a[:3], [0.3, -0.1, 0.05]), 0.0)
    small = straight_line_action(np.zeros(3), np.array([0.01, 0.0, -0.005]), 0.02, grip=1.0)
    assert np.allclose(small, [0.5, 0.0, -0.25, 1.0])  # exact displacement when it fits one step


def test_straight_line_action_at_reduced_speed_caps_components_and_keeps_direction() -> None:
    a = straight_line_action(np.zeros(3), np.array([0.3, -0.1, 0.05]), 0.02, -1.0, speed=0.5)
    assert np.max(np.abs(a[:3])) == pytest.approx(0.5)
    assert np.allclose(np.cross(a[:3], [0.3, -0.1, 0.05]), 0.0)
    fits = straight_line_action(np.zeros(3), np.array([0.004, 0.0, 0.0]), 0.02, 1.0, speed=0.5)
    assert np.allclose(fits, [0.2, 0.0, 0.0, 1.0])  # within half a step: exact
    with pytest.raises(ValueError, match="speed"):
        FreeSpace(np.zeros(3), speed=0.0)


def test_free_space_reaches_in_the_expected_number_of_steps_along_a_line() -> None:
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.3]))
    target = np.array([0.2, 0.1, 0.1])
    prim = FreeSpace(target, FreeSpaceConfig(reach_tol_m=0.005))
    actions = _run(prim, robot)
    assert prim.reached
    assert np.linalg.norm(robot.tcp_pos - target) < 0.005
    # path stays on the segment start -> target
    assert len(actions) == int(np.ceil(0.2 / 0.02))
    assert all(a[3] < 0 for a in actions)


def test_free_space_stops_at_its_step_budget() -> None:
    # the robot is slower than the primitive assumes
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.3]), max_step_m=0.001)
    prim = FreeSpace(np.array([0.5, 0.0, 0.3]), FreeSpaceConfig(step_budget=7))
    assert len(_run(prim, robot)) == 7
    assert not prim.reached


def test_carry_holds_the_gripper_closed() -> None:
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.3]))
    actions = _run(Carry(np.array([0.0, 0.1, 0.3])), robot)
    assert actions and all(a[3] > 0 for a in actions)


def test_drop_settles_then_opens_in_place_for_open_steps() -> None:
    # the kinematic robot stops at once: one closed step to see it settled, then open_steps open
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.3]), gripper_opening_m=0.0)
    actions = _run(Drop(DropConfig(open_steps=4)), robot)
    assert len(actions) == 5
    assert np.allclose(actions[0], [0, 0, 0, 1])
    assert all(np.allclose(a, [0, 0, 0, -1]) for a in actions[1:])
    assert robot.gripper_opening_m == pytest.approx(0.04)


def test_drop_waits_for_a_moving_tcp_at_most_settle_steps() -> None:
    from awda_bench.primitives.base import RobotState

    drop = Drop(DropConfig(open_steps=2, settle_steps=3))
    grips = []
    for z in (0.30, 0.28, 0.26, 0.24, 0.22, 0.20, 0.18):  # still moving 2 cm per step
        action = drop.step(RobotState(tcp_pos=np.array([0.0, 0.0, z]), gripper_opening_m=0.03))
        if action is None:
            break
        grips.append(action[3])
    assert grips == [1.0, 1.0, 1.0, -1.0, -1.0]


def test_grasp_lift_ends_when_the_grasped_thing_does_not_rise() -> None:
    """A handle on a hinge: the TCP cannot rise more than 3 mm after the close; the lift probes
    slowly and stops after ``lift_blocked_steps`` blocked steps instead of pulling on."""
    box = Box(center_xy=np.array([0.4, 0.1]), size=np.array([0.04, 0.04, 0.12]))
    robot = KinematicRobot(tcp_pos=np.array([0.4, 0.1, 0.35]), boxes=[box])
    cfg = GraspConfig()
    grasp = Grasp(_locator(robot), cfg)
    state, ceiling, lift_actions = robot.state, None, []
    while (a := grasp.step(state)) is not None:
        if grasp.phase is GraspPhase.LIFT:
            ceiling = state.tcp_pos[2] + 0.003 if ceiling is None else ceiling
            lift_actions.append(a)
        state = robot.step(a)
        if ceiling is not None:
            robot.tcp_pos[2] = min(robot.tcp_pos[2], ceiling)
            state = robot.state
    assert grasp.lift_blocked and not grasp.failed
    assert len(lift_actions) <= cfg.lift_blocked_steps + 1
    assert all(np.abs(a[:3]).max() <= cfg.lift_probe_speed + 1e-9 for a in lift_actions)


@pytest.mark.parametrize("offset_xy", [(0.0, 0.0), (0.06, -0.04)])
def test_grasp_localizes_hovers_descends_closes_and_lifts(offset_xy) -> None:
    box = Box(center_xy=np.array([0.4, 0.1]), size=np.array([0.04, 0.04, 0.12]))
    start = np.array([0.4 + offset_xy[0], 0.1 + offset_xy[1], 0.35])
    robot = KinematicRobot(tcp_pos=start.copy(), boxes=[box])
    cfg = GraspConfig()
    grasp = Grasp(_locator(robot), cfg)
    heights = []
    state = robot.state
    while (a := grasp.step(state)) is not None:
        state = robot.step(a)
        heights.append((grasp.phase, state.tcp_pos[2]))
    assert grasp.phase is GraspPhase.DONE and not grasp.failed and grasp.hover_reached
    assert robot.held is box
    assert box.bottom_z >= cfg.lift_m - cfg.lift_tol_m  # lifted ~15 cm off the floor
    # hover point: 15 cm above the box top; the descent: 3 cm below its top
    hover_z = [z for p, z in heights if p is GraspPhase.HOVER][-1]
    assert hover_z == pytest.approx(0.12 + cfg.hover_height_m, abs=0.015)
    close_z = [z for p, z in heights if p is GraspPhase.CLOSE]
    assert close_z[0] == pytest.approx(0.12 - cfg.descent_offset_m, abs=cfg.descend_tol_m)
    assert grasp.phase_steps[GraspPhase.CLOSE] == cfg.close_steps
    # wrist frames are taken only while hovering, one per hover step (+1 for the final check)
    assert robot.frames == grasp.localizations == grasp.phase_steps[GraspPhase.HOVER] + 1


def test_a_blocked_descent_closes_at_once_instead_of_pushing_out_its_budget() -> None:
    # the target lies 5 cm under the support the fingertips stop on (the fake's floor, z = 0)
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.1]))
    cfg = GraspConfig()
    grasp = Grasp(lambda: None, cfg, fallback_tcp_target=np.array([0.0, 0.0, -0.05]))
    trace = []
    state = robot.state
    while (a := grasp.step(state)) is not None:
        state = robot.step(a)
        trace.append((grasp.phase, float(state.tcp_pos[2])))
    descent = grasp.phase_steps[GraspPhase.DESCEND]
    on_floor = sum(1 for p, z in trace if p is GraspPhase.DESCEND and z == 0.0)
    assert descent < cfg.descend_step_budget
    assert on_floor == cfg.lift_blocked_steps  # closes after the blocked steps, not the budget
    assert grasp.phase_steps[GraspPhase.CLOSE] == cfg.close_steps


def test_grasp_of_a_flat_object_keeps_clear_of_the_floor() -> None:
    box = Box(center_xy=np.array([0.0, 0.0]), size=np.array([0.05, 0.05, 0.02]))
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.3]), boxes=[box])
    grasp = Grasp(_locator(robot), GraspConfig())
    _run(grasp, robot)
    target = grasp.descent_target()
    assert target is not None
    assert target[2] == pytest.approx(GraspConfig().min_floor_clearance_m, abs=1e-3)


def test_grasp_without_any_localization_or_fallback_fails_at_once() -> None:
    grasp = Grasp(lambda: None, GraspConfig())
    assert grasp.step(RobotState(np.zeros(3), 0.08)) is None
    assert grasp.failed and grasp.localization_misses == 1


def test_grasp_falls_back_on_the_given_target_when_blind() -> None:
    box = Box(center_xy=np.array([0.1, 0.0]), size=np.array([0.04, 0.04, 0.1]))
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.3]), boxes=[box])
    grasp = Grasp(lambda: None, GraspConfig(), fallback_tcp_target=np.array([0.1, 0.0, 0.07]))
    _run(grasp, robot)
    assert not grasp.failed and robot.held is box


def test_configs_reject_bad_values_naming_the_field() -> None:
    with pytest.raises(UsageError, match="hover_height_m"):
        GraspConfig(hover_height_m=0.0)
    with pytest.raises(UsageError, match="step_budget"):
        FreeSpaceConfig(step_budget=0)

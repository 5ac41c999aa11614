"""The waypoint executor's state machine, driven by the kinematic fake robot (no simulator)."""

from __future__ import annotations

import numpy as np
import pytest

from awda_bench.errors import UsageError
from awda_bench.primitives import ExecutorConfig, WaypointExecutor, localize_object
from awda_bench.primitives.executor import prepare_waypoints
from awda_bench.primitives.grasp import GraspPhase
from awda_bench.primitives.kinematic_fake import Box, KinematicRobot


def _scene() -> tuple[KinematicRobot, Box, Box]:
    target = Box(center_xy=np.array([0.45, 0.10]), size=np.array([0.04, 0.04, 0.10]))
    other = Box(center_xy=np.array([0.45, -0.15]), size=np.array([0.04, 0.04, 0.10]))
    robot = KinematicRobot(tcp_pos=np.array([0.3, 0.0, 0.35]), boxes=[target, other])
    return robot, target, other


def _execute(executor: WaypointExecutor, robot: KinematicRobot, limit: int = 600) -> list[str]:
    phases = []
    state = robot.state
    for _ in range(limit):
        a = executor.step(state)
        assert a.shape == (4,) and np.all(np.abs(a) <= 1.0 + 1e-12)
        phases.append(executor.phase)
        if executor.done:
            break
        state = robot.step(a)
    assert executor.done, "executor did not finish within the limit"
    return phases


def _pick_place_waypoints() -> np.ndarray:
    return np.array(
        [
            [0.45, 0.10, 0.10, 0.0],  # above the target (raised 15 cm by the executor)
            [0.45, 0.10, 0.07, 1.0],  # the grasp
            [0.10, 0.30, 0.25, 1.0],  # carry over the goal
            [0.10, 0.30, 0.12, 1.0],  # lower into the goal
            [0.10, 0.30, 0.30, 0.0],  # release there and retreat
        ]
    )


def test_prepare_raises_only_the_waypoint_before_the_first_grasp() -> None:
    W = _pick_place_waypoints()
    P = prepare_waypoints(W, 0.15)
    assert P[0, 2] == pytest.approx(0.25)
    assert np.array_equal(P[1:], W[1:])
    assert W[0, 2] == pytest.approx(0.10)  # input untouched
    first_grasp = W.copy()
    first_grasp[0, 3] = 1.0
    assert np.array_equal(prepare_waypoints(first_grasp, 0.15), first_grasp)


def test_pick_and_place_runs_grasp_carry_drop_in_order() -> None:
    robot, target, other = _scene()
    ex = WaypointExecutor(_pick_place_waypoints(), lambda: localize_object(*robot.depth_frame()))
    phases = _execute(ex, robot)
    kinds = [e.kind for e in ex.log]
    assert kinds == ["move", "grasp", "carry", "carry", "drop+move"]
    # order of primitives over time
    names = [p.split(":")[0] for p in phases]
    compact = [n for i, n in enumerate(names) if i == 0 or n != names[i - 1]]
    assert compact == ["move", "grasp", "carry", "drop", "move", "done"]
    # the approach ends exactly on the raised waypoint, the hover point (finish_exactly): the
    # grasp finds itself hovering and goes straight to its descent
    assert [p for p in phases if p.startswith("grasp")][0] in ("grasp:hover", "grasp:descend")
    assert ex.grasp_primitives[0].hover_reached
    # the target (not the distractor) ends on the floor at the goal; the gripper is open
    assert robot.held is None and target.bottom_z == 0.0
    assert np.linalg.norm(target.center_xy - [0.10, 0.30]) < 0.02
    assert np.allclose(other.center_xy, [0.45, -0.15])
    assert robot.gripper_opening_m == pytest.approx(robot.max_opening_m)
    assert all(e.reached for e in ex.log if e.kind != "grasp")
    # wrist frames only during the grasp's hover phase
    assert robot.frames == sum(p == "grasp:hover" for p in phases) + 1
    assert not ex.holding and ex.grasps == 1
    # the carry rises 18 cm above the grasp: a pick, so the grasp lifts
    assert ex.grasp_primitives[0].lift and "grasp:lift" in phases


def _pull_waypoints() -> np.ndarray:
    """Grasp a thing and lead it sideways at the grasp height (a drawer handle pulled out)."""
    return np.array(
        [
            [0.45, 0.10, 0.10, 0.0],
            [0.45, 0.10, 0.07, 1.0],  # the grasp
            [0.35, 0.10, 0.07, 1.0],  # pulled 10 cm toward the robot, no rise
            [0.25, 0.10, 0.065, 1.0],
            [0.25, 0.10, 0.20, 0.0],  # release and retreat
        ]
    )


def test_a_sideways_carry_after_a_grasp_is_a_slow_pull_without_lift() -> None:
    robot, target, _ = _scene()
    ex = WaypointExecutor(_pull_waypoints(), lambda: localize_object(*robot.depth_frame()))
    phases = _execute(ex, robot)
    assert [e.kind for e in ex.log] == ["move", "grasp", "pull", "pull", "drop+move"]
    grasp = ex.grasp_primitives[0]
    assert not grasp.lift and grasp.phase_steps[GraspPhase.LIFT] == 0
    assert "grasp:lift" not in phases
    # the pull commands at most pull_speed of a step per axis, and still ends on its waypoints
    speed = ExecutorConfig().pull_speed
    assert 0 < speed < 1
    pull_steps = ex.log[2].steps + ex.log[3].steps
    assert pull_steps >= int(0.20 / (speed * ExecutorConfig().motion.max_step_m))
    assert np.linalg.norm(target.center_xy - [0.25, 0.10]) < 0.02
    # a carry that rises at least lift_min_rise_m is a pick again
    rising = _pull_waypoints()
    rising[2, 2] += ExecutorConfig().lift_min_rise_m + 0.01
    assert not WaypointExecutor(rising, lambda: None)._is_pull(1)
    assert WaypointExecutor(_pull_waypoints(), lambda: None)._is_pull(1)


def test_pull_actions_are_capped_at_pull_speed() -> None:
    robot, *_ = _scene()
    ex = WaypointExecutor(_pull_waypoints(), lambda: localize_object(*robot.depth_frame()))
    state, caps = robot.state, []
    for _ in range(600):
        a = ex.step(state)
        if ex.phase == "carry":
            caps.append(float(np.max(np.abs(a[:3]))))
        if ex.done:
            break
        state = robot.step(a)
    assert caps and max(caps) == pytest.approx(ExecutorConfig().pull_speed)


def test_an_episode_without_grasps_pushes_with_the_gripper_closed() -> None:
    push = np.array([[0.45, 0.30, 0.20, 0.0], [0.45, 0.30, 0.08, 0.0], [0.30, 0.30, 0.08, 0.0]])
    for config, sign in ((ExecutorConfig(), 1.0), (ExecutorConfig(push_closed=False), -1.0)):
        robot, *_ = _scene()
        ex = WaypointExecutor(push, lambda: None, config)
        state, grips = robot.state, []
        for _ in range(300):
            a = ex.step(state)
            grips.append(a[3])
            if ex.done:
                break
            state = robot.step(a)
        assert ex.done and all(np.sign(g) == sign for g in grips)
    # with a grasp anywhere, free motions stay open (the approach must arrive open)
    assert WaypointExecutor(_pick_place_waypoints(), lambda: None).free_grip < 0


@pytest.mark.parametrize("bad", [0.0, -0.5, 1.5])
def test_pull_speed_outside_0_1_is_refused(bad) -> None:
    with pytest.raises(UsageError, match="pull_speed"):
        ExecutorConfig(pull_speed=bad)


def test_only_one_grasp_per_episode() -> None:
    robot, target, other = _scene()
    W = np.vstack(
        [
            _pick_place_waypoints(),
            [[0.45, -0.15, 0.10, 0.0], [0.45, -0.15, 0.07, 1.0], [0.2, -0.3, 0.2, 1.0]],
        ]
    )
    ex = WaypointExecutor(W, lambda: localize_object(*robot.depth_frame()))
    _execute(ex, robot)
    assert [e.kind for e in ex.log][5:] == ["move", "move", "move"]
    assert ex.grasps == 1
    assert np.allclose(other.center_xy, [0.45, -0.15]) and other.bottom_z == 0.0


def test_done_executor_holds_still() -> None:
    robot, *_ = _scene()
    ex = WaypointExecutor(np.array([[0.3, 0.0, 0.34, 0.0]]), lambda: None)
    # no grasp-attributed waypoint: a pushing episode, the gripper stays closed (push_closed)
    a = ex.step(robot.state)  # within 2 cm already: one step onto it exactly (finish_exactly)
    assert not ex.done and np.allclose(a, [0, 0, -0.5, 1])
    robot.step(a)
    a = ex.step(robot.state)  # there: finishes without moving
    assert ex.done and np.allclose(a, [0, 0, 0, 1])
    assert ex.log[0].steps == 1 and ex.log[0].reached


def test_a_motion_ends_on_its_destination_not_2_cm_short() -> None:
    robot, *_ = _scene()
    ex = WaypointExecutor(np.array([[0.3, 0.2, 0.35, 0.0]]), lambda: None)
    for _ in range(50):
        if ex.done:
            break
        robot.step(ex.step(robot.state))
    assert ex.done and robot.tcp_pos == pytest.approx([0.3, 0.2, 0.35], abs=1e-9)


def test_grasp_budget_zero_turns_grasp_waypoints_into_moves() -> None:
    robot, target, _ = _scene()
    ex = WaypointExecutor(
        _pick_place_waypoints(),
        lambda: localize_object(*robot.depth_frame()),
        ExecutorConfig(max_grasps=0),
    )
    _execute(ex, robot)
    assert [e.kind for e in ex.log] == ["move"] * 5
    assert robot.frames == 0 and robot.held is None


def test_extra_attributes_are_accepted_and_ignored() -> None:
    robot, target, _ = _scene()
    W = np.hstack([_pick_place_waypoints(), np.zeros((5, 1))])  # k = 2 (e.g. pressing)
    ex = WaypointExecutor(W, lambda: localize_object(*robot.depth_frame()))
    _execute(ex, robot)
    assert np.linalg.norm(target.center_xy - [0.10, 0.30]) < 0.02


@pytest.mark.parametrize("shape", [(5, 3), (0, 4), (4,)])
def test_bad_waypoint_shapes_raise(shape) -> None:
    with pytest.raises(UsageError, match="waypoints"):
        WaypointExecutor(np.zeros(shape), lambda: None)


def test_nan_waypoints_raise() -> None:
    W = _pick_place_waypoints()
    W[2, 0] = np.nan
    with pytest.raises(UsageError, match="NaN"):
        WaypointExecutor(W, lambda: None)

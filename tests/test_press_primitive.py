"""The press primitive's state machine and the executor's press-attributed waypoints, on the
kinematic robot (its TCP cannot go below the floor, z = 0: the floor is what gets pressed)."""

from __future__ import annotations

import numpy as np
import pytest

from awda_bench.errors import UsageError
from awda_bench.primitives.base import GRIP_CLOSE
from awda_bench.primitives.config import ExecutorConfig, PressConfig
from awda_bench.primitives.executor import WaypointExecutor
from awda_bench.primitives.kinematic_fake import KinematicRobot
from awda_bench.primitives.press import Press, PressPhase


def _run(press: Press, robot: KinematicRobot, limit: int = 300) -> list[PressPhase]:
    phases = []
    for _ in range(limit):
        action = press.step(robot.state)
        phases.append(press.phase)
        if action is None:
            return phases
        assert action[3] == GRIP_CLOSE  # a blunt pusher: fingers closed throughout
        assert np.all(np.abs(action[:3]) <= 1.0 + 1e-9)
        robot.step(action)
    raise AssertionError("the press primitive did not finish")


def test_press_approaches_contacts_holds_and_retracts() -> None:
    robot = KinematicRobot(tcp_pos=np.array([0.1, 0.0, 0.12]))
    config = PressConfig(hold_steps=7)
    press = Press(np.array([0.1, 0.0, 0.005]), config)  # the floor stops it 5 mm short
    phases = _run(press, robot)
    assert not press.failed
    assert press.contact_pos is not None and press.contact_pos[2] == pytest.approx(0.0, abs=1e-9)
    assert phases.count(PressPhase.HOLD) == config.hold_steps  # steps spent holding
    # retracted back along the approach (straight up) by retract_m
    assert robot.tcp_pos[2] == pytest.approx(config.retract_m, abs=config.retract_tol_m)
    assert robot.tcp_pos[:2] == pytest.approx([0.1, 0.0], abs=1e-6)
    order = [p for i, p in enumerate(phases) if i == 0 or phases[i - 1] != p]
    assert order == [PressPhase.APPROACH, PressPhase.HOLD, PressPhase.RETRACT, PressPhase.DONE]


def test_press_slows_down_near_the_waypoint() -> None:
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.2]))
    config = PressConfig()
    press = Press(np.array([0.0, 0.0, 0.0]), config)
    speeds = []
    while press.phase == PressPhase.APPROACH:
        action = press.step(robot.state)
        assert action is not None
        if press.phase == PressPhase.APPROACH:
            speeds.append((robot.tcp_pos[2], abs(action[2])))
        robot.step(action)
    far = [s for z, s in speeds if z > config.slow_distance_m + 0.021]
    near = [s for z, s in speeds if z < config.slow_distance_m - 1e-6]
    assert far and max(far) == pytest.approx(1.0)
    assert near and max(near) <= config.press_speed + 1e-9


def test_press_gives_up_without_contact() -> None:
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.3]))
    config = PressConfig()
    press = Press(np.array([0.0, 0.0, 0.15]), config)  # nothing there: mid-air
    phases = _run(press, robot)
    assert press.failed and press.contact_pos is None
    assert PressPhase.HOLD not in phases
    deepest = 0.15 - config.overshoot_m
    assert robot.tcp_pos[2] == pytest.approx(deepest + config.retract_m, abs=config.retract_tol_m)


def test_press_config_is_validated() -> None:
    with pytest.raises(UsageError, match="press_speed"):
        PressConfig(press_speed=0.0)
    with pytest.raises(UsageError, match="hold_steps"):
        PressConfig(hold_steps=0)


def test_executor_presses_at_press_waypoints_and_skips_the_held_one() -> None:
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.2]))
    # above the spot, press start, press end (same spot: the end of the hold), away; k = 2
    W = np.array(
        [
            [0.05, 0.0, 0.10, 0.0, 0.0],
            [0.05, 0.0, 0.00, 0.0, 1.0],
            [0.05, 0.0, 0.00, 0.0, 1.0],
            [0.10, 0.05, 0.15, 0.0, 0.0],
        ]
    )
    executor = WaypointExecutor(W, locate=lambda: None, config=ExecutorConfig())  # type: ignore[arg-type]
    lowest = np.inf
    for _ in range(400):
        if executor.done:
            break
        robot.step(executor.step(robot.state))
        lowest = min(lowest, robot.tcp_pos[2])
    assert executor.done
    assert [e.kind for e in executor.log] == ["move", "press", "press (held)", "move"]
    assert executor.log[1].reached is True
    assert len(executor.press_primitives) == 1 and not executor.press_primitives[0].failed
    assert lowest == pytest.approx(0.0, abs=1e-9)
    assert robot.tcp_pos == pytest.approx([0.10, 0.05, 0.15], abs=0.02)


def test_grasp_only_waypoints_never_press() -> None:
    robot = KinematicRobot(tcp_pos=np.array([0.0, 0.0, 0.2]))
    W = np.array([[0.05, 0.0, 0.10, 0.0], [0.10, 0.0, 0.12, 0.0]])  # k = 1, no grasp
    executor = WaypointExecutor(W, locate=lambda: None, config=ExecutorConfig())  # type: ignore[arg-type]
    for _ in range(200):
        if executor.done:
            break
        robot.step(executor.step(robot.state))
    assert [e.kind for e in executor.log] == ["move", "move"]
    assert not executor.press_primitives

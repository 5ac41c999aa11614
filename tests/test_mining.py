"""The mining formulas on hand-made sequences."""

from __future__ import annotations

import numpy as np
import pytest

from awda_bench.errors import UsageError
from awda_bench.mining import (
    GraspMiningConfig,
    PressMiningConfig,
    grasp_raw,
    mine_grasp,
    mine_press,
    precision_recall,
    press_raw,
    smooth_binary,
)
from awda_bench.trajectory import Trajectory


def _traj(opening, grip, tcp=None, dxyz=None) -> Trajectory:
    T = len(opening)
    actions = np.zeros((T, 4))
    actions[:, 3] = grip
    if dxyz is not None:
        actions[:, :3] = dxyz
    return Trajectory(
        tcp_pos=np.zeros((T, 3)) if tcp is None else np.asarray(tcp, float),
        gripper_opening_m=np.asarray(opening, float),
        actions=actions,
    )


# open, then close on a 4 cm object (one fast step, settling), hold, release
OPEN_CLOSE_HOLD = np.array([0.08, 0.08, 0.08, 0.042, 0.039, 0.039, 0.039, 0.039, 0.056, 0.07, 0.08])
GRIP_CLOSE_HOLD = np.array([-1, -1, 1, 1, 1, 1, 1, 1, -1, -1, -1])


def test_formula_literally_with_d_1() -> None:
    cfg = GraspMiningConfig(lookahead_steps=1, delta_m=-0.01, smooth_steps=1, min_opening_m=0.0)
    raw = grasp_raw(OPEN_CLOSE_HOLD, GRIP_CLOSE_HOLD > 0, cfg)
    # t=2: commanded, but the opening drops by 0.038 next step -> not yet a grasp
    # t=3..7: commanded and the opening stays within 1 cm -> grasp; t>=8: not commanded
    assert raw.tolist() == [False, False, False, True, True, True, True, True, False, False, False]


def test_lookahead_d_delays_the_onset_while_the_jaws_still_move() -> None:
    cfg = GraspMiningConfig(lookahead_steps=2, delta_m=-0.01, smooth_steps=1, min_opening_m=0.0)
    raw = grasp_raw(OPEN_CLOSE_HOLD, GRIP_CLOSE_HOLD > 0, cfg)
    assert raw[2] is np.False_ and raw[3:8].all()
    # t=7 looks at t=9, which is open again (+0.031 > delta): still a grasp by the formula
    slow = np.array([0.08, 0.06, 0.04, 0.035, 0.035])
    raw = grasp_raw(slow, np.ones(5, bool), cfg)
    assert raw.tolist() == [False, False, True, True, True]


def test_free_close_is_not_a_grasp_and_shut_jaws_need_the_guard() -> None:
    opening = np.array([0.08, 0.04, 0.0, 0.0, 0.0, 0.0])
    grip = np.ones(6)
    literal = GraspMiningConfig(smooth_steps=1, min_opening_m=0.0)
    # the reference formula: shut jaws do not shrink either, so they read as a grasp
    assert grasp_raw(opening, grip > 0, literal).tolist() == [False, False, True, True, True, True]
    guarded = GraspMiningConfig(smooth_steps=1, min_opening_m=0.005)
    assert not grasp_raw(opening, grip > 0, guarded).any()


def test_not_commanded_is_never_a_grasp() -> None:
    opening = np.full(6, 0.04)
    assert not mine_grasp(_traj(opening, -np.ones(6))).any()
    assert mine_grasp(_traj(opening, np.ones(6))).all()


def test_smoothing_removes_isolated_flips_and_fills_single_gaps() -> None:
    raw = np.array([0, 1, 0, 0, 1, 1, 0, 1, 1, 1, 0, 0], bool)
    assert smooth_binary(raw, 3).tolist() == [0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 0, 0]
    assert smooth_binary(raw, 1).tolist() == raw.tolist()
    assert smooth_binary(np.ones(4, bool), 5).all()  # edges padded, not zeroed


def test_press_when_commanded_motion_does_not_happen() -> None:
    T = 8
    tcp = np.zeros((T, 3))
    tcp[:4, 2] = [0.30, 0.28, 0.26, 0.24]  # moving down freely
    tcp[4:, 2] = 0.24  # blocked by a button
    d = np.tile([0.0, 0.0, -1.0], (T, 1))
    cfg = PressMiningConfig(smooth_steps=1)
    raw = press_raw(tcp, np.hstack([d, np.zeros((T, 1))]), cfg)
    assert raw.tolist() == [False, False, False, True, True, True, True, False]


def test_press_not_when_idle_or_moving_against_a_small_command() -> None:
    T = 5
    tcp = np.zeros((T, 3))
    traj = _traj(np.full(T, 0.08), -np.ones(T), tcp=tcp)  # zero command: never pressing
    assert not mine_press(traj).any()
    # TCP pushed back while commanded forward: pressing (accelerating against the command)
    tcp = np.array([[0, 0, 0.2], [0, 0, 0.201], [0, 0, 0.202], [0, 0, 0.203], [0, 0, 0.204]])
    traj = _traj(np.full(T, 0.08), -np.ones(T), tcp=tcp, dxyz=[0, 0, -1])
    assert press_raw(traj.tcp_pos, traj.actions, PressMiningConfig(smooth_steps=1))[:4].all()


def test_precision_recall_counts() -> None:
    pr = precision_recall(np.array([1, 1, 0, 0, 1], bool), np.array([1, 0, 1, 0, 1], bool))
    assert (pr.true_positive, pr.false_positive, pr.false_negative) == (2, 1, 1)
    assert pr.precision == pytest.approx(2 / 3) and pr.recall == pytest.approx(2 / 3)
    total = pr + precision_recall(np.ones(2, bool), np.ones(2, bool))
    assert total.precision == pytest.approx(4 / 5)
    with pytest.raises(UsageError):
        precision_recall(np.ones(3, bool), np.ones(4, bool))


def test_configs_validate() -> None:
    with pytest.raises(UsageError, match="smooth_steps"):
        GraspMiningConfig(smooth_steps=4)
    with pytest.raises(UsageError, match="lookahead_steps"):
        GraspMiningConfig(lookahead_steps=0)

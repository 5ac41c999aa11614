"""Ground-truth waypoint extraction on hand-made paths."""

from __future__ import annotations

import numpy as np
import pytest

from awda_bench.errors import UsageError
from awda_bench.primitives import WaypointExecutor, localize_object
from awda_bench.primitives.kinematic_fake import Box, KinematicRobot
from awda_bench.waypoints import (
    extract_waypoint_indices,
    extract_waypoints,
    point_segment_distance,
    polyline_deviation,
)


def _line(a, b, n) -> np.ndarray:
    return np.linspace(a, b, n, endpoint=False)


def _pick_place_path() -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    start, hover, grasp = [0.3, 0.0, 0.35], [0.45, 0.1, 0.2], [0.45, 0.1, 0.07]
    lift, over, release, up = [0.45, 0.1, 0.22], [0.1, 0.3, 0.22], [0.1, 0.3, 0.1], [0.1, 0.3, 0.2]
    parts = [
        _line(start, hover, 10),
        _line(hover, grasp, 8),
        np.tile(grasp, (6, 1)),  # closing
        _line(grasp, lift, 8),
        _line(lift, over, 15),
        _line(over, release, 6),
        np.tile(release, (5, 1)),  # opening
        _line(release, up, 6),
        [up],
    ]
    path = np.vstack(parts)
    T = len(path)
    g = np.zeros(T, bool)
    t_close = 10 + 8
    t_open = 10 + 8 + 6 + 8 + 15 + 6
    g[t_close + 1 : t_open] = True  # as mined: from the step after the jaws stop to the release
    return path, g, {"hover": 10, "grasp": t_close + 1, "release": t_open - 1, "end": T - 1}


def test_point_segment_distance() -> None:
    a, b = np.zeros(3), np.array([1.0, 0, 0])
    p = np.array([[0.5, 1.0, 0], [2.0, 0, 0], [-1.0, 0, 0]])
    assert np.allclose(point_segment_distance(p, a, b), [1.0, 1.0, 1.0])
    assert np.allclose(point_segment_distance(p, a, a), np.linalg.norm(p, axis=1))


def test_polyline_deviation_is_zero_on_anchors_and_straight_runs() -> None:
    path = np.vstack([_line([0, 0, 0], [1, 0, 0], 5), _line([1, 0, 0], [1, 1, 0], 5), [[1, 1, 0]]])
    assert np.allclose(polyline_deviation(path, [0, 5, 10]), 0.0)
    assert polyline_deviation(path, [0, 10])[5] == pytest.approx(np.sqrt(0.5))


def test_pick_place_keeps_the_mandatory_points_and_one_corner() -> None:
    path, g, t = _pick_place_path()
    idx = extract_waypoint_indices(path, g, K=5)
    assert len(idx) == 5
    for name in ("hover", "grasp", "release", "end"):
        assert t[name] in idx, name
    W = extract_waypoints(path, g, K=5)
    assert W.shape == (5, 4)
    assert W[:, 3].tolist() == [0, 1, 1, 1, 0]  # approach, grasp, corner (carried), release, end
    # the release waypoint sits where the gripper was commanded open (one step after the last
    # grasp-attributed step); the others on their own steps
    expected = path[idx].copy()
    expected[idx == t["release"]] = path[t["release"] + 1]
    assert np.allclose(W[:, :3], expected)


def test_more_waypoints_add_the_farthest_corners_first() -> None:
    path, g, _ = _pick_place_path()
    idx5 = set(extract_waypoint_indices(path, g, K=5, grasp_lift_m=0.0).tolist())
    idx7 = set(extract_waypoint_indices(path, g, K=7, grasp_lift_m=0.0).tolist())
    assert idx5 < idx7
    # with 7 points the polyline follows the path within 1 cm
    assert polyline_deviation(path, [0, *sorted(idx7)]).max() < 0.01


def test_the_grasp_primitives_lift_moves_the_free_corner_above_the_goal() -> None:
    path, g, t = _pick_place_path()
    lift_top, over_goal = 32, 47
    plain = extract_waypoint_indices(path, g, K=5, grasp_lift_m=0.0)
    assert lift_top in plain and over_goal not in plain
    driven = extract_waypoint_indices(path, g, K=5, grasp_lift_m=0.15)
    assert over_goal in driven and lift_top not in driven
    assert all(not (t["grasp"] < i < 24 + 8) for i in driven)  # nothing inside the lift column


def test_without_attributes_it_is_plain_rdp() -> None:
    path = np.vstack(
        [_line([0, 0, 0], [1, 0, 0], 10), _line([1, 0, 0], [1, 1, 0], 10), [[1, 1, 0]]]
    )
    W = extract_waypoints(path, np.zeros(len(path), bool), K=2)
    assert np.allclose(W[:, :3], [[1, 0, 0], [1, 1, 0]])
    assert not W[:, 3].any()


def test_too_few_waypoints_keep_the_final_step() -> None:
    path, g, t = _pick_place_path()
    idx = extract_waypoint_indices(path, g, K=2)
    assert len(idx) == 2 and idx[-1] == t["end"]


def test_bad_input_raises() -> None:
    with pytest.raises(UsageError):
        extract_waypoints(np.zeros((5, 2)), np.zeros(5, bool))
    with pytest.raises(UsageError):
        extract_waypoints(np.zeros((5, 3)), np.zeros(5, bool), K=0)


def test_extracted_waypoints_execute_a_pick_and_place_on_the_fake_robot() -> None:
    path, g, _ = _pick_place_path()
    W = extract_waypoints(path, g, K=5)
    box = Box(center_xy=np.array([0.45, 0.1]), size=np.array([0.04, 0.04, 0.1]))
    robot = KinematicRobot(tcp_pos=path[0].copy(), boxes=[box])
    ex = WaypointExecutor(W, lambda: localize_object(*robot.depth_frame()))
    state = robot.state
    for _ in range(400):
        a = ex.step(state)
        if ex.done:
            break
        state = robot.step(a)
    assert ex.done and robot.held is None
    assert np.linalg.norm(box.center_xy - [0.1, 0.3]) < 0.02 and box.bottom_z == 0.0

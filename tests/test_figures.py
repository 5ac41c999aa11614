from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from awda_bench.reporting.figures import (
    GRASP_RGB,
    PRESS_RGB,
    RED_BRIGHT_RGB,
    RED_DIM_RGB,
    draw_waypoints,
    fig_s5,
    plot_success_vs_snapshot,
    project_points,
    scene_figure,
    waypoint_colours,
    write_mp4,
)


def test_projection_matches_a_pinhole_camera() -> None:
    K = np.array([[100.0, 0, 64], [0, 100.0, 48], [0, 0, 1]])
    ext = np.hstack([np.eye(3), [[0.0], [0.0], [1.0]]])  # world origin 1 m in front of the camera
    uv = project_points(np.array([[0.0, 0, 0], [0.1, -0.2, 0], [0, 0, -2.0]]), K, ext)
    assert np.allclose(uv[0], [64, 48]) and np.allclose(uv[1], [74, 28])
    assert np.isnan(uv[2]).all()  # behind the camera


def test_colours_red_brighten_with_order_and_grasp_is_green() -> None:
    colours = waypoint_colours([False, False, True, False])
    assert colours[2] == GRASP_RGB
    reds = [colours[i][0] for i in (0, 1, 3)]
    assert (
        reds == sorted(reds)
        and reds[0] < reds[-1]
        and all(c[1] < 60 for c in (colours[0], colours[3]))
    )


def test_press_attributed_waypoints_have_their_own_colour() -> None:
    colours = waypoint_colours([False, False, False, True], press=[False, True, True, False])
    assert colours[1] == colours[2] == PRESS_RGB and colours[3] == GRASP_RGB
    assert colours[0] == waypoint_colours([False])[0]  # the one free waypoint: red as ever
    assert PRESS_RGB not in (GRASP_RGB, RED_DIM_RGB, RED_BRIGHT_RGB)
    frame = np.zeros((96, 128, 3), np.uint8)
    out = draw_waypoints(frame, np.array([[20.0, 20], [100, 70]]), [False, False], press=[0, 1])
    assert tuple(out[70, 100]) == PRESS_RGB
    with pytest.raises(ValueError, match="press flags"):
        waypoint_colours([False, True], press=[True])


def test_waypoints_are_drawn_where_projected_with_their_colours() -> None:
    frame = np.zeros((96, 128, 3), np.uint8)
    pixels = np.array([[20.0, 20], [100, 70], [np.nan, np.nan]])
    out = draw_waypoints(frame, pixels, [False, True, False])
    assert frame.sum() == 0  # input untouched
    assert out[20, 20, 0] > 100 and out[20, 20, 1] < 60  # red
    assert tuple(out[70, 100]) == GRASP_RGB  # green
    assert out[45, 60].any()  # the segment between them


def test_fig_s5_puts_demo_frames_beside_the_agent_frame() -> None:
    demo = [np.full((240, 320, 3), 40 * i, np.uint8) for i in range(1, 5)]
    agent = np.zeros((240, 320, 3), np.uint8)
    image = fig_s5(demo, agent, np.array([[160.0, 120]]), [True])
    assert image.shape[0] == 240 and image.shape[1] > 320 + 8
    assert tuple(image[120, image.shape[1] - 160]) == GRASP_RGB
    only_agent = fig_s5([], agent, np.array([[160.0, 120]]), [False])
    assert only_agent.shape == (240, 328, 3)


def test_mp4_round_trip(tmp_path: Path) -> None:
    frames = [np.full((48, 64, 3), i * 20, np.uint8) for i in range(10)]
    path = write_mp4(frames, tmp_path / "v" / "a.mp4", fps=10)
    cap = cv2.VideoCapture(str(path))
    assert (
        int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 10
        and int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)) == 64
    )


def test_success_plot_is_written(tmp_path: Path) -> None:
    table = pd.DataFrame(
        {"ord": [0, 1, 2], "name": ["a", "b", "c"], "rate": [0.1, 0.5, 0.7], "ok": [10, 10, 10]}
    )
    assert plot_success_vs_snapshot(table, "t", tmp_path / "p.png").stat().st_size > 1000


def test_scene_figure_puts_the_two_frames_side_by_side_with_labels() -> None:
    first = np.full((240, 320, 3), 40, np.uint8)
    during = np.full((240, 320, 3), 90, np.uint8)
    image = scene_figure(first, during)
    assert image.shape == (240, 640, 3)
    # the frames are where they belong below the label band; the labels are drawn in white
    assert np.all(image[100:, :320] == 40) and np.all(image[100:, 320:] == 90)
    assert (image[:30, :320] == 255).any() and (image[:30, 320:] == 255).any()

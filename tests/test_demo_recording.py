"""Demo recording: trajectory contents, video file, CLI wiring."""

from __future__ import annotations

from typing import cast

import numpy as np
import pytest

from awda_bench.cli import build_parser
from awda_bench.demo_recording import record_demo, save_video
from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.trajectory import Trajectory


def test_demo_command_is_registered() -> None:
    args = build_parser().parse_args(
        [
            "demo",
            "--suite",
            "pick_place",
            "--task",
            "7",
            "--seed",
            "3",
            "--embodiment",
            "demonstrator",
            "--out",
            "d.mp4",
        ]
    )
    assert (args.task, args.seed, args.embodiment, str(args.out)) == (7, 3, "demonstrator", "d.mp4")


def test_bad_arguments_are_usage_errors() -> None:
    with pytest.raises(UnknownChoiceError, match="task"):
        record_demo("pick_place", 99, 0, frames=False)
    with pytest.raises(UsageError, match="render_every"):
        record_demo("pick_place", 0, 0, render_every=0)
    with pytest.raises(UsageError, match="frames"):
        save_video(np.zeros((0, 4, 4, 3), dtype=np.uint8), "x.mp4", fps=10)


def test_save_video_writes_a_readable_mp4(tmp_path) -> None:
    import cv2

    frames = np.zeros((6, 48, 64, 3), dtype=np.uint8)
    frames[:, :, :32, 0] = 255
    path = save_video(frames, tmp_path / "v.mp4", fps=10)
    cap = cv2.VideoCapture(str(path))
    read = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        read.append(frame)
    assert len(read) == 6 and read[0].shape == (48, 64, 3)
    assert (
        read[0][:, :32, 2].mean() > 200 and read[0][:, 32:, 2].mean() < 50
    )  # red stays left (BGR)


@pytest.mark.slow
def test_state_only_recording_of_the_demonstrator(tmp_path) -> None:
    frames, traj = record_demo("pick_place", 7, 3, "demonstrator", frames=False)
    assert frames is None
    T = len(traj)
    assert traj.tcp_pos.shape == (T, 3) and traj.actions.shape == (T, 4)
    assert traj.meta["success"] and traj.meta["embodiment"] == "demonstrator"
    grasp = traj.truth["grasp"]
    closed = traj.actions[:, 3] > 0
    assert (
        grasp.any() and (grasp <= closed | np.roll(closed, 1)).all()
    )  # contact only while closing/closed
    lifted = traj.tcp_pos[grasp, 2].max() - traj.tcp_pos[grasp, 2].min()
    assert lifted > 0.05  # the object moves with the gripper while grasped
    assert (
        traj.gripper_opening_m[grasp].max() < 0.07
    )  # something between the fingers, not fully open
    traj.save(tmp_path / "t.npz")
    again = Trajectory.load(tmp_path / "t.npz")
    np.testing.assert_array_equal(again.actions, traj.actions)
    assert again.meta["task"] == 7


@pytest.mark.slow
def test_rendered_recording_has_frames_at_the_listed_steps() -> None:
    frames, traj = record_demo("pick_place", 1, 0, "demonstrator", render_every=40, frames=True)
    steps = cast(list[int], traj.meta["frame_steps"])
    assert (
        frames is not None
        and frames.shape == (len(steps), 240, 320, 3)
        and frames.dtype == np.uint8
    )
    assert steps[0] == 0 and steps[-1] == len(traj) and steps[1] == 40
    assert frames.std() > 10  # a real image, not a blank
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 1  # the scene changed

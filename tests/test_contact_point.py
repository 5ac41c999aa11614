"""The identification label of episodes without a grasp: where the hand first moves the object
(:mod:`awda_bench.data.contact_point`)."""

from __future__ import annotations

import numpy as np

from awda_bench.data.contact_point import MOTION_THRESHOLD, SETTLE_STEPS, first_object_motion


def _still(steps: int = 40, joints: int = 2) -> np.ndarray:
    return np.tile(np.array([0.3, -0.2, 0.0, 0.0, 0.0, 0.0, 1.0][:joints]), (steps, 1))


def test_the_first_state_past_the_threshold_after_settling() -> None:
    q = _still()
    q[:SETTLE_STEPS, 0] -= 0.03  # dropped into the scene: settles by state 8, not motion
    q[25:, 1] += np.linspace(0.002, 0.2, 15)  # pushed from state 25 on
    crossing = 25 + int(np.argmax(np.abs(q[25:, 1] - q[SETTLE_STEPS, 1]) > MOTION_THRESHOLD))
    assert first_object_motion(q) == crossing
    assert crossing > 25  # the first 2 mm do not count


def test_no_label_without_motion_objects_or_length() -> None:
    assert first_object_motion(_still()) is None  # the hand never touches it
    assert first_object_motion(np.zeros((40, 0))) is None  # reach: no object joints
    assert first_object_motion(_still(SETTLE_STEPS + 1)) is None  # too short to tell


def test_an_object_still_moving_when_settling_ends_is_no_label() -> None:
    """door-close's door swings on by itself: its first motion would be where nothing touched it."""
    q = _still()
    q[:, 0] += np.linspace(0.0, 0.5, len(q))  # drifts from the start
    assert first_object_motion(q) is None

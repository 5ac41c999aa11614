"""On-demand cameras of panda_awda: wrist depth geometry and the third-person RGB frame."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import awda_bench.envs  # noqa: F401  (registers panda_awda, AWDA-EmptyTable-v1)
from awda_bench.errors import UnknownChoiceError
from awda_bench.robot.cameras import capture_rgb, capture_wrist_depth

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def env():
    env = gym.make(
        "AWDA-EmptyTable-v1",
        obs_mode="state",
        reward_mode="none",
        sensor_configs={"wrist_depth": {"width": 96, "height": 72}},
    )
    env.reset(seed=0)
    yield env
    env.close()


def test_wrist_depth_back_projects_onto_the_table_below_the_tcp(env) -> None:
    frame = capture_wrist_depth(env)
    assert frame.depth_m.shape == (1, 72, 96)  # size set through sensor_configs
    assert frame.intrinsic_cv.shape == (1, 3, 3) and frame.cam2world_cv.shape == (1, 4, 4)
    depth, K, cam2world = frame.depth_m[0], frame.intrinsic_cv[0], frame.cam2world_cv[0]
    # 90 degree (vertical) field of view: fy = H / 2
    assert K[1, 1] == pytest.approx(72 / 2, rel=1e-3)
    v, u = 36, 48
    z = depth[v, u]
    point = cam2world @ np.array(
        [(u + 0.5 - K[0, 2]) * z / K[0, 0], (v + 0.5 - K[1, 2]) * z / K[1, 1], z, 1.0]
    )
    tcp = env.unwrapped.agent.tcp.pose.p[0].cpu().numpy()
    assert point[2] == pytest.approx(0.0, abs=0.01)  # the table top
    assert point[:2] == pytest.approx(tcp[:2], abs=0.02)  # straight below the TCP


def test_capture_counts_rendered_frames(env) -> None:
    counter_before = getattr(env.unwrapped, "capture_counter", None)
    before = counter_before.frames if counter_before else 0
    capture_wrist_depth(env)
    capture_wrist_depth(env)
    assert env.unwrapped.capture_counter.frames == before + 2


def test_third_person_frame_is_240x320_rgb_and_not_blank(env) -> None:
    rgb = capture_rgb(env)
    assert rgb.shape == (1, 240, 320, 3) and rgb.dtype == np.uint8
    assert rgb.std() > 10


def test_stepping_does_not_render(env) -> None:
    env.reset(seed=0)
    counter = getattr(env.unwrapped, "capture_counter", None)
    before = counter.frames if counter else 0
    for _ in range(5):
        env.step(np.zeros(4))
    after = (
        env.unwrapped.capture_counter.frames
        if getattr(env.unwrapped, "capture_counter", None)
        else 0
    )
    assert after == before


def test_unknown_camera_lists_the_valid_ones(env) -> None:
    with pytest.raises(UnknownChoiceError, match="wrist_depth"):
        capture_rgb(env, "nope")

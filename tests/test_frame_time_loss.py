"""The frame-time loss: a waypoint's choice of demo frame is taught the frame at the moment its
path reaches it (``awda_bench.models.frame_time_loss``)."""

from __future__ import annotations

import pytest
import torch
from test_demo_pointer import CAMERA, POINTER_TRUNK, _grasping_batch

from awda_bench.errors import UsageError
from awda_bench.models.awda_net import AwdaNet
from awda_bench.models.config import AwdaConfig
from awda_bench.models.demo_pointer import DemoPointer
from awda_bench.models.frame_time_loss import (
    frame_targets,
    frame_time_loss,
    rule_times,
    waypoint_times,
)
from awda_bench.models.waypoint_loss import PolylineArgs
from awda_bench.waypoints import extract_waypoint_indices

SETS: PolylineArgs = {"num_sets": 2, "points_per_segment": 4, "gamma": 1e-3, "attribute_scale": 0.2}


def _rise_and_carry() -> torch.Tensor:
    """One trajectory of 21 points, uniform in time: down to a grasp (points 0-5), up over a wall
    (to point 15), along the top (to 20); grasp flag from point 5 on."""
    t = torch.linspace(0.0, 1.0, 21)
    xyz = torch.stack((t * 0.3, torch.zeros(21), torch.zeros(21)), dim=-1)
    xyz[:6, 2] = torch.linspace(0.10, 0.02, 6)
    xyz[5:16, 2] = torch.linspace(0.02, 0.25, 11)
    xyz[15:, 2] = 0.25
    grasp = (torch.arange(21) >= 5).float()[:, None]
    return torch.cat((xyz, grasp), dim=-1)[None]


def test_each_waypoint_is_timed_where_its_path_meets_the_trajectory() -> None:
    """Waypoints placed on the trajectory's points 5 (the grasp), 15 (over the wall) and 20 (the
    end) are matched at 0.25, 0.75 and 1.0 of the episode; a waypoint's time follows where it is,
    not its index in the set."""
    trajectory = _rise_and_carry()
    grasp_logit = torch.tensor([[-8.0], [8.0], [8.0]])
    on_path = torch.cat((trajectory[0, [20, 5, 15], :3], grasp_logit), dim=-1)  # set 1, set 2
    times = waypoint_times(on_path[None], trajectory, SETS)
    torch.testing.assert_close(times, torch.tensor([[1.0, 0.25, 0.75]]), atol=0.03, rtol=0)


def test_the_rule_times_each_set_at_the_moments_the_gt_waypoints_rule_picks() -> None:
    """``demo_frame_time_source = "rule"``: a set of K waypoints is timed at the rule's K steps
    on the trajectory (set 1: the end; set 2: the approach corner and the end, the rule dropping
    the grasp before the end when its mandatory steps exceed K), whatever is predicted."""
    trajectory = _rise_and_carry()
    times = rule_times(trajectory, num_sets=2)
    torch.testing.assert_close(times, torch.tensor([[1.0, 0.05, 1.0]]))
    sets = rule_times(trajectory.repeat(2, 1, 1), num_sets=5)
    five = extract_waypoint_indices(trajectory[0, :, :3].numpy(), trajectory[0, :, 3:] > 0.5, K=5)
    assert sets.shape == (2, 15)
    torch.testing.assert_close(sets[:, 10:], torch.from_numpy(five / 20.0).float().expand(2, 5))
    assert float(sets[0, 10:].diff().min()) > 0  # five distinct moments, in order
    assert 0.25 in sets[0, 10:].tolist()  # the grasp is one of them
    # a trajectory of 3 points has 2 steps to pick: a set of 5 repeats the last
    short = rule_times(_rise_and_carry()[:, [0, 5, 20]], num_sets=5)[0, 10:]
    torch.testing.assert_close(short, torch.tensor([0.5, 1.0, 1.0, 1.0, 1.0]))


def test_frame_targets_weigh_the_two_frames_around_the_same_fraction_of_the_demo() -> None:
    targets = frame_targets(torch.tensor([[0.0, 0.5, 1.0, 1.3]]), frames=5)
    expected = torch.tensor(
        [[1, 0, 0, 0, 0], [0, 0, 1, 0, 0], [0, 0, 0, 0, 1], [0, 0, 0, 0, 1]], dtype=torch.float32
    )
    torch.testing.assert_close(targets[0], expected)
    between = frame_targets(torch.tensor([[0.35]]), frames=11)[0, 0]
    torch.testing.assert_close(between[3:5], torch.tensor([0.5, 0.5]))
    assert float(between.sum()) == pytest.approx(1.0)


def test_the_loss_is_least_at_the_matched_frame_and_pulls_the_choice_there() -> None:
    trajectory = _rise_and_carry()
    waypoints = torch.cat((trajectory[0, [20, 5, 15], :3], torch.full((3, 1), 8.0)), dim=-1)[None]
    frames = 5  # demo frames at 0, 1/4, 1/2, 3/4, 1 of the demo
    matched = torch.tensor([4, 1, 3])
    right = torch.full((1, 3, frames), -5.0)
    right[0, torch.arange(3), matched] = 5.0
    wrong = right.roll(1, dims=-1)
    times = waypoint_times(waypoints, trajectory, SETS)
    low, info = frame_time_loss(right, times)
    high, _ = frame_time_loss(wrong, times)
    assert float(low) < 0.01 < 5.0 < float(high)
    assert info["frame_time_gap"] < 0.03
    logits = torch.zeros(1, 3, frames, requires_grad=True)
    frame_time_loss(logits, times)[0].backward()
    assert logits.grad is not None
    assert torch.equal(logits.grad[0].argmin(-1), matched)  # descent raises the matched frame
    with pytest.raises(UsageError, match="frame logits"):
        frame_time_loss(torch.zeros(1, 2, frames), times)


def test_the_frame_time_loss_trains_the_choice_of_frame_and_needs_demo_heights() -> None:
    with pytest.raises(UsageError, match="demo_frame_time_weight"):
        AwdaConfig(
            trunk=POINTER_TRUNK, identification_weight=1.0, demo_frame_time_weight=1.0, **CAMERA
        )
    with pytest.raises(UsageError, match="demo_frame_time_weight"):
        AwdaConfig(
            trunk=POINTER_TRUNK, identification_weight=1.0, demo_heights=True,
            demo_frame_time_weight=-1.0, **CAMERA,
        )  # fmt: skip
    batch = _grasping_batch()
    common = {"trunk": POINTER_TRUNK, "identification_weight": 1.0, "demo_heights": True}
    model = AwdaNet(AwdaConfig(**common, demo_frame_time_weight=1.0, **CAMERA), False)
    loss, info = model.compute_loss(batch)
    assert info["frame_time"] > 0 and 0 <= info["frame_time_gap"] <= 1
    loss.backward()
    head = model.scene_head
    assert isinstance(head, DemoPointer)
    assert head.readout.height_phase.grad is not None
    assert float(head.readout.height_phase.grad.abs().sum()) > 0
    with torch.autocast("cpu", dtype=torch.bfloat16):  # [train] precision = "bf16"
        assert model.compute_loss(batch)[1]["frame_time"] > 0
    ruled = AwdaNet(
        AwdaConfig(**common, demo_frame_time_weight=1.0, demo_frame_time_source="rule", **CAMERA),
        False,
    )
    assert ruled.compute_loss(batch)[1]["frame_time"] > 0
    with pytest.raises(UsageError, match="demo_frame_time_source"):
        AwdaConfig(**common, demo_frame_time_source="demo", **CAMERA)
    torch.manual_seed(0)
    without = AwdaNet(AwdaConfig(**common, **CAMERA), load_backbone_weights=False)
    assert "frame_time" not in without.compute_loss(batch)[1]

"""AWDA-PickPlace-v1: geometry helpers (fast), pick-place-specific env checks (slow). The contract
every env keeps (reset and step shapes, the default embodiment, the info keys) is in
``test_env_contract.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from task_env_helpers import DEMONSTRATOR, assert_spread_out, make_task_env, task_env_fixture

from awda_bench.envs.bins import BinSpec
from awda_bench.envs.embodiments import EMBODIMENTS, embodiment
from awda_bench.envs.objects import PICK_PLACE_OBJECTS, ObjectSpec, distance_to_objects
from awda_bench.envs.pick_place import PickPlaceLayout
from awda_bench.errors import UnknownChoiceError
from awda_bench.suites import load_suite

# ---------------------------------------------------------------------------- fast


def test_suite_file_defines_16_tasks_with_held_out_can_tasks() -> None:
    suite = load_suite("pick_place")
    assert suite.env_id == "AWDA-PickPlace-v1"
    assert [t.index for t in suite.tasks] == list(range(16))
    assert suite.held_out == (14, 15)
    assert {t.family for t in suite.tasks} == {"pick_place"}
    assert all(t.name.startswith("can") for t in suite.eval_tasks)
    assert (suite.camera.height, suite.camera.width) == (240, 320)
    # about twice the longest scripted expert episode (86 steps, demonstrator; tasks/pick_place.toml)
    assert suite.control_freq_hz == 20 and 150 <= suite.horizon_steps <= 250


def test_objects_match_spec_sizes() -> None:
    sizes = {o.name: o.size_m for o in PICK_PLACE_OBJECTS}
    assert sizes == {
        "milk": (0.04, 0.04, 0.14),
        "bread": (0.035, 0.035, 0.05),
        "cereal": (0.035, 0.025, 0.054),
        "can": (0.05, 0.05, 0.08),
    }
    assert len({o.color for o in PICK_PLACE_OBJECTS}) == 4


def test_compartments_tile_the_target_bin_without_overlap() -> None:
    spec = PickPlaceLayout().target_bin
    boxes = [spec.compartment_box(i) for i in range(4)]
    cx, cy = spec.center_xy_m
    hx, hy = spec.inner_half_size_m
    for (x_lo, x_hi), (y_lo, y_hi) in boxes:
        assert cx - hx <= x_lo < x_hi <= cx + hx and cy - hy <= y_lo < y_hi <= cy + hy
    for i in range(4):
        for j in range(i + 1, 4):
            (ax, ay), (bx, by) = boxes[i], boxes[j]
            overlap_x = min(ax[1], bx[1]) > max(ax[0], bx[0])
            overlap_y = min(ay[1], by[1]) > max(ay[0], by[0])
            assert not (overlap_x and overlap_y)
    with pytest.raises(ValueError, match="compartment index"):
        spec.compartment_box(4)
    with pytest.raises(ValueError, match="compartment index"):
        BinSpec(center_xy_m=(0, 0), inner_half_size_m=(0.1, 0.1)).compartment_box(0)


def test_spawn_area_keeps_open_fingers_off_the_source_walls() -> None:
    lay = PickPlaceLayout()
    max_radius = max(o.footprint_radius_m for o in PICK_PLACE_OBJECTS)
    for axis in (0, 1):
        assert lay.spawn_half_size_m[axis] + max_radius < lay.source_bin.inner_half_size_m[axis]


def test_distance_to_box_and_cylinder_surfaces() -> None:
    box = ObjectSpec(name="b", shape="box", size_m=(0.04, 0.02, 0.10), color=(1, 1, 1, 1))
    can = ObjectSpec(name="c", shape="cylinder", size_m=(0.05, 0.05, 0.08), color=(1, 1, 1, 1))
    positions = torch.zeros((3, 2, 3))
    yaw90 = torch.tensor([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)], dtype=torch.float32)
    quats = torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(3, 2, 1)
    quats[2, 0] = yaw90
    points = torch.tensor([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.05, 0.0, 0.0]])
    d = distance_to_objects(points, positions, quats, (box, can))
    assert d[0].tolist() == [0.0, 0.0]  # inside both
    assert d[1, 0] == pytest.approx(0.03, abs=1e-6)  # 5 cm from centre, half x = 2 cm
    assert d[1, 1] == pytest.approx(0.025, abs=1e-6)  # radius 2.5 cm
    assert d[2, 0] == pytest.approx(0.04, abs=1e-6)  # yawed 90 deg: half extent along x is 1 cm
    with pytest.raises(ValueError, match="cylinder"):
        ObjectSpec(name="x", shape="cylinder", size_m=(0.04, 0.05, 0.1), color=(1, 1, 1, 1))


def test_embodiment_grip_sign_conversion() -> None:
    action = np.array([[0.1, 0.2, 0.3, 1.0]], dtype=np.float32)
    assert embodiment("panda_awda").to_env_action(action) is action
    flipped = embodiment("panda").to_env_action(action)
    assert flipped[0, 3] == -1.0 and action[0, 3] == 1.0
    assert bool(embodiment("panda").grip_closed(torch.as_tensor(flipped))[0])
    assert bool(embodiment("awda_demonstrator").grip_closed(torch.as_tensor(action))[0])
    with pytest.raises(UnknownChoiceError, match="panda_awda"):
        embodiment("sawyer")
    assert set(EMBODIMENTS) >= {"panda_awda", "awda_demonstrator"}


# ---------------------------------------------------------------------------- slow (simulation)


env = task_env_fixture("AWDA-PickPlace-v1")


@pytest.mark.slow
def test_layouts_respect_separation_and_spawn_area(env) -> None:
    lay = env.unwrapped.layout
    center = np.array(lay.source_bin.center_xy_m)
    for seed in range(8):
        env.reset(seed=seed)
        xy = env.unwrapped.object_poses()[0][0, :, :2].cpu().numpy()
        assert_spread_out(xy, center, lay.spawn_half_size_m, lay.min_separation_m)


@pytest.mark.slow
def test_demonstrator_env_rejects_nan_and_keeps_its_rest_pose() -> None:
    demo = make_task_env("AWDA-PickPlace-v1", DEMONSTRATOR)
    try:
        demo.reset(seed=0)
        tcp = demo.unwrapped.agent.tcp_pose.p.clone()
        for _ in range(10):  # zero action: the hand holds still (gravity off, stiff drives)
            demo.step(np.zeros(4, dtype=np.float32))
        assert float(torch.linalg.norm(demo.unwrapped.agent.tcp_pose.p - tcp)) < 1e-3
        with pytest.raises(ValueError, match="NaN"):
            demo.step(np.array([0.0, np.nan, 0.0, 0.0], dtype=np.float32))
    finally:
        demo.close()


@pytest.mark.slow
def test_success_when_target_is_placed_in_its_compartment_only(env) -> None:
    from mani_skill.utils.structs.pose import Pose

    base = env.unwrapped
    for task in (2, 13):
        env.reset(seed=1, options={"task": task})
        target = base.objects[task // 4]
        spec = base.objects_spec[task // 4]
        floor = base.layout.target_bin.floor_z_m
        for compartment in range(4):
            x, y = base.layout.target_bin.compartment_center(compartment)
            target.set_pose(Pose.create_from_pq(torch.tensor([[x, y, floor + spec.half_height_m]])))
            info = base.evaluate()
            assert bool(info["success"][0]) == (compartment == task % 4)
        # right compartment but held 15 cm above the floor: not a success
        x, y = base.layout.target_bin.compartment_center(task % 4)
        target.set_pose(Pose.create_from_pq(torch.tensor([[x, y, floor + 0.15]])))
        assert not bool(base.evaluate()["success"][0])


@pytest.mark.slow
def test_reached_requires_proximity_before_the_first_grasp_attempt(env) -> None:
    from mani_skill.utils.structs.pose import Pose

    base = env.unwrapped
    # closing the gripper far from the object first: reaching afterwards does not count
    env.reset(seed=2, options={"task": 0})
    env.step(np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32))
    tcp = base.agent.tcp_pose.p
    base.objects[0].set_pose(Pose.create_from_pq(tcp + torch.tensor([[0.0, 0.0, -0.02]])))
    env.step(np.zeros(4, dtype=np.float32))
    info = base.evaluate()
    assert bool(info["grip_attempted"][0]) and not bool(info["reached"][0])

    # near the object with the gripper open: reached; raised >= 5 cm afterwards: grasped
    env.reset(seed=2, options={"task": 0})
    start = base.objects[0].pose.p.clone()
    assert not bool(base.evaluate()["reached"][0])
    tcp = base.agent.tcp_pose.p
    base.objects[0].set_pose(Pose.create_from_pq(tcp + torch.tensor([[0.0, 0.0, -0.09]])))
    info = base.evaluate()
    assert bool(info["reached"][0]) and not bool(info["grasped"][0])
    base.objects[0].set_pose(Pose.create_from_pq(start + torch.tensor([[0.0, 0.0, 0.06]])))
    assert bool(base.evaluate()["grasped"][0])


@pytest.mark.slow
def test_a_grip_command_says_which_object_it_closes_on(env) -> None:
    """``grip_outcome``: the nearest object within 4 cm of the TCP is the target (0) or another
    one (1), or none is that near (2); an open-gripper action closes on nothing (-1)."""
    from mani_skill.utils.structs.pose import Pose

    base = env.unwrapped
    env.reset(seed=2, options={"task": 0})  # task 0: object 0 into compartment 0
    close = np.array([[0.0, 0.0, 0.0, 1.0]], dtype=np.float32)
    assert int(base.grip_outcome(close)[0]) == 2  # at rest the TCP is far above the bin
    assert int(base.grip_outcome(np.zeros((1, 4), np.float32))[0]) == -1
    tcp = base.agent.tcp_pose.p

    def under_fingers(j: int, gap_m: float) -> Pose:  # object j's top gap_m below the TCP
        half_height = base.objects_spec[j].size_m[2] / 2
        return Pose.create_from_pq(tcp - torch.tensor([[0.0, 0.0, half_height + gap_m]]))

    base.objects[1].set_pose(under_fingers(1, 0.02))
    distances, target = base.object_distances()
    assert int(target[0]) == 0 and float(distances[0, 1]) == pytest.approx(0.02, abs=1e-4)
    assert int(base.grip_outcome(close)[0]) == 1  # a distractor under the fingers
    base.objects[0].set_pose(under_fingers(0, 0.01))
    base.objects[1].set_pose(Pose.create_from_pq(tcp + torch.tensor([[0.3, 0.0, 0.0]])))
    assert int(base.grip_outcome(close)[0]) == 0  # now the target
    # asking changes nothing: the grasp attempt is latched by step() alone
    assert not bool(base.evaluate()["grip_attempted"][0])

"""Localization on synthetic depth images with known answers (SPEC §4, six steps)."""

from __future__ import annotations

import numpy as np
import pytest

from awda_bench.errors import UsageError
from awda_bench.primitives.config import LocalizationConfig
from awda_bench.primitives.kinematic_fake import Box, TopDownDepthCamera
from awda_bench.primitives.localization import back_project, localize_object

CAM = TopDownDepthCamera(width=160, height=120)


def _box(x: float, y: float, sx: float = 0.04, sy: float = 0.04, h: float = 0.08) -> Box:
    return Box(center_xy=np.array([x, y]), size=np.array([sx, sy, h]))


def _localize(cam_pos, boxes, config=LocalizationConfig()):
    cam_pos = np.asarray(cam_pos, dtype=float)
    depth = CAM.render(cam_pos, boxes)
    return localize_object(depth, CAM.K, CAM.cam2world(cam_pos), config)


def test_single_object_below_camera_is_found_at_its_top() -> None:
    loc = _localize([0.3, -0.1, 0.35], [_box(0.31, -0.11, h=0.1)])
    assert loc is not None
    assert np.linalg.norm(loc.position_world[:2] - [0.31, -0.11]) < 0.005
    assert loc.position_world[2] == pytest.approx(0.1, abs=1e-4)
    assert loc.floor_world[2] == pytest.approx(0.0, abs=1e-4)
    assert loc.n_proposals == 1


def test_empty_floor_gives_none() -> None:
    assert _localize([0.0, 0.0, 0.3], []) is None


def test_everything_beyond_background_gives_none() -> None:
    # camera 1.5 m above the floor: all depths are background (> 1 m)
    assert _localize([0.0, 0.0, 1.5], [_box(0.0, 0.0, h=0.3)]) is None


def test_object_shorter_than_threshold_is_floor() -> None:
    assert _localize([0.0, 0.0, 0.3], [_box(0.0, 0.0, h=0.005)]) is None


def test_two_objects_the_one_nearest_the_image_centre_wins() -> None:
    boxes = [_box(0.05, 0.02, h=0.12), _box(-0.08, -0.06, h=0.05)]
    loc = _localize([0.04, 0.03, 0.4], boxes)
    assert loc is not None and loc.n_proposals == 2
    assert np.linalg.norm(loc.position_world[:2] - [0.05, 0.02]) < 0.005
    loc = _localize([-0.07, -0.05, 0.4], boxes)
    assert loc is not None
    assert np.linalg.norm(loc.position_world[:2] - [-0.08, -0.06]) < 0.005
    assert loc.position_world[2] == pytest.approx(0.05, abs=1e-4)


def test_object_cut_by_the_image_border_is_localized_on_its_visible_part() -> None:
    # camera at height 0.3 sees |x| <= 0.3 - h on the box top plane; the box straddles x = 0.22
    h = 0.08
    edge = 0.3 - h
    loc = _localize([0.0, 0.0, 0.3], [_box(edge, 0.0, sx=0.06, sy=0.06, h=h)])
    assert loc is not None
    # the centroid of the visible half lies inside the image, left of the true centre
    assert edge - 0.03 < loc.position_world[0] < edge
    assert loc.position_world[1] == pytest.approx(0.0, abs=0.005)
    u, _ = loc.pixel
    assert u < CAM.width - 1


def test_area_bounds_reject_specks_and_giant_components() -> None:
    cfg = LocalizationConfig(min_area_px=50, max_area_px=5000)
    # a 1 cm speck at 0.4 m depth covers ~ (0.01 * 80 / 0.4)^2 = 4 px
    assert _localize([0.0, 0.0, 0.45], [_box(0.0, 0.0, sx=0.01, sy=0.01, h=0.05)], cfg) is None
    # a 0.3 m slab right under the camera covers far more than 5000 px ...
    slab = _box(0.0, 0.0, sx=0.3, sy=0.3, h=0.05)
    assert _localize([0.0, 0.0, 0.3], [slab], cfg) is None
    # ... unless the upper bound allows it
    assert _localize([0.0, 0.0, 0.3], [slab], LocalizationConfig(max_area_px=10**6)) is not None


def test_fingers_in_front_of_the_lens_are_masked() -> None:
    cam_pos = np.array([0.0, 0.0, 0.3])
    depth = CAM.render(cam_pos, [_box(0.1, 0.05)])
    depth[:, 60:100] = 0.02  # a finger band through the image centre, 2 cm from the lens
    unmasked = localize_object(
        depth, CAM.K, CAM.cam2world(cam_pos), LocalizationConfig(max_area_px=10**6)
    )
    assert unmasked is not None and unmasked.position_world[2] > 0.25  # the finger wins unmasked
    loc = localize_object(
        depth, CAM.K, CAM.cam2world(cam_pos), LocalizationConfig(min_depth_m=0.05)
    )
    assert loc is not None
    assert np.linalg.norm(loc.position_world[:2] - [0.1, 0.05]) < 0.005
    depth[:, :] = 0.02
    assert (
        localize_object(depth, CAM.K, CAM.cam2world(cam_pos), LocalizationConfig(min_depth_m=0.05))
        is None
    )


def test_ring_object_uses_component_median_depth() -> None:
    cam_pos = np.array([0.0, 0.0, 0.4])
    depth = CAM.render(cam_pos, [])
    yy, xx = np.mgrid[: CAM.height, : CAM.width]
    r = np.hypot(xx - 80, yy - 60)
    ring = (r > 10) & (r < 16)
    depth[ring] = 0.3  # 10 cm high ring; its centroid (the hole) sees the floor
    loc = localize_object(depth, CAM.K, CAM.cam2world(cam_pos))
    assert loc is not None
    assert loc.position_world[2] == pytest.approx(0.1, abs=1e-4)


def test_tilted_camera_back_projection_matches_geometry() -> None:
    # a camera rotated 30 degrees about x: back_project must invert the projection
    a = np.deg2rad(30)
    R = np.diag([1.0, -1.0, -1.0]) @ np.array(
        [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    )
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = [0.1, 0.2, 0.5]
    p_world = np.array([0.15, 0.1, 0.02])
    p_cam = R.T @ (p_world - T[:3, 3])
    uv = CAM.K @ (p_cam / p_cam[2])
    assert np.allclose(back_project(uv[0], uv[1], p_cam[2], CAM.K, T), p_world)


def test_bad_shapes_raise_usage_error() -> None:
    with pytest.raises(UsageError):
        localize_object(np.zeros((2, 3, 4)), CAM.K, np.eye(4))
    with pytest.raises(UsageError):
        localize_object(np.zeros((4, 4)), np.eye(4), np.eye(4))


def test_config_validates_itself() -> None:
    with pytest.raises(UsageError, match="max_area_px"):
        LocalizationConfig(min_area_px=100, max_area_px=10)
    with pytest.raises(UsageError, match="connectivity"):
        LocalizationConfig(connectivity=6)


def _tilted_pose(position, tilt_deg: float) -> np.ndarray:
    a = np.deg2rad(tilt_deg)
    R = np.diag([1.0, -1.0, -1.0]) @ np.array(
        [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    )
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = position
    return T


def test_depth_and_world_height_references_agree_for_a_downward_camera() -> None:
    boxes = [_box(0.02, 0.01, h=0.1), _box(-0.12, 0.1, h=0.05)]
    for ref in ("depth", "world"):
        loc = _localize([0.0, 0.0, 0.35], boxes, LocalizationConfig(height_reference=ref))
        assert loc is not None and loc.n_proposals == 2
        assert np.linalg.norm(loc.position_world - [0.02, 0.01, 0.1]) < 0.005
        assert loc.floor_world[2] == pytest.approx(0.0, abs=1e-3)


def test_world_heights_handle_a_tilted_camera_where_literal_depths_do_not() -> None:
    # a camera tilted 15 degrees: floor depths vary across the image, so "depth" mode sees the
    # near half of the floor as an object; "world" mode finds the box and the floor height
    T = _tilted_pose([0.0, 0.0, 0.35], 15.0)
    centre_ray = T[:3, :3] @ np.array([0.0, 0.0, 1.0])
    hit = T[:3, 3] + centre_ray * (0.25 / -centre_ray[2])  # centre ray at height 0.1
    boxes = [_box(hit[0], hit[1], sx=0.03, sy=0.03, h=0.1)]
    depth = CAM.render_pose(T, boxes)
    world = localize_object(depth, CAM.K, T, LocalizationConfig(height_reference="world"))
    assert world is not None and world.n_proposals == 1
    assert np.linalg.norm(world.position_world - [hit[0], hit[1], 0.1]) < 0.005
    assert world.floor_world[2] == pytest.approx(0.0, abs=1e-3)
    literal = localize_object(
        depth, CAM.K, T, LocalizationConfig(height_reference="depth", max_area_px=10**6)
    )
    assert literal is not None and literal.n_proposals >= 2  # the near floor became a proposal


def test_edge_cut_separates_an_object_from_a_wall_it_touches_in_the_image() -> None:
    wall = Box(center_xy=np.array([0.0, 0.07]), size=np.array([0.4, 0.03, 0.06]))
    obj = _box(0.0, 0.035, sx=0.04, sy=0.04, h=0.14)  # touches the wall's side
    cam = [0.0, 0.035, 0.45]
    literal = _localize(cam, [wall, obj], LocalizationConfig(max_area_px=10**6))
    assert literal is not None
    assert literal.position_world[1] > 0.04  # the merged blob's centroid is pulled to the wall
    cut = _localize(cam, [wall, obj], LocalizationConfig(edge_jump_m=0.01))
    assert cut is not None and cut.n_proposals == 2
    assert np.linalg.norm(cut.position_world - [0.0, 0.035, 0.14]) < 0.005


# -- waypoint-guided selection (select="waypoint") --------------------------------------------
GUIDED = LocalizationConfig(select="waypoint")


def _guided(cam_pos, boxes, target, config=GUIDED):
    cam_pos = np.asarray(cam_pos, dtype=float)
    depth = CAM.render(cam_pos, boxes)
    return localize_object(
        depth, CAM.K, CAM.cam2world(cam_pos), config, target_world=np.asarray(target, float)
    )


def test_waypoint_picks_the_off_centre_object_it_points_at() -> None:
    centre_obj, other = _box(0.0, 0.0, h=0.08), _box(0.09, 0.05, h=0.06)
    cam = [0.0, 0.0, 0.45]
    by_centre = _guided(cam, [centre_obj, other], [0.09, 0.05, 0.06], LocalizationConfig())
    assert by_centre is not None and np.linalg.norm(by_centre.position_world[:2]) < 0.005
    by_waypoint = _guided(cam, [centre_obj, other], [0.085, 0.045, 0.05])
    assert by_waypoint is not None and by_waypoint.n_proposals == 2
    # grasped where the waypoint points, at the top the depth image measures there
    assert np.linalg.norm(by_waypoint.position_world - [0.085, 0.045, 0.06]) < 0.003
    # a waypoint far from every object does not make the grasp reach into thin air
    far = _guided(cam, [centre_obj, other], [-0.12, 0.1, 0.0])
    assert far is not None and np.linalg.norm(far.position_world[:2]) < 0.005
    # no waypoint given: the reference rule
    no_target = localize_object(
        CAM.render(np.array(cam), [centre_obj, other]), CAM.K, CAM.cam2world(np.array(cam)), GUIDED
    )
    assert no_target is not None and np.linalg.norm(no_target.position_world[:2]) < 0.005


def test_a_handle_separates_from_the_panel_it_is_mounted_on() -> None:
    # a drawer front seen from above: a 2 cm-wide panel top at 12 cm, the handle bar 4 cm in front
    # of it standing 3 cm proud (touching it in the image); the waypoint is at the handle
    panel = Box(center_xy=np.array([0.0, 0.0]), size=np.array([0.3, 0.02, 0.12]))
    handle = Box(center_xy=np.array([0.0, 0.025]), size=np.array([0.08, 0.03, 0.15]))
    cam = [0.0, 0.0, 0.5]
    cut = LocalizationConfig(select="waypoint", edge_jump_m=0.01, min_area_px=5)
    merged = _guided(cam, [panel, handle], [0.0, 0.03, 0.14], LocalizationConfig(select="waypoint"))
    assert merged is not None and merged.n_proposals == 1  # without the cut: one blob
    loc = _guided(cam, [panel, handle], [0.0, 0.03, 0.14], cut)
    assert loc is not None and loc.n_proposals >= 2
    assert np.linalg.norm(loc.position_world - [0.0, 0.025, 0.15]) < 0.006
    panel_pick = _guided(cam, [panel, handle], [0.12, 0.0, 0.12], cut)
    assert panel_pick is not None and abs(panel_pick.position_world[2] - 0.12) < 1e-3


def test_a_nut_is_grasped_on_its_ring_not_in_its_hole() -> None:
    cam_pos = np.array([0.0, 0.0, 0.4])
    depth = CAM.render(cam_pos, [])
    yy, xx = np.mgrid[: CAM.height, : CAM.width]
    r = np.hypot(xx - 80, yy - 60)
    depth[(r > 10) & (r < 16)] = 0.37  # a 3 cm nut ring; its centroid is the hole
    depth[(np.abs(yy - 60) < 3) & (xx > 93) & (xx < 115)] = 0.37  # its handle, to the right
    K, c2w = CAM.K, CAM.cam2world(cam_pos)
    handle_point = back_project(105, 60, 0.37, K, c2w)
    literal = localize_object(depth, K, c2w, LocalizationConfig())
    assert literal is not None
    # the reference rule aims at the centroid, in the hole, far from the handle
    assert np.linalg.norm(literal.position_world[:2] - handle_point[:2]) > 0.03
    guided = localize_object(depth, K, c2w, LocalizationConfig(select="waypoint"), handle_point)
    assert guided is not None
    u, v = guided.pixel
    assert depth[int(round(v)), int(round(u))] == pytest.approx(0.37)  # on the part, not the hole
    assert guided.position_world[2] == pytest.approx(0.03, abs=1e-4)
    assert np.linalg.norm(guided.position_world[:2] - handle_point[:2]) < 0.01


def test_a_handle_too_low_for_the_mask_is_grasped_where_the_waypoint_says() -> None:
    # a nut 3 cm tall with a 1 cm-high handle: the handle is below the 2 cm "object" threshold,
    # so the mask holds the ring only; the demonstration grasped the handle
    cam_pos = np.array([0.0, 0.0, 0.4])
    depth = CAM.render(cam_pos, [])
    yy, xx = np.mgrid[: CAM.height, : CAM.width]
    r = np.hypot(xx - 80, yy - 60)
    depth[(r > 10) & (r < 16)] = 0.37
    depth[(np.abs(yy - 60) < 3) & (xx >= 96) & (xx < 108)] = 0.39  # handle top 1 cm high
    K, c2w = CAM.K, CAM.cam2world(cam_pos)
    config = LocalizationConfig(select="waypoint", above_floor_m=0.02)
    handle_point = back_project(100, 60, 0.39, K, c2w)
    loc = localize_object(depth, K, c2w, config, handle_point)
    assert loc is not None and loc.n_proposals == 1  # the ring alone
    assert np.linalg.norm(loc.position_world - handle_point) < 1e-6
    # 20 px past the ring (beyond guide_radius_px) the waypoint is not trusted: the ring is
    beyond = back_project(120, 60, 0.4, K, c2w)
    loc = localize_object(depth, K, c2w, config, beyond)
    assert loc is not None and loc.position_world[2] == pytest.approx(0.03, abs=1e-4)


def test_select_is_validated() -> None:
    with pytest.raises(UsageError, match="select must be one of"):
        LocalizationConfig(select="nearest")

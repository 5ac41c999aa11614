"""Object localization from one wrist depth image (SPEC §4; supplementary S1, six steps).

Pure numpy + OpenCV on one image, so it is testable on synthetic depth maps::

    depth_m (H, W) [m], 0 = no return      K (3, 3) intrinsics      cam2world (4, 4), OpenCV axes
                                                                     (x right, y down, z forward)

1. background: ``valid = 0 < D <= background_m`` (and ``D >= min_depth_m``: the gripper's fingers);
2. floor: ``height_reference="depth"`` (literal): floor depth ``D_f = median(D[valid])``;
   ``"world"`` (default): back-project every valid pixel, floor height ``z_f = median(z_world)``;
3. object mask: ``"depth"``: ``M = valid & (D <= D_f - above_floor_m)`` (the depth difference is
   the height only for a camera looking straight down); ``"world"``:
   ``M = valid & (z_world >= z_f + above_floor_m)`` (correct for any camera tilt);
   (optional, ``edge_jump_m``, not in the reference: remove from ``M`` the pixels whose height
   (or depth, in "depth" mode) differs from a 3 x 3 neighbour's by more than ``edge_jump_m``:
   ``M &= (dilate(h) - erode(h)) <= edge_jump_m``, cutting objects from walls they touch in the
   image and leaving their flat tops);
4. connected components of ``M`` (OpenCV), kept if ``min_area_px <= area <= max_area_px``;
5. the component whose centroid ``(u_c, v_c)`` is nearest the image centre ``((W-1)/2, (H-1)/2)``
   (``select="centre"``, the reference); or (``select="waypoint"`` with a target) the component
   with a pixel nearest the target's projection ``(u_t, v_t)`` into the image; the grasp pixel is
   ``(u_t, v_t)`` itself, at the depth seen there, when it is within ``guide_radius_px`` of that
   component (the waypoint says where on the part: a nut's handle, too low or thin to survive
   the mask, is grasped where the demonstration grasped it), else the centroid if that lies on
   the component, else the component's pixel nearest ``(u_t, v_t)`` (a ring, not its hole);
6. back-projection of the centroid's depth ``z``::

       p_cam   = z * K^-1 [u_c, v_c, 1]^T
       p_world = cam2world[:3, :3] p_cam + cam2world[:3, 3]

   ``z`` is the depth at the rounded centroid pixel when that pixel belongs to the component, else
   the component's median depth (a concave or ring-shaped blob has its centroid off the object).

The floor point is the back-projection of the image centre at depth ``D_f`` ("depth"), or the
object's x, y at height ``z_f`` ("world").
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from awda_bench.errors import UsageError
from awda_bench.primitives.config import LocalizationConfig


@dataclass(frozen=True)
class Localization:
    """Result of :func:`localize_object` for one image."""

    position_world: np.ndarray
    """(3,) estimated object position [m]: the visible top surface under the centroid."""
    floor_world: np.ndarray
    """(3,) a point of the floor (support) plane [m], under the image centre."""
    pixel: tuple[float, float]
    """Centroid ``(u, v)`` [px] of the chosen component."""
    area_px: int
    """Pixel count of the chosen component."""
    n_proposals: int
    """Components that passed the area bounds (the chosen one included)."""
    floor_depth_m: float
    """Median depth of the valid pixels [m] (the floor distance of step 2 in ``"depth"`` mode)."""


def back_project(u: float, v: float, z: float, K: np.ndarray, cam2world: np.ndarray) -> np.ndarray:
    """World point [m] of pixel ``(u, v)`` at depth ``z`` [m]: ``T (z K^-1 [u, v, 1])``."""
    x = (u - K[0, 2]) * z / K[0, 0]
    y = (v - K[1, 2]) * z / K[1, 1]
    p = np.array([x, y, z, 1.0])
    return (np.asarray(cam2world, dtype=np.float64) @ p)[:3]


def pixel_heights(depth_m: np.ndarray, K: np.ndarray, cam2world: np.ndarray) -> np.ndarray:
    """(H, W) world z [m] of every pixel back-projected at its depth (meaningless where depth = 0).

    ``z_world(u, v) = r_3 . (D (u - c_x) / f_x, D (v - c_y) / f_y, D) + t_3`` with ``r_3`` the
    third row of the camera rotation and ``t_3`` the camera height.
    """
    H, W = depth_m.shape
    r = np.asarray(cam2world, dtype=np.float64)[2]
    a = r[0] / K[0, 0] * (np.arange(W) - K[0, 2])  # (W,)
    b = r[1] / K[1, 1] * (np.arange(H) - K[1, 2])  # (H,)
    return depth_m * (a[None, :] + b[:, None] + r[2]) + r[3]


def project(point_world: np.ndarray, K: np.ndarray, cam2world: np.ndarray) -> np.ndarray | None:
    """Pixel ``(u, v)`` of a world point [m], or ``None`` when it is behind the camera."""
    world2cam = np.linalg.inv(np.asarray(cam2world, dtype=np.float64))
    p = world2cam @ np.append(np.asarray(point_world, dtype=np.float64), 1.0)
    if p[2] <= 1e-6:
        return None
    return np.array([K[0, 0] * p[0] / p[2] + K[0, 2], K[1, 1] * p[1] / p[2] + K[1, 2]])


def localize_object(
    depth_m: np.ndarray,
    K: np.ndarray,
    cam2world: np.ndarray,
    config: LocalizationConfig = LocalizationConfig(),
    target_world: np.ndarray | None = None,
) -> Localization | None:
    """Localize the object nearest the image centre (or the target), ``None`` if none is seen.

    Args:
        depth_m: (H, W) depth along the optical axis [m]; 0 where the camera saw nothing.
        K: (3, 3) pinhole intrinsics [px].
        cam2world: (4, 4) camera pose, OpenCV axes.
        config: thresholds of steps 1-4 and the selection rule of step 5.
        target_world: (3,) where to grasp [m] (the grasp waypoint); used by ``select="waypoint"``.
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    if depth.ndim != 2:
        raise UsageError(f"depth_m must be (H, W), got shape {depth.shape}")
    if np.shape(K) != (3, 3) or np.shape(cam2world) != (4, 4):
        raise UsageError(
            f"K must be (3, 3) and cam2world (4, 4), got {np.shape(K)}, {np.shape(cam2world)}"
        )
    # 1. background (and no-return pixels, and the fingers right in front of the lens)
    valid = (depth > 0) & (depth <= config.background_m) & (depth >= config.min_depth_m)
    if not valid.any():
        return None
    # 2.-3. floor and the pixels at least above_floor_m above it
    floor_depth = float(np.median(depth[valid]))
    floor_z: float | None = None
    if config.height_reference == "depth":
        mask = valid & (depth <= floor_depth - config.above_floor_m)
        height = -depth
    else:
        height = pixel_heights(depth, K, cam2world).astype(np.float32)
        floor_z = float(np.median(height[valid]))
        mask = valid & (height >= floor_z + config.above_floor_m)
    if config.edge_jump_m is not None:
        h = np.where(valid, height, np.float32(-1e3))  # invalid pixels count as a deep edge
        kernel = np.ones((3, 3), np.uint8)
        mask &= (cv2.dilate(h, kernel) - cv2.erode(h, kernel)) <= config.edge_jump_m
    if not mask.any():
        return None
    # 4. connected components -> proposals within the area bounds
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(
        mask.astype(np.uint8), connectivity=config.connectivity
    )
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.flatnonzero((areas >= config.min_area_px) & (areas <= config.max_area_px)) + 1
    if keep.size == 0:
        return None
    # 5. the component nearest the image centre (or the target's projection)
    H, W = depth.shape
    centre = np.array([(W - 1) / 2.0, (H - 1) / 2.0])
    anchor = None
    if config.select == "waypoint" and target_world is not None:
        anchor = project(target_world, K, cam2world)
    if anchor is None:
        dist = np.linalg.norm(centroids[keep] - centre, axis=1)
        label = int(keep[int(np.argmin(dist))])
    else:
        vs, us = np.nonzero(np.isin(labels, keep))
        near = np.hypot(us - anchor[0], vs - anchor[1])
        label = int(labels[vs[int(np.argmin(near))], us[int(np.argmin(near))]])
    u, v = (float(c) for c in centroids[label])
    guided_z = None
    if anchor is not None:
        ua, va = int(round(anchor[0])), int(round(anchor[1]))
        inside = 0 <= ua < W and 0 <= va < H and bool(valid[va, ua])
        if inside and float(np.min(near)) <= config.guide_radius_px:
            # the waypoint is on (or right beside) the part: grasp where it says, at the depth
            # seen there (a nut's handle, too low or thin to survive the mask, is still seen)
            u, v, guided_z = float(anchor[0]), float(anchor[1]), float(depth[va, ua])
    # 6. back-project the grasp pixel's depth
    ui, vi = int(round(u)), int(round(v))
    on_component = 0 <= ui < W and 0 <= vi < H and labels[vi, ui] == label
    if guided_z is not None:
        z = guided_z
    elif on_component:
        z = float(depth[vi, ui])
    elif anchor is not None:
        # the centroid is off the object (a ring, a U): grasp its pixel nearest the target
        vs, us = np.nonzero(labels == label)
        i = int(np.argmin(np.hypot(us - anchor[0], vs - anchor[1])))
        u, v = float(us[i]), float(vs[i])
        z = float(depth[vs[i], us[i]])
    else:
        z = float(np.median(depth[labels == label]))
    position = back_project(u, v, z, K, cam2world)
    if floor_z is None:
        floor = back_project(centre[0], centre[1], floor_depth, K, cam2world)
    else:
        floor = np.array([position[0], position[1], floor_z])
    return Localization(
        position_world=position,
        floor_world=floor,
        pixel=(u, v),
        area_px=int(stats[label, cv2.CC_STAT_AREA]),
        n_proposals=int(keep.size),
        floor_depth_m=floor_depth,
    )

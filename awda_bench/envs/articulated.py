"""Procedural articulated props of the door and drawer tasks: hinged-door cabinets, drawer cabinets.

Everything is built from boxes and cylinders with ManiSkill's articulation builder (a fixed carcass
root link, revolute door panels or prismatic drawers), one articulation per parallel scene, no
downloaded assets. Frames: world, table top at z = 0, x away from the robot, y to its left.

A cabinet's *root frame* sits at the centre of its front face, at table height, turned by the
cabinet's yaw; the carcass extends to +x (away from the robot) and the fronts face -x (the robot).
The Panda hand points down with its fingers spread along world y, so every handle is grasped by its
y-facing sides, and stands far enough in front of the face that the hand body (3.2 cm either side of
the TCP along x) clears it::

    top view, door cabinet, hinge_side = -1           side view, drawer cabinet
                                                     (drawer k pulled out by q_k)
        +y ^      carcass                                  ____________
           |   ______________                             |  _________ |  <- upper drawer (1)
           |  |  .  .  .  .  |  <- panel, shut (q = 0)   =|=|         ||
           |  |______________|                        head |_________ ||
           |  o  hinge  ==|  <- handle bar, standoff       |  _________ |  <- lower drawer (0)
           |               (in front of the face)         =|=|         ||
           +--------------------> +x                       |____________|
        robot at -x                                     robot at -x     +x

A door opens toward the robot: joint angle ``q >= 0`` turns the panel about the vertical hinge
axis by ``opening_sign * q`` (counter-clockwise seen from above when the hinge is on the -y edge).
A drawer slides out along the cabinet's -x axis by ``q >= 0`` metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import sapien
import torch
from mani_skill.envs.scene import ManiSkillScene
from mani_skill.utils.building.articulation_builder import ArticulationBuilder
from mani_skill.utils.structs.articulation import Articulation
from sapien.wrapper.articulation_builder import LinkBuilder

RGBA = tuple[float, float, float, float]
"""Red, green, blue, alpha in [0, 1]."""

_SQRT_HALF = math.sqrt(0.5)
_CYLINDER_UP = sapien.Pose(q=[_SQRT_HALF, 0.0, _SQRT_HALF, 0.0])
"""SAPIEN cylinders lie along x; this turns their axis to z."""
_PRISMATIC_TOWARD_ROBOT = [0.0, 0.0, 0.0, 1.0]
"""Joint frame turned 180 deg about z: a prismatic joint's +x axis points along the cabinet's -x."""
_NO_SELF_COLLISION_BIT = 1 << 29
"""Collision-group bit shared by every link of a prop: links of one articulation never collide."""


HOLD_MIN_FORCE_N = 0.5
"""A finger touching a handle with at least this force [N] can hold it (ManiSkill's ``is_grasping``
threshold)."""
HOLD_OPENING_M = (0.01, 0.06)
"""... while the fingers are this far apart [m]: closed on something. Below: closed fingers that
push (contact spreads them by up to 7.4 mm; the narrowest real grasp, a nut's handle, holds them
12.7 mm apart -- the grasp miner's ``min_opening_m`` rests on the same measurement); above: an
open hand that only touches."""


def hand_holds(
    grasping: torch.Tensor,
    finger_forces_n: torch.Tensor,
    opening_m: torch.Tensor,
    commanded_closed: torch.Tensor,
) -> torch.Tensor:
    """Simulator truth "grasp" of a door or drawer handle, (n,) bool.

    ManiSkill's two-finger test (``grasping``: both fingers press on the link, forces along their
    closing direction), or the closed hand *drags* the handle: one finger pulls on it with at
    least :data:`HOLD_MIN_FORCE_N` while the fingers are closed on something (commanded closed,
    opening within :data:`HOLD_OPENING_M`). Measured on a door-open demonstration: while the hand carried the
    handle along the arc, the trailing finger lost contact and the leading one pulled with up to
    47 N, the door swinging with it, and the two-finger test said "not grasped" for the whole
    swing (mined grasp precision on doors 0.54-0.64 against it).

    Args:
        grasping: (n,) ManiSkill's ``agent.is_grasping(link)``.
        finger_forces_n: (n, 2) contact force magnitude of each finger on the link [N].
        opening_m: (n,) distance between the finger pads [m].
        commanded_closed: (n,) the gripper's last command was "close". Without it, fingers
            *opening* against a handle after a closed-hand push (passing 1-6 cm with one finger
            still pressing) read as a grasp for 1-2 steps: every door/drawer-close demonstration
            had such a truth grasp that nothing mined (grasp recall on those families 0.84-0.95).
    """
    low, high = HOLD_OPENING_M
    pulling = finger_forces_n.max(dim=1).values >= HOLD_MIN_FORCE_N
    closed_on_something = (opening_m >= low) & (opening_m <= high)
    return grasping | (pulling & closed_on_something & commanded_closed)


def hinge_joint_quat(opening_sign: int) -> list[float]:
    """Joint-frame quaternion (wxyz) whose x axis is ``opening_sign`` * z (SAPIEN revolute joints
    turn about their frame's x axis)."""
    return [_SQRT_HALF, 0.0, -opening_sign * _SQRT_HALF, 0.0]


def yaw_quat(yaw_rad: torch.Tensor) -> torch.Tensor:
    """(b, 4) wxyz quaternions of rotations by ``yaw_rad`` (b,) about the vertical axis."""
    q = torch.zeros((*yaw_rad.shape, 4), dtype=yaw_rad.dtype, device=yaw_rad.device)
    q[..., 0] = torch.cos(yaw_rad / 2)
    q[..., 3] = torch.sin(yaw_rad / 2)
    return q


def rotate_z(v: torch.Tensor, yaw_rad: torch.Tensor) -> torch.Tensor:
    """Rotate the vectors ``v`` (b, 3) by ``yaw_rad`` (b,) about the vertical axis."""
    c, s = torch.cos(yaw_rad), torch.sin(yaw_rad)
    return torch.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], dim=1)


def _material(color: RGBA) -> sapien.render.RenderMaterial:
    return sapien.render.RenderMaterial(base_color=list(color))


def add_box(
    link: LinkBuilder,
    *,
    lo_m: tuple[float, float, float],
    hi_m: tuple[float, float, float],
    color: RGBA,
    collision: bool = True,
) -> None:
    """Add the axis-aligned box spanning corners ``lo_m``..``hi_m`` (link frame) to ``link``."""
    center = [(a + b) / 2 for a, b in zip(lo_m, hi_m, strict=True)]
    half = [(b - a) / 2 for a, b in zip(lo_m, hi_m, strict=True)]
    if min(half) <= 0:
        raise ValueError(f"box corners must satisfy lo < hi on every axis, got {lo_m} .. {hi_m}")
    pose = sapien.Pose(p=center)
    if collision:
        link.add_box_collision(pose=pose, half_size=half)
    link.add_box_visual(pose=pose, half_size=half, material=_material(color))


def add_vertical_cylinder(
    link: LinkBuilder,
    *,
    center_m: tuple[float, float, float],
    radius_m: float,
    half_height_m: float,
    color: RGBA,
) -> None:
    """Add a cylinder with a vertical axis centred at ``center_m`` (link frame) to ``link``."""
    pose = sapien.Pose(p=list(center_m)) * _CYLINDER_UP
    link.add_cylinder_collision(pose=pose, radius=radius_m, half_length=half_height_m)
    link.add_cylinder_visual(
        pose=pose, radius=radius_m, half_length=half_height_m, material=_material(color)
    )


def _new_cabinet(
    scene: ManiSkillScene, center_xy_m: tuple[float, float]
) -> tuple[ArticulationBuilder, LinkBuilder]:
    """An articulation builder rooted at ``center_xy_m`` on the table, and its root link
    ``carcass``."""
    builder = scene.create_articulation_builder()
    builder.initial_pose = sapien.Pose(p=[*center_xy_m, 0.0])
    return builder, _prop_link(builder, "carcass")


def _prop_link(
    builder: ArticulationBuilder, name: str, parent: LinkBuilder | None = None
) -> LinkBuilder:
    """A new link ``name`` of ``builder`` (a child of ``parent``) that never collides with the
    prop's other links."""
    link = builder.create_link_builder(parent)
    link.set_name(name)
    link.collision_groups[2] |= _NO_SELF_COLLISION_BIT
    return link


def _add_carcass_shell(
    carcass: LinkBuilder,
    *,
    front_x_m: float,
    half_width_m: float,
    depth_m: float,
    height_m: float,
    wall_m: float,
    color: RGBA,
) -> None:
    """The carcass's two sides, top and bottom, from ``front_x_m`` back to ``depth_m`` (root
    frame) [m]; the caller adds the back and any divider."""
    w, d, h, t, x = half_width_m, depth_m, height_m, wall_m, front_x_m
    add_box(carcass, lo_m=(x, -w, 0.001), hi_m=(d, -w + t, h), color=color)  # side -y
    add_box(carcass, lo_m=(x, w - t, 0.001), hi_m=(d, w, h), color=color)  # side +y
    add_box(carcass, lo_m=(x, -w, h - t), hi_m=(d, w, h), color=color)  # top
    add_box(carcass, lo_m=(x, -w, 0.001), hi_m=(d, w, t), color=color)  # bottom


def _set_joint_dynamics(art: Articulation, *, damping: float, friction: float) -> None:
    """Passive joints: no drive stiffness, velocity damping and Coulomb-like joint friction."""
    for joint in art.active_joints:
        joint.set_drive_properties(stiffness=0.0, damping=damping)
        joint.set_friction(friction)


# ============================================================================ door cabinet


@dataclass(frozen=True)
class DoorCabinetSpec:
    """A box cabinet whose whole front is one door on a vertical hinge, with a vertical bar handle.

    Lengths in the cabinet's root frame (see the module docstring): x into the cabinet, y across
    its front, z up from the table.
    """

    name: str
    """Articulation name (unique in the scene)."""
    center_xy_m: tuple[float, float]
    """Nominal world position of the front face's centre [m]."""
    hinge_side: int
    """-1: hinge on the cabinet's -y edge (door swings counter-clockwise seen from above); +1: on
    its +y edge."""
    panel_color: RGBA
    """Door panel colour (what tells the doors apart in a video)."""
    carcass_color: RGBA = (0.80, 0.78, 0.72, 1.0)
    """Colour of the fixed cabinet body."""
    handle_color: RGBA = (0.25, 0.25, 0.27, 1.0)
    """Colour of the handle bar and its post."""
    width_m: float = 0.20
    """Outer width of the cabinet along y [m]."""
    depth_m: float = 0.16
    """Outer depth of the cabinet along x [m]."""
    height_m: float = 0.262
    """Height of the cabinet and of the door panel's top edge [m] (the hand body, 3.7 cm above the
    TCP, passes over it when the TCP holds the handle's top 2 cm below)."""
    wall_m: float = 0.012
    """Thickness of the carcass walls [m]."""
    panel_thickness_m: float = 0.015
    """Door panel thickness [m]."""
    panel_gap_m: float = 0.004
    """Clearance between the panel and the hinge edge, the table and the far edge [m]."""
    handle_from_hinge_m: float = 0.15
    """Distance from the hinge axis to the handle bar's axis, along the panel [m]."""
    handle_standoff_m: float = 0.05
    """Distance of the handle bar's axis in front of the panel's front face [m]."""
    handle_radius_m: float = 0.009
    """Radius of the handle bar [m]."""
    handle_bottom_z_m: float = 0.13
    """Height of the handle bar's lower end [m] (its upper end is flush with the panel's top)."""
    post_height_m: float = 0.02
    """Height of the post joining the bar's lower end to the panel [m]."""
    max_angle_rad: float = 1.4
    """Upper limit of the hinge [rad] (lower limit 0 = shut)."""
    damping: float = 0.3
    """Hinge damping [N m s / rad]: the door stays where it is left."""
    friction: float = 0.02
    """Hinge joint friction coefficient."""

    def __post_init__(self) -> None:
        if self.hinge_side not in (-1, 1):
            raise ValueError(f"hinge_side must be -1 or +1, got {self.hinge_side}")
        if not self.handle_radius_m < self.handle_standoff_m:
            raise ValueError(
                f"handle_standoff_m {self.handle_standoff_m} must exceed handle_radius_m "
                f"{self.handle_radius_m}"
            )
        if not 0 < self.handle_from_hinge_m < self.panel_width_m:
            raise ValueError(
                f"handle_from_hinge_m must be in (0, {self.panel_width_m}), got "
                f"{self.handle_from_hinge_m}"
            )

    @property
    def opening_sign(self) -> int:
        """+1: opening turns the panel counter-clockwise about world z (seen from above)."""
        return -self.hinge_side

    @property
    def panel_width_m(self) -> float:
        """Width of the door panel [m]."""
        return self.width_m - 2 * self.panel_gap_m

    @property
    def handle_top_z_m(self) -> float:
        """Height of the handle bar's top [m]."""
        return self.height_m - self.panel_gap_m

    @property
    def hinge_local_m(self) -> tuple[float, float, float]:
        """Hinge axis position in the root frame [m] (on the front face, at the hinge edge)."""
        return (0.0, self.hinge_side * self.width_m / 2, 0.0)

    def handle_from_hinge_local_m(self) -> tuple[float, float, float]:
        """Handle axis (at height 0) relative to the hinge, in the door frame at q = 0 [m]."""
        return (-self.handle_standoff_m, -self.hinge_side * self.handle_from_hinge_m, 0.0)

    def point_from_hinge_local_m(self, along_m: float, out_m: float) -> tuple[float, float, float]:
        """A point ``along_m`` from the hinge along the panel and ``out_m`` in front of the front
        face, relative to the hinge, door frame at q = 0 [m]."""
        return (-out_m, -self.hinge_side * along_m, 0.0)


def build_door_cabinet(scene: ManiSkillScene, spec: DoorCabinetSpec) -> Articulation:
    """Build ``spec`` (one articulation per parallel scene): links ``carcass`` and ``door``."""
    builder, carcass = _new_cabinet(scene, spec.center_xy_m)
    w, d, h, t = spec.width_m / 2, spec.depth_m, spec.height_m, spec.wall_m
    inset = spec.panel_thickness_m + spec.panel_gap_m  # carcass walls start behind the panel
    color = spec.carcass_color
    _add_carcass_shell(
        carcass, front_x_m=inset, half_width_m=w, depth_m=d, height_m=h, wall_m=t, color=color
    )
    add_box(carcass, lo_m=(d - t, -w, 0.001), hi_m=(d, w, h), color=color)  # back

    door = _prop_link(builder, "door", carcass)
    joint_q = hinge_joint_quat(spec.opening_sign)
    door.set_joint_name("hinge")
    door.set_joint_properties(
        "revolute",
        limits=[[0.0, spec.max_angle_rad]],
        pose_in_parent=sapien.Pose(p=list(spec.hinge_local_m), q=joint_q),
        pose_in_child=sapien.Pose(q=joint_q),
        friction=spec.friction,
        damping=spec.damping,
    )
    s = -spec.hinge_side  # panel extends from the hinge along s * y
    near, far = spec.panel_gap_m, spec.panel_gap_m + spec.panel_width_m
    y_lo, y_hi = sorted((s * near, s * far))
    panel_top = spec.height_m - spec.panel_gap_m
    add_box(
        door,
        lo_m=(0.0, y_lo, spec.panel_gap_m),
        hi_m=(spec.panel_thickness_m, y_hi, panel_top),
        color=spec.panel_color,
    )
    hx, hy, _ = spec.handle_from_hinge_local_m()
    bar_bottom = spec.handle_bottom_z_m
    add_vertical_cylinder(
        door,
        center_m=(hx, hy, (bar_bottom + panel_top) / 2),
        radius_m=spec.handle_radius_m,
        half_height_m=(panel_top - bar_bottom) / 2,
        color=spec.handle_color,
    )
    post_half_w = 0.007
    add_box(
        door,
        lo_m=(hx, hy - post_half_w, bar_bottom),
        hi_m=(0.0, hy + post_half_w, bar_bottom + spec.post_height_m),
        color=spec.handle_color,
    )
    art = builder.build(name=spec.name, fix_root_link=True)
    _set_joint_dynamics(art, damping=spec.damping, friction=spec.friction)
    return art


# ============================================================================ drawer cabinet


@dataclass(frozen=True)
class DrawerCabinetSpec:
    """A box cabinet with two drawers stacked vertically (0 = lower, 1 = upper), each with a short
    horizontal pull handle on a stem in the middle of its front.

    Lengths in the cabinet's root frame (see the module docstring).
    """

    name: str
    """Articulation name (unique in the scene)."""
    center_xy_m: tuple[float, float]
    """Nominal world position of the front face's centre [m]."""
    front_color: RGBA
    """Colour of both drawer fronts (what tells the cabinets apart in a video)."""
    carcass_color: RGBA = (0.80, 0.78, 0.72, 1.0)
    """Colour of the fixed cabinet body."""
    handle_color: RGBA = (0.25, 0.25, 0.27, 1.0)
    """Colour of the handles."""
    tray_color: RGBA = (0.62, 0.52, 0.40, 1.0)
    """Colour of the drawer trays (visible when pulled out)."""
    handle_y_m: tuple[float, float] = (0.07, -0.07)
    """Handle position across the front (root-frame y) of the lower and upper drawer [m]. They
    must differ by more than the hand's half length (10.4 cm) plus half a handle head: the hand
    descending to the lower handle passes beside, not through, the upper one."""
    width_m: float = 0.26
    """Outer width along y [m]."""
    depth_m: float = 0.20
    """Outer depth along x [m]."""
    height_m: float = 0.30
    """Outer height [m] (both handles below the 0.35 m the Panda reaches pointing down)."""
    wall_m: float = 0.012
    """Carcass wall / divider thickness [m]."""
    gap_m: float = 0.003
    """Clearance between a drawer front and the carcass opening [m]."""
    front_thickness_m: float = 0.015
    """Drawer front thickness [m] (flush with the carcass front when shut)."""
    tray_depth_m: float = 0.17
    """Depth of a drawer (front included) [m]."""
    tray_wall_m: float = 0.008
    """Tray wall thickness [m]."""
    tray_height_m: float = 0.07
    """Height of the tray's side and back walls [m]."""
    handle_stem_m: float = 0.045
    """Length of the stem from the front face to the handle head [m]."""
    handle_head_size_m: tuple[float, float, float] = (0.016, 0.05, 0.024)
    """Handle head extent (x depth, y width, z height) [m]; the fingers (8 cm apart when open)
    close on its two y faces."""
    max_slide_m: float = 0.21
    """Upper limit of each drawer's slide [m] (lower limit 0 = shut)."""
    damping: float = 8.0
    """Slide damping [N s / m]: a drawer stays where it is left."""
    friction: float = 0.02
    """Slide joint friction coefficient."""

    def __post_init__(self) -> None:
        lower, upper = self.handle_y_m
        if abs(lower - upper) < 0.104 + self.handle_head_size_m[1] / 2:
            raise ValueError(
                f"handle_y_m {self.handle_y_m}: the lower and upper handles must be at least "
                f"{0.104 + self.handle_head_size_m[1] / 2:.3f} m apart across the front"
            )
        half_inner = self.width_m / 2 - self.wall_m - self.gap_m
        if max(abs(y) for y in self.handle_y_m) + self.handle_head_size_m[1] / 2 > half_inner:
            raise ValueError(f"handle_y_m {self.handle_y_m} puts a handle beyond the drawer front")

    @property
    def opening_height_m(self) -> float:
        """Height of one drawer opening in the carcass [m]."""
        return (self.height_m - 3 * self.wall_m) / 2

    @property
    def drawer_center_z_m(self) -> tuple[float, float]:
        """Height of the lower and upper drawer's centre (= handle centre) [m]."""
        h, t = self.opening_height_m, self.wall_m
        return (t + h / 2, 2 * t + 1.5 * h)

    @property
    def handle_center_x_m(self) -> float:
        """Handle head centre along x in the drawer frame (front face at 0, shut) [m]."""
        return -(self.handle_stem_m + self.handle_head_size_m[0] / 2)

    @property
    def handle_front_x_m(self) -> float:
        """The handle head's robot-facing face along x in the drawer frame [m]."""
        return -(self.handle_stem_m + self.handle_head_size_m[0])


def build_drawer_cabinet(scene: ManiSkillScene, spec: DrawerCabinetSpec) -> Articulation:
    """Build ``spec``: links ``carcass``, ``drawer_0`` (lower), ``drawer_1`` (upper)."""
    builder, carcass = _new_cabinet(scene, spec.center_xy_m)
    w, d, h, t = spec.width_m / 2, spec.depth_m, spec.height_m, spec.wall_m
    color = spec.carcass_color
    _add_carcass_shell(
        carcass, front_x_m=0.0, half_width_m=w, depth_m=d, height_m=h, wall_m=t, color=color
    )
    mid = t + spec.opening_height_m
    add_box(carcass, lo_m=(0.0, -w, mid), hi_m=(d, w, mid + t), color=color)  # divider
    add_box(carcass, lo_m=(d - t, -w, 0.001), hi_m=(d, w, h), color=color)  # back

    inner = w - t - spec.gap_m  # half width of a drawer
    half_front = spec.opening_height_m / 2 - spec.gap_m
    tf, tw, depth = spec.front_thickness_m, spec.tray_wall_m, spec.tray_depth_m
    tray_top = -half_front + spec.tray_height_m
    hd, hw, hh = spec.handle_head_size_m
    stem = spec.handle_stem_m
    for k, (z, hy) in enumerate(zip(spec.drawer_center_z_m, spec.handle_y_m, strict=True)):
        drawer = _prop_link(builder, f"drawer_{k}", carcass)
        drawer.set_joint_name(f"slide_{k}")
        drawer.set_joint_properties(
            "prismatic",
            limits=[[0.0, spec.max_slide_m]],
            pose_in_parent=sapien.Pose(p=[0.0, 0.0, z], q=_PRISMATIC_TOWARD_ROBOT),
            pose_in_child=sapien.Pose(q=_PRISMATIC_TOWARD_ROBOT),
            friction=spec.friction,
            damping=spec.damping,
        )
        front = spec.front_color
        tray = spec.tray_color
        add_box(drawer, lo_m=(0.0, -inner, -half_front), hi_m=(tf, inner, half_front), color=front)
        add_box(
            drawer,
            lo_m=(tf, -inner, -half_front),
            hi_m=(depth, inner, -half_front + tw),
            color=tray,
        )
        add_box(
            drawer, lo_m=(tf, -inner, -half_front), hi_m=(depth, -inner + tw, tray_top), color=tray
        )
        add_box(
            drawer, lo_m=(tf, inner - tw, -half_front), hi_m=(depth, inner, tray_top), color=tray
        )
        add_box(
            drawer,
            lo_m=(depth - tw, -inner, -half_front),
            hi_m=(depth, inner, tray_top),
            color=tray,
        )
        handle = spec.handle_color
        add_box(
            drawer, lo_m=(-stem, hy - 0.006, -0.006), hi_m=(0.0, hy + 0.006, 0.006), color=handle
        )
        add_box(
            drawer,
            lo_m=(-stem - hd, hy - hw / 2, -hh / 2),
            hi_m=(-stem, hy + hw / 2, hh / 2),
            color=handle,
        )
    art = builder.build(name=spec.name, fix_root_link=True)
    _set_joint_dynamics(art, damping=spec.damping, friction=spec.friction)
    return art


# ============================================================================ placement


@dataclass(frozen=True)
class PlacementNoise:
    """Per-episode random offset of a cabinet's pose (uniform, independent per cabinet)."""

    xy_m: tuple[float, float] = (0.02, 0.02)
    """Half range of the x and y offsets [m]."""
    yaw_rad: float = 0.06
    """Half range of the yaw offset [rad] (about 3.4 deg)."""


def sample_placements(
    nominal_xy_m: tuple[float, float], noise: PlacementNoise, b: int, device: torch.device | str
) -> tuple[torch.Tensor, torch.Tensor]:
    """(b, 3) root positions and (b,) yaws drawn under ``noise`` (uses the global torch RNG, which
    ManiSkill seeds from ``reset(seed=...)``)."""
    u = torch.rand((b, 3), device=device) * 2 - 1
    p = torch.zeros((b, 3), device=device)
    p[:, 0] = nominal_xy_m[0] + u[:, 0] * noise.xy_m[0]
    p[:, 1] = nominal_xy_m[1] + u[:, 1] * noise.xy_m[1]
    return p, u[:, 2] * noise.yaw_rad

"""AWDA-PressButton-v1: two procedural button panels, 3 spring-loaded buttons each (SPEC §3.2).

Each panel is one articulation: a fixed base plate (root link) and three button links on vertical
prismatic joints. A button's joint position ``q`` is its height change [m]: ``q = 0`` at rest
(the upper limit), ``q = -travel_m`` fully pressed (the lower limit). A joint drive is the spring:
it pulls towards ``spring_preload_m`` above the upper limit, so a released button pops back up and
rests firmly on its stop against gravity::

       finger                      pressed by d = -q:  spring force = k (preload + d)
         v
      ._____.  <- cap top, protrusion_m above the plate at rest
    __|     |__  plate top
    |  |   |  |  <- the cap slides into the plate (no collision between a link and its parent)

The success depth is SPEC's "pressed >= 4 cm" scaled to our 2 cm travel: 1.5 cm (75 % of travel).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import sapien
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.articulation import Articulation
from mani_skill.utils.structs.link import Link
from mani_skill.utils.structs.pose import Pose

from awda_bench.envs.task_base import AwdaTaskEnv

_X_TO_Z = [float(np.sqrt(0.5)), 0.0, float(-np.sqrt(0.5)), 0.0]
"""Quaternion (wxyz) turning the x axis onto +z: SAPIEN prismatic joints slide along their frame's
x axis, and SAPIEN cylinders lie along x."""


@dataclass(frozen=True)
class ButtonPanelSpec:
    """One panel: a box plate standing on the table with three buttons on its top face."""

    name: str
    """Articulation name."""
    center_xy_m: tuple[float, float]
    """Nominal plate centre on the table (world) [m]; randomized by ``PressButtonLayout``."""
    plate_size_m: tuple[float, float, float]
    """Full plate extent x, y, z [m] (its bottom rests on the table, z = 0)."""
    plate_color: tuple[float, float, float, float]
    """RGBA plate colour."""
    button_xy_m: tuple[tuple[float, float], ...]
    """Button centres in the plate frame (x, y) [m], button 0 first."""
    button_colors: tuple[tuple[float, float, float, float], ...]
    """RGBA cap colour per button (all six buttons of the scene differ)."""

    def __post_init__(self) -> None:
        if len(self.button_xy_m) != 3 or len(self.button_colors) != 3:
            raise ValueError(f"panel {self.name!r} needs exactly 3 buttons and 3 colours")

    @property
    def top_z_m(self) -> float:
        """Height of the plate's top face above the table [m]."""
        return self.plate_size_m[2]


@dataclass(frozen=True)
class PressButtonLayout:
    """Geometry, spring and randomization of the press-button scene (table top z = 0)."""

    panels: tuple[ButtonPanelSpec, ...] = (
        ButtonPanelSpec(
            name="panel_row",
            center_xy_m=(-0.07, -0.22),
            plate_size_m=(0.26, 0.10, 0.04),
            plate_color=(0.18, 0.18, 0.20, 1.0),
            button_xy_m=((-0.08, 0.0), (0.0, 0.0), (0.08, 0.0)),
            button_colors=(
                (0.90, 0.10, 0.10, 1.0),
                (0.10, 0.75, 0.15, 1.0),
                (0.10, 0.25, 0.90, 1.0),
            ),
        ),
        ButtonPanelSpec(
            name="panel_triangle",
            center_xy_m=(-0.07, 0.21),
            plate_size_m=(0.18, 0.18, 0.03),
            plate_color=(0.88, 0.82, 0.66, 1.0),
            button_xy_m=((0.045, -0.05), (0.045, 0.05), (-0.05, 0.0)),
            button_colors=(
                (0.95, 0.85, 0.05, 1.0),
                (0.85, 0.15, 0.80, 1.0),
                (0.05, 0.80, 0.85, 1.0),
            ),
        ),
    )
    """Panel 0: dark bar (long axis towards the camera), a row of red/green/blue buttons; panel 1:
    cream square, a triangle of yellow/magenta/cyan buttons. Both stay clear of the table area the
    robot's rest pose hides from the third-person camera (|y| < ~0.14 m). Variation ``v`` = panel
    ``v // 3``, button ``v % 3``."""
    button_radius_m: float = 0.022
    """Cap radius [m] (the closed Panda fingertips are ~2 cm across)."""
    cap_length_m: float = 0.03
    """Cap cylinder length [m]; the part below the plate top is hidden inside the plate."""
    protrusion_m: float = 0.02
    """Cap top above the plate top at rest [m]."""
    travel_m: float = 0.02
    """Joint travel from rest to the lower stop [m] (cap top flush with the plate when pressed)."""
    success_depth_m: float = 0.015
    """Success: the target button pressed at least this deep [m] (SPEC's 4 cm, scaled to our
    2 cm travel: 75 %)."""
    bezel_radius_m: float = 0.029
    """Radius of the dark ring drawn around each button on the plate [m] (visual only)."""
    spring_stiffness_n_m: float = 300.0
    """Joint drive stiffness (the spring) [N/m]."""
    spring_damping_n_s_m: float = 5.0
    """Joint drive damping [N s/m]."""
    spring_preload_m: float = 0.01
    """Drive target this far above the rest stop [m]: the rest force k * preload (3 N) holds the
    cap on its stop against gravity; fully pressed, the spring pushes k * (preload + travel)
    (9 N)."""
    joint_friction: float = 0.0
    """Joint friction coefficient."""
    spawn_jitter_m: tuple[float, float] = (0.03, 0.02)
    """Each panel's centre is drawn uniformly in its nominal centre +- this (x, y) [m]."""
    yaw_jitter_rad: float = 0.25
    """Each panel's yaw is drawn uniformly in +- this [rad]."""
    press_min_depth_m: float = 0.001
    """Truth "press": the target is at least this deep [m] ..."""
    press_min_force_n: float = 0.5
    """... the fingers push on it with at least this force [N] ..."""
    press_max_rise_m_s: float = 0.01
    """... and it is not rising faster than this [m/s] (moving down or held down) unless it is on
    its lower stop (within ``press_stop_band_m`` of full travel): pinned on the stop by the
    fingers, the button's joint velocity jitters by up to 0.08 m/s (measured with the agent
    pushing ~40 N) without the button moving."""
    press_stop_band_m: float = 0.001
    """Depths within this of ``travel_m`` count as on the stop [m]."""

    def __post_init__(self) -> None:
        if len(self.panels) != 2:
            raise ValueError(f"the press-button scene has 2 panels, got {len(self.panels)}")
        if not 0 < self.success_depth_m <= self.travel_m:
            raise ValueError(
                f"success_depth_m must be in (0, travel_m={self.travel_m}], "
                f"got {self.success_depth_m}"
            )
        if self.cap_length_m <= self.protrusion_m:
            raise ValueError(
                "cap_length_m must exceed protrusion_m (the cap must reach into the plate)"
            )
        if self.travel_m > self.protrusion_m:
            raise ValueError("travel_m must not exceed protrusion_m (a pressed cap ends flush)")


def build_button_panel(
    scene: Any, spec: ButtonPanelSpec, layout: PressButtonLayout
) -> Articulation:
    """Build ``spec`` as an articulation: fixed plate + 3 prismatic, spring-driven button links."""
    builder = scene.create_articulation_builder()
    plate = builder.create_link_builder()
    plate.set_name("plate")
    half = [s / 2 for s in spec.plate_size_m]
    plate_pose = sapien.Pose(p=[0.0, 0.0, half[2]])
    plate.add_box_collision(pose=plate_pose, half_size=half)
    plate.add_box_visual(
        pose=plate_pose,
        half_size=half,
        material=sapien.render.RenderMaterial(base_color=list(spec.plate_color)),
    )
    bezel = sapien.render.RenderMaterial(base_color=[0.05, 0.05, 0.05, 1.0])
    for i, ((bx, by), color) in enumerate(zip(spec.button_xy_m, spec.button_colors, strict=True)):
        plate.add_cylinder_visual(
            pose=sapien.Pose(p=[bx, by, spec.top_z_m + 0.001], q=_X_TO_Z),
            radius=layout.bezel_radius_m,
            half_length=0.001,
            material=bezel,
        )
        button = builder.create_link_builder(plate)
        button.set_name(f"button_{i}")
        cap_pose = sapien.Pose(
            p=[0.0, 0.0, layout.protrusion_m - layout.cap_length_m / 2], q=_X_TO_Z
        )
        button.add_cylinder_collision(
            pose=cap_pose, radius=layout.button_radius_m, half_length=layout.cap_length_m / 2
        )
        button.add_cylinder_visual(
            pose=cap_pose,
            radius=layout.button_radius_m,
            half_length=layout.cap_length_m / 2,
            material=sapien.render.RenderMaterial(base_color=list(color)),
        )
        button.set_joint_name(f"button_{i}_joint")
        button.set_joint_properties(
            type="prismatic",
            limits=[[-layout.travel_m, 0.0]],
            pose_in_parent=sapien.Pose(p=[bx, by, spec.top_z_m], q=_X_TO_Z),
            pose_in_child=sapien.Pose(q=_X_TO_Z),
            friction=layout.joint_friction,
            damping=layout.spring_damping_n_s_m,
        )
    builder.initial_pose = sapien.Pose(p=[*spec.center_xy_m, 0.0])
    panel = builder.build(name=spec.name, fix_root_link=True)
    for joint in panel.active_joints:
        joint.set_drive_properties(
            stiffness=layout.spring_stiffness_n_m, damping=layout.spring_damping_n_s_m
        )
    return panel


@register_env("AWDA-PressButton-v1", max_episode_steps=200)
class PressButtonEnv(AwdaTaskEnv):
    """
    **Task Description:**
    Press one of six buttons. Two button panels stand on the table: panel 0 (dark plate) with a row
    of red, green and blue buttons, panel 1 (cream plate, lower) with a triangle of yellow, magenta
    and cyan buttons. Every button is a spring-loaded cap on a vertical prismatic joint that pops
    back up when released. ``reset(options={"task": v})`` selects panel ``v // 3`` and its button
    ``v % 3``; the gripper, pointing down, presses the cap from above.

    **Randomizations:**
    - each panel's centre is drawn uniformly within ``spawn_jitter_m`` of its nominal place
    - each panel's yaw is drawn uniformly in ``+- yaw_jitter_rad``
    - all buttons start at rest (not pressed); the robot starts at its rest keyframe

    **Success Conditions:**
    - the target button is pressed at least ``success_depth_m`` (1.5 cm of its 2 cm travel);
      ``success_once`` latches it (a released button pops back, so "success at end" is false
      once the gripper lets go)
    """

    family: ClassVar[str] = "press_button"
    num_variations: ClassVar[int] = 6
    has_grasp_target: ClassVar[bool] = False

    def __init__(self, *args: Any, layout: PressButtonLayout | None = None, **kwargs: Any) -> None:
        self.layout = layout or PressButtonLayout()
        super().__init__(*args, **kwargs)

    # ------------------------------------------------------------------ scene
    def _load_task_scene(self, options: dict) -> None:
        lay = self.layout
        self.panels = [build_button_panel(self.scene, spec, lay) for spec in lay.panels]
        self.buttons: list[Link] = [
            panel.links_map[f"button_{b}"] for panel in self.panels for b in range(3)
        ]
        """The six button links, indexed by variation."""
        self._set_springs()

    def _set_springs(self) -> None:
        target = torch.full((self.num_envs, 3), self.layout.spring_preload_m, device=self.device)
        for panel in self.panels:
            panel.set_joint_drive_targets(target, joints=panel.active_joints)

    def _initialize_task(self, env_idx: torch.Tensor, variation: torch.Tensor) -> None:
        lay = self.layout
        b = len(env_idx)
        for panel, spec in zip(self.panels, lay.panels, strict=True):
            jitter = torch.tensor(lay.spawn_jitter_m)
            xy = torch.tensor(spec.center_xy_m) + (torch.rand((b, 2)) * 2 - 1) * jitter
            yaw = (torch.rand(b) * 2 - 1) * lay.yaw_jitter_rad
            p = torch.zeros((b, 3))
            p[:, :2] = xy
            q = torch.zeros((b, 4))
            q[:, 0] = torch.cos(yaw / 2)
            q[:, 3] = torch.sin(yaw / 2)
            panel.set_pose(Pose.create_from_pq(p, q))
            panel.set_qpos(torch.zeros((b, 3)))
            panel.set_qvel(torch.zeros((b, 3)))
        self._set_springs()

    # ------------------------------------------------------------------ task state
    @property
    def target_panel(self) -> torch.Tensor:
        """(n,) panel index (0, 1) of each env's task."""
        return self.task // 3

    @property
    def target_button(self) -> torch.Tensor:
        """(n,) button index on its panel (0-2) of each env's task."""
        return self.task % 3

    def button_qpos(self) -> torch.Tensor:
        """(n, 6) joint positions of all six buttons [m] (0 at rest, negative when pressed)."""
        return torch.cat([panel.get_qpos() for panel in self.panels], dim=1)

    def button_qvel(self) -> torch.Tensor:
        """(n, 6) joint velocities of all six buttons [m/s] (negative when moving down)."""
        return torch.cat([panel.get_qvel() for panel in self.panels], dim=1)

    def _target_column(self, values: torch.Tensor) -> torch.Tensor:
        return values[torch.arange(self.num_envs, device=self.device), self.task]

    def target_depth_m(self) -> torch.Tensor:
        """(n,) how deep the target button is pressed [m] (0 at rest, ``travel_m`` on the stop)."""
        return -self._target_column(self.button_qpos())

    def button_cap_top(self) -> torch.Tensor:
        """(n, 6, 3) centre of each button's cap top face in the world [m] (moves when pressed)."""
        pos = torch.stack([link.pose.p for link in self.buttons], dim=1)
        return pos + torch.tensor([0.0, 0.0, self.layout.protrusion_m], device=self.device)

    def target_cap_top(self) -> torch.Tensor:
        """(n, 3) the target button's cap top centre [m] (reads only the targets' link poses)."""
        out = torch.zeros((self.num_envs, 3), device=self.device)
        for v in torch.unique(self.task).tolist():
            out = torch.where((self.task == v)[:, None], self.buttons[v].pose.p, out)
        return out + torch.tensor([0.0, 0.0, self.layout.protrusion_m], device=self.device)

    def target_rest_cap_top(self) -> torch.Tensor:
        """(n, 3) where the target's cap top is when the button is not pressed [m]."""
        top = self.target_cap_top().clone()
        top[:, 2] += self.target_depth_m()
        return top

    def finger_force_on_target(self) -> torch.Tensor:
        """(n,) magnitude of the summed contact force of the two fingers on the target button [N].

        Both embodiments are Panda hands (``finger1_link``/``finger2_link``)."""
        out = torch.zeros(self.num_envs, device=self.device)
        for v in torch.unique(self.task).tolist():
            force = sum(
                self.scene.get_pairwise_contact_forces(finger, self.buttons[v])
                for finger in (self.agent.finger1_link, self.agent.finger2_link)
            )
            out = torch.where(self.task == v, torch.linalg.norm(force, dim=1), out)
        return out

    def is_pressing_target(self) -> torch.Tensor:
        """(n,) simulator truth "press": the fingers push the target button while it is moving down
        or held down (depth >= ``press_min_depth_m``, finger force >= ``press_min_force_n``, not
        rising faster than ``press_max_rise_m_s`` unless held on the lower stop)."""
        lay = self.layout
        depth = self.target_depth_m()
        rising = self._target_column(self.button_qvel())
        on_stop = depth >= lay.travel_m - lay.press_stop_band_m
        return (
            (depth >= lay.press_min_depth_m)
            & ((rising <= lay.press_max_rise_m_s) | on_stop)
            & (self.finger_force_on_target() >= lay.press_min_force_n)
        )

    def truth_signals(self) -> dict[str, torch.Tensor]:
        return {**super().truth_signals(), "press": self.is_pressing_target()}

    def _evaluate_task(self) -> dict[str, torch.Tensor]:
        depth = self.target_depth_m()
        return {"success": depth >= self.layout.success_depth_m, "button_depth_m": depth}

    def _get_obs_extra(self, info: dict) -> dict:
        obs = super()._get_obs_extra(info)
        if "state" in self.obs_mode:
            obs.update(
                button_qpos=self.button_qpos(),
                target_cap_top=self.target_cap_top(),
            )
        return obs


__all__ = ["ButtonPanelSpec", "PressButtonEnv", "PressButtonLayout", "build_button_panel"]

"""``CabinetTaskEnv``: what the door and drawer tasks share -- open or close one part (a hinged
door, a drawer) of the cabinets in front of the robot, by grasping its handle or pushing it.

A subclass builds ``cabinets`` (articulations whose joint positions, concatenated, are the parts'
openings in part-index order), names the part links, measures the two fingers' contact on the
target part (:meth:`CabinetTaskEnv._target_contacts`), locates the target handle, gives its
success thresholds and the names its openings go by in ``evaluate()`` and the state observation.
The variation is ``2 * part + action`` (action 0 = open, 1 = close).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import torch
from mani_skill.utils.structs.articulation import Articulation
from mani_skill.utils.structs.link import Link

from awda_bench.envs.articulated import hand_holds
from awda_bench.envs.task_base import AwdaTaskEnv
from awda_bench.robot.controller import gripper_commanded_closed


class CabinetTaskEnv(AwdaTaskEnv):
    """Base of the door and drawer tasks (see the module docstring)."""

    has_grasp_target: ClassVar[bool] = False
    third_person_eye_m: ClassVar[tuple[float, float, float]] = (-0.46, 0.0, 0.44)
    """In front of the cabinets, under the arm's upper links, looking at their fronts (they face
    the robot, so the pick-place camera at +x would see their backs)."""
    third_person_target_m: ClassVar[tuple[float, float, float]] = (0.10, 0.0, 0.12)
    third_person_fov_rad: ClassVar[float] = 1.25

    openings_key: ClassVar[str]
    """Name of every part's opening in the state observation (``door_angles``, ...)."""
    opening_key: ClassVar[str]
    """Name of the target part's opening in :meth:`evaluate`'s dict (``door_angle_rad``, ...)."""

    cabinets: list[Articulation]
    """The cabinets, in part-index order of their joints."""

    # ------------------------------------------------------------------ hooks for subclasses
    def _part_links(self) -> Sequence[Link]:
        """The parts' links in part-index order (what a grasp or a push is tested on)."""
        raise NotImplementedError

    def _target_contacts(self) -> torch.Tensor:
        """(n, 2) contact force magnitudes [N] of the two fingers on each env's target part."""
        raise NotImplementedError

    def _success_thresholds(self) -> tuple[float, float]:
        """Open: success at an opening of at least the first; close: at most the second."""
        raise NotImplementedError

    def handle_position(self) -> torch.Tensor:
        """(n, 3) each env's target handle now [m]."""
        raise NotImplementedError

    # ------------------------------------------------------------------ task state
    @property
    def target_part(self) -> torch.Tensor:
        """(n,) index of each env's target part."""
        return self.task // 2

    @property
    def wants_open(self) -> torch.Tensor:
        """(n,) True where the variation asks to open the part (False: close it)."""
        return (self.task % 2) == 0

    def part_openings(self) -> torch.Tensor:
        """(n, parts) opening of every part (joint position; 0 = shut), part-index order."""
        return torch.cat([c.get_qpos() for c in self.cabinets], dim=1)

    def target_opening(self) -> torch.Tensor:
        """(n,) opening of each env's target part."""
        rows = torch.arange(self.num_envs, device=self.device)
        return self.part_openings()[rows, self.target_part]

    # ------------------------------------------------------------------ truths
    def is_grasping_target(self) -> torch.Tensor:
        """(n,) the hand holds the target part's handle (:func:`~.articulated.hand_holds`: both
        fingers on it, or the closed hand dragging it along its path)."""
        both = self._is_grasping_per_env(self._part_links(), self.target_part)
        contacts = self._target_contacts()
        opening = self.agent.gripper_opening_m.reshape(-1)
        closed = gripper_commanded_closed(self.agent)
        return hand_holds(both, contacts, opening, closed)

    def is_pushing_target(
        self, min_force_n: float = 0.05, grasping: torch.Tensor | None = None
    ) -> torch.Tensor:
        """(n,) a finger presses on the target part with >= ``min_force_n`` [N], no grasp (the
        passive, damped joint resists a steady push with only a few tenths of a newton).
        ``grasping``: :meth:`is_grasping_target` if the caller has it already."""
        force = self._target_contacts().max(dim=1).values
        return (force >= min_force_n) & ~(
            self.is_grasping_target() if grasping is None else grasping
        )

    def truth_signals(self) -> dict[str, torch.Tensor]:
        """``grasp`` (scored against the mined grasp attribute) and ``push`` (a finger on the
        part without a grasp: the part being pushed shut, which moves -- not the pressing
        attribute, commanded motion that does not move, so it is not scored as "press")."""
        grasp = self.is_grasping_target()  # contact queries once per step, not twice
        return {"grasp": grasp, "push": self.is_pushing_target(grasping=grasp)}

    # ------------------------------------------------------------------ evaluation
    def _evaluate_task(self) -> dict[str, torch.Tensor]:
        opening = self.target_opening()
        open_success, close_success = self._success_thresholds()
        opened = opening >= open_success
        closed = opening <= close_success
        return {"success": torch.where(self.wants_open, opened, closed), self.opening_key: opening}

    def _get_obs_extra(self, info: dict) -> dict:
        obs = super()._get_obs_extra(info)
        if "state" in self.obs_mode:
            obs.update(
                {self.openings_key: self.part_openings(), "handle_pos": self.handle_position()}
            )
        return obs

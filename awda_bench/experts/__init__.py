"""Scripted experts (privileged state, 4-D actions): the ``scripted`` method, the demonstrators."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from awda_bench.episode import EpisodeContext, Policy
from awda_bench.errors import UnknownChoiceError
from awda_bench.experts.basketball import BasketballExpert
from awda_bench.experts.door import DoorExpert
from awda_bench.experts.drawer import DrawerExpert
from awda_bench.experts.nut_assembly import NutAssemblyExpert
from awda_bench.experts.pick_place import PickPlaceExpert, PickPlaceExpertConfig
from awda_bench.experts.press_button import PressButtonExpert
from awda_bench.experts.stack_block import StackBlockExpert

EMBODIMENT_NAMES = ("agent", "demonstrator")
"""Who the expert drives: the evaluated Panda agent or the demonstrator embodiment."""

EXPERT_SUITES = ("pick_place", "mosaic")
"""Suites that have a scripted expert."""

FAMILY_EXPERTS: dict[str, Callable[[], Policy]] = {
    "pick_place": lambda: PickPlaceExpert(PickPlaceExpertConfig(), name="scripted"),
    "press_button": lambda: PressButtonExpert(name="scripted"),
    "stack_block": lambda: StackBlockExpert(name="scripted"),
    "basketball": lambda: BasketballExpert(name="scripted"),
    "nut_assembly": lambda: NutAssemblyExpert(name="scripted"),
    "door": lambda: DoorExpert(name="scripted"),
    "drawer": lambda: DrawerExpert(name="scripted"),
}
"""Expert factory per task family (the env class's ``family`` attribute); one line per family."""


class FamilyExpert:
    """Picks the expert of the env's task family at each reset (suites mixing families)."""

    name = "scripted"

    def __init__(self) -> None:
        self._experts: dict[str, Policy] = {}
        self._current: Policy | None = None

    def reset(self, ctx: EpisodeContext) -> None:
        family = getattr(ctx.env, "family", "") or "pick_place"
        if family not in FAMILY_EXPERTS:
            raise UnknownChoiceError("task family with a scripted expert", family, FAMILY_EXPERTS)
        if family not in self._experts:
            self._experts[family] = FAMILY_EXPERTS[family]()
        self._current = self._experts[family]
        self._current.reset(ctx)

    def act(self, obs: Any) -> np.ndarray:
        if self._current is None:
            raise RuntimeError("FamilyExpert.act() before reset(ctx)")
        return self._current.act(obs)

    @property
    def done(self) -> bool:
        return self._current is not None and bool(self._current.done)

    @property
    def waypoints(self) -> np.ndarray | None:
        return None


def make_expert(suite: str, embodiment: str = "agent") -> Policy:
    """A fresh scripted expert for ``suite`` driving ``embodiment`` (agent or demonstrator).

    Both embodiments carry a Panda hand, so they share the grasp settings; the step size and grip
    sign come from the env the expert is reset in.
    """
    if embodiment not in EMBODIMENT_NAMES:
        raise UnknownChoiceError("embodiment", embodiment, EMBODIMENT_NAMES)
    if suite == "pick_place":
        return PickPlaceExpert(PickPlaceExpertConfig(), name="scripted")
    if suite in EXPERT_SUITES:
        return FamilyExpert()
    raise UnknownChoiceError("suite with a scripted expert", suite, EXPERT_SUITES)


__all__ = [
    "EMBODIMENT_NAMES",
    "FAMILY_EXPERTS",
    "FamilyExpert",
    "PickPlaceExpert",
    "PickPlaceExpertConfig",
    "make_expert",
]

"""Scripted experts (privileged state, 4-D actions): the ``scripted`` method, the demonstrators."""

from __future__ import annotations

from awda_bench.errors import UnknownChoiceError
from awda_bench.experts.pick_place import PickPlaceExpert, PickPlaceExpertConfig
from awda_bench.policies.base import Policy

EMBODIMENT_NAMES = ("agent", "demonstrator")
"""Who the expert drives: the evaluated Panda agent or the demonstrator embodiment."""

EXPERT_SUITES = ("pick_place",)
"""Suites that have a scripted expert."""


def make_expert(suite: str, embodiment: str = "agent") -> Policy:
    """A fresh scripted expert for ``suite`` driving ``embodiment`` (agent or demonstrator).

    Both embodiments carry a Panda hand, so they share the grasp settings; the step size and grip
    sign come from the env the expert is reset in.
    """
    if embodiment not in EMBODIMENT_NAMES:
        raise UnknownChoiceError("embodiment", embodiment, EMBODIMENT_NAMES)
    if suite == "pick_place":
        return PickPlaceExpert(PickPlaceExpertConfig(), name="scripted")
    raise UnknownChoiceError("suite with a scripted expert", suite, EXPERT_SUITES)


__all__ = ["EMBODIMENT_NAMES", "PickPlaceExpert", "PickPlaceExpertConfig", "make_expert"]

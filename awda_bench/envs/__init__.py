"""ManiSkill tasks of the benchmark, and the empty-table scene (``AWDA-EmptyTable-v1``) that
controller checks and benchmarks use; importing this package registers them with gymnasium.

Importing it also registers the robots the tasks accept: the demonstrator
(:mod:`awda_bench.robot.demonstrator`, whose import runs ``awda_bench.robot``'s own registration of
the ``panda_awda`` agent).
"""

# importing a task module registers its env with gymnasium
from awda_bench.envs import (  # noqa: F401
    basketball,
    door,
    drawer,
    empty_table,
    nut_assembly,
    press_button,
    stack_block,
)
from awda_bench.envs.pick_place import PickPlaceEnv, PickPlaceLayout
from awda_bench.robot import demonstrator as _demonstrator  # noqa: F401  (registers robots)

__all__ = ["PickPlaceEnv", "PickPlaceLayout"]

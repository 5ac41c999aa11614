"""ManiSkill tasks of the benchmark; importing this package registers them with gymnasium.

Importing it also registers the robots the tasks accept: the demonstrator
(:mod:`awda_bench.robot.demonstrator`, whose import runs ``awda_bench.robot``'s own registration of
the ``panda_awda`` agent).
"""

from awda_bench.envs import press_button, stack_block  # noqa: F401  (register their envs)
from awda_bench.envs import basketball, nut_assembly  # noqa: F401  (register their envs)
from awda_bench.envs import door, drawer  # noqa: F401  (register their envs)
from awda_bench.envs.pick_place import PickPlaceEnv, PickPlaceLayout
from awda_bench.robot import demonstrator as _demonstrator  # noqa: F401  (registers robots)

__all__ = ["PickPlaceEnv", "PickPlaceLayout"]

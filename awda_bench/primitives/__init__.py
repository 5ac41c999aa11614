"""Motor primitives (free-space, carry, drop, grasp), wrist-depth localization and the
attributed-waypoint executor (SPEC §4, supplementary S1).

Every primitive acts only through the 4-D action space ``(dx, dy, dz, grip)`` in [-1, 1] and works
on one env at a time (no batch dimension); batched policies run one executor per env.
"""

from awda_bench.primitives.carry import Carry
from awda_bench.primitives.config import (
    DropConfig,
    ExecutorConfig,
    FreeSpaceConfig,
    GraspConfig,
    LocalizationConfig,
)
from awda_bench.primitives.drop import Drop
from awda_bench.primitives.executor import WaypointExecutor
from awda_bench.primitives.free_space import FreeSpace
from awda_bench.primitives.grasp import Grasp
from awda_bench.primitives.localization import Localization, localize_object

__all__ = [
    "Carry",
    "Drop",
    "DropConfig",
    "ExecutorConfig",
    "FreeSpace",
    "FreeSpaceConfig",
    "Grasp",
    "GraspConfig",
    "Localization",
    "LocalizationConfig",
    "WaypointExecutor",
    "localize_object",
]

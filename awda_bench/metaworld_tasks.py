"""Meta-World's task names and ML45's split, as the ``metaworld`` 3.1.1 package defines them
(``metaworld.env_dict.ALL_V3_ENVIRONMENTS`` and ``ML45_V3``; a test in ``.venv-metaworld`` checks
these against the package). Plain data, outside :mod:`awda_bench.metaworld`, so the main
environment checks a suite file without importing ``metaworld`` or that package."""

from __future__ import annotations

from awda_bench.errors import UnknownChoiceError
from awda_bench.suites import Suite

ALL_TASKS: tuple[str, ...] = (
    "assembly-v3",
    "basketball-v3",
    "bin-picking-v3",
    "box-close-v3",
    "button-press-topdown-v3",
    "button-press-topdown-wall-v3",
    "button-press-v3",
    "button-press-wall-v3",
    "coffee-button-v3",
    "coffee-pull-v3",
    "coffee-push-v3",
    "dial-turn-v3",
    "disassemble-v3",
    "door-close-v3",
    "door-lock-v3",
    "door-open-v3",
    "door-unlock-v3",
    "hand-insert-v3",
    "drawer-close-v3",
    "drawer-open-v3",
    "faucet-open-v3",
    "faucet-close-v3",
    "hammer-v3",
    "handle-press-side-v3",
    "handle-press-v3",
    "handle-pull-side-v3",
    "handle-pull-v3",
    "lever-pull-v3",
    "pick-place-wall-v3",
    "pick-out-of-hole-v3",
    "pick-place-v3",
    "plate-slide-v3",
    "plate-slide-side-v3",
    "plate-slide-back-v3",
    "plate-slide-back-side-v3",
    "peg-insert-side-v3",
    "peg-unplug-side-v3",
    "soccer-v3",
    "stick-push-v3",
    "stick-pull-v3",
    "push-v3",
    "push-wall-v3",
    "push-back-v3",
    "reach-v3",
    "reach-wall-v3",
    "shelf-place-v3",
    "sweep-into-v3",
    "sweep-v3",
    "window-open-v3",
    "window-close-v3",
)
"""The 50 tasks, in the package's order."""

ML45_TEST: tuple[str, ...] = (
    "bin-picking-v3",
    "box-close-v3",
    "hand-insert-v3",
    "door-lock-v3",
    "door-unlock-v3",
)
"""ML45's own test tasks (the ``metaworld_ml45`` suite holds these out)."""

REFERENCE_HELD_OUT: tuple[str, ...] = (
    "sweep-into-v3",
    "window-open-v3",
    "button-press-v3",
    "door-unlock-v3",
    "pick-place-wall-v3",
)
"""The AWDA reference's held-out five (the ``metaworld`` suite holds these out)."""


def check_task_names(suite: Suite) -> None:
    """Every task of a Meta-World suite names a Meta-World task (one line listing them if not)."""
    for task in suite.tasks:
        if task.name not in ALL_TASKS:
            raise UnknownChoiceError(
                f"Meta-World task (suite {suite.name!r}, task {task.index})", task.name, ALL_TASKS
            )

"""One Meta-World task's env and its seeded layouts.

``reset(seed=...)`` is ignored by Meta-World's envs; a task's layout (object and goal positions,
``rand_vec``) is drawn at reset from the env's own generator when ``_freeze_rand_vec`` is off and
``seeded_rand_vec`` on (the private flags ``metaworld.MT1``'s task sampling uses). So a layout is
``env.seed(seed)`` then ``env.reset()``: the same seed gives the same layout, bit for bit, in any
process and after any earlier episode of the env (MuJoCo's reset clears the whole simulation
state).

The goal stays in the observation (``partially_observable = False``, MT1's setting): the
package's scripted policies read it there; observation-only methods never see that vector.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from metaworld.env_dict import ALL_V3_ENVIRONMENTS, ML1_ARGS_KWARGS

from awda_bench.errors import UnknownChoiceError


def make_task_env(name: str) -> Any:
    """A ``SawyerXYZEnv`` of task ``name`` (``"sweep-into-v3"``) ready for seeded layouts; it
    renders nothing itself (frames come from :mod:`awda_bench.metaworld.renderer`)."""
    if name not in ALL_V3_ENVIRONMENTS:
        raise UnknownChoiceError("Meta-World task", name, list(ALL_V3_ENVIRONMENTS))
    env = ALL_V3_ENVIRONMENTS[name]()
    kwargs = {k: v for k, v in ML1_ARGS_KWARGS[name]["kwargs"].items() if k != "task_id"}
    env._set_task_inner(**kwargs)
    env._partially_observable = False
    env.__dict__.pop("sawyer_observation_space", None)  # recomputed with the goal's bounds
    env._set_task_called = True
    env._freeze_rand_vec = False
    env.seeded_rand_vec = True
    return env


def reset_to_layout(env: Any, seed: int) -> np.ndarray:
    """Reset ``env`` to the layout of ``seed``; the first observation (39 numbers: hand, gripper,
    objects, the previous frame of those, goal).

    The goal markers (sites) are put where the goal is, as every ``step`` does: after Meta-World's
    own reset they stand elsewhere until the first step (pick-place-wall's by up to ~10 cm), so the
    first frame would show the goal where it is not. Rendering only: physics and observations
    never read the sites' world positions."""
    env.seed(int(seed))
    obs, _info = env.reset()
    for site in env._target_site_config:
        env._set_pos_site(*site)
    return np.asarray(obs, dtype=np.float64)

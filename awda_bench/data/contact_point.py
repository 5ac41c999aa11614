"""Where the hand first moves the task's object: the identification label of an episode that
never grasps (a push: button-press, door-unlock, window-open).

The ``demo-pointer`` head's identification loss (:mod:`awda_bench.models.identification_loss`)
tells the head, per sample, which cell of o_1 holds what the demo acts on. Its label was the
first grasping point, so on Meta-World's pushes (no grasp) nothing told the head where the
button or the handle is: their waypoints stayed 12-15 cm from the truth on held-out pairs
(``reports/learned/recipe-study-metaworld.md``). This label is the TCP at the first state where
the scene's non-robot joints (the object's, from the recorded ``env_states/qpos``) leave where
they rested::

    rest     = q_obj[settle_steps]                 (objects dropped into the scene settle first)
    contact  = first t > settle_steps with max_j |q_obj[t, j] - rest_j| > threshold
    label    = tcp[contact]

Measured on the 45 training tasks' agent episodes of ``runs/rp-mw20`` (20 per task): with
``settle_steps = 8`` and ``threshold = 0.01`` (m for slides and free joints, rad for hinges)
every task with an object fires; where the episode also grasps, the contact point lies
0.0-1.1 cm from the first grasping point on the pick/push tasks (pick-place 0.3 cm, push 0.8,
sweep 0.7, basketball 0.8); buttons fire at their press (button-press-topdown: state 59 of 72).
Scenes whose objects move by themselves past ``settle_steps`` (door-close's door, coffee's mug,
box-close's lid: first motion at state 9) fire at once; a label at ``settle_steps + 1`` is
therefore refused (``None``), as is an episode whose objects never move (reach).

A deviation from the reference (which has no identification loss at all), stated where it is
switched on: ``DataRecipe.identification_contact`` and the recipe files. It reads simulator
joint state recorded with the episode, unlike the grasp label (mined from the TCP and the
gripper); only training reads it, never a policy.
"""

from __future__ import annotations

import numpy as np

SETTLE_STEPS = 8
"""States the scene's objects are given to come to rest before motion counts."""
MOTION_THRESHOLD = 0.01
"""Departure from rest that counts as motion (m for slide and free joints, rad for hinges)."""


def first_object_motion(
    object_qpos: np.ndarray,
    settle_steps: int = SETTLE_STEPS,
    threshold: float = MOTION_THRESHOLD,
) -> int | None:
    """``object_qpos (T + 1, n)``: the non-robot joint positions of an episode -> the first state
    index at which they leave their rest (module docstring), or ``None``: no object joints, too
    short an episode, no motion, or motion right after settling (an object moving by itself)."""
    q = np.asarray(object_qpos, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] == 0 or len(q) <= settle_steps + 1:
        return None
    departure = np.abs(q[settle_steps + 1 :] - q[settle_steps]).max(axis=1)
    moving = np.flatnonzero(departure > threshold)
    if len(moving) == 0 or moving[0] == 0:
        return None
    return int(moving[0]) + settle_steps + 1

"""A Meta-World demonstration: the package's scripted policy (the Sawyer, as the agent) doing the
task in another layout, as the frames a one-shot policy watches.

Played twice in the given env, which layouts and physics make exact: once without frames to find
its length (to the first success, or the horizon), once rendering only the frames wanted::

    t:      0 ............................................. T (first success)
    frames: ^ first        ^            ^            ^      ^ last   (count, evenly spaced)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from awda_bench.metaworld.expert import scripted_chooser
from awda_bench.metaworld.layout import reset_to_layout
from awda_bench.rollout import roll_out


def first_success_step(env: Any, task_name: str, seed: int, horizon: int) -> int:
    """The step (1-based) of the expert's first success in layout ``seed``; 0 if none comes
    within ``horizon`` steps."""
    end = roll_out(
        env.step,
        reset_to_layout(env, seed),
        scripted_chooser(task_name),
        horizon,
        after_step=lambda _t, _action, info: bool(info.get("success", 0.0)),
    )
    return end.steps if end.info.get("success", 0.0) else 0


def demo_length(env: Any, task_name: str, seed: int, horizon: int) -> int:
    """Steps until the expert's first success in layout ``seed`` (``horizon`` if none)."""
    return first_success_step(env, task_name, seed, horizon) or horizon


def demo_frames(
    env: Any,
    task_name: str,
    seed: int,
    *,
    count: int,
    horizon: int,
    render: Callable[[], np.ndarray],
) -> np.ndarray:
    """``(count, H, W, 3)`` frames of the expert in layout ``seed``, ``render()`` capturing
    ``env``'s scene now. ``env`` is left in the demo's last state: reset it afterwards."""
    length = demo_length(env, task_name, seed, horizon)
    steps = np.linspace(0, length, count).round().astype(int)
    rendered: dict[int, np.ndarray] = {}

    def render_wanted(t: int) -> None:
        if t in steps:
            rendered[t] = render()

    roll_out(
        env.step,
        reset_to_layout(env, seed),
        scripted_chooser(task_name),
        length,
        before_step=render_wanted,
    )
    render_wanted(length)
    return np.stack([rendered[int(t)] for t in steps])

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

from awda_bench.metaworld.expert import expert_action, task_policy
from awda_bench.metaworld.layout import reset_to_layout


def demo_length(env: Any, task_name: str, seed: int, horizon: int) -> int:
    """Steps until the expert's first success in layout ``seed`` (``horizon`` if none)."""
    obs = reset_to_layout(env, seed)
    policy = task_policy(task_name)
    for t in range(1, horizon + 1):
        obs, _reward, _terminated, _truncated, info = env.step(expert_action(policy, obs)[0])
        if info.get("success", 0.0):
            return t
    return horizon


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
    obs = reset_to_layout(env, seed)
    policy = task_policy(task_name)
    for t in range(length + 1):
        if t in steps:
            rendered[t] = render()
        if t < length:
            obs, *_ = env.step(expert_action(policy, obs)[0])
    return np.stack([rendered[int(t)] for t in steps])

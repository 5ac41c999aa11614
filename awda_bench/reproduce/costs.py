"""The per-unit wall times behind ``reproduce``'s printed plan, and how a duration is printed."""

from __future__ import annotations

from dataclasses import dataclass, field, replace


@dataclass(frozen=True)
class Costs:
    """Per-unit wall times [s] for the printed estimate (2-core CPU machine, idle, 2026-11)."""

    collect_episode_s: float = 1.75
    """Per kept episode with 2 workers at 240x320 (pick-place: 760 episodes in 1314 s on an idle
    fresh machine, pick_place-small-v4; 1588-2154 s beside other work)."""
    train_step_s: dict[str, float] = field(
        default_factory=lambda: {"awda": 2.23, "tosvi": 3.16, "tosvi-depth": 4.7}
    )
    """Per step of the ``small`` recipe, 2 threads (``recipes/small.toml`` has the measurements)."""
    frozen_step_s: float = 0.3
    """Per step of a frozen-backbone recipe over cached features (``small``: median compute
    0.28 s a step on the idle machine in pick_place-small-v4 and -v7, plus ~0.01 s of data;
    0.49-0.65 s beside another job, -v5; batch 16, 2 threads)."""
    frozen_tosvi_step_s: dict[str, float] = field(
        default_factory=lambda: {"tosvi": 0.8, "tosvi-depth": 3.1}
    )
    """Per T-OSVI step over cached maps pooled 2x2 (``small``: batch 16, 2 threads), with
    ``train``'s denormal flush (:mod:`awda_bench.models.denormals`): the median compute of a real
    run's steps on the idle machine, 0.77 s + 0.01 s of data (pick-place v8, steps 1401-3000,
    2026-12-03). Without the flush a step grew with training (0.9 -> 3.1 s over v8's first 600
    steps; the 1.4 s this plan used before came from such runs). tosvi-depth (which trains its
    depth ResNet-18 over 96 wrist depth images a step): 3.05 s median compute + 0.03 s of data,
    alone on the idle machine (pick-place default collection, steps 6-121, 2026-12-05); the 1.6 s
    this plan used before was scaled from a ratio measured before the attention fix and
    undercounted it by 1.9x."""
    frozen_tosvi_one_frame_step_s: float = 0.49
    """The same for a one-frame T-OSVI (``tosvi-no-frame-stack``): 0.485 s a step (median
    compute 0.47 s), pick-place's default collection, 2026-12-04, with the test suite running at
    the lowest priority beside it for ~17 of its 24.6 minutes (so an idle figure may be lower)."""
    agent_episode_steps: float = 62.4
    """Mean steps of a kept pick-place agent episode (T-OSVI caches every agent frame; the
    20-per-task train split: 17,472 steps in 280 episodes)."""
    synthesized_episode_frames: float = 23.5
    """Frames a T-OSVI-style column that trains on the synthesized episodes (``no-waypoints``)
    adds to the pooled cache per synthesized episode (every step, as agent stacks, plus its demo
    frames): 4,701 frames for pick-place's 200, session 25."""
    encode_frame_s: float = 0.035
    """Encoding one 240x320 frame into the feature cache (pick-place's T-OSVI cache: 20,272
    frames at ~29 frames/s, pick_place-small-v6; 0.077 s beside another job)."""
    paper_step_factor: float = 32.0
    """``paper`` recipe step cost ÷ ``small``'s on a CPU (~71 s vs 2.23 s)."""
    eval_episode_s: dict[str, float] = field(
        default_factory=lambda: {"awda": 1.5, "tosvi": 16.5, "tosvi-depth": 27.5}
    )
    """Per evaluated episode and worker, 2 workers on the 2 cores (awda: open loop, one forward
    pass; tosvi: a frame and a forward pass every step for the whole horizon; measured on
    pick-place: 120 T-OSVI episodes of 180 steps at 16.5 s each per worker; tosvi-depth:
    ``bench episode-cost`` alone, 1 worker, gives 22.0 s beside tosvi's 13.2 s, scaled by the
    same 1.25 to two workers)."""


COSTS = Costs()


SUITE_COSTS: dict[str, dict[str, object]] = {
    "metaworld": {
        # 2,250 training episodes (900 + 900 + 450 synthesized) in 23.6 min with 2 workers on
        # an idle machine (sessions 39 and 43, from an empty directory): 0.63 s each (48.8 min,
        # 1.30 s, in session 32, learned/metaworld-small/)
        "collect_episode_s": 0.63,
        # small's Full-1 on 14x14 cached maps with demo heights, the frame-time loss and a
        # bfloat16 forward pass (session 45): 7.4-9.3 steps/s on 2 threads, 0.12 s a step
        "frozen_step_s": 0.12,
        # awda: 1000 episodes in 8.5 min with 2 workers on the idle machine (metaworld-small/);
        # tosvi: 500-step episodes, 26.8-28.9 s each with one worker beside another benchmark
        # (docs/metaworld.md), 33-48 s with two workers beside the test suite (session 34)
        "eval_episode_s": {"awda": 1.0, "tosvi": 30.0, "tosvi-depth": 50.0},
        # T-OSVI over 7x7 pooled maps (224x224 frames): 0.50 s a step (10th percentile; median
        # 0.71) with one thread on the shared machine, session 34's full-protocol run
        "frozen_tosvi_step_s": {"tosvi": 0.5, "tosvi-depth": 2.0},
    },
}
"""Per-suite figures that differ from pick-and-place's (the defaults above): Meta-World's frames
are smaller and its episodes longer. ``metaworld_ml45`` shares Meta-World's."""


def costs_for(suite: str) -> Costs:
    """The cost figures of ``suite`` (:data:`SUITE_COSTS` over :data:`COSTS`)."""
    found = SUITE_COSTS.get("metaworld" if suite.startswith("metaworld") else suite)
    return COSTS if found is None else replace(COSTS, **found)  # type: ignore[arg-type]


def clock(seconds: float) -> str:
    minutes = round(seconds / 60.0)
    return f"{minutes // 60} h {minutes % 60:02d} min" if minutes >= 60 else f"{minutes} min"

"""One episode's outcome, as a worker returns it and the store keeps it."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

STATUS_OK = "ok"
"""The episode ran to its end (success or failure)."""
STATUS_ERROR = "error"
"""The episode raised, hung or lost its worker; it is neither a success nor a failure."""


@dataclass(frozen=True)
class EpisodeRecord:
    """The outcome of one episode of one (method, snapshot)."""

    suite: str
    """Suite name."""
    task: int
    """Task (variation) index."""
    family: str
    """Task family (column of Table S4)."""
    episode: int
    """Episode index within the task (or family)."""
    seed: int
    """Agent scene seed."""
    demo_seed: int
    """Demonstration scene seed."""
    method: str
    """Method name."""
    snapshot: str
    """Snapshot content hash (``"builtin"`` for non-learned methods)."""
    status: str
    """:data:`STATUS_OK` or :data:`STATUS_ERROR`."""
    success_once: bool | None = None
    """``info["success"]`` was true at some step."""
    success_at_end: bool | None = None
    """``info["success"]`` was true at the last step played."""
    reached: bool | None = None
    """End-effector came within reach of the target before any grasp (``None``: not reported)."""
    grasped: bool | None = None
    """Reached, then lifted the target (``None``: env does not say)."""
    first_grip: str | None = None
    """What the gripper was first commanded closed on: one of
    :data:`~awda_bench.episode.GRIP_OUTCOMES` or ``"never"`` (``None``: the task does not tell)."""
    carry: str | None = None
    """What became of the grasped target: one of :data:`~awda_bench.evaluation.carry.CARRY_OUTCOMES`
    (``None``: never grasped, or the task carries nothing to a place)."""
    release_xy_m: float | None = None
    """Where the fingers let the target go: its horizontal distance from over its goal [m]."""
    release_dz_m: float | None = None
    """... and its height above the goal [m] (``None``: never released)."""
    place_goal: list[float] | None = None
    """Where the target had to go, world xyz at the start [m] (the env's ``place_goal``; ``None``
    on a task without one): what the predicted place waypoint is measured against."""
    steps: int = 0
    """Control steps played."""
    wall_time_s: float = 0.0
    """Wall time of reset + policy reset + steps [s]."""
    act_time_s: float = 0.0
    """Part of :attr:`wall_time_s` spent in ``policy.reset`` and ``policy.act`` [s]."""
    env_time_s: float = 0.0
    """Part of :attr:`wall_time_s` spent in ``env.reset`` and ``env.step`` [s]."""
    error: str | None = None
    """Traceback or watchdog message when ``status == "error"``."""
    waypoints: list[list[float]] | None = None
    """Attributed waypoints ``(K, 3 + k)`` the method predicted, if it predicts any."""
    server: dict[str, Any] | None = None
    """A policy served over openpi's protocol: what its server said about the episode (protocol,
    metadata, requests, ``server_timing`` mean and max per key; the policy's ``server_notes``);
    stored as JSON in the ``server`` column. ``None`` for every other policy."""
    setup_time_s: float = 0.0
    """Time spent building the policy just before this episode (a worker's first episode of a
    snapshot) [s]; not part of :attr:`wall_time_s`, not stored (throughput accounting only)."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

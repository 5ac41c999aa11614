"""Does the 4-D action do what it says? ``python -m awda_bench bench controller --fidelity``.

Measured on the pick-and-place scene (or any scene with a 4-D TCP-delta embodiment), CPU sim:

- **gain**: achieved ÷ commanded TCP displacement per step at steady state, for constant commands
  ``|a|`` in :data:`MAGNITUDES` along each axis (strokes kept inside the workspace: the stroke
  goes out and back, and only its middle steps are counted);
- **top speed**: achieved displacement per step at full scale [mm/step];
- **proportional law** ``a = clip(k (target - tcp) / max_step_m)`` for ``k`` in :data:`GAINS` over
  random reachable targets: final error after :data:`LAW_STEPS` steps and overshoot past the
  target along the approach direction (an ideal follower lands in one step at ``k = 1``;
  ``k = 2`` is the oscillation boundary);
- **drift**: TCP motion while holding still (zero command) for 100 steps;
- **wind-up**: press down on the table at full scale for 20 steps, then command up: how many
  steps until the TCP rises (> 1 mm above its lowest point).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

MAGNITUDES = (0.02, 0.05, 0.1, 0.25, 0.5, 1.0)
"""Constant command magnitudes whose gain is measured."""
GAINS = (0.25, 0.5, 1.0, 2.0)
"""Proportional-law gains ``k``."""
LAW_STEPS = 60
"""Steps the proportional law gets per target."""
START_TCP_M = np.array([-0.10, 0.0, 0.20])
"""Where each stroke starts (world frame, above the pick-place scene's source bin) [m]."""
STROKE_M = 0.16
"""Longest stroke out (and back) [m]."""


@dataclass
class FidelityReport:
    """What :func:`measure_fidelity` found."""

    gains: dict[tuple[str, float], float]
    """(axis, |a|) -> achieved ÷ commanded per step at steady state (mean of the out and back
    strokes)."""
    top_speed_mm: float
    """Achieved TCP displacement per step at full scale, worst axis [mm/step]."""
    law: dict[float, tuple[float, float, float]]
    """k -> (median final error, worst final error, worst overshoot) [mm]."""
    drift_mm: float
    """Largest TCP motion from its start while holding still 100 steps [mm]."""
    windup_steps: int
    """Steps after the up command until the TCP rose > 1 mm (-1: it never did)."""


class _Probe:
    def __init__(self, env: Any) -> None:
        self.env = env
        self.u = env.unwrapped
        self.max_step = (
            float(self.u.embodiment.max_step_m) if hasattr(self.u, "embodiment") else 0.02
        )

    def tcp(self) -> np.ndarray:
        return self.u.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)

    def step(self, delta: np.ndarray, grip: float = -1.0) -> np.ndarray:
        self.env.step(
            np.concatenate([np.asarray(delta, dtype=np.float64), [grip]]).astype(np.float32)
        )
        return self.tcp()

    def go_to(self, target: np.ndarray, steps: int = 80, tol_m: float = 2e-4) -> None:
        for _ in range(steps):
            error = target - self.tcp()
            if np.linalg.norm(error) < tol_m:
                break
            self.step(np.clip(0.5 * error / self.max_step, -1.0, 1.0))
        for _ in range(5):
            self.step(np.zeros(3))


def _stroke_gain(probe: _Probe, axis: int, magnitude: float) -> float:
    """Out and back along ``axis`` at ``magnitude``; steady-state gain over the middle steps."""
    per_step = magnitude * probe.max_step
    steps = int(np.clip(STROKE_M / per_step, 12, 40))
    warm = max(3, steps // 4)
    gains = []
    for sign in (1.0, -1.0):
        command = np.zeros(3)
        command[axis] = sign * magnitude
        positions = [probe.tcp()]
        for _ in range(steps):
            positions.append(probe.step(command))
        moved = positions[-1][axis] - positions[warm][axis]
        gains.append(sign * moved / ((steps - warm) * per_step))
        for _ in range(10):  # settle before reversing
            probe.step(np.zeros(3))
    return float(np.mean(gains))


def _law(probe: _Probe, k: float, targets: np.ndarray) -> tuple[float, float, float]:
    finals, overshoots = [], []
    for target in targets:
        probe.go_to(START_TCP_M)
        start = probe.tcp()
        direction = (target - start) / max(np.linalg.norm(target - start), 1e-9)
        overshoot = 0.0
        for _ in range(LAW_STEPS):
            tcp = probe.step(np.clip(k * (target - probe.tcp()) / probe.max_step, -1.0, 1.0))
            overshoot = max(overshoot, float((tcp - target) @ direction))
        finals.append(float(np.linalg.norm(target - probe.tcp())))
        overshoots.append(overshoot)
    return 1e3 * float(np.median(finals)), 1e3 * max(finals), 1e3 * max(overshoots)


def measure_fidelity(env: Any, targets: int = 20, seed: int = 0) -> FidelityReport:
    """Run every fidelity measurement on ``env`` (reset with ``seed``; state obs is enough)."""
    env.reset(seed=seed)
    probe = _Probe(env)
    probe.go_to(START_TCP_M)
    gains = {}
    for axis, name in enumerate("xyz"):
        for magnitude in MAGNITUDES:
            probe.go_to(START_TCP_M)
            gains[(name, magnitude)] = _stroke_gain(probe, axis, magnitude)
    top = min(gains[(name, 1.0)] for name in "xyz") * probe.max_step * 1e3

    rng = np.random.default_rng(seed)
    goals = START_TCP_M + rng.uniform([-0.12, -0.15, -0.04], [0.12, 0.15, 0.10], size=(targets, 3))
    law = {k: _law(probe, k, goals) for k in GAINS}

    probe.go_to(START_TCP_M)
    start = probe.tcp()
    drift = max(float(np.linalg.norm(probe.step(np.zeros(3)) - start)) for _ in range(100))

    # wind-up: from 4 cm above the table top, press down at full scale for 20 steps, then go up
    probe.go_to(np.array([START_TCP_M[0], START_TCP_M[1], 0.04]))
    lowest = np.inf
    for _ in range(20):
        lowest = min(lowest, probe.step(np.array([0.0, 0.0, -1.0]))[2])
    windup = -1
    for i in range(1, 21):
        z = probe.step(np.array([0.0, 0.0, 1.0]))[2]
        if z > lowest + 1e-3:
            windup = i
            break
    return FidelityReport(gains, top, law, 1e3 * drift, windup)


def format_fidelity(report: FidelityReport, env_id: str) -> str:
    lines = [
        f"controller fidelity on {env_id} (CPU sim): achieved / commanded per step, steady state"
    ]
    header = "axis " + "".join(f"{f'|a|={m:g}':>10}" for m in MAGNITUDES)
    lines.append(header)
    for name in "xyz":
        lines.append(
            f"{name:<5}" + "".join(f"{report.gains[(name, m)]:>10.3f}" for m in MAGNITUDES)
        )
    worst = min(report.gains.values()), max(report.gains.values())
    lines.append(f"gain range {worst[0]:.3f} .. {worst[1]:.3f} (goal 0.9 .. 1.1)")
    lines.append(
        f"top speed (full scale, worst axis): {report.top_speed_mm:.1f} mm/step (goal >= 15)"
    )
    lines.append(
        f"proportional law a = clip(k (target - tcp) / max_step), {LAW_STEPS} steps per target:"
    )
    lines.append(f"{'k':>6}{'final median mm':>18}{'final worst mm':>17}{'overshoot worst mm':>21}")
    for k, (median, worst_final, overshoot) in report.law.items():
        lines.append(f"{k:>6g}{median:>18.2f}{worst_final:>17.2f}{overshoot:>21.2f}")
    lines.append(f"drift holding still 100 steps: {report.drift_mm:.3f} mm (goal < 0.5)")
    windup = "never" if report.windup_steps < 0 else f"{report.windup_steps} step(s)"
    lines.append(
        f"wind-up: after 20 full-scale steps pressing on the table, TCP rises within {windup} (goal <= 2)"
    )
    return "\n".join(lines)

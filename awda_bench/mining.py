"""Attribute mining from a recorded trajectory of states and commanded actions (SPEC §5, S1-A).

Grasp attribute per control step ``t`` (``c_t``: commanded closed, ``s^g_t``: jaw opening [m])::

    g_t = c_t AND (s^g_{t+d} - s^g_t > delta)          (s^g_{t+d} := s^g_{T-1} past the end)

"commanded to close, but the jaws do not close by more than |delta| over the next d steps":
something is between the fingers. The raw sequence is smoothed by a box filter of
``smooth_steps`` taps and thresholded at 1/2 (a majority vote: isolated flips vanish, short gaps
close).

Choice of d, delta and the filter for our robot (``panda_awda``, 20 Hz control, binary gripper),
from expert rollouts in ``AWDA-PickPlace-v1`` (training tasks): on a close command the opening drops
from 0.080 m to ~0.040 m within one control step, and a free close keeps shrinking by > 0.03 m per
step until shut; once the jaws stop on an object the opening changes by <= 0.004 m per step (jaw
settling) and then by < 0.0001 m. So d = 1 step (0.05 s: the jaw motion happens within one step,
a longer look-ahead only delays the onset) and delta = -0.01 m (between the 0.004 m settling and the
0.03 m free closing, with margin to both); a 3-tap box filter removes single-step flips at the
settling step without shifting the onset or the release by more than a step.
``min_opening_m`` (an addition to the reference formula, documented as such): a jaw that is already
fully shut also "does not shrink", so steps with ``s^g_t < min_opening_m`` are not grasps (the
reference formula is ``min_opening_m = 0``; see the field for the measured margins).
Measured agreement with simulator truth: ``python -m awda_bench bench primitives --measure mining``.

Pressing attribute (commanded motion, no end-effector motion), per step ``t < T-1``::

    c = a_t[:3] * max_step_m                     commanded displacement [m]
    r = (x_{t+1} - x_t) . c / |c|                realized progress along the command [m]
    p_t = |c| >= min_command_m AND r < progress_ratio * |c|

i.e. the command asked for motion but the TCP moved less than a fraction of it along the command
(or moved backwards: "accelerates against the command"); then the same box-filter vote. Caveat: a
target clipped by the controller's workspace box also stalls the TCP and reads as pressing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from awda_bench.errors import UsageError
from awda_bench.trajectory import Trajectory


@dataclass(frozen=True)
class GraspMiningConfig:
    """Parameters of the grasp attribute (see the module docstring for how they were chosen)."""

    lookahead_steps: int = 1
    """d: control steps looked ahead (0.05 s at 20 Hz; reference: Meta-World 10, T-OSVI/BC-Z 1)."""
    delta_m: float = -0.01
    """delta [m]: the opening may shrink by at most |delta| over d steps for a grasp
    (reference: -0.05 / -0.07 in their normalized units)."""
    smooth_steps: int = 3
    """Taps of the box filter (odd); 1 disables smoothing."""
    min_opening_m: float = 0.01
    """Jaws shut tighter than this [m] hold nothing (0 = the reference formula). Measured with the
    tracking controller: the narrowest true grasp (a nut's handle) holds the jaws 12.7 mm apart;
    closed fingers pushing a button or a door are spread up to 7.4 mm by the contact, which a
    5 mm guard read as grasps (press-button grasp precision 0)."""

    def __post_init__(self) -> None:
        if self.lookahead_steps < 1:
            raise UsageError(
                f"GraspMiningConfig.lookahead_steps must be >= 1, got {self.lookahead_steps}"
            )
        if self.smooth_steps < 1 or self.smooth_steps % 2 == 0:
            raise UsageError(
                f"GraspMiningConfig.smooth_steps must be odd and >= 1, got {self.smooth_steps}"
            )
        if self.min_opening_m < 0:
            raise UsageError(
                f"GraspMiningConfig.min_opening_m must be >= 0, got {self.min_opening_m}"
            )


@dataclass(frozen=True)
class PressMiningConfig:
    """Parameters of the pressing attribute."""

    max_step_m: float = 0.02
    """TCP displacement of a unit action component [m] (the controller's step)."""
    min_command_m: float = 0.004
    """Commands shorter than this [m] (20 % of a full step) are not "commanded to move"."""
    progress_ratio: float = 0.15
    """Pressing if the TCP advanced less than this fraction of the command along it. Chosen from
    ``panda_awda`` press-button expert rollouts (20 Hz): held against a button's stop the TCP
    realizes < 0.02 of the command, the step onto the stop 0.04-0.2, free space >= 0.185 (the
    first step from standstill; >= 0.22 otherwise); 0.2 flagged some of those standstill starts.
    Re-checked with the tracking controller (free-space steps now realize ~1.0 of the command):
    precision 1.000, recall 0.95-0.96 on press-button trajectories of both embodiments
    (``bench primitives --measure mining --suite mosaic``)."""
    smooth_steps: int = 3
    """Taps of the box filter (odd); 1 disables smoothing."""

    def __post_init__(self) -> None:
        if not self.max_step_m > 0 or not self.min_command_m > 0:
            raise UsageError("PressMiningConfig.max_step_m and min_command_m must be > 0")
        if self.smooth_steps < 1 or self.smooth_steps % 2 == 0:
            raise UsageError(
                f"PressMiningConfig.smooth_steps must be odd and >= 1, got {self.smooth_steps}"
            )


def smooth_binary(raw: np.ndarray, taps: int) -> np.ndarray:
    """Box-filter a boolean sequence, threshold at 1/2 (``taps`` odd; edges padded by repetition).

    ``out_t = (1/taps) sum_{|j| <= taps//2} raw_{t+j} > 1/2``.
    """
    raw = np.asarray(raw, dtype=bool)
    if taps == 1 or raw.size == 0:
        return raw.copy()
    half = taps // 2
    padded = np.pad(raw.astype(np.float64), half, mode="edge")
    return np.convolve(padded, np.ones(taps) / taps, mode="valid") > 0.5


def grasp_raw(
    gripper_opening_m: np.ndarray, commanded_close: np.ndarray, config: GraspMiningConfig
) -> np.ndarray:
    """Unsmoothed ``g_t = c_t AND (s_{t+d} - s_t > delta) AND s_t >= min_opening_m``, shape (T,)."""
    s = np.asarray(gripper_opening_m, dtype=np.float64)
    c = np.asarray(commanded_close, dtype=bool)
    if s.shape != c.shape or s.ndim != 1:
        raise UsageError(f"opening and command must both be (T,), got {s.shape} and {c.shape}")
    T = len(s)
    ahead = s[np.minimum(np.arange(T) + config.lookahead_steps, T - 1)]
    return c & (ahead - s > config.delta_m) & (s >= config.min_opening_m)


def mine_grasp(traj: Trajectory, config: GraspMiningConfig = GraspMiningConfig()) -> np.ndarray:
    """(T,) bool grasp attribute of a trajectory (commanded close = ``actions[:, 3] > 0``)."""
    raw = grasp_raw(traj.gripper_opening_m, traj.actions[:, 3] > 0, config)
    return smooth_binary(raw, config.smooth_steps)


def press_raw(tcp_pos: np.ndarray, actions: np.ndarray, config: PressMiningConfig) -> np.ndarray:
    """Unsmoothed pressing flags (T,); the last step has no successor and is False."""
    x = np.asarray(tcp_pos, dtype=np.float64)
    a = np.asarray(actions, dtype=np.float64)
    T = len(x)
    out = np.zeros(T, dtype=bool)
    if T < 2:
        return out
    c = np.clip(a[:-1, :3], -1.0, 1.0) * config.max_step_m
    n = np.linalg.norm(c, axis=1)
    moved = x[1:] - x[:-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        progress = np.where(n > 0, np.einsum("ij,ij->i", moved, c) / np.where(n > 0, n, 1.0), 0.0)
    out[:-1] = (n >= config.min_command_m) & (progress < config.progress_ratio * n)
    return out


def mine_press(traj: Trajectory, config: PressMiningConfig = PressMiningConfig()) -> np.ndarray:
    """(T,) bool pressing attribute of a trajectory."""
    return smooth_binary(press_raw(traj.tcp_pos, traj.actions, config), config.smooth_steps)


@dataclass(frozen=True)
class PrecisionRecall:
    """Per-step agreement of a mined attribute with simulator truth."""

    true_positive: int
    false_positive: int
    false_negative: int

    @property
    def precision(self) -> float:
        """TP / (TP + FP); 1 when nothing was predicted."""
        d = self.true_positive + self.false_positive
        return 1.0 if d == 0 else self.true_positive / d

    @property
    def recall(self) -> float:
        """TP / (TP + FN); 1 when the truth is empty."""
        d = self.true_positive + self.false_negative
        return 1.0 if d == 0 else self.true_positive / d

    def __add__(self, other: PrecisionRecall) -> PrecisionRecall:
        return PrecisionRecall(
            self.true_positive + other.true_positive,
            self.false_positive + other.false_positive,
            self.false_negative + other.false_negative,
        )


def precision_recall(predicted: np.ndarray, truth: np.ndarray) -> PrecisionRecall:
    """Count per-step true/false positives and false negatives of two (T,) boolean sequences."""
    p = np.asarray(predicted, dtype=bool)
    t = np.asarray(truth, dtype=bool)
    if p.shape != t.shape:
        raise UsageError(f"predicted and truth must have one shape, got {p.shape} and {t.shape}")
    return PrecisionRecall(int((p & t).sum()), int((p & ~t).sum()), int((~p & t).sum()))

"""The TCP target every 4-D-action controller carries from step to step (agent and demonstrator).

A command ``a`` moves the *target* by exactly ``a * max_step_m``; the arm follows the target. The
target is accumulated from the previous target, not re-based on the measured TCP (re-basing
loses whatever the drives lag behind each step: measured on the first controller, a 2 cm command
moved the TCP 0.8 cm and 0.4 mm moved it not at all). Two bounds keep the target honest:

- **workspace**: the target is clipped to a box (and a horizontal reach) the robot can reach;
- **bounded lag**: what the target carries over from earlier steps is kept within ``max_lag_m``
  of the measured TCP, then this step's ``delta`` is added. In free motion the arm is within a
  few millimetres of its target at the end of a step, so nothing is clipped and the gain is
  exactly 1. When motion is blocked (pressing a button, pushing on the table, holding a door)
  the target stops ``max_lag_m + |delta|`` beyond the contact instead of winding up: a reversed
  command moves the TCP again on the next step, and the contact force follows the command
  (a small push presses gently, a full-scale push hard) instead of growing with time.

:func:`check_target_bounds` refuses a controller config whose step or box cannot work.
"""

from __future__ import annotations

import numpy as np


def advance_target(
    target: np.ndarray,
    measured: np.ndarray,
    delta: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    max_lag_m: float,
    max_reach_xy_m: float = np.inf,
) -> np.ndarray:
    """The next target(s): the previous target, kept within ``max_lag_m`` of ``measured``, plus
    ``delta``, clipped to the workspace box and horizontal reach. All arrays (..., 3) in one
    frame [m]; returns a new array."""
    lag = np.asarray(target, dtype=np.float64) - measured
    distance = np.sqrt((lag**2).sum(axis=-1, keepdims=True))
    if (distance > max_lag_m).any():
        lag = np.where(distance > max_lag_m, lag * (max_lag_m / np.maximum(distance, 1e-12)), lag)
    nxt = np.minimum(np.maximum(measured + lag + delta, low), high)
    radius = np.sqrt(nxt[..., 0] ** 2 + nxt[..., 1] ** 2)
    if (radius > max_reach_xy_m).any():
        scale = np.minimum(1.0, max_reach_xy_m / np.maximum(radius, 1e-12))
        nxt[..., :2] *= scale[..., None]
    return nxt


def check_target_bounds(
    max_step_m: float, low: tuple[float, float, float], high: tuple[float, float, float]
) -> None:
    """``ValueError`` unless a controller config's unit step is > 0 and its workspace box's
    ``low`` corner is below its ``high`` corner on every axis (both embodiments' configs)."""
    if not max_step_m > 0:
        raise ValueError(f"max_step_m must be > 0, got {max_step_m}")
    if any(lo >= hi for lo, hi in zip(low, high, strict=True)):
        raise ValueError(f"workspace_low_m {low} must be below workspace_high_m {high}")

"""The TCP target every 4-D-action controller carries from step to step (agent and demonstrator).

A command ``a`` moves the *target* by exactly ``a * max_step_m``; the arm follows the target. The
target is accumulated from the previous target, not re-based on the measured TCP (re-basing
loses whatever the drives lag behind each step: measured on the first controller, a 2 cm command
moved the TCP 0.8 cm and 0.4 mm moved it not at all). Two bounds keep the target honest:

- **workspace**: the target is clipped to a box (and a horizontal reach) the robot can reach;
- **bounded lead**: the target never gets farther than ``max_lead_m`` ahead of the measured TCP.
  When motion is blocked (pressing a button, pushing on the table, holding a door) the target
  stops ``max_lead_m`` beyond the contact instead of winding up, so a reversed command moves the
  TCP again within a step or two, and the contact force stays bounded.
"""

from __future__ import annotations

import numpy as np


def advance_target(
    target: np.ndarray,
    measured: np.ndarray,
    delta: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    max_lead_m: float,
    max_reach_xy_m: float = np.inf,
) -> np.ndarray:
    """The next target(s): ``target + delta`` clipped to the workspace and to ``max_lead_m`` from
    ``measured``. All arrays (..., 3) in one frame [m]; returns a new array."""
    nxt = np.minimum(np.maximum(target + delta, low), high)
    radius = np.sqrt(nxt[..., 0] ** 2 + nxt[..., 1] ** 2)
    if (radius > max_reach_xy_m).any():
        scale = np.minimum(1.0, max_reach_xy_m / np.maximum(radius, 1e-12))
        nxt[..., :2] *= scale[..., None]
    lead = nxt - measured
    distance = np.sqrt((lead**2).sum(axis=-1, keepdims=True))
    if (distance > max_lead_m).any():
        nxt = np.where(
            distance > max_lead_m, measured + lead * (max_lead_m / np.maximum(distance, 1e-12)), nxt
        )
    return nxt

"""Meta-World's Sawyer as the motor primitives' robot: its state, the action the primitives'
commands become, and the primitive, mining and localization parameters of this arm.

The primitives (:mod:`awda_bench.primitives`) command a TCP displacement ``a[:3] x max_step_m``
from the measured TCP and a gripper command ``a[3]`` (> 0 closes). Meta-World's action instead
moves the hand's mocap target by ``a[:3] x 1 cm`` (clipped per component), and the hand follows
the mocap through a weld constraint with a lag (the scripted experts run the mocap up to 15 cm
ahead of the hand). Executing the primitives' command as a mocap delta would let the target run
ahead the same way and every motion overshoot its waypoint by that lag. So the primitives'
command is read as a *position target* (the tracking controller of the ManiSkill agent does the
same), with a proportional lead::

    d               a[:3] * STEP_M                            (the TCP displacement asked for)
    desired mocap   m* = tcp + o + G d,   o = mocap - tcp at rest (the hand's fixed geometry)
    action          (m* - mocap) / 1 cm, scaled into [-1, 1] keeping its direction; a[3] as is

``o`` is measured at the episode's start (the hand at rest after Meta-World's reset, its
orientation fixed by the env). The mocap never leads the TCP by more than ``G`` commands, and at
rest (``d = 0``) it stands at ``tcp + o``. :data:`TRACKING_GAIN` ``G`` was measured on reach-v3
(free-space primitive from rest, 10 cm along x / 8 cm down / 1 cm along y): G = 1 never gets
within 2 mm (the weld's pull at a 1 cm lead balances the arm's damping and sag: 4.6 mm left,
more than the grasp's 4 mm descent tolerance; 10 cm along x is 19 mm short after 60 steps);
G = 2: within 2 mm after 28 / 20 / 4 steps; G = 5: 13 / 23 / 3 steps, 0.9 mm left.

A recorded expert rollout is put into the same action space by the inverse
(:func:`tracking_command`), as the ManiSkill trajectories are in their controller's: a step's
command is then the lead the expert's mocap had over the TCP, not its raw mocap increment (which
keeps commanding motion against the mocap's workspace box and reads the hand's lag behind an
accelerating mocap as "blocked": on the raw increments the pressing miner, off on Meta-World,
flagged the first 20 steps of a button-press plan, the hand's approach along the workspace's y
bound).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from awda_bench.mining import GraspMiningConfig
from awda_bench.primitives.base import RobotState
from awda_bench.primitives.config import (
    DropConfig,
    ExecutorConfig,
    FreeSpaceConfig,
    GraspConfig,
    PressConfig,
)
from awda_bench.primitives.wrist_camera import WRIST_LOCALIZATION

STEP_M = 0.01
"""Mocap displacement of a unit action component [m] (Meta-World's ``action_scale``), and the
primitives' step on this arm."""

TRACKING_GAIN = 5.0
"""``G``: the mocap target leads the TCP by ``G`` times the primitives' commanded displacement."""

GRIPPER_NORMALIZER_M = 0.1
"""Meta-World's observation divides the finger distance by this [m] (``obs[3]``, clipped to 1)."""


def robot_state(env: Any) -> RobotState:
    """TCP (midpoint of the finger pads' end-effector sites, Meta-World's ``tcp_center``) [m] and
    the distance between those sites [m] of a ``SawyerXYZEnv`` now (as the observations'
    proprioception)."""
    left = np.asarray(env.data.site("leftEndEffector").xpos, dtype=np.float64)
    right = np.asarray(env.data.site("rightEndEffector").xpos, dtype=np.float64)
    return RobotState(
        tcp_pos=0.5 * (left + right), gripper_opening_m=float(np.linalg.norm(left - right))
    )


def mocap_offset(env: Any) -> np.ndarray:
    """``o = mocap - tcp`` [m] of ``env`` now (take it with the hand at rest)."""
    return np.asarray(env.data.mocap_pos[0], dtype=np.float64) - robot_state(env).tcp_pos


def mocap_action(env: Any, action: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Meta-World's action ``(4,)`` float32 that puts the mocap where the primitives' ``action``
    (a TCP displacement in units of :data:`STEP_M`, and the gripper command) wants the TCP
    (:func:`lead_action` with ``env``'s TCP and mocap now)."""
    mocap = np.asarray(env.data.mocap_pos[0], dtype=np.float64)
    return lead_action(robot_state(env).tcp_pos, mocap, action, offset)


def lead_action(
    tcp: np.ndarray, mocap: np.ndarray, action: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """Meta-World's action ``(4,)`` float32 at TCP ``tcp`` [m] and mocap ``mocap`` [m] for the
    primitives' ``action``: the mocap moves toward ``tcp + offset + G x action[:3] x STEP_M``
    (in units of 1 cm, scaled into [-1, 1] keeping its direction); ``action[3]`` as is."""
    a = np.asarray(action, dtype=np.float64).reshape(4)
    target = np.asarray(tcp, dtype=np.float64) + offset + TRACKING_GAIN * STEP_M * a[:3]
    move = (target - np.asarray(mocap, dtype=np.float64)) / STEP_M
    move = move / max(1.0, float(np.max(np.abs(move))))
    return np.array([move[0], move[1], move[2], a[3]], dtype=np.float32)


def tracking_command(tcp: np.ndarray, mocap: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """The primitives' ``(3,)`` command that :func:`mocap_action` turns into mocap target
    ``mocap`` at TCP ``tcp`` (its inverse), scaled into [-1, 1] keeping its direction."""
    a = (np.asarray(mocap, np.float64) - offset - np.asarray(tcp, np.float64)) / (
        TRACKING_GAIN * STEP_M
    )
    return a / max(1.0, float(np.max(np.abs(a))))


SAWYER_GRASP_MINING = GraspMiningConfig(
    lookahead_steps=10, delta_m=-0.05 * GRIPPER_NORMALIZER_M, smooth_steps=3, min_opening_m=0.035
)
"""The grasp attribute on Meta-World (80 Hz): the supplementary's Meta-World values d = 10 steps
and delta = -0.05 in Meta-World's normalized finger distance (``obs[3]`` = distance / 0.1 m), i.e.
-5 mm. ``min_opening_m``: the Sawyer's fingers closed on nothing stop 29.7 mm apart (window-open
and door-unlock experts, which push with the hand closed), which the reference formula reads as
a grasp; holding the pick-place-wall puck they are 45 mm apart, the sweep-into cube 39-71 mm."""

SAWYER_LOCALIZATION = replace(WRIST_LOCALIZATION, min_depth_m=0.12)
"""Wrist-depth localization on ``gripperPOV`` (128 x 128): the ManiSkill wrist camera's settings,
with the hand masked by depth: the Sawyer's hand and fingers fill the image's depths from 2.5 to
11 cm (reach-v3, an empty table, hand open and closed; the camera sits 10 cm above the TCP), an
object at the grasp's hover point is at least 25 cm away."""

SAWYER_EXECUTOR = ExecutorConfig(
    motion=FreeSpaceConfig(
        max_step_m=STEP_M, reach_tol_m=0.002, exact_tol_m=0.001, step_budget=120
    ),
    grasp=GraspConfig(
        hover_step_budget=120,
        descent_offset_m=0.035,
        min_floor_clearance_m=0.01,
        descend_step_budget=60,
        close_steps=15,
        lift_step_budget=40,
        lift_blocked_steps=4,
        lift_min_command_m=0.2 * STEP_M,
    ),
    drop=DropConfig(open_steps=15, settle_steps=8, settled_m=0.001),
    press=PressConfig(max_step_m=STEP_M, min_command_m=0.2 * STEP_M, step_budget=120),
    push_closed=False,
)
"""The executor on the Sawyer at 80 Hz: 1 cm steps, so budgets twice the Panda's (120 steps: 1.2 m);
the fingers close from open to a grip in ~12 steps and open in ~10 (the experts' rollouts), hence
15-step close and open holds.

Grasp: the descent goes 3.5 cm below the seen top, never lower than 1 cm above the floor: on pick-
place-wall's puck (top seen at 4 cm) the floor bound holds (the expert closes with the TCP 1.2-1.6
cm above the table), on sweep-into's cube (top 9 cm, on a platform at 5 cm) the fingers close 0.5
cm under the cube's centre (2.5 cm: no difference measured, 6 seeds of each). ``lift_blocked_steps
= 4`` (the descent and lift end when blocked for this many steps): from standstill the hand
realizes 0.11 of a full-speed command on the first step and 0.27 on the second, and a descent that
starts while the hover's upward motion is still dying out read as blocked twice and closed the
fingers in the air (sweep-into, seed 5005).

Motions count as reached within 2 mm (the tracking target brings the TCP within 1 mm; at 5 mm
and 1 cm the last push of button-press stopped short of the button's travel: Meta-World's
success regions begin just where the expert's last waypoint lies).

``push_closed = False``: an episode without a grasp moves with the hand open. Closing the Sawyer's
fingers moves its TCP (the finger sites' midpoint) 5.2 mm along +y relative to the hand, so a
closed hand steered to waypoints recorded with it open stops 5 mm short of them: button-press
(whose expert pushes with the hand open) 11/20 with the hand closed (the first waypoint, at the
workspace's y bound, also became unreachable), 8/8 open (seeds 5000-5007; 5/5 on seeds that had
failed closed); window-open and door-unlock (their experts push closed) 8/8 open as well."""

"""Execute attributed waypoints with the motor primitives (reference semantics, SPEC §4).

Input: waypoints ``W`` of shape ``(N, 3 + k)``, ``k >= 1``: world position [m] plus attribute flags,
the first attribute being "object grasped", the second (when ``k >= 2``) "pressing" (> 0.5 = set).
Waypoint ``i`` is handled, in order, by::

    grasp flag | press flag | holding | action
    -----------+------------+---------+-------------------------------------------------------
    set        |            | no      | GRASP primitive (localize, hover, descend, close, lift),
               |            |         | if the episode's grasp budget (one) is left; else
               |            |         | FREE-SPACE to W[i]
    set        |            | yes     | CARRY to W[i]
    clear      | set        | no      | PRESS primitive toward W[i] (approach until blocked,
               |            |         | hold, retract); a press-attributed waypoint right after
               |            |         | a press belongs to the same press (the end of its hold)
               |            |         | and is skipped
    clear      |            | yes     | DROP in place, then FREE-SPACE to W[i]
    clear      | clear      | no      | FREE-SPACE to W[i]

Before execution, the waypoint preceding the first grasp-attributed waypoint is raised by
``pregrasp_raise_m`` (15 cm), so the approach ends above the object, where the wrist camera sees it.
Two readings of the waypoints the reference does not make (:class:`ExecutorConfig`): a grasp whose
next waypoint carries sideways (rises less than ``lift_min_rise_m``) is a *pull* -- no lift, and the
carry runs at ``pull_speed`` -- and an episode without any grasp-attributed waypoint moves with the
gripper closed (``push_closed``: it pushes).
A motion counts as reached within ``reach_tol_m`` (2 cm) or ends after its step budget. "Holding" is
the executor's belief (set by a completed grasp, cleared by a drop), not simulator truth.

Per control step the executor calls the current primitive; a primitive that has finished returns
``None`` without consuming the step and the next one starts at once.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass

import numpy as np

from awda_bench.errors import UsageError
from awda_bench.primitives.base import GRIP_CLOSE, GRIP_OPEN, Primitive, RobotState, hold_action
from awda_bench.primitives.carry import Carry
from awda_bench.primitives.config import ExecutorConfig
from awda_bench.primitives.drop import Drop
from awda_bench.primitives.free_space import FreeSpace
from awda_bench.primitives.grasp import Grasp, Locator
from awda_bench.primitives.press import Press


@dataclass
class WaypointLog:
    """What happened at one waypoint."""

    index: int
    kind: str
    """``"move"``, ``"carry"``, ``"pull"`` (a carry after a grasp without lift), ``"grasp"``,
    ``"drop+move"``, ``"press"`` or ``"press (held)"``."""
    steps: int = 0
    """Control steps spent on this waypoint."""
    reached: bool | None = None
    """Motion ended within tolerance (None for a grasp)."""


def prepare_waypoints(waypoints: np.ndarray, pregrasp_raise_m: float) -> np.ndarray:
    """Validate ``(N, 3 + k)`` waypoints and raise the one before the first grasp waypoint.

    Returns a float64 copy; the input is not modified.
    """
    W = np.array(waypoints, dtype=np.float64, copy=True)
    if W.ndim != 2 or W.shape[1] < 4 or W.shape[0] < 1:
        raise UsageError(f"waypoints must be (N >= 1, 3 + k) with k >= 1, got shape {W.shape}")
    if not np.all(np.isfinite(W)):
        raise UsageError("waypoints contain NaN or infinite values")
    grasp = np.flatnonzero(W[:, 3] > 0.5)
    if grasp.size and grasp[0] >= 1:
        W[grasp[0] - 1, 2] += pregrasp_raise_m
    return W


class WaypointExecutor:
    """Turns attributed waypoints into actions, one control step per :meth:`step` call.

    Args:
        waypoints: ``(N, 3 + k)`` attributed waypoints (attribute 0 = grasp).
        locate: wrist-depth localizer handed to the grasp primitive.
        config: reference semantics parameters.
    """

    def __init__(
        self, waypoints: np.ndarray, locate: Locator, config: ExecutorConfig = ExecutorConfig()
    ) -> None:
        self.config = config
        self.waypoints = prepare_waypoints(waypoints, config.pregrasp_raise_m)
        self.locate = locate
        self.holding = False
        self.grasps = 0
        self.log: list[WaypointLog] = []
        self.current: Primitive | None = None
        self.done = False
        self.grasp_primitives: list[Grasp] = []
        self.press_primitives: list[Press] = []
        self.free_grip = (
            GRIP_CLOSE
            if config.push_closed and not np.any(self.waypoints[:, 3] > 0.5)
            else GRIP_OPEN
        )
        """Gripper command of free-space motions (closed in an episode that only pushes)."""
        self._gen = self._run()
        next(self._gen)  # advance to the first ``yield`` (waits for a state)

    @property
    def phase(self) -> str:
        """Name of the running primitive (``"move"``, ``"carry"``, ``"drop"``, ``"grasp:<phase>"``,
        ``"done"``)."""
        if self.done or self.current is None:
            return "done" if self.done else "idle"
        if isinstance(self.current, Grasp):
            return f"grasp:{self.current.phase.value}"
        if isinstance(self.current, Carry):
            return "carry"
        if isinstance(self.current, Drop):
            return "drop"
        if isinstance(self.current, Press):
            return f"press:{self.current.phase.value}"
        return "move"

    def step(self, state: RobotState) -> np.ndarray:
        """The action ``(4,)`` for this control step (zero motion once all waypoints are done)."""
        if self.done:
            return self._idle()
        return self._gen.send(state)

    def _idle(self) -> np.ndarray:
        return hold_action(GRIP_CLOSE if self.holding else self.free_grip)

    def _run_primitive(
        self, primitive: Primitive, entry: WaypointLog, state: RobotState
    ) -> Generator[np.ndarray, RobotState, RobotState]:
        self.current = primitive
        while (action := primitive.step(state)) is not None:
            entry.steps += 1
            state = yield action
        return state

    def _is_pull(self, i: int) -> bool:
        """The grasp at waypoint ``i`` is a pull: its next waypoint is a carry that rises less than
        ``lift_min_rise_m`` above it (a handle led sideways along its slide or arc)."""
        W = self.waypoints
        if i + 1 >= len(W) or not W[i + 1, 3] > 0.5:
            return False
        return bool(W[i + 1, 2] - W[i, 2] < self.config.lift_min_rise_m)

    def _run(self) -> Generator[np.ndarray, RobotState, None]:
        c = self.config
        state: RobotState = yield hold_action(GRIP_OPEN)  # primed by __init__; value discarded
        pressed_last = False
        pulling = False
        for i, wp in enumerate(self.waypoints):
            target = wp[:3]
            grasp_flag = bool(wp[3] > 0.5)
            press_flag = len(wp) > 4 and bool(wp[4] > 0.5)
            if press_flag and not grasp_flag and not self.holding:
                if pressed_last:
                    self.log.append(WaypointLog(i, "press (held)"))
                    continue
                entry = WaypointLog(i, "press")
                self.log.append(entry)
                press = Press(target, c.press)
                self.press_primitives.append(press)
                state = yield from self._run_primitive(press, entry, state)
                entry.reached = not press.failed
                pressed_last = True
                continue
            pressed_last = False
            if grasp_flag and not self.holding and self.grasps < c.max_grasps:
                entry = WaypointLog(i, "grasp")
                self.log.append(entry)
                if hasattr(self.locate, "target_world"):
                    self.locate.target_world = np.asarray(target, dtype=np.float64)  # the guide
                pulling = self._is_pull(i)
                grasp = Grasp(
                    self.locate,
                    c.grasp,
                    c.motion.max_step_m,
                    fallback_tcp_target=target,
                    lift=not pulling,
                )
                self.grasp_primitives.append(grasp)
                state = yield from self._run_primitive(grasp, entry, state)
                self.grasps += 1
                self.holding = not grasp.failed
                continue
            if grasp_flag and self.holding:
                entry = WaypointLog(i, "pull" if pulling else "carry")
                self.log.append(entry)
                motion: FreeSpace = Carry(target, c.motion, speed=c.pull_speed if pulling else 1.0)
            else:
                entry = WaypointLog(i, "move")
                self.log.append(entry)
                if self.holding:
                    entry.kind = "drop+move"
                    state = yield from self._run_primitive(Drop(c.drop), entry, state)
                    self.holding = False
                    pulling = False
                motion = FreeSpace(target, c.motion, grip=self.free_grip)
            state = yield from self._run_primitive(motion, entry, state)
            entry.reached = motion.reached
        self.done = True
        self.current = None
        while True:
            yield self._idle()

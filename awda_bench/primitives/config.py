"""Parameters of the motor primitives, the localizer and the waypoint executor.

All are frozen dataclasses whose fields carry their unit in the name or docstring; each validates
itself in ``__post_init__`` and raises :class:`~awda_bench.errors.UsageError` naming the field and
the value. Defaults are the reference values of supplementary S1 / SPEC §4 where those exist,
otherwise chosen for our controller (20 Hz, at most 0.02 m of TCP motion per control step).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from awda_bench.errors import UsageError


def _require_positive(obj: object, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not value > 0:
            raise UsageError(f"{type(obj).__name__}.{name} must be > 0, got {value!r}")


def _require_non_negative(obj: object, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not value >= 0:
            raise UsageError(f"{type(obj).__name__}.{name} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class FreeSpaceConfig:
    """Straight-line motion of the TCP towards a destination (also used by carry).

    Per control step the commanded displacement is ``d = p* - p`` scaled to the controller's step:
    ``a_xyz = d / max_step_m``, divided by ``max(1, max_i |a_i|)`` so every component lies in
    [-1, 1] *and the direction is kept* (a straight line, not a per-axis clip).
    """

    max_step_m: float = 0.02
    """TCP displacement [m] the controller makes for a unit action component (lead's controller:
    0.02 m per control step at 20 Hz)."""
    reach_tol_m: float = 0.02
    """The destination counts as reached within this Euclidean distance [m] (reference: 2 cm)."""
    step_budget: int = 60
    """Control steps after which the motion ends even if not reached (60 steps = 3 s, enough for
    1.2 m at full speed, more than the workspace diagonal)."""
    finish_exactly: bool = True
    """On reaching the tolerance, command the remaining displacement (< 2 cm: one step) once
    before finishing, so the controller's target *is* the destination. With the tracking
    controller the target is where the commands put it: stopping 2 cm short left it short, and a
    cube released there missed its base (stack block gt-waypoints 0.4)."""
    exact_tol_m: float = 0.002
    """No finishing step when already this close [m]."""

    def __post_init__(self) -> None:
        _require_positive(self, "max_step_m", "reach_tol_m", "step_budget")
        _require_non_negative(self, "exact_tol_m")


@dataclass(frozen=True)
class DropConfig:
    """Open the gripper in place."""

    open_steps: int = 6
    """Control steps the open command is held with zero motion (0.3 s at 20 Hz; the Panda fingers
    open from a 3.5 cm grip to fully open in about that time, measured on ``panda_awda``)."""
    settle_steps: int = 4
    """Before opening, up to this many zero-motion steps with the grip closed until the TCP has
    settled: a carry ends within 2 cm of its waypoint while the arm still moves at up to 2 cm per
    step, and an object released in motion lands off target (stack block 0.5 without it)."""
    settled_m: float = 0.002
    """The TCP has settled when it moved less than this in one step [m]."""

    def __post_init__(self) -> None:
        _require_positive(self, "open_steps", "settled_m")
        _require_non_negative(self, "settle_steps")


GRASP_SELECTS: tuple[str, ...] = ("waypoint", "centre")
"""``--grasp-select`` values: how the grasp primitive picks the depth component to grasp
(``waypoint``, the default of the simulated wrist camera, or ``centre``, the reference's rule)."""

CENTRE_SUFFIX = "-centre"
"""Method-name suffix of the reference's centre rule (``run --grasp-select centre``): e.g.
``gt-waypoints-centre`` beside ``gt-waypoints`` (waypoint-guided, the default)."""


@dataclass(frozen=True)
class LocalizationConfig:
    """Object localization from one wrist depth image (SPEC §4, six steps)."""

    background_m: float = 1.0
    """Step 1: depths beyond this [m] (and 0 = no return) are background."""
    above_floor_m: float = 0.01
    """Step 3: a pixel belongs to an object if its depth is at least this much [m] nearer than the
    floor depth (the median of step 2)."""
    min_area_px: int = 50
    """Step 4: smallest connected component kept as an object proposal [px] (reference: 50)."""
    max_area_px: int = 5000
    """Step 4: largest connected component kept [px] (reference: 5000)."""
    min_depth_m: float = 0.0
    """Pixels nearer than this [m] are the gripper's own fingers and masked out before step 2
    (0 disables; the sim adapter sets it from the camera mount)."""
    connectivity: int = 8
    """Pixel connectivity of the connected components (4 or 8)."""
    edge_jump_m: float | None = None
    """Optional, between steps 3 and 4 (not in the reference): drop mask pixels whose height
    differs from a 3 x 3 neighbour by more than this [m] (depth edges and steep side faces), so
    objects seen touching a bin wall in the image are not one component with it. ``None``
    keeps the six reference steps literally."""
    height_reference: str = "world"
    """How steps 2-3 measure "above the floor": ``"depth"`` compares camera depths literally
    (floor depth = median depth; exact only for a camera looking straight down), ``"world"``
    back-projects every valid pixel and compares world heights (floor height = median z). Our
    wrist camera is tilted ~11 degrees (it looks at the point 15 cm below the TCP), which makes
    floor depths vary by +-20 % across the image, so ``"world"`` is the default; for a downward
    camera the two agree."""

    select: str = "centre"
    """Step 5, which component: ``"centre"`` (the reference) takes the centroid nearest the image
    centre; ``"waypoint"`` takes the component with a pixel nearest the grasp waypoint's projection
    into the image (the waypoint says *where* to grasp, the depth image exactly where the object
    is) and grasps at that projection when it is within ``guide_radius_px`` of the component (at
    the depth seen there), else at the centroid if that lies on the component, else at its pixel
    nearest the projection (a nut's ring, not its hole). Without a waypoint, ``"waypoint"``
    behaves like ``"centre"``. Measured on MOSAIC gt-waypoints (20 episodes per family, final
    executor): centre -> waypoint nut assembly 0.00 -> 0.95 (the nut's handle is 1 cm high,
    under the 2 cm object threshold, so the centre rule grasped the ring 2-3 cm from where the
    demonstration held the nut and the nut landed beside its peg), drawer 0.70 -> 1.00, the
    others 1.00 both; pick-place 0.97 -> 1.00. The simulator's wrist camera uses "waypoint"
    (:data:`~awda_bench.primitives.wrist_camera.WRIST_LOCALIZATION`)."""

    guide_radius_px: float = 12.0
    """``select="waypoint"``: when the waypoint's projection is within this many pixels of the
    chosen component (12 px of the 128 px, 90-degree wrist image: ~3.5 cm at 20 cm), the grasp
    goes exactly where the waypoint points, at the depth seen there."""

    def __post_init__(self) -> None:
        if self.select not in GRASP_SELECTS:
            raise UsageError(
                f"LocalizationConfig.select must be one of {GRASP_SELECTS}, got {self.select!r}"
            )
        _require_positive(self, "background_m", "above_floor_m", "min_area_px", "max_area_px")
        _require_non_negative(self, "min_depth_m")
        if self.edge_jump_m is not None and not self.edge_jump_m > 0:
            raise UsageError(
                f"LocalizationConfig.edge_jump_m must be > 0 or None, got {self.edge_jump_m!r}"
            )
        if self.max_area_px < self.min_area_px:
            raise UsageError(
                f"LocalizationConfig.max_area_px ({self.max_area_px}) must be >= "
                f"min_area_px ({self.min_area_px})"
            )
        if self.height_reference not in ("depth", "world"):
            raise UsageError(
                "LocalizationConfig.height_reference must be 'depth' or 'world', "
                f"got {self.height_reference!r}"
            )
        if self.connectivity not in (4, 8):
            raise UsageError(
                f"LocalizationConfig.connectivity must be 4 or 8, got {self.connectivity!r}"
            )


@dataclass(frozen=True)
class GraspConfig:
    """The grasp primitive: localize, hover above, descend, close, lift (S1 steps 1-5)."""

    hover_height_m: float = 0.15
    """Step 2: the TCP goes to this height [m] above the localized object top (reference: 15 cm)."""
    hover_tol_m: float = 0.01
    """Step 2 ends when the TCP is within this distance [m] of the hover point."""
    hover_step_budget: int = 60
    """Control steps allowed for step 2."""
    descent_offset_m: float = 0.03
    """Step 3: the TCP descends to the localized z (the object's visible top surface) minus this
    offset [m], so the finger pads close this far below the top (reference: 3 cm for the Panda
    gripper; a parameter per end-effector)."""
    min_floor_clearance_m: float = 0.015
    """Step 3: the descent target is never lower than this [m] above the localized floor (keeps
    the fingertips off the support for flat objects)."""
    descend_tol_m: float = 0.004
    """Step 3 ends within this distance [m] of the descent target (or when the descent is blocked:
    ``lift_blocked_steps`` steps of the pressing condition, the fingertips on the support). 1 cm
    let a full 2 cm step stop 1 cm high, and the fingers closed above a nut's 1 cm handle (nut
    assembly 2 of 20 failures)."""
    descend_step_budget: int = 30
    """Control steps allowed for step 3."""
    close_steps: int = 8
    """Step 4: control steps the close command is held in place (0.4 s at 20 Hz)."""
    lift_m: float = 0.15
    """Step 5: lift this far [m] straight up with the gripper closed (reference: 15 cm)."""
    lift_tol_m: float = 0.02
    """Step 5 ends within this distance [m] of the lift target."""
    lift_step_budget: int = 20
    """Control steps allowed for step 5."""
    lift_probe_m: float = 0.02
    """Step 5 starts gently: the first this-many metres at ``lift_probe_speed`` [m] ..."""
    lift_probe_speed: float = 0.25
    """... as a fraction of a full step; if the lift is blocked there (the pressing condition,
    ``lift_blocked_steps`` steps in a row) the grasped thing is fixed or articulated (a door or
    drawer handle) and the lift ends instead of tearing the handle out of the fingers. Measured:
    with the tracking controller a full-speed lift pulled every door handle free (door open 0/10
    with gt-waypoints); the reference's compliant arm just stalled."""
    lift_blocked_steps: int = 2
    """Consecutive blocked steps that end the lift."""
    lift_min_command_m: float = 0.004
    """Blocked: the lift command asked for at least this much motion [m] ..."""
    lift_progress_ratio: float = 0.15
    """... and the TCP rose less than this fraction of it (as the pressing miner)."""

    def __post_init__(self) -> None:
        _require_positive(
            self,
            "hover_height_m",
            "hover_tol_m",
            "hover_step_budget",
            "descend_tol_m",
            "descend_step_budget",
            "close_steps",
            "lift_m",
            "lift_tol_m",
            "lift_step_budget",
            "lift_probe_speed",
            "lift_blocked_steps",
            "lift_min_command_m",
            "lift_progress_ratio",
        )
        _require_non_negative(self, "descent_offset_m", "min_floor_clearance_m")


@dataclass(frozen=True)
class PressConfig:
    """The press primitive (:mod:`awda_bench.primitives.press`): approach, contact, hold, retract."""

    max_step_m: float = 0.02
    """Displacement of a unit action component in one control step [m] (the controller's)."""
    slow_distance_m: float = 0.04
    """Within this distance before the waypoint (along the approach) the primitive slows down [m]
    (the press-button expert's pressed waypoint lies a button travel, 2 cm, below the cap)."""
    press_speed: float = 0.25
    """Approach speed near the waypoint and push while holding, as a fraction of a full step
    (5 mm/step: a gentle, bounded push)."""
    overshoot_m: float = 0.03
    """The approach continues at most this far past the waypoint before giving up [m]."""
    end_tolerance_m: float = 0.002
    """The approach has reached its end within this [m]."""
    min_command_m: float = 0.004
    """Blocked: the command asked for at least this much motion [m] (as the pressing miner) ..."""
    progress_ratio: float = 0.15
    """... and the TCP advanced less than this fraction of it (as the pressing miner)."""
    contact_steps: int = 2
    """Consecutive blocked steps that mean contact."""
    hold_steps: int = 20
    """Control steps the press is held after contact (1 s at 20 Hz; a button counts as pressed
    the moment it reaches its depth, the hold makes the pressing visible in the trajectory)."""
    retract_m: float = 0.08
    """RETRACT moves back along the approach direction this far [m]."""
    retract_tol_m: float = 0.01
    """RETRACT is done within this of its goal [m]."""
    step_budget: int = 60
    """Most control steps of the approach and of the retract."""

    def __post_init__(self) -> None:
        _require_positive(
            self,
            "max_step_m",
            "slow_distance_m",
            "press_speed",
            "min_command_m",
            "progress_ratio",
            "contact_steps",
            "hold_steps",
            "retract_tol_m",
            "step_budget",
        )
        _require_non_negative(self, "overshoot_m", "end_tolerance_m", "retract_m")


@dataclass(frozen=True)
class ExecutorConfig:
    """Reference semantics of attributed-waypoint execution (SPEC §4)."""

    pregrasp_raise_m: float = 0.15
    """The waypoint before the first grasp-attributed waypoint is raised this much [m]."""
    motion: FreeSpaceConfig = FreeSpaceConfig()
    """Free-space / carry motion between waypoints (2 cm reach tolerance, step budget)."""
    grasp: GraspConfig = GraspConfig()
    """The grasp primitive run at the first grasp-attributed waypoint."""
    drop: DropConfig = DropConfig()
    """The drop run at the first free waypoint after carrying."""
    press: PressConfig = PressConfig()
    """The press run at a press-attributed waypoint (attribute 1), when present."""
    max_grasps: int = 1
    """Grasp attempts per episode (reference: one)."""
    lift_min_rise_m: float = 0.03
    """The grasp lifts (the reference's 15 cm) only when the next waypoint, a carry, lies at least
    this much [m] above the grasp waypoint. Otherwise the demonstration moved the grasped thing
    sideways -- a drawer or door handle pulled along its slide or arc -- and the carry starts from
    where the gripper closed: a lift there slid the pads up and off the fixed handle (door open
    and drawer open 0/20 with gt-waypoints). Measured on the demonstrations' K = 5 waypoints:
    door and drawer -0.5 cm, stack block +9 cm, pick-place +10 cm, nut +12 cm, basketball +21 cm."""
    pull_speed: float = 0.5
    """Carry speed after a grasp without lift (a pull), as a fraction of a full step: the articulation
    follows the hand through the pads' friction only, and a full-speed pull slips out of them (the
    drawer expert leads its handle by 1.2 cm per step for the same reason)."""
    push_closed: bool = True
    """In an episode without any grasp-attributed waypoint, free-space motions keep the gripper
    closed instead of open: such demonstrations push (a drawer shut), and open fingers straddle the
    handle and push nothing until the drawer front meets them (drawer close 0/20 with the open
    hand, the drawer left 1-2 cm out). An episode with a grasp approaches open, as the reference."""

    def __post_init__(self) -> None:
        _require_non_negative(self, "pregrasp_raise_m", "max_grasps", "lift_min_rise_m")
        if not 0.0 < self.pull_speed <= 1.0:
            raise UsageError(
                f"ExecutorConfig.pull_speed must be in (0, 1], got {self.pull_speed!r}"
            )


def describe(config: object) -> dict[str, object]:
    """Flat ``{field: value}`` of a config dataclass (nested configs as dicts), for records."""
    out: dict[str, object] = {}
    for f in fields(config):  # type: ignore[arg-type]
        value = getattr(config, f.name)
        out[f.name] = describe(value) if hasattr(value, "__dataclass_fields__") else value
    return out

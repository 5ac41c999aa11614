"""What ``python -m awda_bench collect`` decides, as frozen, validated dataclasses."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from awda_bench.errors import UnknownChoiceError, UsageError
from awda_bench.suites import SUITES_DIR, Suite

SPLITS: tuple[str, ...] = ("train", "test")
"""``train``: the suite's training tasks; ``test``: its held-out (evaluated) tasks."""

EMBODIMENT_CHOICES: tuple[str, ...] = ("agent", "demonstrator", "both")
"""``--embodiment`` values; ``both`` records the agent and the demonstrator."""

ROLE_AGENT = "agent"
ROLE_DEMONSTRATOR = "demonstrator"
ROLE_SYNTHESIZED = "synthesized"
ROLES: tuple[str, ...] = (ROLE_AGENT, ROLE_DEMONSTRATOR, ROLE_SYNTHESIZED)


def embodiment_of(role: str) -> str:
    """The embodiment acting in ``role`` (synthesis is recorded by the agent)."""
    return ROLE_DEMONSTRATOR if role == ROLE_DEMONSTRATOR else ROLE_AGENT


"""Who produced a unit's episodes: a scripted expert of an embodiment, or trajectory synthesis
(free-space motion through random waypoints, recorded by the agent)."""

DEFAULT_DEPTH_SIZE: tuple[int, int] = (128, 128)
"""Wrist depth frame (height, width) [px]: ``TosviConfig``'s default depth input."""

_SIZE = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")


def parse_image_size(text: str) -> tuple[int, int]:
    """``"HxW"`` -> ``(H, W)``, refusing sizes below what the models accept (``TrunkConfig``)."""
    from awda_bench.models.config import TrunkConfig

    match = _SIZE.match(text)
    if match is None:
        raise UsageError(f"--image-size {text!r} is not HxW (e.g. 240x320)")
    height, width = int(match.group(1)), int(match.group(2))
    try:
        TrunkConfig(image_height_px=height, image_width_px=width, backbone_weights="none")
    except UsageError as exc:
        raise UsageError(
            f"--image-size {text}: the models cannot take it ({exc}); use at least 64x64"
        ) from None
    return height, width


@dataclass(frozen=True)
class SynthesisConfig:
    """Trajectory synthesis (SPEC §6 TS): free-space motion through 1-3 random waypoints.

    The waypoint box is in the world frame [m] (table top z = 0, robot base at x = -0.615). It
    covers both pick-and-place bins, stays inside the controller's workspace (base-frame box and
    0.75 m horizontal reach: the far corner (0.05, +-0.30) is 0.73 m from the base axis) and keeps
    the TCP above the tallest object (milk carton top ~0.16 m), so synthesized motion never grasps
    or pushes objects.
    """

    low_m: tuple[float, float, float] = (-0.25, -0.30, 0.20)
    """Lower corner of the waypoint box [m]."""
    high_m: tuple[float, float, float] = (0.05, 0.30, 0.38)
    """Upper corner of the waypoint box [m]."""
    min_waypoints: int = 1
    """Fewest waypoints per trajectory (reference: 1)."""
    max_waypoints: int = 3
    """Most waypoints per trajectory (reference: 3)."""
    settle_steps: int = 3
    """Zero-motion steps recorded after the last waypoint is reached."""

    def __post_init__(self) -> None:
        if any(lo >= hi for lo, hi in zip(self.low_m, self.high_m, strict=True)):
            raise UsageError(
                f"SynthesisConfig.low_m {self.low_m} must be below high_m {self.high_m}"
            )
        if not 1 <= self.min_waypoints <= self.max_waypoints:
            raise UsageError(
                "SynthesisConfig needs 1 <= min_waypoints <= max_waypoints, got "
                f"{self.min_waypoints}, {self.max_waypoints}"
            )
        if self.settle_steps < 0:
            raise UsageError(f"SynthesisConfig.settle_steps must be >= 0, got {self.settle_steps}")

    def draw_waypoints(self, seed: int) -> np.ndarray:
        """``(K, 3)`` waypoints [m] uniform in the box, ``K`` uniform in ``min_waypoints ..
        max_waypoints``, from a generator seeded with ``seed`` (the attempt's)."""
        rng = np.random.default_rng(seed)
        count = int(rng.integers(self.min_waypoints, self.max_waypoints + 1))
        return rng.uniform(self.low_m, self.high_m, size=(count, 3))


METAWORLD_SYNTHESIS = SynthesisConfig(low_m=(-0.25, 0.45, 0.10), high_m=(0.25, 0.80, 0.30))
"""Trajectory synthesis on Meta-World (its world frame [m]: table top z = 0, the Sawyer's base at
y = 0, the hand starting near (0, 0.6, 0.2)). The box lies inside every task's hand and mocap
workspace (Meta-World's ``hand_low`` / ``mocap_low`` (-0.5, 0.40, 0.05), ``hand_high`` /
``mocap_high`` (0.5, 1.0, 0.5)) and over the table's part that the corner4 camera sees and the
tasks' objects occupy; its floor (10 cm) is above the pucks, blocks and handles the hand would
otherwise push, but not above the fixtures that stand up to ~30 cm (doors, shelves, the hoop,
the window frame): a motion the hand cannot finish (blocked by a fixture, or the fixture moved)
does not reach its waypoint within the motion's step budget, and the episode is discarded and
replaced like a failed expert episode (``collect``'s discard count says how many). The hand moves
open, as the reference's synthesized motion (no grasps): the grasp attribute is mined from the
recorded trajectory with the experts' miner all the same, so a hand that closed on something
would be labelled as such."""


def synthesis_for(suite: Suite) -> SynthesisConfig:
    """The synthesis box of ``suite``'s world: :data:`METAWORLD_SYNTHESIS` on Meta-World's suites,
    :class:`SynthesisConfig`'s defaults (pick-and-place's bins) on the ManiSkill ones."""
    return METAWORLD_SYNTHESIS if suite.simulator == "metaworld" else SynthesisConfig()


@dataclass(frozen=True)
class CollectConfig:
    """Everything ``python -m awda_bench collect`` decides."""

    suite: str
    """Suite name (``tasks/<suite>.toml``)."""
    split: str
    """``train`` (training tasks) or ``test`` (held-out tasks); see :data:`SPLITS`."""
    embodiment: str
    """``agent``, ``demonstrator`` or ``both``."""
    episodes_per_task: int
    """Successful episodes kept per task and embodiment (failed ones are discarded and replaced)."""
    out: Path
    """DATA_DIR: where shards, trajectory files and ``manifest.json`` go."""
    workers: int = 1
    """Worker processes or Ray actors (0: record in this process; local backend only)."""
    backend: str = "local"
    """Where workers run: ``"local"`` processes or ``"ray"`` actors (not part of the data)."""
    ray_address: str | None = None
    """Ray cluster to join with ``backend="ray"``; ``None`` starts a private local instance."""
    image_size: tuple[int, int] | None = None
    """Third-person frame (height, width) [px]; ``None``: the suite's camera size (its file's
    ``[camera]``: 240x320 on the ManiSkill suites, the reference pick-and-place images; 224x224
    on Meta-World's, Table S2's size there). See :meth:`frame_size`."""
    depth_size: tuple[int, int] = DEFAULT_DEPTH_SIZE
    """Agent wrist depth frame (height, width) [px]."""
    seed: int = 0
    """Base seed every episode seed is derived from."""
    synthesize: int = 0
    """Synthesized trajectories (spread over the split's tasks, agent embodiment)."""
    tasks: tuple[int, ...] = ()
    """Only these tasks of the split (empty: all of them)."""
    jpeg_quality: int = 90
    """JPEG quality of the third-person frames (OpenCV scale 0-100)."""
    chunk_episodes: int = 10
    """Successful episodes one job records: a killed run re-records at most this many per worker,
    and every job pays an env build (~1 s) plus the first capture of each camera (~5 s on
    lavapipe) plus the unrendered replay of its unit's earlier attempts. Never changes the data
    (see :class:`~awda_bench.data.plan.CollectJob`)."""
    max_attempts_factor: int = 3
    """A unit gives up (error) after ``factor * episodes + 10`` attempts: the expert is broken."""
    episode_timeout_s: float = 600.0
    """Watchdog: an episode running longer is killed and recorded as an error [s]."""
    synthesis: SynthesisConfig | None = None
    """Trajectory synthesis parameters; ``None``: the suite's (:func:`synthesis_for`). See
    :meth:`synthesis_config`."""
    suites_dir: Path = SUITES_DIR
    """Where suite files live."""
    progress: bool = True
    """Show a progress bar on stderr."""
    extend_from: Path | None = None
    """A finished collection of the same options and fewer episodes whose episodes this one
    starts from (:mod:`awda_bench.data.extend`); not part of the dataset's definition."""

    def __post_init__(self) -> None:
        if self.split not in SPLITS:
            raise UnknownChoiceError("split", self.split, SPLITS)
        if self.embodiment not in EMBODIMENT_CHOICES:
            raise UnknownChoiceError("embodiment", self.embodiment, EMBODIMENT_CHOICES)
        if self.episodes_per_task < 0:
            raise UsageError(f"--episodes-per-task must be >= 0, got {self.episodes_per_task}")
        if self.synthesize < 0:
            raise UsageError(f"--synthesize must be >= 0, got {self.synthesize}")
        if self.episodes_per_task == 0 and self.synthesize == 0:
            raise UsageError("nothing to collect: give --episodes-per-task > 0 or --synthesize > 0")
        if self.workers < 0:
            raise UsageError(f"--workers must be >= 0, got {self.workers}")
        from awda_bench.execution.backends import check_backend

        check_backend(self.backend, self.workers, self.ray_address)
        if self.seed < 0:
            raise UsageError(f"--seed must be >= 0, got {self.seed}")
        if not 1 <= self.jpeg_quality <= 100:
            raise UsageError(f"--jpeg-quality must be in 1..100, got {self.jpeg_quality}")
        if self.episode_timeout_s <= 0:
            raise UsageError(f"--episode-timeout must be > 0, got {self.episode_timeout_s}")
        if self.chunk_episodes < 1:
            raise UsageError(f"chunk_episodes must be >= 1, got {self.chunk_episodes}")
        if self.max_attempts_factor < 1:
            raise UsageError(f"max_attempts_factor must be >= 1, got {self.max_attempts_factor}")

    def frame_size(self, suite: Suite) -> tuple[int, int]:
        """The third-person frame (height, width) [px] recorded from ``suite``."""
        if self.image_size is not None:
            return self.image_size
        return (suite.camera.height, suite.camera.width)

    def synthesis_config(self, suite: Suite) -> SynthesisConfig:
        """The synthesis parameters used on ``suite``: :attr:`synthesis` or the suite's own."""
        return self.synthesis if self.synthesis is not None else synthesis_for(suite)

    @property
    def expert_roles(self) -> tuple[str, ...]:
        """Roles whose scripted expert is recorded."""
        if self.embodiment == "both":
            return (ROLE_AGENT, ROLE_DEMONSTRATOR)
        return (self.embodiment,)

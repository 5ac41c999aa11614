"""The episode protocol: what one episode is, what a policy is handed, the interface it implements.

:class:`EpisodeSpec`, :class:`EpisodeContext`, :class:`Observations` and :class:`Policy` are
shared by everything that plays episodes (the scripted experts, demo recording, the primitives,
the evaluated methods, the harness and the collector), so they sit below all of them and import
nothing of the package but its errors. :func:`derive_seed` gives an episode its seeds (and a
collection attempt its own) from its identity, never from a shared generator.

Timeline of one episode (``T = suite.horizon_steps`` control steps)::

    env.reset(seed, task) -> obs_0
    policy.reset(ctx)                       # ctx: spec, observations (+ env if privileged)
    for t in 0 .. T-1:
        a_t = policy.act(obs_t)             # (num_envs, 4) float32 in [-1, 1]: dx, dy, dz, grip
        obs_{t+1}, ... = env.step(a_t)
        stop early if policy.done

**Privileged or not.** A policy declares ``privileged = True`` (a class attribute) to read the
simulator: ``ctx.env`` is then the unwrapped ManiSkill env and ``act`` gets the env's state
observation. Only ``scripted`` and the ``gt-waypoints`` family do; their rows are marked
privileged in the tables. Every other method (no attribute, or ``privileged = False``) plays an
*observation-only* episode: ``ctx.env`` raises :class:`~awda_bench.errors.PrivilegedAccessError`
(the episode is recorded as an error, the run goes on), and both ``ctx.observations`` and the
``obs`` argument of ``act`` are the episode's :class:`Observations`: frames rendered on request,
the demonstration, camera matrices and proprioception, nothing else of the scene. (The boundary
stops accidents, not a determined policy in the same process; a served policy, run in its own
process, sees only what crosses the socket.)
"""

from __future__ import annotations

import hashlib
import random
import sys
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from awda_bench.errors import PrivilegedAccessError

GRIP_OUTCOMES: tuple[str, ...] = ("target", "other", "nothing")
"""What the gripper was first commanded closed on, where a task can tell (``object_distances``
of :class:`~awda_bench.envs.task_base.AwdaTaskEnv`): the object nearest the TCP within
``reach_threshold_m`` was the target, or another object, or no object was that near. An episode
record's ``first_grip`` is one of these or :data:`NEVER_GRIPPED` (``None`` where the task does not
tell): the supplementary's §S3 asks whether a policy fails by going for the wrong object."""
NEVER_GRIPPED = "never"
"""``first_grip`` of an episode whose policy never commanded the gripper closed."""


@dataclass(frozen=True)
class EpisodeSpec:
    """One evaluation episode, fixed before any scheduling (so results never depend on workers)."""

    suite: str
    """Suite name."""
    task: int
    """Suite-wide task index; its env receives ``suite.task(task).reset_task`` as
    ``options["task"]`` (the variation, for suites mixing families)."""
    episode: int
    """Episode index within the task (0-based)."""
    seed: int
    """Seed of the agent's scene (``env.reset(seed=seed)``)."""
    demo_seed: int
    """Seed of the demonstrator's scene (a different layout of the same task)."""


def derive_seed(suite: str, base_seed: int, task: int, episode: int, role: str) -> int:
    """A seed in ``[0, 2**31)`` from a hash of the episode's identity and ``role`` (agent/demo)."""
    key = f"{suite}|{base_seed}|{task}|{episode}|{role}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:4], "little") & 0x7FFF_FFFF


@dataclass(frozen=True)
class Proprioception:
    """The agent's own state now, one row per env, world frame (z up, metres)."""

    tcp_pos: np.ndarray
    """``(num_envs, 3)`` float64: the tool centre point (between the fingertips) [m]."""
    tcp_quat: np.ndarray
    """``(num_envs, 4)`` float64: the TCP orientation, quaternion ``(w, x, y, z)``."""
    gripper_opening_m: np.ndarray
    """``(num_envs,)`` float64: distance between the fingers [m] (0 closed, ~0.08 open)."""
    qpos: np.ndarray
    """``(num_envs, 9)`` float64: the 7 arm joints and 2 finger joints [rad, m]."""


@dataclass(frozen=True)
class WristDepth:
    """One wrist depth capture, with what back-projection needs."""

    depth_m: np.ndarray
    """``(num_envs, 128, 128)`` float32 depth along the optical axis [m]; 0 where nothing was hit."""
    intrinsic_cv: np.ndarray
    """``(num_envs, 3, 3)`` float64 OpenCV intrinsics (fx, fy, cx, cy in pixels)."""
    cam2world_cv: np.ndarray
    """``(num_envs, 4, 4)`` float64 camera-to-world transform, OpenCV axes (x right, y down,
    z forward)."""


def demo_frame_indices(steps: int, count: int) -> np.ndarray:
    """``count`` indices over 0..steps, first and last included; a demo shorter than ``count``
    repeats frames. The one rule for which frames of a demonstration a network sees: training
    (over a recorded episode's states) and evaluation (over its rendered video) both use it, so a
    short demo gives ``count`` frames at both (it gave fewer at evaluation before session 17:
    MOSAIC's "door 1 close" has demos of 9 rendered frames)."""
    return np.linspace(0, steps, count).round().astype(np.int64)


@runtime_checkable
class Observations(Protocol):
    """What an observation-only policy may see of its episode (the harness's implementation is
    :class:`awda_bench.evaluation.observations.SimObservations`). Frames render when asked for
    (~50 ms each on a CPU renderer), so ask only for those the method uses."""

    num_envs: int
    """Parallel envs in this episode (1 in the harness); actions are ``(num_envs, 4)``."""

    def demo_frames(self, count: int = 10) -> np.ndarray:
        """The demonstration: ``(count, 240, 320, 3)`` uint8 RGB frames of the demonstrator (the
        blue floating Panda hand) doing this task in another layout of the scene (``spec.demo_seed``),
        evenly spaced over its video, first and last included (:func:`demo_frame_indices`; a
        short video repeats frames); from the same third-person camera."""

    def first_frame(self) -> np.ndarray:
        """The agent's third-person RGB frame at reset, ``(240, 320, 3)`` uint8 (env 0)."""

    def rgb(self) -> np.ndarray:
        """The third-person RGB frame now, ``(num_envs, 240, 320, 3)`` uint8."""

    def wrist_depth(self) -> WristDepth:
        """The wrist camera's depth image now (eye-in-hand, 90 degree field of view)."""

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        """The third-person camera's ``intrinsic_cv`` ``(3, 3)`` and world-to-camera
        ``extrinsic_cv`` ``(3, 4)``, float64, OpenCV axes (fixed for a suite)."""

    def proprio(self) -> Proprioception:
        """The agent's TCP pose, gripper opening and joint positions now."""


class EpisodeContext:
    """What a policy gets at the start of an episode.

    ``env`` given: a privileged context (``ctx.env`` is the simulator). ``env=None``: an
    observation-only one, where ``ctx.env`` raises :class:`PrivilegedAccessError` naming the rule.
    """

    def __init__(
        self,
        env: Any,
        spec: EpisodeSpec,
        extras: dict[str, Any] | None = None,
        *,
        observations: Observations | None = None,
        method: str = "",
    ) -> None:
        self._env = env
        self.spec = spec
        """Which episode this is."""
        self.extras: dict[str, Any] = {} if extras is None else extras
        """What the harness keeps of the episode besides its record (``"demo_frames"``,
        ``"first_frame"``, filled as they are observed)."""
        self.observations = observations
        """The episode's :class:`Observations` (``None`` only where no harness built one)."""
        self.method = method
        """The method playing the episode (names it in the boundary's error)."""

    @property
    def privileged(self) -> bool:
        """True when this context carries the simulator."""
        return self._env is not None

    @property
    def env(self) -> Any:
        """The unwrapped ManiSkill env, already reset to ``spec`` (privileged methods only)."""
        if self._env is None:
            who = f"method {self.method!r}" if self.method else "this method"
            raise PrivilegedAccessError(
                f"{who} is not privileged, so its episode is observation-only and ctx.env (the "
                "simulator) is off limits; read ctx.observations (frames, demo, wrist depth, "
                "cameras, proprioception) or declare privileged = True on the policy class"
            )
        return self._env


def observations_of(ctx: EpisodeContext) -> Observations:
    """``ctx.observations``, or a one-line error for a context built without them."""
    if ctx.observations is None:
        raise RuntimeError(
            "this EpisodeContext carries no observations; build it with observations=... "
            "(the harness does: awda_bench.evaluation.observations.SimObservations)"
        )
    return ctx.observations


def seed_globals(seed: int) -> None:
    """Seed Python's, NumPy's and (if loaded) torch's global generators for one episode (the
    harness does it before ``env.reset``, a policy server before ``policy.reset``)."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 (policies may use the legacy global generator)
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.manual_seed(seed)


def is_privileged(policy: object) -> bool:
    """The policy's declaration: its ``privileged`` attribute, False when it has none."""
    return bool(getattr(policy, "privileged", False))


@runtime_checkable
class Policy(Protocol):
    """A method under evaluation.

    Optional class attribute ``privileged: bool`` (default False): see the module docstring.
    """

    name: str
    """Method name as used with ``--method``."""

    def reset(self, ctx: EpisodeContext) -> None:
        """Prepare for a new episode (plan, predict waypoints, ...)."""

    def act(self, obs: Any) -> np.ndarray:
        """Return the next action, shape ``(num_envs, 4)``, values in [-1, 1]: the TCP's
        displacement this step as a fraction of 2 cm along world x, y, z, and the gripper
        command (> 0 closes). ``obs``: the env's state vector (privileged methods) or the
        episode's :class:`Observations` (every other method)."""

    @property
    def done(self) -> bool:
        """True once the policy has nothing more to do (the harness may stop the episode)."""

    @property
    def waypoints(self) -> np.ndarray | None:
        """Attributed waypoints ``(K, 3 + k)`` the policy predicted this episode, if any."""


class ClosedLoopPolicy:
    """Base of a :class:`Policy` that acts step by step to the horizon: never done, no waypoints
    (T-OSVI, the random baseline). Subclasses define ``name``, ``reset`` and ``act``."""

    @property
    def done(self) -> bool:
        return False

    @property
    def waypoints(self) -> np.ndarray | None:
        return None

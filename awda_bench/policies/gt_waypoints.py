"""``gt-waypoints``: ground-truth attributed waypoints executed by the motor primitives.

The upper bound of any waypoint predictor on a suite (privileged: it reads the simulator state).
Per episode::

    reset(ctx):  S = env.get_state_dict()                          the real start
                 expert rollout from S, recording a Trajectory     (plan on the scene itself)
                 env.set_state_dict(S)                             back to the real start
                 g = mine_grasp(trajectory), p = mine_press(...)   mined, not simulator truth
                 W = extract_waypoints(tcp path, [g, p], K=5)      (5, 3 + 2): grasped, pressing
    act(obs):    WaypointExecutor(W).step(state) per env          grasp uses wrist depth only

Rendered frames per episode: wrist depth images during grasps only (one per HOVER step of the
grasp primitive), counted in :attr:`GtWaypointsPolicy.stats`.

What is the simulator's is one small *scene* object per episode: :class:`ManiSkillScene` here,
:class:`awda_bench.metaworld.gt_scene.MetaWorldScene` on Meta-World (the package's scripted
policy plans, the Sawyer's parameters replace the Panda's, the primitives' commands become mocap
actions). Mining, extraction and the executor are the same code on both.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from awda_bench.episode import EpisodeContext, EpisodeSpec, Policy
from awda_bench.errors import UnknownChoiceError
from awda_bench.mining import GraspMiningConfig, PressMiningConfig, mine_grasp, mine_press
from awda_bench.primitives.base import RobotState
from awda_bench.primitives.config import (
    CENTRE_SUFFIX,
    GRASP_SELECTS,
    ExecutorConfig,
    LocalizationConfig,
)
from awda_bench.primitives.executor import WaypointExecutor
from awda_bench.primitives.wrist_camera import WRIST_LOCALIZATION, WristLocator
from awda_bench.rollout import roll_out
from awda_bench.trajectory import Trajectory
from awda_bench.waypoints import extract_waypoints


@dataclass(frozen=True)
class GtWaypointsConfig:
    """Settings of the ``gt-waypoints`` method."""

    num_waypoints: int = 5
    """K attributed waypoints per episode (the paper's downstream value)."""
    planning_steps: int = 300
    """Most control steps the expert may take while planning (15 s at 20 Hz)."""
    executor: ExecutorConfig = ExecutorConfig()
    """Primitive and execution parameters."""
    mining: GraspMiningConfig = GraspMiningConfig()
    """Grasp attribute mining."""
    press_mining: PressMiningConfig | None = PressMiningConfig()
    """Pressing attribute mining (the second attribute; the executor's press primitive acts on
    it); ``None``: the grasp attribute alone (Meta-World, see
    :mod:`awda_bench.metaworld.gt_scene`)."""
    localization: LocalizationConfig = WRIST_LOCALIZATION
    """Wrist-depth localization in the grasp primitive."""
    record_truth: bool = False
    """The planning rollout also records the simulator's grasp truth (``truth["grasp"]``, for
    scoring the miner). Off when evaluating: the waypoints use only the mined attributes, and the
    contact-force test cost 12 % of a pick-place episode (1.24 of 10.7 s over 7 episodes,
    cProfile)."""
    physics_only_planning: bool = True
    """The planning rollout steps the physics alone (:func:`record_rollouts`): the scene is
    restored afterwards and the expert reads the scene, so ManiSkill's ``evaluate()``,
    observation and reward of every planning step are skipped."""


def _numpy(x: Any) -> np.ndarray:
    """A NumPy copy of a torch tensor (ManiSkill's state) or an array; torch is not imported
    here, so the policy also loads where there is none (the Meta-World workers)."""
    if hasattr(x, "detach"):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def robot_states(env: Any) -> list[RobotState]:
    """Per-env :class:`RobotState` read from a ManiSkill env with the ``panda_awda`` agent."""
    tcp = _numpy(env.agent.tcp_pose.p).astype(np.float64)
    opening = _numpy(env.agent.gripper_opening_m).astype(np.float64).reshape(-1)
    return [
        RobotState(tcp_pos=tcp[i], gripper_opening_m=float(opening[i])) for i in range(len(tcp))
    ]


def record_rollouts(
    env: Any,
    policy: Policy,
    max_steps: int,
    record_truth: bool = True,
    physics_only: bool = False,
) -> list[Trajectory]:
    """Run ``policy`` (already reset) on ``env`` from its current state; one Trajectory per env.

    Stops when the policy is done or after ``max_steps``. With ``record_truth``,
    ``truth["grasp"]`` is the simulator's contact test on the target object when the env has one
    (``is_grasping_target``). ``physics_only`` (``env`` unwrapped, a policy that reads the scene,
    not ``obs``: the scripted experts): each step is ManiSkill's ``_step_action`` alone -- no
    ``evaluate()``, observation or reward, a quarter of an env step, which a rollout whose state
    is restored afterwards does not need; the policy gets ``obs=None``.
    """
    n = int(env.num_envs)
    tcp, opening, actions, grasp = [], [], [], []
    has_truth = record_truth and hasattr(env, "is_grasping_target")

    def choose(obs: Any) -> np.ndarray | None:
        if policy.done:
            return None
        states = robot_states(env)  # the state an action is taken from
        tcp.append([s.tcp_pos for s in states])
        opening.append([s.gripper_opening_m for s in states])
        if has_truth:
            grasp.append(_numpy(env.is_grasping_target()).astype(bool).reshape(n))
        action = np.asarray(policy.act(obs), dtype=np.float32).reshape(n, 4)
        actions.append(action)
        return action

    def step_physics(action: np.ndarray) -> tuple[None, None, None, None, dict[str, Any]]:
        env._step_action(action)
        env._elapsed_steps += 1
        return None, None, None, None, {}

    roll_out(
        step_physics if physics_only else env.step,
        None if physics_only else env.get_obs(),
        choose,
        max_steps,
    )
    T = len(actions)
    tcp_a = np.asarray(tcp, dtype=np.float64).reshape(T, n, 3)
    open_a = np.asarray(opening, dtype=np.float64).reshape(T, n)
    act_a = np.asarray(actions, dtype=np.float32).reshape(T, n, 4)
    grasp_a = np.asarray(grasp, dtype=bool).reshape(T, n) if has_truth else None
    return [
        Trajectory(
            tcp_pos=tcp_a[:, i],
            gripper_opening_m=open_a[:, i],
            actions=act_a[:, i],
            truth={} if grasp_a is None else {"grasp": grasp_a[:, i]},
            meta={"expert_done": bool(policy.done), "steps": T},
        )
        for i in range(n)
    ]


@dataclass
class EpisodeStats:
    """What one episode of ``gt-waypoints`` cost (reset by :meth:`GtWaypointsPolicy.reset`)."""

    planning_s: float = 0.0
    """Wall time of the expert rollout + state save/restore [s] (simulation)."""
    planning_steps: int = 0
    act_calls: int = 0
    act_s: float = 0.0
    """Wall time inside :meth:`GtWaypointsPolicy.act` [s], rendering and localization included."""
    frames: int = 0
    """Wrist depth frames rendered."""
    capture_s: float = 0.0
    """Of ``act_s``: rendering the wrist depth frames [s]."""
    localize_s: float = 0.0
    """Of ``act_s``: localization on the frames [s]."""
    step_overhead_ms: list[float] = field(default_factory=list)
    """Per :meth:`~GtWaypointsPolicy.act` call: its wall time minus rendering [ms]."""
    trajectories: list[Trajectory] = field(default_factory=list)

    @property
    def overhead_per_step_ms(self) -> float:
        """Primitive + executor time per env step, rendering excluded [ms]."""
        if self.act_calls == 0:
            return 0.0
        return 1e3 * (self.act_s - self.capture_s) / self.act_calls


class Scene(Protocol):
    """What ``gt-waypoints`` asks of the simulator in one episode."""

    def configure(self, config: GtWaypointsConfig) -> GtWaypointsConfig:
        """The settings the episode runs with (the robot's own parameters put in)."""

    def plan(self, max_steps: int) -> list[Trajectory]:
        """Expert rollout(s) from the current state, which is restored afterwards."""

    def robot_states(self) -> list[RobotState]:
        """Per env, the primitives' view of the robot now."""

    def locator(self, env_index: int, config: LocalizationConfig) -> WristLocator:
        """The grasp primitive's wrist-depth localizer of env ``env_index``."""

    def env_actions(self, actions: np.ndarray) -> np.ndarray:
        """The primitives' ``(n, 4)`` commands as the env's actions."""


class ManiSkillScene:
    """``gt-waypoints``' view of one ManiSkill episode: the suite's expert plans on a copy of the
    scene state (``get_state_dict``/``set_state_dict``), the ``panda_awda`` wrist camera
    localizes, actions go to the env as they are."""

    def __init__(self, ctx: EpisodeContext) -> None:
        self.ctx = ctx
        self.env = ctx.env
        self._physics_only = True
        self._record_truth = False

    def configure(self, config: GtWaypointsConfig) -> GtWaypointsConfig:
        self._physics_only = config.physics_only_planning
        self._record_truth = config.record_truth
        return config

    def plan(self, max_steps: int) -> list[Trajectory]:
        """Expert rollout(s) from the current scene, which is restored afterwards."""
        from awda_bench.experts import make_expert

        env = self.env
        saved = env.get_state_dict()
        elapsed = env._elapsed_steps.clone() if hasattr(env, "_elapsed_steps") else None
        expert = make_expert(self.ctx.spec.suite, embodiment="agent")
        expert.reset(self.ctx)
        trajectories = record_rollouts(
            env,
            expert,
            max_steps,
            record_truth=self._record_truth,
            physics_only=self._physics_only,
        )
        env.set_state_dict(saved)
        if elapsed is not None:
            env._elapsed_steps = elapsed
        return trajectories

    def robot_states(self) -> list[RobotState]:
        return robot_states(self.env)

    def locator(self, env_index: int, config: LocalizationConfig) -> WristLocator:
        return WristLocator(self.env, env_index=env_index, config=config)

    def env_actions(self, actions: np.ndarray) -> np.ndarray:
        return actions


def scene_for(ctx: EpisodeContext) -> Scene:
    """The simulator's scene of ``ctx`` (Meta-World's imported only there: it needs
    ``.venv-metaworld``)."""
    if getattr(ctx.env, "simulator", None) == "metaworld":
        from awda_bench.metaworld.gt_scene import MetaWorldScene

        return MetaWorldScene(ctx)
    return ManiSkillScene(ctx)


class GtWaypointsPolicy:
    """Plans with the suite's scripted expert on the scene itself, then executes K waypoints."""

    name = "gt-waypoints"
    privileged = True
    """It plans on the simulator (``ctx.env``): its rows are marked privileged."""

    def __init__(self, config: GtWaypointsConfig | None = None) -> None:
        self.config = config or GtWaypointsConfig()
        """The method's settings (the Panda's parameters; on Meta-World the episode runs with
        :attr:`episode_config`, the Sawyer's in their place)."""
        self.episode_config = self.config
        """The settings the current episode runs with."""
        self._env: Any = None
        self._scene: Scene | None = None
        self._executors: list[WaypointExecutor] = []
        self._locators: list[WristLocator] = []
        self._waypoints: np.ndarray | None = None
        self.stats = EpisodeStats()

    # ------------------------------------------------------------------ planning
    def plan(self, ctx: EpisodeContext) -> list[Trajectory]:
        """Expert rollout(s) from the current scene, which is restored afterwards."""
        scene = scene_for(ctx)
        self._scene = scene
        self.episode_config = scene.configure(self.config)
        return scene.plan(self.episode_config.planning_steps)

    def reset(self, ctx: EpisodeContext) -> None:
        self.stats = EpisodeStats()
        self._env = ctx.env
        t0 = time.perf_counter()
        trajectories = self.plan(ctx)
        self.stats.planning_s = time.perf_counter() - t0
        self.stats.planning_steps = sum(len(t) for t in trajectories)
        self.stats.trajectories = trajectories
        config = self.episode_config
        self._executors, self._locators, waypoints = [], [], []
        for i, traj in enumerate(trajectories):
            columns = [mine_grasp(traj, config.mining)]
            if config.press_mining is not None:
                columns.append(mine_press(traj, config.press_mining))
            attributes = np.column_stack(columns)
            W = extract_waypoints(
                traj.tcp_pos,
                attributes,
                config.num_waypoints,
                config.executor.grasp.lift_m,
            )
            assert self._scene is not None  # set by plan()
            locator = self._scene.locator(i, config.localization)
            self._locators.append(locator)
            self._executors.append(WaypointExecutor(W, locator, config.executor))
            waypoints.append(W)
        self._waypoints = waypoints[0]

    # ------------------------------------------------------------------ acting
    def act(self, obs: Any) -> np.ndarray:
        if self._env is None or self._scene is None:
            raise RuntimeError("GtWaypointsPolicy.act() before reset(ctx)")
        t0 = time.perf_counter()
        states = self._scene.robot_states()
        commands = np.stack([ex.step(s) for ex, s in zip(self._executors, states, strict=True)])
        action = self._scene.env_actions(commands)
        elapsed = time.perf_counter() - t0
        capture_s = sum(loc.capture_s for loc in self._locators)
        self.stats.step_overhead_ms.append(1e3 * (elapsed - (capture_s - self.stats.capture_s)))
        self.stats.act_s += elapsed
        self.stats.act_calls += 1
        self.stats.frames = sum(loc.frames for loc in self._locators)
        self.stats.capture_s = capture_s
        self.stats.localize_s = sum(loc.localize_s for loc in self._locators)
        return action.astype(np.float32)

    @property
    def done(self) -> bool:
        return bool(self._executors) and all(ex.done for ex in self._executors)

    @property
    def waypoints(self) -> np.ndarray | None:
        """The (K, 4) ground-truth waypoints of env 0 (before the pre-grasp raise)."""
        return self._waypoints

    @property
    def executors(self) -> list[WaypointExecutor]:
        return self._executors


def episode_spec_for(suite: str, task: int, seed: int) -> EpisodeSpec:
    """A spec for ad-hoc runs (benchmarks, tests) outside the harness."""
    return EpisodeSpec(suite=suite, task=task, episode=0, seed=seed, demo_seed=seed + 1)


WAYPOINT_COUNTS = (3, 5, 8)
"""K values offered as methods: ``gt-waypoints`` (K = 5, the paper's) and ``gt-waypoints-k3``,
``gt-waypoints-k8`` (``run --method gt-waypoints --num-waypoints K``): how many are enough."""


def gt_waypoints_method_name(num_waypoints: int) -> str:
    """The method (and table column) name of gt-waypoints with K waypoints."""
    return "gt-waypoints" if num_waypoints == 5 else f"gt-waypoints-k{num_waypoints}"


def gt_waypoints(num_waypoints: int = 5, grasp_select: str = GRASP_SELECTS[0]) -> GtWaypointsPolicy:
    """The gt-waypoints family (one method per setting, :mod:`awda_bench.evaluation.methods`): K
    waypoints (``gt-waypoints-k3``, ``-k8``; the paper's 5 by default), and grasps that take the
    wrist depth component the grasp waypoint points at (``waypoint``) or the one nearest the
    wrist image's centre (``centre``, the reference's rule: ``gt-waypoints-centre``)."""
    if grasp_select not in GRASP_SELECTS:
        raise UnknownChoiceError("--grasp-select", grasp_select, GRASP_SELECTS)
    config = GtWaypointsConfig(num_waypoints=num_waypoints)
    if grasp_select != GRASP_SELECTS[0]:
        config = replace(config, localization=replace(WRIST_LOCALIZATION, select=grasp_select))
    policy = GtWaypointsPolicy(config)
    policy.name = gt_waypoints_method_name(num_waypoints) + (
        CENTRE_SUFFIX if grasp_select == "centre" else ""
    )
    return policy

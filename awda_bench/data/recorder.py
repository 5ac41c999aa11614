"""Record one collection job in a worker: reset, act, capture, and return the episode's arrays.

Per control step ``t`` (state *before* action ``t``; ``T`` actions, ``T + 1`` states)::

    env.reset(seed, options={"task": variation})                                  state 0
    for t in 0 .. T-1:
        record state t: third-person RGB (JPEG), wrist depth (agent roles), TCP pose, gripper
                        opening, qpos/qvel, env state (get_state_dict), simulator truths
        a_t = expert.act(obs_t)    or the free-space primitive toward the next random waypoint
        env.step(a_t)                                                             state t + 1
        stop SETTLE_STEPS after the expert is done (synthesis: settle_steps after the last
        waypoint), or at the suite's horizon
    record state T (no truths: they describe the state an action is taken from)
    mined attributes (grasp, press) from the T recorded states and commanded actions

A camera frame costs ~25-50 ms on lavapipe; every recorded state renders the third-person camera,
and for the agent also the wrist depth camera (T-OSVI+depth needs it); nothing else renders.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from awda_bench.data.config import (
    ROLE_DEMONSTRATOR,
    ROLE_SYNTHESIZED,
    CollectConfig,
    SynthesisConfig,
    embodiment_of,
)
from awda_bench.data.plan import Attempt, code_sha256
from awda_bench.rollout import SettleAfterDone, roll_out
from awda_bench.suites import Suite, load_suite
from awda_bench.trajectory import Trajectory

ENV_CACHE_SIZE = 4
"""Envs a worker keeps built (LRU); MOSAIC units switch env ids, pick-and-place needs two."""


@dataclass
class EpisodeData:
    """Everything one attempt recorded (no batch dimension)."""

    job: Attempt
    success: bool
    """Kept or discarded: the task succeeded at some step (``success_once``; synthesis: every
    waypoint reached). The JSON's ``success`` stays ManiSkill's: success after the last step."""
    actions: np.ndarray
    """(T, 4) float32 env actions."""
    success_steps: np.ndarray
    """(T,) bool: the env's ``success`` after each action."""
    rgb_jpeg: list[bytes]
    """T + 1 JPEG-encoded third-person frames (RGB)."""
    obs: dict[str, Any]
    """Nested dict of (T + 1, ...) arrays (``agent``, ``extra``, ``sensor_param``, and
    ``sensor_data/wrist_depth/depth`` as uint16 millimetres for agent roles)."""
    env_states: dict[str, Any]
    """Nested dict of (T + 1, ...) float32 arrays, the tree of ``env.get_state_dict()``."""
    attributes: dict[str, np.ndarray]
    """(T,) bool mined attributes: ``grasp``, ``press``."""
    truth: dict[str, np.ndarray]
    """(T,) bool simulator truths of the env (``grasp``; ``press`` where the task has it)."""
    meta: dict[str, Any]
    """JSON-able episode description (written to the trajectory file's JSON)."""
    env_info: dict[str, Any]
    """ManiSkill ``env_info``: ``env_id``, ``env_kwargs``, ``max_episode_steps``."""
    timing: dict[str, float] = field(default_factory=dict)
    """Wall time [s] of the episode and of its rendering, frames rendered (never written)."""

    @property
    def steps(self) -> int:
        return len(self.actions)


def _to_numpy_tree(tree: Any) -> Any:
    """Nested dict of (1, ...) tensors/arrays -> nested dict of (...) float32 arrays."""
    if isinstance(tree, dict):
        return {k: _to_numpy_tree(v) for k, v in tree.items()}
    if hasattr(tree, "detach"):
        tree = tree.detach().cpu().numpy()
    return np.asarray(tree, dtype=np.float32)[0]


def _stack_trees(trees: list[Any]) -> Any:
    first = trees[0]
    if isinstance(first, dict):
        return {k: _stack_trees([t[k] for t in trees]) for k in first}
    return np.stack(trees)


def _camera_params(env: Any, uid: str) -> dict[str, np.ndarray]:
    params = env.unwrapped.scene.sensors[uid].get_params()
    out = {}
    for key in ("intrinsic_cv", "extrinsic_cv", "cam2world_gl"):
        value = params[key]
        if hasattr(value, "detach"):
            value = value.detach().cpu().numpy()
        out[key] = np.asarray(value, dtype=np.float32)[0]
    return out


def encode_jpeg(rgb: np.ndarray, quality: int) -> bytes:
    """(H, W, 3) uint8 RGB -> JPEG bytes (OpenCV)."""
    import cv2

    ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not encode a JPEG frame")
    return buf.tobytes()


class EpisodeRecorder:
    """Worker-side: owns the envs (built on first use, LRU-cached) and records jobs."""

    def __init__(self, config: CollectConfig) -> None:
        self.config = config
        self.suite: Suite = load_suite(config.suite, config.suites_dir)
        self.code_sha256 = code_sha256()
        """Hash of the recording code in this process (stamped on every episode)."""
        self._envs: OrderedDict[tuple[str, str], tuple[Any, dict[str, Any]]] = OrderedDict()

    def env_kwargs(self, uid: str, control_mode: str) -> dict[str, Any]:
        """``gym.make`` keyword arguments recorded in the trajectory file (render backend aside:
        it depends on the machine, not on the data)."""
        height, width = self.config.frame_size(self.suite)
        sensors: dict[str, Any] = {"third_person": {"height": height, "width": width}}
        if uid == "panda_awda":
            dh, dw = self.config.depth_size
            sensors["wrist_depth"] = {"height": dh, "width": dw}
        return {
            "robot_uids": uid,
            "control_mode": control_mode,
            "obs_mode": "state",
            "reward_mode": "none",
            "num_envs": 1,
            "sensor_configs": sensors,
        }

    def build_env(self, task: int, role: str) -> tuple[Any, dict[str, Any]]:
        """A freshly built env for ``role`` serving ``task``, and its ManiSkill ``env_info``."""
        import gymnasium as gym

        import awda_bench.envs  # noqa: F401  (registers the envs and robots)
        from awda_bench.demo_recording import EMBODIMENT_UIDS
        from awda_bench.envs.embodiments import embodiment
        from awda_bench.render_device import render_backend

        uid = EMBODIMENT_UIDS[embodiment_of(role)]
        env_id = self.suite.env_id_for(task)
        kwargs = self.env_kwargs(uid, embodiment(uid).control_mode)
        env = gym.make(
            env_id,
            max_episode_steps=self.suite.horizon_steps,
            render_backend=render_backend(),
            **kwargs,
        )
        env_info = {
            "env_id": env_id,
            "env_kwargs": kwargs,
            "max_episode_steps": self.suite.horizon_steps,
        }
        return env, env_info

    def env_for(self, task: int, role: str) -> tuple[Any, dict[str, Any]]:
        """An env for inspection (start-up checks, tests), built once and closed by
        :meth:`close`; recording always uses a fresh one (see :class:`CollectJob`)."""
        key = (self.suite.env_id_for(task), embodiment_of(role))
        if key not in self._envs:
            while len(self._envs) >= ENV_CACHE_SIZE:
                _, (old, _) = self._envs.popitem(last=False)
                old.close()
            self._envs[key] = self.build_env(task, role)
        return self._envs[key]

    def close(self) -> None:
        for env, _ in self._envs.values():
            env.close()
        self._envs.clear()

    def replay(self, env: Any, job: Attempt) -> None:
        """Play ``job`` again without recording anything (rebuilds the env's history)."""
        from awda_bench.episode import seed_globals

        seed_globals(job.seed)
        reset_kwargs = {"seed": job.seed, "options": {"task": self.suite.task(job.task).reset_task}}
        obs, _ = env.reset(**reset_kwargs)
        rec = _Stepper(env)
        if job.role == ROLE_SYNTHESIZED:
            self._play_synthesis(env, rec, job.seed)
        else:
            self._play_expert(env, rec, obs, job)

    def record(self, env: Any, env_info: dict[str, Any], job: Attempt) -> EpisodeData:
        """Play and record ``job`` on ``env``; exceptions propagate (the pool reports them)."""
        from awda_bench.episode import seed_globals

        t_start = time.perf_counter()
        task = self.suite.task(job.task)
        seed_globals(job.seed)
        reset_kwargs = {"seed": job.seed, "options": {"task": task.reset_task}}
        obs, info = env.reset(**reset_kwargs)
        rec = _Recording(
            env,
            self.config,
            with_depth=job.role != ROLE_DEMONSTRATOR,
            image_size=self.config.frame_size(self.suite),
        )
        if job.role == ROLE_SYNTHESIZED:
            success, extra_meta = self._play_synthesis(env, rec, job.seed)
            info = rec.last_info
        else:
            success, extra_meta = self._play_expert(env, rec, obs, job)
            info = rec.last_info
        rec.capture_state(truth=False)
        data = rec.finish(job, success)
        base = env.unwrapped
        flags = {}
        for name in ("success", "success_once", "reached", "grasped"):
            if name in info:
                flags[name] = bool(np.asarray(_numpy(info[name])).reshape(-1)[0])
        data.meta = {
            **{
                "episode_seed": job.seed,
                "reset_kwargs": reset_kwargs,
                "control_mode": base.control_mode,
                "elapsed_steps": data.steps,
                "success": flags.get("success", False),
                "info": flags,
                **job.identity(task, self.suite.name, self.config.split),
                "robot_uid": base.robot_uids,
                "attempt": job.attempt,
                "kept": success,
                "head": 1 if job.role == ROLE_SYNTHESIZED else 0,
                "max_step_m": base.embodiment.max_step_m,
                "control_freq_hz": self.suite.control_freq_hz,
                "code_sha256": self.code_sha256,
                **extra_meta,
            },
            **data.meta,
        }
        data.env_info = env_info
        data.timing["wall_s"] = time.perf_counter() - t_start
        return data

    def _play_expert(
        self, env: Any, rec: _Stepper, obs: Any, job: Attempt
    ) -> tuple[bool, dict[str, Any]]:
        from awda_bench.demo_recording import SETTLE_STEPS
        from awda_bench.episode import EpisodeContext, EpisodeSpec
        from awda_bench.experts import make_expert

        base = env.unwrapped
        expert = make_expert(self.suite.name, embodiment_of(job.role))
        spec = EpisodeSpec(self.suite.name, job.task, job.attempt, job.seed, job.seed)
        expert.reset(EpisodeContext(env=base, spec=spec))
        roll_out(
            rec.step,
            obs,
            lambda obs_t: np.asarray(expert.act(obs_t), dtype=np.float32).reshape(1, 4),
            self.suite.horizon_steps,
            before_step=lambda _t: rec.capture_state(truth=True),
            after_step=SettleAfterDone(expert, SETTLE_STEPS),
        )
        # kept if the task was achieved during the episode (the evaluation's default metric):
        # pressed buttons pop back, so success at the end would discard every press episode
        info = rec.last_info
        key = "success_once" if "success_once" in info else "success"
        success = bool(np.asarray(_numpy(info[key])).reshape(-1)[0])
        return success, {"expert_done": bool(expert.done)}

    def _play_synthesis(self, env: Any, rec: _Stepper, seed: int) -> tuple[bool, dict[str, Any]]:
        from awda_bench.primitives.base import RobotState
        from awda_bench.primitives.config import FreeSpaceConfig
        from awda_bench.primitives.waypoint_tour import WaypointTour

        cfg: SynthesisConfig = self.config.synthesis_config(self.suite)
        base = env.unwrapped
        emb = base.embodiment
        waypoints = cfg.draw_waypoints(seed)
        tour = WaypointTour(waypoints, FreeSpaceConfig(max_step_m=emb.max_step_m), cfg.settle_steps)

        def choose(_obs: Any) -> np.ndarray | None:
            state = RobotState(
                tcp_pos=base.agent.tcp_pose.p[0].cpu().numpy().astype(np.float64),
                gripper_opening_m=float(base.gripper_opening_m()[0]),
            )
            action = tour.step(state)
            if action is None:
                return None
            rec.capture_state(truth=True)  # only states an action follows are recorded
            return emb.to_env_action(np.asarray(action, dtype=np.float32).reshape(1, 4))

        roll_out(rec.step, None, choose, self.suite.horizon_steps)
        reached = tour.reached
        return all(reached), {
            "waypoints": waypoints.tolist(),
            "waypoints_reached": reached,
        }


class _Stepper:
    """Steps the env and keeps the last info; records nothing (replays)."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.last_info: dict[str, Any] = {}

    def capture_state(self, truth: bool) -> None:
        """Nothing to capture when replaying."""

    def step(self, action: np.ndarray) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        """``env.step(action)``, its info kept."""
        result = self.env.step(action)
        self.last_info = result[-1]
        return result


def _numpy(value: Any) -> np.ndarray:
    if hasattr(value, "detach"):
        return value.detach().cpu().numpy()
    return np.asarray(value)


class EpisodeArrays:
    """One episode's per-state and per-action arrays as a recorder accumulates them, and the
    :class:`EpisodeData` they become: the one place the recorded layout is assembled, whichever
    simulator captured the states (ManiSkill's :class:`_Recording`; Meta-World's
    :mod:`awda_bench.data.metaworld_recorder`)."""

    def __init__(
        self,
        config: CollectConfig,
        with_depth: bool,
        third_person: dict[str, np.ndarray],
        image_size: tuple[int, int],
    ) -> None:
        self.config = config
        self.with_depth = with_depth
        self.third_person = third_person
        """The fixed third-person camera's ``intrinsic_cv``, ``extrinsic_cv``, ``cam2world_gl``."""
        self.image_size = image_size
        self.jpeg: list[bytes] = []
        self.depth_mm: list[np.ndarray] = []
        self.wrist_intrinsic: list[np.ndarray] = []
        self.wrist_cam2world: list[np.ndarray] = []
        self.tcp_pose: list[np.ndarray] = []
        self.opening: list[float] = []
        self.qpos: list[np.ndarray] = []
        self.qvel: list[np.ndarray] = []
        self.states: list[Any] = []
        self.truth: dict[str, list[bool]] = {}
        self.actions: list[np.ndarray] = []
        self.success: list[bool] = []
        self.render_s = 0.0
        """Time spent capturing and encoding frames [s] (the capturing recorder adds to it)."""

    def add_frames(self, rgb: np.ndarray, wrist: Any | None) -> None:
        """One state's third-person ``(H, W, 3)`` uint8 RGB (JPEG-encoded here) and, when this
        episode records depth, its wrist depth (``depth_m``, ``intrinsic_cv``, ``cam2world_cv``
        with a leading batch dimension of 1, as :class:`~awda_bench.episode.WristDepth`)."""
        self.jpeg.append(encode_jpeg(rgb, self.config.jpeg_quality))
        if self.with_depth:
            assert wrist is not None
            mm = np.clip(np.round(wrist.depth_m[0] * 1000.0), 0, np.iinfo(np.uint16).max)
            self.depth_mm.append(mm.astype(np.uint16)[..., None])
            self.wrist_intrinsic.append(np.asarray(wrist.intrinsic_cv[0], dtype=np.float32))
            self.wrist_cam2world.append(np.asarray(wrist.cam2world_cv[0], dtype=np.float32))

    def add_state(
        self,
        *,
        tcp_pose: np.ndarray,
        opening_m: float,
        qpos: np.ndarray,
        qvel: np.ndarray,
        env_state: Any,
        truth: dict[str, bool] | None = None,
    ) -> None:
        """One state's robot and env arrays: TCP pose (7,) xyz [m] + wxyz, gripper opening [m],
        joint positions and velocities, the env state tree, and the truths of the state an action
        is taken from (``None`` for the last state)."""
        self.tcp_pose.append(np.asarray(tcp_pose, dtype=np.float32))
        self.opening.append(float(opening_m))
        self.qpos.append(np.asarray(qpos, dtype=np.float32))
        self.qvel.append(np.asarray(qvel, dtype=np.float32))
        self.states.append(env_state)
        for name, value in (truth or {}).items():
            self.truth.setdefault(name, []).append(bool(value))

    def add_action(self, action: np.ndarray, success: bool) -> None:
        """The env action taken from the last state and the env's success flag after it."""
        self.actions.append(np.asarray(action, dtype=np.float32).reshape(4))
        self.success.append(bool(success))

    def trajectory(self, close_when_positive: bool = True) -> Trajectory:
        """States 0..T-1 and the actions as attribute mining reads them (gripper ``> 0``
        closes: the sign flipped when the env's does not)."""
        T = len(self.actions)
        tcp_pose = np.stack(self.tcp_pose)
        opening = np.asarray(self.opening, dtype=np.float32)
        method_actions = np.asarray(self.actions, dtype=np.float32).reshape(T, 4).copy()
        if not close_when_positive:
            method_actions[:, 3] = -method_actions[:, 3]
        return Trajectory(
            tcp_pos=tcp_pose[:T, :3].astype(np.float64),
            gripper_opening_m=opening[:T].astype(np.float64),
            actions=method_actions,
            truth=self.truth_arrays(),
        )

    def truth_arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v, dtype=bool) for k, v in self.truth.items()}

    def finish(self, job: Attempt, success: bool, attributes: dict[str, np.ndarray]) -> EpisodeData:
        """The episode (``attributes``: the ``(T,)`` mined attributes, ``grasp`` and ``press``)."""
        T = len(self.actions)
        n = T + 1
        tcp_pose = np.stack(self.tcp_pose)
        opening = np.asarray(self.opening, dtype=np.float32)
        actions = np.asarray(self.actions, dtype=np.float32).reshape(T, 4)
        tp = self.third_person
        obs: dict[str, Any] = {
            "agent": {"qpos": np.stack(self.qpos), "qvel": np.stack(self.qvel)},
            "extra": {"tcp_pose": tcp_pose, "gripper_opening_m": opening[:, None]},
            "sensor_param": {
                "third_person": {k: np.repeat(v[None], n, axis=0) for k, v in tp.items()}
            },
        }
        if self.with_depth:
            obs["sensor_data"] = {"wrist_depth": {"depth": np.stack(self.depth_mm)}}
            obs["sensor_param"]["wrist_depth"] = {
                "intrinsic_cv": np.stack(self.wrist_intrinsic),
                "cam2world_cv": np.stack(self.wrist_cam2world),
            }
        height, width = self.image_size
        meta: dict[str, Any] = {
            "image_size": [height, width],
            "camera": {k: v.tolist() for k, v in tp.items()},
        }
        frames = n * (2 if self.with_depth else 1)
        return EpisodeData(
            job=job,
            success=success,
            actions=actions,
            success_steps=np.asarray(self.success, dtype=bool),
            rgb_jpeg=self.jpeg,
            obs=obs,
            env_states=_stack_trees(self.states),
            attributes=attributes,
            truth=self.truth_arrays(),
            meta=meta,
            env_info={},
            timing={"render_s": self.render_s, "frames": float(frames)},
        )


class _Recording(_Stepper):
    """Captures one ManiSkill episode's states into :class:`EpisodeArrays`."""

    def __init__(
        self, env: Any, config: CollectConfig, with_depth: bool, image_size: tuple[int, int]
    ) -> None:
        super().__init__(env)
        self.base = env.unwrapped
        self.arrays = EpisodeArrays(
            config, with_depth, _camera_params(env, "third_person"), image_size
        )

    def capture_state(self, truth: bool) -> None:
        from awda_bench.robot.cameras import capture_rgb, capture_wrist_depth

        base, arrays = self.base, self.arrays
        t0 = time.perf_counter()
        rgb = capture_rgb(self.env, "third_person")[0]
        arrays.add_frames(rgb, capture_wrist_depth(self.env) if arrays.with_depth else None)
        arrays.render_s += time.perf_counter() - t0
        arrays.add_state(
            tcp_pose=_numpy(base.agent.tcp_pose.raw_pose)[0],
            opening_m=float(base.gripper_opening_m()[0]),
            qpos=_numpy(base.agent.robot.get_qpos())[0],
            qvel=_numpy(base.agent.robot.get_qvel())[0],
            env_state=_to_numpy_tree(base.get_state_dict()),
            truth={
                name: bool(_numpy(value).reshape(-1)[0])
                for name, value in base.truth_signals().items()
            }
            if truth
            else None,
        )

    def step(self, action: np.ndarray) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        """``env.step(action)``, the action and its success recorded."""
        result = super().step(action)
        self.arrays.add_action(action, bool(_numpy(self.last_info["success"]).reshape(-1)[0]))
        return result

    def finish(self, job: Attempt, success: bool) -> EpisodeData:
        from awda_bench.mining import PressMiningConfig, mine_grasp, mine_press

        trajectory = self.arrays.trajectory(self.base.embodiment.close_when_positive)
        attributes = {
            "grasp": mine_grasp(trajectory),
            "press": mine_press(
                trajectory, PressMiningConfig(max_step_m=self.base.embodiment.max_step_m)
            ),
        }
        return self.arrays.finish(job, success, attributes)

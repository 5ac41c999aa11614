"""Record one Meta-World collection job in a ``.venv-metaworld`` worker: the same
:class:`~awda_bench.data.recorder.EpisodeData` as ManiSkill's recorder, so the trajectory files,
the manifest and every reader of them (``awda_bench.data.datasets``, ``train``) are the same.

Per attempt (``T`` actions, ``T + 1`` states; state ``t`` is the one before action ``t``)::

    env.seed(seed); reset()  (awda_bench.metaworld.layout)                        state 0
    the package's scripted policy (awda_bench.metaworld.rollout.expert_rollout), before
    each action t: record state t: third-person RGB (the suite's camera, corner4, upright;
                   JPEG), gripperPOV wrist depth (agent role; uint16 mm), TCP pose, finger
                   distance, the Sawyer's 7 arm + 2 finger joints, env state
    stop AFTER_SUCCESS_STEPS (5) past the first success, or at the suite's horizon
    record state T
    attributes: grasp mined with SAWYER_GRASP_MINING from the rollout's trajectory (the miner and
                parameters gt-waypoints mines its plan with); press all False (the pressing
                miner is off on Meta-World: MetaWorldScene.configure)

What differs from the ManiSkill collection, and why:

- **Roles.** The reference used the same arm, Meta-World's Sawyer, as agent and demonstrator;
  so do both roles here: the ``demonstrator`` unit of a task is the same expert in other seeded
  layouts of that task (its seeds hashed with the role, as on ManiSkill), recorded without wrist
  depth like ManiSkill's demonstrator.
- **Kept** when Meta-World's per-step ``info["success"]`` was up at any step (it is not
  sticky; the JSON's ``success`` is the flag after the last action, ``info.success_once`` any
  step). Episodes stop 5 steps after the first success (the reference's demo cut, as the
  gt-waypoints plan), not after ManiSkill's expert settle steps.
- **Actions** are Meta-World's own (the hand's mocap moves ``a[:3] x 1 cm``, ``a[3] > 0``
  closes): what the expert stepped, what T-OSVI learns and plays back.
- **Env states** are the MuJoCo model's ``qpos``, ``qvel``, ``mocap_pos`` and ``mocap_quat``
  (float32, as ManiSkill's state trees): enough to put a scene back for a look (``mj_forward``),
  not to continue it bit-exactly (the solver's warm start and the env's Python attributes are not
  stored); an exact replay is the layout of ``episode_seed`` and the actions.
- **No simulator truth** (``truth/`` is empty): Meta-World has no grasp or press signal common
  to its tasks (``info["grasp_success"]`` means something else on every task).
- **No history to replay.** A ManiSkill job replays the unit's earlier attempts first (PhysX
  carries contact caches between episodes); Meta-World's reset clears the whole simulation, so an
  attempt records the same whatever was played before (``tests/test_metaworld_suite.py``), and
  :meth:`MetaWorldRecorder.replay` does nothing.
- **Trajectory synthesis** (``synthesized`` units, agent role, head 1): the hand driven open
  through 1-3 random waypoints of :data:`~awda_bench.data.config.METAWORLD_SYNTHESIS` in the task's
  seeded layout (:mod:`awda_bench.metaworld.synthesis`), recorded like an agent episode (frames,
  wrist depth, states, Meta-World's actions, the grasp mined by the same miner); kept when every
  waypoint was reached, ending ``settle_steps`` after the last one.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from awda_bench.data.config import ROLE_DEMONSTRATOR, ROLE_SYNTHESIZED, CollectConfig
from awda_bench.data.plan import Attempt, code_sha256
from awda_bench.data.recorder import EpisodeArrays, EpisodeData
from awda_bench.suites import Suite, load_suite

ROBOT_UID = "sawyer"
"""What the trajectory files call the arm (both roles)."""

CONTROL_MODE = "mocap_delta_pos"
"""What they call Meta-World's action space (the hand's mocap target moves ``a[:3] x 1 cm``)."""


class MetaWorldRecorder:
    """Worker-side: records attempts of a Meta-World suite's tasks (see the module docstring).
    The counterpart of :class:`~awda_bench.data.recorder.EpisodeRecorder`, with its methods."""

    def __init__(self, config: CollectConfig) -> None:
        self.config = config
        self.suite: Suite = load_suite(config.suite, config.suites_dir)
        self.code_sha256 = code_sha256()
        """Hash of the recording code in this process (stamped on every episode)."""
        self._env: Any = None

    def env_kwargs(self, role: str) -> dict[str, Any]:
        """What the trajectory file's ``env_info.env_kwargs`` records of the cameras."""
        height, width = self.config.frame_size(self.suite)
        sensors: dict[str, Any] = {
            "third_person": {"camera": self.suite.camera.name, "height": height, "width": width}
        }
        if role != ROLE_DEMONSTRATOR:
            from awda_bench.metaworld.observations import WRIST_CAMERA

            dh, dw = self.config.depth_size
            sensors["wrist_depth"] = {"camera": WRIST_CAMERA, "height": dh, "width": dw}
        return {"robot_uids": ROBOT_UID, "control_mode": CONTROL_MODE, "sensor_configs": sensors}

    def build_env(self, task: int, role: str) -> tuple[Any, dict[str, Any]]:
        """A :class:`~awda_bench.metaworld.env.MetaWorldEnv` of the suite and the ``env_info``
        (``env_id``: the Meta-World task name)."""
        from awda_bench.metaworld.env import MetaWorldEnv

        env_info = {
            "env_id": self.suite.task(task).name,
            "env_kwargs": self.env_kwargs(role),
            "max_episode_steps": self.suite.horizon_steps,
        }
        return MetaWorldEnv(self.suite), env_info

    def env_for(self, task: int, role: str) -> tuple[Any, dict[str, Any]]:
        """An env with ``task``'s first layout rendered once (the worker's start-up check: a
        broken renderer stops the collection before any job); closed by :meth:`close`."""
        self.close()
        env, env_info = self.build_env(task, role)
        self._env = env
        env.reset(seed=0, options={"task": self.suite.task(task).reset_task})
        _third_person(env, self.config.frame_size(self.suite))
        return env, env_info

    def close(self) -> None:
        if self._env is not None:
            self._env.close()
        self._env = None

    def replay(self, env: Any, job: Attempt) -> None:
        """Nothing: an attempt's recording does not depend on the env's history."""

    def record(self, env: Any, env_info: dict[str, Any], job: Attempt) -> EpisodeData:
        """Play and record ``job`` on ``env``; exceptions propagate (the pool reports them)."""
        from awda_bench.metaworld.rollout import expert_rollout
        from awda_bench.metaworld.sawyer import SAWYER_GRASP_MINING, STEP_M, mocap_offset
        from awda_bench.metaworld.synthesis import synthesized_rollout
        from awda_bench.mining import mine_grasp

        t_start = time.perf_counter()
        task = self.suite.task(job.task)
        reset_kwargs = {"seed": job.seed, "options": {"task": task.reset_task}}
        env.reset(**reset_kwargs)
        task_env = env.task_env
        size = self.config.frame_size(self.suite)
        intrinsic, cam2world = _camera_params(env, size)
        arrays = EpisodeArrays(
            self.config,
            with_depth=job.role != ROLE_DEMONSTRATOR,
            third_person={
                "intrinsic_cv": intrinsic.astype(np.float32),
                "extrinsic_cv": np.linalg.inv(cam2world)[:3, :].astype(np.float32),
                "cam2world_gl": (cam2world @ np.diag([1.0, -1.0, -1.0, 1.0])).astype(np.float32),
            },
            image_size=size,
        )

        def capture(_t: int = 0) -> None:
            self._capture(env, arrays)

        extra_meta: dict[str, Any]
        if job.role == ROLE_SYNTHESIZED:
            synthesis = self.config.synthesis_config(self.suite)
            waypoints = synthesis.draw_waypoints(job.seed)
            synthesized = synthesized_rollout(
                task_env,
                waypoints,
                self.suite.horizon_steps,
                synthesis.settle_steps,
                before_step=capture,
            )
            rollout = synthesized.rollout
            kept = all(synthesized.reached)
            extra_meta = {
                "expert_done": False,
                "waypoints": waypoints.tolist(),
                "waypoints_reached": synthesized.reached,
            }
        else:
            rollout = expert_rollout(
                task_env,
                env.task_name,
                self.suite.horizon_steps,
                mocap_offset(task_env),
                before_step=capture,
            )
            kept = bool(rollout.success.any())
            extra_meta = {"expert_done": kept}
        capture()  # state T
        for action, success in zip(rollout.env_actions, rollout.success, strict=True):
            arrays.add_action(action, bool(success))
        success_once = bool(rollout.success.any())
        T = len(rollout.env_actions)
        attributes = {
            "grasp": mine_grasp(rollout.trajectory, SAWYER_GRASP_MINING),
            "press": np.zeros(T, dtype=bool),
        }
        data = arrays.finish(job, kept, attributes)
        flags = {"success": bool(rollout.success[-1]), "success_once": success_once}
        data.meta = {
            **{
                "episode_seed": job.seed,
                "reset_kwargs": reset_kwargs,
                "control_mode": CONTROL_MODE,
                "elapsed_steps": T,
                "success": flags["success"],
                "info": flags,
                **job.identity(task, self.suite.name, self.config.split),
                "robot_uid": ROBOT_UID,
                "attempt": job.attempt,
                "kept": kept,
                "head": 1 if job.role == ROLE_SYNTHESIZED else 0,
                "max_step_m": STEP_M,
                "control_freq_hz": self.suite.control_freq_hz,
                "code_sha256": self.code_sha256,
                "success_step": rollout.success_step,
                **extra_meta,
            },
            **data.meta,
        }
        data.env_info = env_info
        data.timing["wall_s"] = time.perf_counter() - t_start
        return data

    def _capture(self, env: Any, arrays: EpisodeArrays) -> None:
        """Record the state ``env`` is in now."""
        from awda_bench.metaworld.observations import wrist_capture
        from awda_bench.metaworld.sawyer import robot_state

        task_env = env.task_env
        t0 = time.perf_counter()
        rgb = _third_person(env, arrays.image_size)
        wrist = wrist_capture(env, *self.config.depth_size) if arrays.with_depth else None
        arrays.add_frames(rgb, wrist)
        arrays.render_s += time.perf_counter() - t0
        data = task_env.data
        state = robot_state(task_env)
        arrays.add_state(
            tcp_pose=np.concatenate([state.tcp_pos, np.asarray(data.body("hand").xquat)]),
            opening_m=state.gripper_opening_m,
            qpos=np.asarray(data.qpos[:9]),
            qvel=np.asarray(data.qvel[:9]),
            env_state={
                "qpos": np.asarray(data.qpos, dtype=np.float32),
                "qvel": np.asarray(data.qvel, dtype=np.float32),
                "mocap_pos": np.asarray(data.mocap_pos, dtype=np.float32).reshape(-1),
                "mocap_quat": np.asarray(data.mocap_quat, dtype=np.float32).reshape(-1),
            },
        )


def _third_person(env: Any, size: tuple[int, int]) -> np.ndarray:
    """The suite camera's ``(H, W, 3)`` uint8 frame of ``env`` now, at ``size``."""
    camera = env.suite.camera
    task_env = env.task_env
    frame = env.renderer.capture(
        task_env.model, task_env.data, camera.name, height=size[0], width=size[1]
    )
    assert frame.rgb is not None
    return frame.rgb


def _camera_params(env: Any, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The suite camera's ``intrinsic_cv`` (3, 3) and camera-to-world (4, 4, OpenCV axes) for an
    upright ``size`` image (the camera is fixed: one state's are every state's)."""
    from awda_bench.metaworld.renderer import camera_pose

    task_env = env.task_env
    intrinsic, cam2world, _ = camera_pose(
        task_env.model, task_env.data, env.suite.camera.name, size[0], size[1]
    )
    return intrinsic, cam2world

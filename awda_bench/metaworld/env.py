"""A Meta-World suite's tasks behind the harness's env interface (what
:func:`awda_bench.evaluation.episode_runner.run_episode` calls).

::

    reset(seed=s, options={"task": i})   task i's Meta-World env (built once per process),
                                         layout of seed s (awda_bench.metaworld.layout)
    step(a)                              a: (4,) or (1, 4) in [-1, 1]; Meta-World's own action:
                                         hand (mocap) moves a[:3] x 1 cm, a[3] > 0 closes
    info["success"]                      Meta-World's per-step flag (not sticky: the harness's
                                         success_once is "any step")
    info["reached"], info["grasped"]     the grasp analysis (SPEC §7), latched, on the task's
                                         object (Meta-World's obs[4:7]): reached = the TCP within
                                         REACH_THRESHOLD_M of it before the first grip command;
                                         grasped = reached, then the object raised
                                         LIFT_THRESHOLD_M above its start
    grip_outcome(a)                      what a closes the gripper on: the object (within
                                         REACH_THRESHOLD_M of the TCP: "target") or nothing
    place_goal(), is_grasping_target(),  the carry analysis's questions (awda_bench.evaluation.
    target_position(), grip_commanded(a) carry), on the tasks of PLACE_TOLERANCE_M: the goal
                                         and its radius, the object touched by a finger pad
    episode_observations(spec, extras)   what an observation-only policy sees

The obs ``reset`` and ``step`` return is Meta-World's 39-number state (with the goal): it reaches
privileged methods only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from awda_bench.episode import EpisodeSpec
from awda_bench.errors import UsageError
from awda_bench.metaworld.layout import make_task_env, reset_to_layout
from awda_bench.metaworld.observations import MetaWorldObservations
from awda_bench.metaworld.renderer import FrameRenderer, process_renderer
from awda_bench.suites import Suite

REACH_THRESHOLD_M = 0.04
"""*Reached*: the TCP within this of the task's object [m] (SPEC §7; the ManiSkill tasks'
``reach_threshold_m``)."""
LIFT_THRESHOLD_M = 0.05
"""*Grasped*: reached, then the object raised this far above its start height [m] (the ManiSkill
tasks' ``lift_threshold_m``). Objects fixed to a fixture (buttons, handles, the lock) never rise:
grasped stays False on those tasks."""

PLACE_TOLERANCE_M: dict[str, float] = {
    "pick-place-v3": 0.07,
    "pick-place-wall-v3": 0.07,
    "sweep-v3": 0.05,
    "sweep-into-v3": 0.05,
}
"""The tasks whose object is carried to a goal and get the carry analysis
(:mod:`awda_bench.evaluation.carry`): the held-out carries (pick-place-wall, sweep-into) and their
training siblings, each with Meta-World's own success radius (object to goal, its
``evaluate_state``), the tolerance a release is judged *over its goal* by."""

MAX_PATH_LENGTH = 500
"""Steps after which a Meta-World env refuses to step without a reset (its ``max_path_length``)."""


class MetaWorldEnv:
    """Every task of ``suite``; one task env per task name, built on first use and reused."""

    simulator = "metaworld"
    num_envs = 1

    def __init__(self, suite: Suite, *, render_mode: str | None = None) -> None:
        if suite.horizon_steps > MAX_PATH_LENGTH:
            raise UsageError(
                f"suite {suite.name!r}: horizon {suite.horizon_steps} exceeds Meta-World's "
                f"{MAX_PATH_LENGTH} steps per episode"
            )
        if suite.camera.name is None:
            raise UsageError(f"suite {suite.name!r}: name the third-person camera ([camera] name)")
        self.suite = suite
        self.render_mode = render_mode
        self.renderer: FrameRenderer = process_renderer()
        self._task_envs: dict[str, Any] = {}
        self.task_name: str | None = None
        """The current task's Meta-World name (``None`` before the first reset)."""
        self.seed: int | None = None
        """The current episode's layout seed."""
        self.last_success = False
        """``info["success"]`` of the last step (False after a reset)."""
        self.reached = False
        """The grasp analysis's latched flags of this episode (module docstring)."""
        self.grasped = False
        self.grip_attempted = False
        self._object_start_z = 0.0

    @property
    def unwrapped(self) -> MetaWorldEnv:
        return self

    @property
    def task_env(self) -> Any:
        """The current task's ``SawyerXYZEnv`` (its ``model`` and ``data`` are the scene)."""
        if self.task_name is None:
            raise RuntimeError("MetaWorldEnv used before reset()")
        return self._task_envs[self.task_name]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Task ``options["task"]`` (a suite task index) in the layout of ``seed`` (required: an
        unseeded layout would not be reproducible)."""
        if seed is None or options is None or "task" not in options:
            raise UsageError("MetaWorldEnv.reset needs seed= and options={'task': index}")
        name = self.suite.task(int(options["task"])).name
        if name not in self._task_envs:
            self._task_envs[name] = make_task_env(name)
        self.task_name = name
        self.seed = int(seed)
        self.last_success = False
        obs = reset_to_layout(self._task_envs[name], seed)
        self.grip_attempted = self.grasped = False
        self._object_start_z = float(self._object_pos()[2])
        self.reached = self._object_distance() <= REACH_THRESHOLD_M
        return obs, {"reached": self.reached, "grasped": False}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = np.clip(np.asarray(action, dtype=np.float32).reshape(-1)[:4], -1.0, 1.0)
        self.grip_attempted |= bool(a[3] > 0)  # the grip is latched on the commanded action
        obs, reward, terminated, truncated, info = self.task_env.step(a)
        self.last_success = bool(info.get("success", 0.0))
        if not self.grip_attempted:
            self.reached |= self._object_distance() <= REACH_THRESHOLD_M
        lifted = self._object_pos()[2] - self._object_start_z >= LIFT_THRESHOLD_M
        self.grasped |= self.reached and bool(lifted)
        info = {**info, "reached": self.reached, "grasped": self.grasped}
        return np.asarray(obs, dtype=np.float64), float(reward), terminated, truncated, info

    def _object_pos(self) -> np.ndarray:
        """The task's object [m] (Meta-World's ``obs[4:7]``: the puck, the cube, the button, the
        window's handle, the lock, ...)."""
        return np.asarray(self.task_env._get_pos_objects(), dtype=np.float64).reshape(-1)[:3]

    def _object_distance(self) -> float:
        from awda_bench.metaworld.sawyer import robot_state

        return float(np.linalg.norm(robot_state(self.task_env).tcp_pos - self._object_pos()))

    def object_distances(self) -> tuple[np.ndarray, np.ndarray]:
        """``(1, 1)`` TCP-to-object distance [m] and ``(1,)`` the target's index (0): one object
        per task, so a first grip is on the target or on nothing."""
        return np.array([[self._object_distance()]]), np.zeros(1, dtype=np.int64)

    def grip_outcome(self, action: Any) -> np.ndarray:
        """``(1,)``: -1 where ``action`` does not close the gripper, else 0 (the object within
        :data:`REACH_THRESHOLD_M` of the TCP: ``target``) or 2 (``nothing``), indices into
        :data:`~awda_bench.episode.GRIP_OUTCOMES`."""
        if not float(np.asarray(action, dtype=np.float64).reshape(-1)[3]) > 0:
            return np.array([-1])
        return np.array([0 if self._object_distance() <= REACH_THRESHOLD_M else 2])

    def place_goal(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``((1, 3) goal [m], (1,) tolerance [m])`` on a task that carries its object to a goal
        (:data:`PLACE_TOLERANCE_M`: Meta-World's ``_target_pos`` and success radius), else
        ``None``."""
        tolerance = PLACE_TOLERANCE_M.get(self.task_name or "")
        if tolerance is None:
            return None
        goal = np.asarray(self.task_env._target_pos, dtype=np.float64).reshape(1, 3)
        return goal, np.array([tolerance])

    def is_grasping_target(self) -> np.ndarray:
        """``(1,)``: a finger pad touches the task's object (Meta-World's
        ``touching_main_object``)."""
        return np.array([bool(self.task_env.touching_main_object)])

    def target_position(self) -> np.ndarray:
        """``(1, 3)``: the task's object [m]."""
        return self._object_pos().reshape(1, 3)

    def grip_commanded(self, action: Any) -> np.ndarray:
        """``(1,)``: ``action`` closes the gripper (``a[3] > 0``)."""
        return np.array([float(np.asarray(action, dtype=np.float64).reshape(-1)[3]) > 0])

    def episode_observations(
        self, spec: EpisodeSpec, extras: dict[str, Any]
    ) -> MetaWorldObservations:
        return MetaWorldObservations(self, spec, extras)

    def render(self) -> np.ndarray:
        """The third-person frame now, ``(H, W, 3)`` uint8 (videos)."""
        camera = self.suite.camera
        assert camera.name is not None
        env = self.task_env
        frame = self.renderer.capture(
            env.model, env.data, camera.name, height=camera.height, width=camera.width
        )
        assert frame.rgb is not None
        return frame.rgb

    def close(self) -> None:
        for env in self._task_envs.values():
            env.close()
        self._task_envs.clear()
        self.renderer.close()

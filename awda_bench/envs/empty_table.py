"""``AWDA-EmptyTable-v1``: the robot on ManiSkill's table and nothing else.

The scene for controller checks and benchmarks (IK tracking, control-mode speed comparisons), so
they measure the robot and not a task. Works with any Panda-shaped agent and any of its control
modes. Like the tasks it has exact state round trips (:class:`awda_bench.envs.exact_state
.ExactStateEnv`) and a render camera (the third-person view), so ManiSkill's ``RecordEpisode``
can write its videos.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import torch
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils.registration import register_env
from mani_skill.utils.scene_builder.table import TableSceneBuilder

from awda_bench.envs.exact_state import ExactStateEnv
from awda_bench.errors import UsageError
from awda_bench.robot.ik import REST_QPOS


@register_env("AWDA-EmptyTable-v1", max_episode_steps=200)
class EmptyTableEnv(ExactStateEnv):
    """**Task Description:** none; the Panda stands at its rest pose on an empty table.

    **Randomizations:** none (the robot starts at the rest keyframe every episode). There is
    one variation: ``reset(options={"task": 0})``; any other value is refused.

    **Success Conditions:** none (``success`` is always False).
    """

    SUPPORTED_ROBOTS = ["panda_awda", "panda"]
    num_variations: ClassVar[int] = 1
    """Valid ``options["task"]`` values: only 0 (as the tasks' attribute of the same name)."""

    def __init__(self, *args, robot_uids: str = "panda_awda", **kwargs) -> None:
        super().__init__(*args, robot_uids=robot_uids, **kwargs)

    @property
    def _default_sensor_configs(self) -> list:
        from awda_bench.robot.cameras import third_person_camera_config

        return [third_person_camera_config()]

    @property
    def _default_human_render_camera_configs(self) -> CameraConfig:
        from awda_bench.robot.cameras import third_person_camera_config

        return dataclasses.replace(third_person_camera_config(), uid="render_camera")

    def _load_agent(self, options: dict) -> None:
        import sapien

        super()._load_agent(options, sapien.Pose(p=[-0.615, 0, 0]))

    def _load_scene(self, options: dict) -> None:
        self.table_scene = TableSceneBuilder(self)
        self.table_scene.build()

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict) -> None:
        task = torch.as_tensor(options.get("task", 0)).reshape(-1)
        if task.numel() == 0 or bool((task != 0).any()):
            raise UsageError(
                f"AWDA-EmptyTable-v1 has one variation: options['task'] must be 0, got "
                f"{options['task']!r}"
            )
        with torch.device(self.device):
            self.table_scene.initialize(env_idx)
            qpos = torch.as_tensor(REST_QPOS, dtype=torch.float32).repeat(len(env_idx), 1)
            self.agent.reset(qpos)
            import sapien

            self.agent.robot.set_pose(sapien.Pose(p=[-0.615, 0, 0]))

    def evaluate(self) -> dict:
        return {"success": torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)}

    def _get_obs_extra(self, info: dict) -> dict:
        return {"tcp_pos": self.agent.tcp.pose.p}

    def compute_dense_reward(self, obs, action, info) -> torch.Tensor:
        return torch.zeros(self.num_envs, device=self.device)

    def compute_normalized_dense_reward(self, obs, action, info) -> torch.Tensor:
        return self.compute_dense_reward(obs, action, info)

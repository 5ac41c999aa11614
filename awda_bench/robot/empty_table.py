"""``AWDA-EmptyTable-v1``: the robot on ManiSkill's table and nothing else.

The scene for controller checks and benchmarks (IK tracking, control-mode speed comparisons), so
they measure the robot and not a task. Works with any Panda-shaped agent and any of its control
modes.
"""

from __future__ import annotations

import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.utils.registration import register_env
from mani_skill.utils.scene_builder.table import TableSceneBuilder

from awda_bench.robot.ik import REST_QPOS


@register_env("AWDA-EmptyTable-v1", max_episode_steps=200)
class EmptyTableEnv(BaseEnv):
    """**Task Description:** none; the Panda stands at its rest pose on an empty table.

    **Randomizations:** none (the robot starts at the rest keyframe every episode).

    **Success Conditions:** none (``success`` is always False).
    """

    SUPPORTED_ROBOTS = ["panda_awda", "panda"]

    def __init__(self, *args, robot_uids: str = "panda_awda", **kwargs) -> None:
        super().__init__(*args, robot_uids=robot_uids, **kwargs)

    @property
    def _default_sensor_configs(self) -> list:
        from awda_bench.robot.cameras import third_person_camera_config

        return [third_person_camera_config()]

    def _load_agent(self, options: dict) -> None:
        import sapien

        super()._load_agent(options, sapien.Pose(p=[-0.615, 0, 0]))

    def _load_scene(self, options: dict) -> None:
        self.table_scene = TableSceneBuilder(self)
        self.table_scene.build()

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict) -> None:
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

"""Robots: the ``panda_awda`` agent (registered with ManiSkill on import), its mink IK and cameras."""

from awda_bench.robot.agent import CONTROL_MODE, WRIST_CAMERA, PandaAwda

__all__ = ["CONTROL_MODE", "WRIST_CAMERA", "PandaAwda"]

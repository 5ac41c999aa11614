"""The MuJoCo model mink solves on, compiled from the very URDF ManiSkill loads for the Panda.

One robot description, two engines: SAPIEN simulates ``panda_v2.urdf``; MuJoCo (through
``mujoco.MjSpec``) compiles the same file's kinematic tree for mink. Meshes are dropped (IK needs
kinematics only, and MuJoCo cannot read the ``.glb`` visuals); ``fusestatic="false"`` keeps the
fixed-joint link ``panda_hand_tcp`` as a body, on which a site ``tcp`` is hung for mink's frame task.
"""

from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
from mani_skill import PACKAGE_ASSET_DIR

PANDA_URDF = Path(PACKAGE_ASSET_DIR) / "robots" / "panda" / "panda_v2.urdf"
"""The Panda description ManiSkill's ``panda`` agent (and our ``panda_awda``) loads."""

TCP_BODY = "panda_hand_tcp"
"""URDF link whose origin is the tool centre point (between the finger pads)."""
TCP_SITE = "tcp"
"""Name of the MuJoCo site placed at :data:`TCP_BODY` (mink's frame task targets it)."""
ARM_JOINTS: tuple[str, ...] = tuple(f"panda_joint{i}" for i in range(1, 8))
"""The seven arm joints IK drives; the two finger joints are left to the gripper controller."""


def _kinematic_urdf(urdf_path: Path) -> str:
    """The URDF's text with visual/collision geometry removed and MuJoCo compiler flags added."""
    root = ET.parse(urdf_path).getroot()
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    compiler = ET.SubElement(ET.SubElement(root, "mujoco"), "compiler")
    compiler.set("fusestatic", "false")
    compiler.set("discardvisual", "true")
    compiler.set("balanceinertia", "true")
    compiler.set("inertiafromgeom", "false")
    return ET.tostring(root, encoding="unicode")


@functools.cache
def panda_spec_xml(urdf_path: Path = PANDA_URDF) -> str:
    """MJCF text of the compiled kinematic Panda with the TCP site (cached per process)."""
    spec = mujoco.MjSpec.from_string(_kinematic_urdf(urdf_path))
    body = spec.body(TCP_BODY)
    if body is None:
        raise RuntimeError(f"{urdf_path} has no link {TCP_BODY!r}; the TCP site cannot be placed")
    body.add_site(name=TCP_SITE, size=[0.005, 0.005, 0.005])
    spec.compile()
    return spec.to_xml()


def load_panda_model(urdf_path: Path = PANDA_URDF) -> mujoco.MjModel:
    """A fresh ``MjModel`` of the Panda (one per controller: mink keeps its own ``MjData``)."""
    return mujoco.MjModel.from_xml_string(panda_spec_xml(urdf_path))

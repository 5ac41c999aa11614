"""mink IK on the Panda model compiled from ManiSkill's URDF (no simulator needed)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from awda_bench.robot.ik import REST_QPOS, IKConfig, PandaIK
from awda_bench.robot.panda_model import ARM_JOINTS, PANDA_URDF, TCP_SITE, load_panda_model


def test_model_is_compiled_from_maniskill_urdf() -> None:
    model = load_panda_model()
    joints = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, i) for i in range(model.njnt)]
    assert joints[:7] == list(ARM_JOINTS)
    assert model.site(TCP_SITE).id >= 0
    assert PANDA_URDF.name == "panda_v2.urdf" and "mani_skill" in str(PANDA_URDF)
    # joint limits come from the URDF (panda_joint4 is the only all-negative one)
    assert model.jnt_range[3] == pytest.approx([-3.0718, -0.0698])


def test_rest_pose_points_down() -> None:
    ik = PandaIK()
    rotation = ik.tcp_rotation(REST_QPOS)
    assert rotation[:, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-3)


def test_error_decreases_and_converges() -> None:
    ik = PandaIK(IKConfig(max_iterations=1, tolerance_m=1e-9))
    q = REST_QPOS.copy()
    target = ik.tcp_position(q) + np.array([0.05, -0.04, 0.03])
    errors = []
    for _ in range(8):
        q_arm, error = ik.solve(q, target)
        q[:7] = q_arm
        errors.append(error)
    assert all(b < a for a, b in zip(errors, errors[1:], strict=False) if a > 1e-7)
    assert errors[-1] < 1e-4


def test_one_call_per_step_converges_on_a_fixed_target() -> None:
    """The controller solves once per step, warm-started from the last solution: a 2 cm move
    leaves ~1 mm after one call and the next call toward the same target removes it."""
    ik = PandaIK()
    rng = np.random.default_rng(0)
    q = REST_QPOS.copy()
    for _ in range(50):
        target = ik.tcp_position(q) + rng.uniform(-0.02, 0.02, 3)
        q_arm, first = ik.solve(q, target)
        assert first < 2e-3
        q_arm, second = ik.solve(q_arm, target)
        assert second < 5e-5
        q[:7] = q_arm


def test_unreachable_target_stays_finite_and_within_limits() -> None:
    ik = PandaIK()
    model = ik.model
    q = REST_QPOS.copy()
    for target in ([3.0, 0.0, 0.5], [0.0, 0.0, -2.0], [0.0, 2.5, 2.5]):
        for _ in range(20):
            q_arm, error = ik.solve(q, np.array(target))
            q[:7] = q_arm
        assert np.all(np.isfinite(q))
        assert np.all(q[:7] >= model.jnt_range[:7, 0] - 1e-6)
        assert np.all(q[:7] <= model.jnt_range[:7, 1] + 1e-6)
        assert error > 0.1  # honestly reports it did not get there


def test_solve_delta_clips_to_workspace() -> None:
    ik = PandaIK()
    low, high = np.array([0.2, -0.5, 0.01]), np.array([0.85, 0.5, 0.7])
    _q, target, _err = ik.solve_delta(REST_QPOS, np.array([0.0, 0.0, -5.0]), low, high)
    assert target[2] == pytest.approx(0.01)


def test_bad_qpos_shape_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="qpos must have shape"):
        PandaIK().solve(np.zeros(5), np.zeros(3))


def test_config_validation_names_the_field() -> None:
    with pytest.raises(ValueError, match="max_iterations"):
        IKConfig(max_iterations=0)

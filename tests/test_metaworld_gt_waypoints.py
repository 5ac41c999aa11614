"""``gt-waypoints`` on Meta-World (:mod:`awda_bench.metaworld.gt_scene`, ``.state``, ``.sawyer``).

The mocap driver is plain NumPy and is tested here directly; what needs ``metaworld`` runs in
``.venv-metaworld``: a script through its interpreter (restore, mining), and the method through
the harness's workers.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from metaworld_env import metaworld_python, needs_metaworld

from awda_bench.evaluation.results_store import ResultsStore
from awda_bench.evaluation.sweep import SweepConfig, run_sweep
from awda_bench.metaworld.sawyer import STEP_M, TRACKING_GAIN, mocap_action, tracking_command
from awda_bench.runtimes import PROJECT_ROOT
from awda_bench.suites import load_suite


def _fake_env(tcp: np.ndarray, mocap: np.ndarray) -> SimpleNamespace:
    """What the driver reads of a ``SawyerXYZEnv``: the finger sites and the mocap."""
    half = np.array([0.02, 0.0, 0.0])
    sites = {
        "leftEndEffector": SimpleNamespace(xpos=tcp - half),
        "rightEndEffector": SimpleNamespace(xpos=tcp + half),
    }
    data = SimpleNamespace(site=sites.__getitem__, mocap_pos=np.asarray(mocap)[None])
    return SimpleNamespace(data=data)


def test_the_mocap_action_leads_the_tcp_by_the_gain_and_tracking_command_inverts_it() -> None:
    tcp = np.array([0.1, 0.6, 0.1])
    offset = np.array([-0.004, 0.0, 0.049])
    mocap = tcp + offset + np.array([0.003, 0.0, 0.0])  # the mocap 3 mm ahead in x
    env = _fake_env(tcp, mocap)
    command = np.array([0.1, -0.1, 0.0, 1.0])  # 1 mm in +x, 1 mm in -y, closed
    action = mocap_action(env, command, offset)
    target = tcp + offset + TRACKING_GAIN * STEP_M * command[:3]
    assert np.allclose(mocap + action[:3] * STEP_M, target, atol=1e-7)
    assert action[3] == 1.0
    assert np.allclose(tracking_command(tcp, target, offset), command[:3])
    far = mocap_action(env, np.array([1.0, 0.0, 0.0, -1.0]), offset)  # 5 cm lead asked
    assert float(np.max(np.abs(far[:3]))) == pytest.approx(1.0)  # Meta-World's 1 cm per step


CHECKS = r"""
import json, sys
import numpy as np
from awda_bench.metaworld.layout import make_task_env, reset_to_layout
from awda_bench.metaworld.expert import expert_action, task_policy
from awda_bench.metaworld.state import save_state, restore_state
from awda_bench.metaworld.gt_scene import expert_trajectory
from awda_bench.metaworld.sawyer import SAWYER_GRASP_MINING, mocap_offset
from awda_bench.mining import mine_grasp

def rollout(env, obs, name, steps):
    policy, out = task_policy(name), []
    for _ in range(steps):
        obs, reward, *_, info = env.step(expert_action(policy, obs)[0])
        out.append(np.concatenate([obs, [reward, info["success"]], env.data.qpos, env.data.qvel]))
    return np.array(out)

result = {"restore": {}, "grasp": {}}
for name in ("sweep-into-v3", "pick-place-wall-v3"):
    env = make_task_env(name)
    obs = reset_to_layout(env, 11)
    rng = np.random.default_rng(0)
    for _ in range(7):
        obs, *_ = env.step(rng.uniform(-1, 1, 4).astype(np.float32))
    saved = save_state(env)
    first = rollout(env, obs, name, 60)
    restore_state(env, saved)
    second = rollout(env, obs, name, 60)
    result["restore"][name] = [bool(np.array_equal(first, second)), int(env.curr_path_length)]
for name in ("pick-place-wall-v3", "door-unlock-v3"):
    env = make_task_env(name)
    reset_to_layout(env, 3)
    start = env._get_pos_objects()[:3].copy()
    traj = expert_trajectory(env, name, 300, mocap_offset(env))
    grasp = mine_grasp(traj, SAWYER_GRASP_MINING)
    onset = int(np.flatnonzero(grasp)[0]) if grasp.any() else -1
    at = traj.tcp_pos[onset].tolist() if onset >= 0 else None
    result["grasp"][name] = {"onset": onset, "tcp": at, "object": start.tolist(),
                             "success_step": traj.meta["success_step"]}
print(json.dumps(result))
"""


@pytest.fixture(scope="module")
def checks() -> dict:
    python = metaworld_python()
    assert python is not None
    env = {**os.environ, "PYTHONPATH": str(PROJECT_ROOT), "MUJOCO_GL": "egl"}
    out = subprocess.run(
        [python, "-c", CHECKS], capture_output=True, text=True, check=True, env=env, timeout=600
    ).stdout
    return json.loads(out.strip().splitlines()[-1])


@needs_metaworld
def test_a_restored_rollout_is_bit_identical(checks: dict) -> None:
    # sweep-into keeps a view of MuJoCo's memory as an attribute (its reward reads it)
    for name, (identical, path_length) in checks["restore"].items():
        assert identical, name
        assert path_length == 67, name  # 7 + 60: the step counter was restored too


@needs_metaworld
def test_the_mined_grasp_starts_on_the_object_and_pushing_closed_is_not_a_grasp(
    checks: dict,
) -> None:
    pick = checks["grasp"]["pick-place-wall-v3"]
    assert pick["success_step"] > 0 and pick["onset"] > 0
    tcp, puck = np.array(pick["tcp"]), np.array(pick["object"])
    assert np.linalg.norm(tcp[:2] - puck[:2]) < 0.02  # closing around the puck
    assert abs(tcp[2] - puck[2]) < 0.03
    door = checks["grasp"]["door-unlock-v3"]  # the expert pushes the lock with the hand closed
    assert door["success_step"] > 0 and door["onset"] == -1


@pytest.mark.slow
@needs_metaworld
def test_gt_waypoints_picks_over_the_wall_and_presses_the_button_through_the_harness(
    tmp_path: Path,
) -> None:
    suite = load_suite("metaworld")
    index = {suite.task(t).name: t for t in suite.held_out}
    pick, button = index["pick-place-wall-v3"], index["button-press-v3"]
    result = run_sweep(
        SweepConfig(
            suite="metaworld",
            method="gt-waypoints",
            out=tmp_path,
            episodes=2,
            workers=1,
            tasks=(pick, button),
            progress=False,
        )
    )
    assert result.errors == 0 and result.successes == 4
    with ResultsStore(tmp_path, create=False) as store:
        rows = store.raw("SELECT task, waypoints, steps FROM episodes")
    for task, waypoints, steps in rows:
        W = np.asarray(json.loads(waypoints))
        assert W.shape == (5, 4)  # K = 5, positions + the grasp attribute (no pressing one)
        if task == pick:
            assert W[:, 3].tolist() == [0.0, 1.0, 1.0, 1.0, 1.0]  # approach, grasp, carried
        else:
            assert not W[:, 3].any()  # a push: no grasp mined
        assert steps < suite.horizon_steps  # the executor finished the waypoints

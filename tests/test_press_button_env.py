"""AWDA-PressButton-v1: layout checks (fast), button-specific env checks (slow). The contract every
env keeps is in ``test_env_contract.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from task_env_helpers import run_expert, task_env_fixture

from awda_bench.envs.press_button import PressButtonLayout
from awda_bench.experts.press_button import PressButtonExpert

# ---------------------------------------------------------------------------- fast


def test_layout_has_two_distinct_panels_and_six_distinct_buttons() -> None:
    lay = PressButtonLayout()
    assert len(lay.panels) == 2
    colors = [c for panel in lay.panels for c in panel.button_colors]
    assert len(set(colors)) == 6
    assert lay.panels[0].plate_color != lay.panels[1].plate_color
    assert lay.panels[0].plate_size_m != lay.panels[1].plate_size_m
    # success is SPEC's "pressed >= 4 cm" scaled to our travel, reachable before the stop
    assert 0 < lay.success_depth_m < lay.travel_m <= lay.protrusion_m


def test_layout_validates() -> None:
    with pytest.raises(ValueError, match="success_depth_m"):
        PressButtonLayout(success_depth_m=0.03)
    with pytest.raises(ValueError, match="travel_m"):
        PressButtonLayout(travel_m=0.03, success_depth_m=0.02)
    with pytest.raises(ValueError, match="2 panels"):
        PressButtonLayout(panels=PressButtonLayout().panels[:1])


# ---------------------------------------------------------------------------- slow (simulation)


env = task_env_fixture("AWDA-PressButton-v1")


def _panel_poses(env) -> np.ndarray:
    return torch.cat([p.pose.raw_pose for p in env.unwrapped.panels], dim=1).cpu().numpy()


@pytest.mark.slow
def test_no_button_starts_pressed(env) -> None:
    base = env.unwrapped
    env.reset(seed=0, options={"task": 4})
    env.step(np.zeros(4, dtype=np.float32))
    np.testing.assert_allclose(base.button_qpos().cpu().numpy(), 0.0, atol=1e-4)


@pytest.mark.slow
def test_state_dict_round_trip_restores_buttons_and_task(env) -> None:
    base = env.unwrapped
    env.reset(seed=4, options={"task": 5})
    base.panels[1].set_qpos(torch.tensor([[0.0, 0.0, -0.012]]))
    state = base.get_state_dict()
    before = (_panel_poses(env), base.button_qpos().clone())
    env.reset(seed=5, options={"task": 0})
    base.set_state_dict(state)
    np.testing.assert_allclose(_panel_poses(env), before[0], atol=1e-6)
    torch.testing.assert_close(base.button_qpos(), before[1])
    assert int(base.task[0]) == 5
    assert float(base.target_depth_m()[0]) == pytest.approx(0.012, abs=1e-6)


@pytest.mark.slow
def test_success_only_for_the_target_button_and_buttons_spring_back(env) -> None:
    base = env.unwrapped
    lay = base.layout
    for task in (0, 4):
        env.reset(seed=1, options={"task": task})
        for v in range(6):
            qpos = torch.zeros((1, 6))
            qpos[0, v] = -lay.travel_m
            base.panels[0].set_qpos(qpos[:, :3])
            base.panels[1].set_qpos(qpos[:, 3:])
            assert bool(base.evaluate()["success"][0]) == (v == task)
    # shallower than the success depth: not a success
    env.reset(seed=1, options={"task": 0})
    base.panels[0].set_qpos(torch.tensor([[-(lay.success_depth_m - 0.002), 0.0, 0.0]]))
    assert not bool(base.evaluate()["success"][0])
    # pressed and let go: the spring pops it back within half a second
    base.panels[0].set_qpos(torch.tensor([[-lay.travel_m, 0.0, 0.0]]))
    for _ in range(10):
        env.step(np.zeros(4, dtype=np.float32))
    assert float(base.target_depth_m()[0]) < 0.001
    assert not bool(base.truth_signals()["press"][0])


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [(1, 0), (5, 3)])
def test_expert_presses_the_button_and_the_press_truth_fires(env, task: int, seed: int) -> None:
    base = env.unwrapped
    depths: list[np.ndarray] = []  # per step, how deep each button is pressed [m]
    expert = PressButtonExpert()
    run = run_expert(
        env,
        expert,
        task,
        seed,
        horizon=160,
        on_step=lambda: depths.append(-base.button_qpos()[0].cpu().numpy()),
    )
    assert run.done and bool(run.info["success_once"][0])
    assert not bool(run.info["success"][0])  # released: the button popped back
    assert run.signals["press"] >= expert.config.hold_steps
    assert np.delete(np.stack(depths), task, axis=1).max() < 0.002  # no other button was pushed

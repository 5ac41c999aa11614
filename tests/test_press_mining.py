"""The pressing attribute (awda_bench.mining) against the press-button simulator truth.

Fast: a hand-made sequence shaped like the agent's measured press (per-step progress along the
command, as fractions of the command, measured on ``panda_awda`` in AWDA-PressButton-v1, e.g.
seed 3 of variation 2): first step from standstill 0.19, free-space steps >= 0.22 (0.36-0.44 at
speed), the fingertips touch the cap within a step, the 2 cm button travel at free-space speed,
the step onto the stop 0.23 (a shorter command, the goal being close), held < 0.02.
Slow: one recorded expert episode of the agent, scored against the env's ``"press"`` truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from awda_bench.mining import PressMiningConfig, mine_press, precision_recall
from awda_bench.trajectory import Trajectory

FULL_STEP_M = 0.02


def _press_sequence(hold_steps: int) -> tuple[Trajectory, np.ndarray]:
    """Descend, touch and push the button down, hit the stop, hold, rise.

    Returns the trajectory and the truth "press" per step (state before the action: the button is
    below rest, pushed by the fingers, not rising).
    """
    down = [0.19, 0.26, 0.38, 0.38]  # free space (first step from standstill)
    contact = [0.39]  # the fingertips reach the cap during this step
    travel = [0.36, 0.35]  # the button moves down with the fingers: unimpeded
    stop = [0.23]  # the cap reaches its lower stop
    held = [0.0] * hold_steps
    up = [0.29, 0.44, 0.43, 0.43]
    ratios = down + contact + travel + stop + held + up
    commands = [-1.0] * (len(ratios) - len(up)) + [1.0] * len(up)
    T = len(ratios) + 1
    z = np.zeros(T)
    z[0] = 0.12
    for t, (r, c) in enumerate(zip(ratios, commands, strict=True)):
        z[t + 1] = z[t] + c * r * FULL_STEP_M
    actions = np.zeros((T, 4))
    actions[: len(commands), 2] = commands
    actions[:, 3] = 1.0  # fingers shut throughout
    tcp = np.zeros((T, 3))
    tcp[:, 2] = z
    truth = np.zeros(T, dtype=bool)
    first = len(down) + len(contact)  # the state after the contact step
    last = first + len(travel) + len(stop) + hold_steps  # the state before the first up step
    truth[first : last + 1] = True
    traj = Trajectory(
        tcp_pos=tcp, gripper_opening_m=np.zeros(T), actions=actions, truth={"press": truth}
    )
    return traj, truth


def test_mined_press_is_the_held_part_of_the_press() -> None:
    traj, truth = _press_sequence(hold_steps=12)
    mined = mine_press(traj, PressMiningConfig())
    # every held step, nothing in free space, while the button travels, or while rising
    assert np.flatnonzero(mined).tolist() == list(range(8, 8 + 12))
    pr = precision_recall(mined, truth)
    assert pr.precision == 1.0
    # two travel steps, the step onto the stop and the state before the release are not seen
    assert pr.false_negative == 4


def test_recall_grows_with_the_hold_as_the_expert_relies_on() -> None:
    recalls = [
        precision_recall(mine_press(t), truth).recall
        for t, truth in (_press_sequence(h) for h in (5, 20, 40))
    ]
    assert recalls == pytest.approx([5 / 9, 20 / 24, 40 / 44])
    assert recalls[2] >= 0.9  # the expert's 2 s hold (40 steps at 20 Hz)


def test_a_start_from_standstill_is_not_a_press() -> None:
    traj, _ = _press_sequence(hold_steps=12)
    first = (traj.tcp_pos[1, 2] - traj.tcp_pos[0, 2]) / -FULL_STEP_M
    assert 0.15 < first < 0.2  # the measured first step of an episode: slow, but moving
    assert not mine_press(traj)[:8].any()
    # the former progress_ratio 0.2 read it as a press (kept by the edge-padded filter at t = 0)
    assert mine_press(traj, PressMiningConfig(progress_ratio=0.2))[0]


@pytest.mark.slow
def test_recorded_agent_press_matches_the_truth() -> None:
    import gymnasium as gym

    import awda_bench.envs  # noqa: F401
    from awda_bench.episode import EpisodeContext, EpisodeSpec
    from awda_bench.experts.press_button import PressButtonExpert

    env = gym.make("AWDA-PressButton-v1", obs_mode="state", reward_mode="none", num_envs=1)
    try:
        base = env.unwrapped
        obs, _ = env.reset(seed=2, options={"task": 3})
        expert = PressButtonExpert()
        spec = EpisodeSpec(suite="mosaic", task=3, episode=0, seed=2, demo_seed=2)
        expert.reset(EpisodeContext(env=base, spec=spec))
        tcp, opening, actions, press = [], [], [], []
        for _ in range(160):
            tcp.append(base.agent.tcp_pose.p[0].cpu().numpy())
            opening.append(float(base.gripper_opening_m()[0]))
            press.append(bool(base.truth_signals()["press"][0]))
            action = expert.act(obs)
            actions.append(np.asarray(action[0], dtype=np.float64))
            obs, _, _, _, info = env.step(action)
            if expert.done:
                break
    finally:
        env.close()
    assert bool(info["success_once"][0])
    traj = Trajectory(
        tcp_pos=np.asarray(tcp, dtype=np.float64),
        gripper_opening_m=np.asarray(opening),
        actions=np.asarray(actions),
        truth={"press": np.asarray(press)},
    )
    pr = precision_recall(mine_press(traj, PressMiningConfig(max_step_m=0.02)), traj.truth["press"])
    assert pr.precision >= 0.9 and pr.recall >= 0.9

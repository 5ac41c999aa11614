"""Controller benchmark: env steps/s of mink IK vs ManiSkill's own IK vs raw joint targets.

All three run on the same scene (by default both ``AWDA-EmptyTable-v1`` and the pick-and-place
task ``AWDA-PickPlace-v1``; the ``panda_awda`` agent, state observations, CPU physics) in
interleaved rounds, so background load hits them alike; the median
round is reported. Actions trace the same slow circle for the two end-effector modes; the joint
mode replays joint targets recorded from the mink run, so all three move the arm alike.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from awda_bench.render_device import render_backend

MODES = ("pd_ee_delta_pos_mink", "pd_ee_delta_pos", "pd_joint_pos")
"""Control modes compared (first = ours)."""


def add_controller_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--steps", type=int, default=300, help="env steps per round (default %(default)s)"
    )
    parser.add_argument(
        "--rounds", type=int, default=3, help="interleaved rounds per mode (default %(default)s)"
    )
    parser.add_argument(
        "--env",
        action="append",
        dest="envs",
        help="scene(s) to measure on (repeatable; default: AWDA-EmptyTable-v1 and AWDA-PickPlace-v1)",
    )
    parser.add_argument(
        "--fidelity",
        action="store_true",
        help="measure what the 4-D action does instead of speed: achieved/commanded per step, "
        "top speed, proportional-law error and overshoot, drift, wind-up (pick-place scene)",
    )
    parser.add_argument(
        "--robot",
        default="panda_awda",
        help="embodiment for --fidelity: panda_awda or awda_demonstrator (default %(default)s)",
    )
    parser.add_argument(
        "--targets",
        type=int,
        default=20,
        help="random targets of the proportional law for --fidelity (default %(default)s)",
    )


def _circle_action(t: int, scale: float) -> np.ndarray:
    return np.array([scale * np.sin(t / 15), scale * np.cos(t / 15), 0.2 * np.sin(t / 40), -1.0])


def run_controller_bench(args: argparse.Namespace) -> int:
    import awda_bench.envs  # noqa: F401  (registers the tasks and robots)

    if args.fidelity:
        for env_id in args.envs or ["AWDA-PickPlace-v1"]:
            _fidelity_scene(env_id, args.robot, args.targets)
        return 0
    for env_id in args.envs or ["AWDA-EmptyTable-v1", "AWDA-PickPlace-v1"]:
        _bench_scene(env_id, args.steps, args.rounds)
    return 0


def _fidelity_scene(env_id: str, robot: str, targets: int) -> None:
    import gymnasium as gym

    from awda_bench.benchmarks.controller_fidelity import format_fidelity, measure_fidelity

    env = gym.make(
        env_id,
        obs_mode="state",
        reward_mode="none",
        robot_uids=robot,
        render_backend=render_backend(),
    )
    try:
        report = measure_fidelity(env, targets=targets)
    finally:
        env.close()
    print(format_fidelity(report, f"{env_id} ({robot})"))
    print()


def _bench_scene(env_id: str, steps: int, rounds: int) -> None:
    import gymnasium as gym

    envs = {
        mode: gym.make(
            env_id,
            obs_mode="state",
            reward_mode="none",
            control_mode=mode,
            robot_uids="panda_awda",
            render_backend=render_backend(),
        )
        for mode in MODES
    }
    # ManiSkill's pd_ee_delta_pos spans +-0.1 m per unit action; ours +-0.02 m: same motion.
    scales = {"pd_ee_delta_pos_mink": 0.5, "pd_ee_delta_pos": 0.1}
    joint_targets: list[np.ndarray] = []
    rates: dict[str, list[float]] = {mode: [] for mode in MODES}
    for _round in range(rounds):
        for mode, env in envs.items():
            env.reset(seed=0)
            agent = env.unwrapped.agent  # type: ignore[attr-defined]
            if mode == "pd_joint_pos":
                if not joint_targets:
                    raise RuntimeError(
                        "joint targets are recorded from the mink run, which must come first"
                    )
                actions = [np.concatenate([q, [0.04]]) for q in joint_targets[:steps]]
            else:
                actions = [_circle_action(t, scales[mode]) for t in range(steps)]
            start = time.perf_counter()
            for action in actions:
                env.step(action)
                if mode == "pd_ee_delta_pos_mink" and len(joint_targets) < steps:
                    joint_targets.append(
                        agent.controller.controllers["arm"]._target_qpos[0].cpu().numpy()
                    )
            rates[mode].append(steps / (time.perf_counter() - start))
    for env in envs.values():
        env.close()

    median = {mode: statistics.median(values) for mode, values in rates.items()}
    ours = median["pd_ee_delta_pos_mink"]
    print(f"controller benchmark: {env_id}, state obs, CPU sim, {rounds} rounds x {steps} steps")
    print(f"{'control mode':<24}{'steps/s (median)':>18}{'rounds':>28}{'mink / this':>14}")
    for mode in MODES:
        per_round = ", ".join(f"{r:.0f}" for r in rates[mode])
        print(f"{mode:<24}{median[mode]:>18.1f}{per_round:>28}{ours / median[mode]:>14.2f}")
    print(
        f"mink vs ManiSkill pd_ee_delta_pos: {ours / median['pd_ee_delta_pos']:.2f}x (goal >= 1.3); "
        f"mink vs pd_joint_pos: {ours / median['pd_joint_pos']:.2f}x (goal >= 0.85)"
    )
    print()

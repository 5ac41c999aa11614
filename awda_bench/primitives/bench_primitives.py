"""``python -m awda_bench bench primitives``: what the primitive layer costs and how good it is.

Measures (``--measure``, default ``all``):

``episodes``      gt-waypoints on the held-out pick-and-place tasks (14, 15 cycled): success (at
                  end and once), reached, grasped; primitive + executor overhead per env step
                  *excluding* simulation and rendering (the time inside ``policy.act`` minus the
                  wrist-depth captures); rendered frames per episode; planning time.
``localization``  random scenes (task cycled over 0-15), the TCP driven to 15-30 cm above the
                  target's top (uniform), one wrist depth frame, xy error of the localized
                  position to the target's true centre: distribution and the share within 1.5 cm.
``mining``        expert trajectories of the agent on the training tasks (0-13 cycled): per-step
                  precision and recall of the mined grasp attribute against simulator contact
                  truth (``is_grasping_target``); pressing is not measured (no press-button suite).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

MEASURES = ("episodes", "localization", "mining")


def add_primitives_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--measure",
        choices=(*MEASURES, "all"),
        default="all",
        help="what to measure (default: all)",
    )
    parser.add_argument("--suite", default="pick_place", help="suite (default: pick_place)")
    parser.add_argument("--episodes", type=int, default=40, help="gt-waypoints episodes (40)")
    parser.add_argument("--scenes", type=int, default=100, help="localization scenes (100)")
    parser.add_argument("--demos", type=int, default=28, help="expert trajectories mined (28)")
    parser.add_argument("--seed", type=int, default=70_000, help="first seed (70000)")


def _percentiles(values: np.ndarray) -> str:
    p = np.percentile(values, [50, 90, 95, 99, 100])
    return "median {:.4f}  p90 {:.4f}  p95 {:.4f}  p99 {:.4f}  max {:.4f}".format(*p)


def _make_env(suite: Any) -> Any:
    from awda_bench.harness.env_factory import make_env

    return make_env(suite)


def measure_episodes(suite: Any, env: Any, episodes: int, seed: int) -> dict[str, float]:
    from awda_bench.policies.base import EpisodeContext
    from awda_bench.policies.gt_waypoints import GTWaypointsPolicy, episode_spec_for

    policy = GTWaypointsPolicy()
    base = env.unwrapped
    rows = []
    overheads: list[float] = []
    for e in range(episodes):
        task = suite.held_out[e % len(suite.held_out)]
        s = seed + e
        obs, info = env.reset(seed=s, options={"task": task})
        policy.reset(EpisodeContext(env=base, spec=episode_spec_for(suite.name, task, s)))
        once = False
        steps = 0
        while steps < suite.horizon_steps and not policy.done:
            obs, _, _, _, info = env.step(policy.act(obs))
            steps += 1
            once |= bool(np.asarray(info["success"]).reshape(-1)[0])
        st = policy.stats
        overheads += st.step_overhead_ms
        flag = {
            k: bool(np.asarray(info[k]).reshape(-1)[0]) for k in ("success", "reached", "grasped")
        }
        rows.append((flag["success"], once, flag["reached"], flag["grasped"], steps, st.frames))
        print(
            f"  episode {e:3d} task {task} seed {s}: success={flag['success']} once={once} "
            f"reached={flag['reached']} grasped={flag['grasped']} steps={steps} "
            f"frames={st.frames} overhead={st.overhead_per_step_ms:.3f} ms/step "
            f"planning={st.planning_s:.2f} s",
            flush=True,
        )
    r = np.array(rows, dtype=float)
    o = np.array(overheads)
    print(f"gt-waypoints, {episodes} episodes, tasks {list(suite.held_out)}:")
    print(
        f"  success (at end) {r[:, 0].mean():.3f}   success once {r[:, 1].mean():.3f}   "
        f"reached {r[:, 2].mean():.3f}   grasped {r[:, 3].mean():.3f}"
    )
    print(f"  steps/episode mean {r[:, 4].mean():.1f} (horizon {suite.horizon_steps})")
    print(
        f"  rendered frames/episode (wrist depth, grasp only): mean {r[:, 5].mean():.2f} "
        f"min {r[:, 5].min():.0f} max {r[:, 5].max():.0f}"
    )
    print(
        f"  primitive + executor overhead per env step, excl. sim and rendering [ms]: "
        f"mean {o.mean():.3f}  {_percentiles(o)}"
    )
    return {"success": float(r[:, 0].mean()), "overhead_ms": float(o.mean())}


def measure_localization(suite: Any, env: Any, scenes: int, seed: int) -> dict[str, float]:
    from awda_bench.policies.gt_waypoints import robot_states
    from awda_bench.primitives.config import FreeSpaceConfig
    from awda_bench.primitives.free_space import FreeSpace
    from awda_bench.primitives.wrist_camera import WristLocator

    base = env.unwrapped
    locator = WristLocator(base)
    rng = np.random.default_rng(seed)
    errors, misses = [], 0
    for i in range(scenes):
        task = i % 16
        env.reset(seed=seed + i, options={"task": task})
        target, _ = (t[0].cpu().numpy().astype(np.float64) for t in base.target_pose())
        top = target[2] + base.objects_spec[task // 4].half_height_m
        height = rng.uniform(0.15, 0.30)
        goal = np.array([target[0], target[1], top + height])
        move = FreeSpace(goal, FreeSpaceConfig(reach_tol_m=0.003, step_budget=80))
        while (a := move.step(robot_states(base)[0])) is not None:
            env.step(a[None].astype(np.float32))
        for _ in range(3):  # let the arm settle
            env.step(np.array([[0.0, 0.0, 0.0, -1.0]], dtype=np.float32))
        loc = locator()
        if loc is None:
            misses += 1
            errors.append(np.inf)
            continue
        errors.append(float(np.linalg.norm(loc.position_world[:2] - target[:2])))
    e = np.array(errors)
    ok = float(np.mean(e <= 0.015))
    print(f"localization, {scenes} scenes, TCP 15-30 cm above the target's top:")
    print(f"  within 1.5 cm (xy): {ok:.3f}   no object found: {misses}")
    print(f"  xy error [m]: {_percentiles(e[np.isfinite(e)]) if np.isfinite(e).any() else 'n/a'}")
    worst = np.argsort(-e)[:5]
    print(
        "  worst scenes (seed, task, error m): "
        + ", ".join(f"({seed + int(i)}, {int(i) % 16}, {e[i]:.3f})" for i in worst)
    )
    print(
        f"  rendering {1e3 * locator.capture_s / max(locator.frames, 1):.1f} ms/frame, "
        f"localization {1e3 * locator.localize_s / max(locator.frames, 1):.2f} ms/frame"
    )
    return {"within_1p5cm": ok}


def measure_mining(suite: Any, demos: int, seed: int) -> dict[str, float]:
    from awda_bench.demo_recording import make_demo_env, record_demo
    from awda_bench.mining import GraspMiningConfig, PrecisionRecall, mine_grasp, precision_recall

    env = make_demo_env(suite, "agent")
    train = [t.index for t in suite.train_tasks]
    configs = {
        "default (d=1, delta=-0.01, 3 taps, guard 5 mm)": GraspMiningConfig(),
        "reference formula (guard off)": GraspMiningConfig(min_opening_m=0.0),
        "no smoothing": GraspMiningConfig(smooth_steps=1),
        "d=2": GraspMiningConfig(lookahead_steps=2),
    }
    totals: dict[str, PrecisionRecall | None] = dict.fromkeys(configs)
    for i in range(demos):
        task = train[i % len(train)]
        _, traj = record_demo(suite, task, seed + i, embodiment="agent", frames=False, env=env)
        for name, cfg in configs.items():
            pr = precision_recall(mine_grasp(traj, cfg), traj.truth["grasp"])
            so_far = totals[name]
            totals[name] = pr if so_far is None else so_far + pr
    print(
        f"grasp attribute mining, {demos} agent expert trajectories (tasks {train[0]}-{train[-1]}):"
    )
    for name, total in totals.items():
        assert total is not None
        pr = total
        print(
            f"  {name:48s} precision {pr.precision:.3f}  recall {pr.recall:.3f}  "
            f"(TP {pr.true_positive}, FP {pr.false_positive}, FN {pr.false_negative})"
        )
    print("  pressing: not measured (no press-button suite yet)")
    env.close()
    first = totals[next(iter(configs))]
    assert first is not None
    return {"precision": first.precision, "recall": first.recall}


def run_primitives_bench(args: argparse.Namespace) -> int:
    """Print the measures asked for; returns 0."""
    import torch

    from awda_bench.suites import load_suite

    torch.set_num_threads(1)
    suite = load_suite(args.suite)
    todo = MEASURES if args.measure == "all" else (args.measure,)
    t0 = time.perf_counter()
    env = _make_env(suite) if {"episodes", "localization"} & set(todo) else None
    if "localization" in todo:
        measure_localization(suite, env, args.scenes, args.seed)
    if "mining" in todo:
        measure_mining(suite, args.demos, args.seed)
    if "episodes" in todo:
        measure_episodes(suite, env, args.episodes, args.seed)
    if env is not None:
        env.close()
    print(f"(bench primitives took {time.perf_counter() - t0:.0f} s)")
    return 0

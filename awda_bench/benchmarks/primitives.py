"""``python -m awda_bench bench primitives``: what the primitive layer costs and how good it is.

Measures (``--measure``, default ``all``):

``episodes``      gt-waypoints on the held-out pick-and-place tasks (14, 15 cycled): success (at
                  end and once), reached, grasped; primitive + executor overhead per env step
                  *excluding* simulation and rendering (the time inside ``policy.act`` minus the
                  wrist-depth captures); rendered frames per episode; planning time.
``localization``  random scenes (task cycled over 0-15), the TCP driven to 15-30 cm above the
                  target's top (uniform), one wrist depth frame, xy error of the localized
                  position to the target's true centre: distribution and the share within 1.5 cm.
``mining``        expert trajectories of both embodiments (pick_place: training tasks cycled;
                  mosaic: every variation cycled): per-step precision and recall of the mined
                  grasp and pressing attributes against simulator truth (finger contact on the
                  target; the button pushed down by the fingers), per family.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from awda_bench.rollout import roll_out

if TYPE_CHECKING:
    from awda_bench.trajectory import Trajectory

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
    from awda_bench.evaluation.env_factory import make_env

    return make_env(suite)


def measure_episodes(suite: Any, env: Any, episodes: int, seed: int) -> dict[str, float]:
    from awda_bench.episode import EpisodeContext
    from awda_bench.policies.gt_waypoints import GtWaypointsPolicy, episode_spec_for

    policy = GtWaypointsPolicy()
    base = env.unwrapped
    rows = []
    overheads: list[float] = []
    successes: list[bool] = []  # the episode's success after each step

    def note_success(_t: int, _a: Any, info_t: dict[str, Any]) -> bool:
        successes.append(bool(np.asarray(info_t["success"]).reshape(-1)[0]))
        return False

    for e in range(episodes):
        task = suite.held_out[e % len(suite.held_out)]
        s = seed + e
        obs, info = env.reset(seed=s, options={"task": task})
        policy.reset(EpisodeContext(env=base, spec=episode_spec_for(suite.name, task, s)))
        successes.clear()
        end = roll_out(
            env.step,
            obs,
            lambda obs_t: None if policy.done else policy.act(obs_t),
            suite.horizon_steps,
            info=info,
            after_step=note_success,
        )
        info, steps, once = end.info, end.steps, any(successes)
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
    """Per-step precision/recall of the mined attributes against simulator truth, per embodiment
    and family: grasp on every task with a grasp truth, pressing where the env reports ``press``.

    ``demos`` expert episodes per embodiment, the suite's tasks cycled (pick_place: its training
    tasks; mosaic: every variation), seeds from ``seed``."""
    from awda_bench.demo_recording import demo_env_for, record_demo
    from awda_bench.experts import EMBODIMENT_NAMES
    from awda_bench.mining import PrecisionRecall, mine_grasp, mine_press, precision_recall

    tasks = [t.index for t in (suite.train_tasks if suite.name == "pick_place" else suite.tasks)]
    miners: dict[str, Callable[[Trajectory], np.ndarray]] = {
        "grasp": mine_grasp,
        "press": mine_press,
    }
    totals: dict[tuple[str, str, str], PrecisionRecall] = {}
    envs: dict[tuple[str, str], Any] = {}
    for embodiment in EMBODIMENT_NAMES:
        for i in range(demos):
            task = tasks[i % len(tasks)]
            env = demo_env_for(envs, suite, task, embodiment)
            _, traj = record_demo(suite, task, seed + i, embodiment, frames=False, env=env)
            family = suite.task(task).family
            for attribute, truth in traj.truth.items():
                if attribute not in miners:
                    continue
                pr = precision_recall(miners[attribute](traj), truth)
                key = (embodiment, attribute, family)
                totals[key] = totals[key] + pr if key in totals else pr
    for opened in envs.values():
        opened.close()
    print(f"attribute mining vs simulator truth, {demos} expert trajectories per embodiment:")
    print(
        f"  {'embodiment':<14}{'attribute':<10}{'family':<14}{'precision':>10}{'recall':>8}"
        f"{'TP':>7}{'FP':>6}{'FN':>6}"
    )
    summary: dict[str, float] = {}
    for (embodiment, attribute, family), pr in sorted(totals.items()):
        if pr.true_positive + pr.false_negative + pr.false_positive == 0:
            continue  # this family never has the attribute and nothing was mined
        print(
            f"  {embodiment:<14}{attribute:<10}{family:<14}{pr.precision:>10.3f}{pr.recall:>8.3f}"
            f"{pr.true_positive:>7}{pr.false_positive:>6}{pr.false_negative:>6}"
        )
    for embodiment in EMBODIMENT_NAMES:
        for attribute in miners:
            parts = [v for (e, a, _f), v in totals.items() if e == embodiment and a == attribute]
            if not parts:
                continue
            total = parts[0]
            for part in parts[1:]:
                total = total + part
            print(
                f"  {embodiment:<14}{attribute:<10}{'all':<14}{total.precision:>10.3f}"
                f"{total.recall:>8.3f}{total.true_positive:>7}{total.false_positive:>6}"
                f"{total.false_negative:>6}"
            )
            summary[f"{embodiment}_{attribute}_precision"] = total.precision
            summary[f"{embodiment}_{attribute}_recall"] = total.recall
    return summary


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

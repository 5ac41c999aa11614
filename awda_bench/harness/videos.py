"""``run --videos K``: MP4s of K successful and K failed episodes per (snapshot, task), and a
Fig. S5-style image for each saved episode of a waypoint-predicting method.

Nothing is rendered during the sweep (frames cost ~60 ms each on lavapipe). Afterwards the chosen
episodes — the first K successes and first K failures by episode index, status ok — are replayed
in this process with frame capture; episodes are deterministic in their spec, so the replay is the
recorded episode (a replay whose outcome differs is saved with ``_replay-differs`` in its name).

Layout: ``RUN_DIR/videos/<suite>/<method>/<snapshot>/task<T>_ep<E>_<success|failure>.mp4`` and
``..._waypoints.png`` beside it.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from awda_bench.harness.episode_specs import make_protocol
from awda_bench.harness.figures import fig_s5, project_points, write_mp4, write_png
from awda_bench.harness.methods import get_method, select_snapshots
from awda_bench.harness.results_store import ResultsStore
from awda_bench.harness.sweep import SweepConfig
from awda_bench.harness.worker_pool import EpisodeExecutor, Job, WorkerConfig
from awda_bench.policies.base import EpisodeSpec
from awda_bench.suites import load_suite

THIRD_PERSON = "third_person"
"""Sensor uid of the suites' third-person camera (see :mod:`awda_bench.robot.cameras`)."""


def grab_frame(env: Any) -> tuple[np.ndarray, dict[str, np.ndarray] | None]:
    """One RGB frame of env 0 and, when it comes from a camera sensor, its parameters."""
    base = env.unwrapped
    sensors = getattr(getattr(base, "scene", None), "sensors", {})
    if THIRD_PERSON in sensors:
        from awda_bench.robot.cameras import capture_rgb

        frame = capture_rgb(env, THIRD_PERSON)[0]
        params = {
            k: np.asarray(v.cpu() if hasattr(v, "cpu") else v)[0]
            for k, v in sensors[THIRD_PERSON].get_params().items()
        }
        return frame, params
    frame = np.asarray(env.render())
    return (frame[0] if frame.ndim == 4 else frame).astype(np.uint8), None


def choose_episodes(rows: list[tuple[int, int, int]], k: int) -> list[tuple[int, int, bool]]:
    """From ``(task, episode, success)`` rows: the first ``k`` successes and failures per task."""
    chosen = []
    for task in sorted({r[0] for r in rows}):
        for outcome in (True, False):
            picked = sorted(e for t, e, s in rows if t == task and bool(s) == outcome)[:k]
            chosen += [(task, e, outcome) for e in picked]
    return chosen


def record_videos(config: SweepConfig, k: int) -> list[Path]:
    """Replay and save the chosen episodes of the sweep ``config`` describes; returns the files."""
    suite = load_suite(config.suite, config.suites_dir)
    protocol = make_protocol(suite, episodes=config.episodes, base_seed=config.seed)
    method = get_method(config.method)
    snapshots = select_snapshots(method, config.checkpoints, config.snapshots)
    executor = EpisodeExecutor(
        WorkerConfig(
            suite_name=suite.name,
            suites_dir=str(config.suites_dir),
            env_factory=config.env_factory,
            render_mode="rgb_array",
        )
    )
    written: list[Path] = []
    try:
        with ResultsStore(config.out, create=False) as store:
            for snap in snapshots:
                rows = store.raw(
                    "SELECT task, episode, success_once, seed, demo_seed FROM episodes "
                    "WHERE protocol=? AND method=? AND snapshot=? AND status='ok'",
                    (protocol.fingerprint, method.name, snap.sha256),
                )
                seeds = {(r[0], r[1]): (r[3], r[4]) for r in rows}
                for task, episode, success in choose_episodes([r[:3] for r in rows], k):
                    seed, demo_seed = seeds[(task, episode)]
                    spec = EpisodeSpec(
                        suite=suite.name, task=task, episode=episode, seed=seed, demo_seed=demo_seed
                    )
                    frames: list[np.ndarray] = []
                    params: list[dict[str, np.ndarray] | None] = []

                    def on_frame(env: Any, frames: list = frames, params: list = params) -> None:
                        frame, p = grab_frame(env)
                        frames.append(frame)
                        if not params:
                            params.append(p)

                    extras: dict[str, Any] = {}
                    record = executor.play(
                        Job(spec=spec, method=method, snapshot=snap),
                        on_frame=on_frame,
                        extras=extras,
                    )
                    if record.status != "ok":
                        print(
                            f"warning: replay of task {task} episode {episode} failed: "
                            f"{(record.error or '').strip().splitlines()[-1]}",
                            file=sys.stderr,
                        )
                        continue
                    stem = f"task{task}_ep{episode}_{'success' if success else 'failure'}"
                    if bool(record.success_once) != success:
                        stem += "_replay-differs"
                        print(
                            f"warning: replay of task {task} episode {episode} changed outcome",
                            file=sys.stderr,
                        )
                    directory = (
                        config.out
                        / "videos"
                        / suite.name
                        / method.name.replace(":", "_")
                        / snap.sha256
                    )
                    written.append(
                        write_mp4(frames, directory / f"{stem}.mp4", fps=suite.control_freq_hz)
                    )
                    if record.waypoints and params and params[0] is not None:
                        wp = np.asarray(record.waypoints, dtype=float)
                        pixels = project_points(
                            wp[:, :3], params[0]["intrinsic_cv"], params[0]["extrinsic_cv"]
                        )
                        grasp = (
                            [bool(g > 0.5) for g in wp[:, 3]]
                            if wp.shape[1] > 3
                            else [False] * len(wp)
                        )
                        demo = [
                            np.asarray(f) for f in extras.get("demo_frames", [])
                        ]  # none until a policy provides them
                        image = fig_s5(demo, frames[0], pixels, grasp)
                        written.append(write_png(image, directory / f"{stem}_waypoints.png"))
                        (directory / f"{stem}_waypoints.json").write_text(
                            json.dumps(record.waypoints)
                        )
    finally:
        executor.close()
    return written

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

from awda_bench.episode import EpisodeSpec
from awda_bench.evaluation.episode_record import EpisodeRecord
from awda_bench.evaluation.methods import resolve, select_snapshots
from awda_bench.evaluation.results_store import ResultsStore
from awda_bench.evaluation.sweep import SweepConfig, sweep_method, sweep_protocol
from awda_bench.evaluation.worker_pool import EpisodeExecutor, Job, WorkerConfig
from awda_bench.reporting.figures import fig_s5, project_points, write_mp4, write_png
from awda_bench.suites import Suite, load_suite

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


DEFAULT_DEMO_SOURCE = "awda_bench.reporting.videos:record_demo_frames"
"""``"module:attribute"`` of ``f(suite, task, demo_seed, cache) -> list of RGB frames``."""


def record_demo_frames(
    suite: Suite, task: int, demo_seed: int, cache: dict[str, Any]
) -> list[np.ndarray]:
    """The demonstrator's video of ``(task, demo_seed)``, subsampled to :data:`awda_bench.demo_recording.DEMO_FRAMES`
    frames (first and last included), as the method sees them.

    The demo envs are built once per ``cache`` (one per env id).
    """
    from awda_bench.demo_recording import demo_video_frames

    return list(demo_video_frames(suite, task, demo_seed, cache.setdefault("demo_envs", {})))


def choose_episodes(rows: list[tuple[int, int, int]], k: int) -> list[tuple[int, int, bool]]:
    """From ``(task, episode, success)`` rows: the first ``k`` successes and failures per task."""
    chosen = []
    for task in sorted({r[0] for r in rows}):
        for outcome in (True, False):
            picked = sorted(e for t, e, s in rows if t == task and bool(s) == outcome)[:k]
            chosen += [(task, e, outcome) for e in picked]
    return chosen


def _replay(
    executor: EpisodeExecutor, job: Job
) -> tuple[EpisodeRecord, list[np.ndarray], dict | None]:
    """Play ``job`` again, capturing a frame after reset and after every step."""
    frames: list[np.ndarray] = []
    params: list[dict[str, np.ndarray] | None] = []

    def on_frame(env: Any) -> None:
        frame, p = grab_frame(env)
        frames.append(frame)
        if not params:
            params.append(p)

    record = executor.play(job, on_frame=on_frame)
    return record, frames, params[0] if params else None


def record_videos(
    config: SweepConfig, k: int, demo_source: str | None = DEFAULT_DEMO_SOURCE
) -> list[Path]:
    """Replay and save the chosen episodes of the sweep ``config`` describes; returns the files.

    ``demo_source`` (``"module:attribute"``, see :data:`DEFAULT_DEMO_SOURCE`) supplies the demo
    frames of Fig. S5 images; ``None`` draws the agent's frame alone.
    """
    suite = load_suite(config.suite, config.suites_dir)
    protocol = sweep_protocol(config, suite)
    method = sweep_method(config)
    snapshots = select_snapshots(method, config.checkpoints, config.snapshots)
    demo_frames = None if demo_source is None else resolve(demo_source, what="demo frame source")
    demo_cache: dict[str, Any] = {}
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
                directory = (
                    config.out / "videos" / suite.name / method.name.replace(":", "_") / snap.sha256
                )
                for task, episode, success in choose_episodes([r[:3] for r in rows], k):
                    seed, demo_seed = seeds[(task, episode)]
                    spec = EpisodeSpec(suite.name, task, episode, seed, demo_seed)
                    job = Job(spec=spec, method=method, snapshot=snap)
                    record, frames, params = _replay(executor, job)
                    name = f"task {task} episode {episode}"
                    if record.status != "ok":
                        last = (record.error or "").strip().splitlines()[-1:]
                        print(f"warning: replay of {name} failed: {last}", file=sys.stderr)
                        continue
                    stem = f"task{task}_ep{episode}_{'success' if success else 'failure'}"
                    if bool(record.success_once) != success:
                        stem += "_replay-differs"
                        print(f"warning: replay of {name} changed outcome", file=sys.stderr)
                    fps = suite.control_freq_hz
                    written.append(write_mp4(frames, directory / f"{stem}.mp4", fps=fps))
                    if record.waypoints and params is not None:
                        demo = (
                            []
                            if demo_frames is None
                            else demo_frames(suite, task, demo_seed, demo_cache)
                        )
                        written += _waypoint_figure(
                            record.waypoints, frames[0], params, demo, directory / stem
                        )
    finally:
        executor.close()
        for env in demo_cache.get("demo_envs", {}).values():
            env.close()
    return written


def _waypoint_figure(
    waypoints: list[list[float]],
    first_frame: np.ndarray,
    params: dict[str, np.ndarray],
    demo: list[np.ndarray],
    stem: Path,
) -> list[Path]:
    """Fig. S5-style PNG (+ the waypoints as JSON) for one episode."""
    wp = np.asarray(waypoints, dtype=float)
    pixels = project_points(wp[:, :3], params["intrinsic_cv"], params["extrinsic_cv"])
    grasp = [bool(g > 0.5) for g in wp[:, 3]] if wp.shape[1] > 3 else [False] * len(wp)
    press = [bool(p > 0.5) for p in wp[:, 4]] if wp.shape[1] > 4 else None
    png = write_png(
        fig_s5(demo, first_frame, pixels, grasp, press),
        stem.with_name(stem.name + "_waypoints.png"),
    )
    js = stem.with_name(stem.name + "_waypoints.json")
    js.write_text(json.dumps(waypoints))
    return [png, js]

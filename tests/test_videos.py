from pathlib import Path

import cv2
from harness_fakes import fake_suites_dir, fake_sweep_config

from awda_bench.evaluation.sweep import run_sweep
from awda_bench.reporting.videos import choose_episodes, record_videos


def test_choose_first_k_successes_and_failures_per_task() -> None:
    rows = [(2, 0, 1), (2, 1, 0), (2, 2, 1), (2, 3, 1), (3, 0, 0), (3, 1, 0)]
    assert choose_episodes(rows, 2) == [
        (2, 0, True),
        (2, 2, True),
        (2, 1, False),
        (3, 0, False),
        (3, 1, False),
    ]


def test_videos_replay_the_recorded_episodes(tmp_path: Path) -> None:
    suites = fake_suites_dir(tmp_path / "tasks")
    config = fake_sweep_config(suites, tmp_path / "runs", "harness_fakes:SkillPolicy", episodes=4)
    run_sweep(config)
    files = record_videos(config, 1, demo_source=None)
    videos = sorted(p.name for p in files if p.suffix == ".mp4")
    assert len(videos) == 4 and not any("differs" in v for v in videos)
    assert {v.split("_")[-1] for v in videos} == {"success.mp4", "failure.mp4"}
    cap = cv2.VideoCapture(str(next(p for p in files if p.suffix == ".mp4")))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 7  # first frame + 6 steps

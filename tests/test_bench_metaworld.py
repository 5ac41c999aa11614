"""``bench metaworld``: run from the project's environment, it measures in ``.venv-metaworld``.
(Through the module, as ``bench`` calls it: the CLI's own import costs ~30 s here.)"""

from __future__ import annotations

import subprocess
import sys

import pytest
from test_metaworld_suite import needs_metaworld

pytestmark = [pytest.mark.slow, needs_metaworld]


def _bench(*options: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "awda_bench.benchmarks.metaworld", *options],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_experts_reports_successes_and_steps_to_success() -> None:
    result = _bench("experts", "--seeds", "2", "door-unlock-v3")
    assert result.returncode == 0, result.stderr
    assert "door-unlock-v3" in result.stdout and "2/2 succeed" in result.stdout
    assert "all: 2/2 succeed" in result.stdout


def test_frames_measures_both_settings_in_one_run() -> None:
    result = _bench("frames", "--frames", "2")
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.splitlines() if " ms" in line]
    assert len(lines) == 2 and "own settings" in lines[0] and "fast" in lines[1]

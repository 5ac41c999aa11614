"""``doctor`` and the renderer check, run as a user would (subprocess)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow


def _run(args: list[str], **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "awda_bench", *args],
        capture_output=True,
        text=True,
        env={**os.environ, **env},
        timeout=300,
        check=False,
    )


def test_doctor_reports_the_device_and_writes_a_frame(tmp_path: Path) -> None:
    frame = tmp_path / "frame.png"
    result = _run(["doctor", "--frame", str(frame)])
    assert result.returncode == 0, result.stderr
    assert "render device" in result.stdout
    assert "sapien" in result.stdout and "mink" in result.stdout
    assert (
        ".venv-metaworld" in result.stdout
    )  # the Meta-World workers' environment, or how to make it
    assert frame.is_file() and frame.stat().st_size > 1000


@pytest.mark.parametrize(
    "command", [["doctor"], ["bench", "controller", "--steps", "5", "--rounds", "1"]]
)
def test_without_a_renderer_commands_fail_in_one_line(tmp_path: Path, command: list[str]) -> None:
    result = _run(command, VK_ICD_FILENAMES=str(tmp_path / "no_such_icd.json"))
    assert result.returncode == 3
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "mesa-vulkan-drivers" in errors[0]
    assert "Traceback" not in result.stderr

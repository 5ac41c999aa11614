"""Shared fixtures. Simulation fixtures are module-scoped: building an env costs ~1 s and a camera's
first capture ~5 s on lavapipe, so each test module builds what it needs once."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")


@pytest.fixture
def suites(tmp_path: Path) -> Path:
    """A directory holding the fake suite (``harness_fakes``: 4 tasks, 2 held out), for
    ``--tasks-dir`` / ``tasks_dir``."""
    from harness_fakes import write_fake_suite

    directory = tmp_path / "tasks"
    directory.mkdir()
    write_fake_suite(directory)
    return directory

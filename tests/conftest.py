"""Shared fixtures. Simulation fixtures are module-scoped: building an env costs ~1 s and a camera's
first capture ~5 s on lavapipe, so each test module builds what it needs once."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")


@pytest.fixture
def suites(tmp_path: Path) -> Path:
    """A directory holding the fake suite (``harness_fakes``: 4 tasks, 2 held out), for
    ``--tasks-dir`` / ``tasks_dir``."""
    from harness_fakes import fake_suites_dir

    return fake_suites_dir(tmp_path / "tasks")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny collection (``test_collect.tiny_collection_dir``: recorded once per session)."""
    from test_collect import tiny_collection_dir

    return tiny_collection_dir(tmp_path_factory)


@pytest.fixture
def tiny_copy(tiny: Path, tmp_path: Path) -> Path:
    """A copy of the tiny collection that a test may write into (feature caches):
    ``tmp_path/data``."""
    data_dir = tmp_path / "data"
    shutil.copytree(tiny, data_dir)
    return data_dir

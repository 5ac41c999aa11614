"""What the Meta-World tests share: the second environment's interpreter, and the mark that skips
a test without it (never under CI, where `bash scripts/setup.sh test` makes it)."""

from __future__ import annotations

import os

import pytest

from awda_bench.errors import UsageError
from awda_bench.runtimes import worker_python


def metaworld_python() -> str | None:
    """``.venv-metaworld``'s interpreter, or ``None`` where it is missing."""
    try:
        return worker_python("metaworld")
    except UsageError:  # MissingEnvironmentError is one
        return None


needs_metaworld = pytest.mark.skipif(
    metaworld_python() is None and not os.environ.get("CI"),
    reason=".venv-metaworld is missing (make it with `bash scripts/setup.sh`); under CI these run",
)

"""Fault drills for the Ray backend's tests (imported by the actors through the driver's sys.path).

``AWDA_FAKE_MARKERS`` names a directory shared by the actors of one test.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from awda_bench.evaluation.env_factory import make_env
from awda_bench.suites import Suite


def _claim(path: Path) -> bool:
    """Create ``path``; ``False`` if another process did first."""
    try:
        os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return False
    return True


def make_env_second_dies_once(suite: Suite, *, env_id: str | None = None, **kwargs: Any) -> Any:
    """The first actor builds its env; the next one dies (like a lost node) once the first has
    built its env (and, 3 s later, reported ready)."""
    markers = Path(os.environ["AWDA_FAKE_MARKERS"])
    if _claim(markers / "first"):
        env = make_env(suite, env_id=env_id, **kwargs)
        _claim(markers / "built")
        return env
    if _claim(markers / "died"):
        deadline = time.monotonic() + 120
        while not (markers / "built").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(3.0)
        os._exit(9)
    return make_env(suite, env_id=env_id, **kwargs)

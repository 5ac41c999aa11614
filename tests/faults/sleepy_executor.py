"""A pool executor for the fault tests: each job writes the worker's pid to ``DIR/<pid>`` and
sleeps the job's seconds (a long episode, without the simulator)."""

from __future__ import annotations

import os
import time
from pathlib import Path


class SleepyExecutor:
    def __init__(self, directory: str) -> None:
        self.directory = Path(directory)

    def play(self, seconds: float) -> float:
        (self.directory / str(os.getpid())).write_text("busy")
        time.sleep(seconds)
        return seconds

    def close(self) -> None:
        pass

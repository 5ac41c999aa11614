"""What the fault tests read of the process table (Linux ``/proc``)."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path


def alive(pid: int) -> bool:
    """``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (children, their children, ...)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            parents[int(entry.name)] = int(fields[1])
    found: set[int] = set()
    frontier = {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def wait_for(condition, timeout_s: float, poll_s: float = 0.1) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(poll_s)
    return bool(condition())


def outlived_s(pids: set[int], timeout_s: float = 20.0) -> float:
    """Seconds until none of ``pids`` is alive (``inf`` past ``timeout_s``; then they are
    SIGKILLed so that a failing test leaves nothing behind)."""
    t0 = time.monotonic()
    if wait_for(lambda: not any(alive(p) for p in pids), timeout_s, 0.05):
        return time.monotonic() - t0
    for p in pids:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return float("inf")


def kill_and_reap(process: subprocess.Popen, sig: int) -> None:
    process.send_signal(sig)
    process.wait(timeout=30)


def descendants_outlive_s(
    argv: list[str], below: int, sig: int, cwd: Path, busy_s: float = 10.0
) -> float:
    """Start ``argv``, wait until at least ``below`` processes run under it and ``busy_s`` more
    (they build their envs and are at work), send it ``sig``, and return how long its
    descendants outlived it (:func:`outlived_s`)."""
    parent = subprocess.Popen(argv, cwd=cwd, stderr=subprocess.DEVNULL)
    try:
        assert wait_for(lambda: len(descendants(parent.pid)) >= below, 120), "nothing started"
        time.sleep(busy_s)
        under = descendants(parent.pid)
        assert all(alive(p) for p in under)
        kill_and_reap(parent, sig)
        return outlived_s(under)
    finally:
        if parent.poll() is None:
            parent.kill()

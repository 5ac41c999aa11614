"""Processes that do not outlive the process that started them, however it dies (SIGKILL too).

A pool's worker learns of its parent's death only when it next sends or receives on its socket:
a worker in the middle of a long job (a collection unit, a 500-step Meta-World episode) went on at
full CPU for the rest of the job after its parent was killed. So every worker, and every stage
``reproduce`` starts, arms a *parent-death signal* first thing::

    Linux     prctl(PR_SET_PDEATHSIG, sig): the kernel sends ``sig`` when the parent exits
    elsewhere a daemon thread polls os.getppid() every WATCHDOG_POLL_S and sends ``sig`` to itself
              when the parent changed (the orphan was re-parented)

and checks that the parent it armed against is still the one it had (a parent that died before
the signal was armed is not seen by the kernel). Workers use SIGKILL (their results have nowhere
to go; a job cut short is re-played by the next run, as a worker killed mid-episode always was);
``reproduce``'s stages SIGTERM, so a stage stops its own pool the way it does on Ctrl-C.

PR_SET_PDEATHSIG fires when the *thread* that started the child exits; the pools start their
workers from the thread that runs them, which outlives them.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
"""``prctl`` option (linux/prctl.h)."""

WATCHDOG_POLL_S = 0.5
"""How often the fallback watchdog looks at the parent [s]."""

PARENT_ENV = "AWDA_DIE_WITH_PARENT"
"""Set by a parent in a child's environment (the parent's pid) to make the CLI arm SIGTERM against
it (:func:`die_with_parent_from_env`): ``reproduce`` does this for its stages."""


def _arm_prctl(sig: int) -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent: int, sig: int) -> None:
    while os.getppid() == parent:
        time.sleep(WATCHDOG_POLL_S)
    os.kill(os.getpid(), sig)


def die_with_parent(sig: int = signal.SIGKILL, parent: int | None = None) -> str:
    """Arm ``sig`` to be delivered to this process when ``parent`` (default: the current parent)
    exits; returns how (``"prctl"`` or ``"watchdog"``). If ``parent`` is already gone, ``sig`` is
    sent at once."""
    parent = os.getppid() if parent is None else parent
    how = "prctl" if _arm_prctl(sig) else "watchdog"
    if how == "watchdog":
        threading.Thread(
            target=_watch, args=(parent, sig), daemon=True, name="parent-watch"
        ).start()
    if os.getppid() != parent:  # the parent died before the signal was armed
        os.kill(os.getpid(), sig)
    return how


def die_with_parent_from_env() -> None:
    """If :data:`PARENT_ENV` names a pid, SIGTERM this process when that parent exits (a
    ``reproduce`` stage), and drop the variable so this process's own children do not inherit
    it."""
    value = os.environ.pop(PARENT_ENV, None)
    if value and value.isdigit():
        die_with_parent(signal.SIGTERM, int(value))

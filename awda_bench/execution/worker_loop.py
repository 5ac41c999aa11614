"""The worker side of the local process pool: build the executor once, then play jobs one at a
time until told to stop. Runs in a process spawned from this interpreter
(:mod:`awda_bench.execution.process_pool`) or in one started from another environment's
(:mod:`awda_bench.execution.interpreter_process`); the conversation is the same::

    worker                                       parent
      executor = build(config)  --> ("ready", pid)   or ("fatal", message, traceback)
      <-- job;  result = executor.play(job) --> ("result", result)
      <-- None: executor.close(), exit
"""

from __future__ import annotations

import os
import signal
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

from awda_bench.execution.job_pool import Executor
from awda_bench.execution.parent_death import die_with_parent


def serve_jobs(conn: Connection, build: Callable[[Any], Executor], config: Any) -> None:
    """Build ``build(config)`` and play the jobs received on ``conn`` until ``None`` (or the
    parent's end closes). The worker is SIGKILLed by the kernel when its parent dies
    (:func:`~awda_bench.execution.parent_death.die_with_parent`), mid-job included."""
    die_with_parent(signal.SIGKILL)
    try:
        executor = build(config)
    except BaseException as exc:
        conn.send(("fatal", f"{type(exc).__name__}: {exc}", traceback.format_exc()))
        conn.close()
        return
    conn.send(("ready", os.getpid()))
    try:
        while True:
            try:
                job = conn.recv()
            except EOFError:
                break  # the parent was killed: nobody to report to, exit quietly
            if job is None:
                break
            result = executor.play(job)
            try:
                conn.send(("result", result))
            except BrokenPipeError:
                break  # the parent was killed mid-job; the job runs again on resume
    finally:
        executor.close()
        conn.close()

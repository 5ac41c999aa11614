"""A pool worker started from another interpreter (another virtual environment's ``bin/python``),
speaking the same conversation as a spawned one (:mod:`awda_bench.execution.worker_loop`).

``multiprocessing``'s spawn cannot do this: its child takes the parent's ``sys.path`` and would
import the parent environment's packages (mujoco 4 instead of Meta-World's 3.3). So the parent
makes a socket pair, starts ``python -m awda_bench.execution.interpreter_process FD`` with one end
(and this checkout on ``PYTHONPATH``, so both sides run the same code), wraps its own end as a
``multiprocessing`` :class:`~multiprocessing.connection.Connection` (the pool waits on it like on a
pipe), and sends ``(build, config)`` first::

    parent (.venv)                                  child (other interpreter)
      socketpair; Popen(python -m ... FD) ----->      conn = Connection(FD)
      ("start", build, config) ---------------->      serve_jobs(conn, build, config)
            <------------------------- ("ready", pid) ... as a spawned worker
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from awda_bench.execution.job_pool import THREAD_VARS, Executor

CODE_ROOT = str(Path(__file__).resolve().parents[2])
"""The directory holding this ``awda_bench`` package: the child's first ``PYTHONPATH`` entry."""


class InterpreterProcess:
    """A started child process with the methods the pool uses on a ``multiprocessing`` one."""

    def __init__(self, popen: subprocess.Popen[bytes]) -> None:
        self._popen = popen
        self.pid = popen.pid

    def is_alive(self) -> bool:
        return self._popen.poll() is None

    def kill(self) -> None:
        if self.is_alive():
            self._popen.kill()

    def join(self, timeout: float | None = None) -> None:
        try:
            self._popen.wait(timeout)
        except subprocess.TimeoutExpired:
            pass

    @property
    def exitcode(self) -> int | None:
        return self._popen.poll()


def child_environment() -> dict[str, str]:
    """This process's environment variables, with the checkout first on ``PYTHONPATH`` and one
    thread per BLAS/OpenMP pool (as spawned workers have)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = child_pythonpath()
    env.update({k: "1" for k in THREAD_VARS})
    return env


def child_pythonpath() -> str:
    """``PYTHONPATH`` of a worker started from another interpreter: this checkout first, then
    this process's own ``PYTHONPATH`` (never its ``sys.path``, which names its environment's
    site-packages)."""
    return os.pathsep.join(p for p in (CODE_ROOT, os.environ.get("PYTHONPATH", "")) if p)


def start_in_interpreter(
    python: str, build: Callable[[Any], Executor], config: Any
) -> tuple[Connection, InterpreterProcess]:
    """Start a worker from ``python`` holding ``build(config)``: the parent's end of its
    connection and the process."""
    parent_end, child_end = socket.socketpair()
    try:
        popen = subprocess.Popen(
            [python, "-m", __name__, str(child_end.fileno())],
            pass_fds=(child_end.fileno(),),
            env=child_environment(),
            stdin=subprocess.DEVNULL,
        )
    finally:
        child_end.close()
    conn = Connection(parent_end.detach())
    conn.send(("start", build, config))
    return conn, InterpreterProcess(popen)


def main(argv: list[str]) -> None:
    """The child: take the connection on file descriptor ``argv[0]``, then serve jobs."""
    from awda_bench.execution.parent_death import die_with_parent
    from awda_bench.execution.worker_loop import serve_jobs

    die_with_parent(signal.SIGKILL)  # before the executor's (slow) imports
    conn = Connection(int(argv[0]))
    try:
        _kind, build, config = conn.recv()  # imports the executor's module: may fail here
    except EOFError:
        return  # the parent went away before sending anything
    except Exception as exc:
        conn.send(("fatal", f"{type(exc).__name__}: {exc}", traceback.format_exc()))
        conn.close()
        return
    serve_jobs(conn, build, config)


if __name__ == "__main__":
    main(sys.argv[1:])

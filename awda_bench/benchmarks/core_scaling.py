"""How much N processes can do at once on this machine: the ceiling for N workers' speed-up.

``bench harness`` prints this beside the harness's own speed-up, so a worker count that scales
poorly can be told apart from a machine that cannot run N things at full speed (virtual CPUs that
share a physical core, or a memory bus that one process already fills). Two fixed kernels, each run
by one process alone and then by N processes started together (a barrier), all timed::

    compute  pure-Python integer arithmetic, a few KB of working set (what the cores give)
    memory   numpy copies of a 64 MB array, beyond the caches (what the memory bus gives)

    speed-up N vs 1 = N * (one process's time alone) / (the slowest of the N processes' times)

An ideal machine gives N. Each measurement is the median of ``rounds``.
"""

from __future__ import annotations

import multiprocessing
import statistics
import time
from dataclasses import dataclass

import numpy as np

KERNELS: tuple[str, ...] = ("compute", "memory")

_MEMORY_ELEMENTS = 8_000_000
"""float64 elements in the memory kernel's arrays: 64 MB each, twice the 32 MB L3 seen here."""


def _compute(units: int) -> float:
    x = 0
    for i in range(units * 200_000):
        x = (x * 31 + i) & 0xFFFFFFFF
    return float(x)


def _memory(units: int) -> float:
    source = np.ones(_MEMORY_ELEMENTS)
    target = np.empty_like(source)
    for _ in range(units * 2):
        np.copyto(target, source)
    return float(target[-1])


def _timed(kernel: str, units: int, barrier, results) -> None:  # type: ignore[no-untyped-def]
    work = _compute if kernel == "compute" else _memory
    work(1)  # warm: first-touch page faults and bytecode caches stay out of the timing
    barrier.wait()
    start = time.perf_counter()
    work(units)
    results.put(time.perf_counter() - start)


def _run(kernel: str, units: int, processes: int) -> list[float]:
    """Seconds each of ``processes`` spawned processes took for ``units`` of ``kernel``."""
    context = multiprocessing.get_context("spawn")
    barrier = context.Barrier(processes)
    results = context.Queue()
    workers = [
        context.Process(target=_timed, args=(kernel, units, barrier, results))
        for _ in range(processes)
    ]
    for worker in workers:
        worker.start()
    times = [results.get(timeout=600) for _ in workers]
    for worker in workers:
        worker.join()
    return times


@dataclass(frozen=True)
class CoreScaling:
    kernel: str
    processes: int
    alone_s: float
    together_s: float
    """The slowest of the ``processes`` processes running at once (median over rounds)."""

    @property
    def speedup(self) -> float:
        return self.processes * self.alone_s / self.together_s


def measure_core_scaling(
    processes: int, *, units: int = 20, rounds: int = 3, kernels: tuple[str, ...] = KERNELS
) -> list[CoreScaling]:
    """One process alone vs ``processes`` at once, per kernel, rounds interleaved."""
    if processes < 2:
        raise ValueError(f"core scaling compares 1 process with 2 or more, not {processes}")
    unknown = set(kernels) - set(KERNELS)
    if unknown:
        raise ValueError(f"unknown kernel(s) {sorted(unknown)}; known: {', '.join(KERNELS)}")
    out = []
    for kernel in kernels:
        alone, together = [], []
        for _ in range(rounds):
            alone.append(_run(kernel, units, 1)[0])
            together.append(max(_run(kernel, units, processes)))
        out.append(
            CoreScaling(kernel, processes, statistics.median(alone), statistics.median(together))
        )
    return out

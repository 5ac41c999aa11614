"""Flush denormal floats to zero on the CPU threads that run the networks.

As training sharpens the attention and spatial softmaxes, more of their ``exp`` outputs (and what
flows back through them) fall below float32's normal range (~1.2e-38), and x86 CPUs compute on such
denormal numbers through a microcode path many times slower than normal arithmetic. Measured here
(session 18, T-OSVI ``small`` on cached pick-place features, one batch, forward + backward + Adam,
same process conditions): the step-200 snapshot 1.70 s, the step-600 snapshot 3.28 s at 2 threads;
at 1 thread the step-600 snapshot takes 5.83 s without flushing and 1.53 s with it. A T-OSVI
training run therefore slowed step by step (0.9 s -> 3.1 s over 600 steps; session 17 read the
same drift as "the machine slowed"). Flushing changes only values below ~1.2e-38 to zero.

The flag (SSE's FTZ/DAZ bits, ``torch.set_flush_denormal``) belongs to a CPU thread. Torch's
intra-op threads copy it from the thread that starts them, and they start at the first operation
large enough to be split; a thread pool already running keeps its old setting. So
:func:`flush_denormals` must run before a process's first parallel torch operation, and it checks
its own effect on every intra-op thread.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

DENORMAL_BITS = 0x00400000
"""A float32 denormal's bit pattern (exponent bits 0, mantissa nonzero): 5.9e-39."""

PROBE_ELEMENTS = 1 << 20
"""Elements of the check's tensor: enough for torch to split the multiply over every intra-op
thread (its element-wise grain is 32,768)."""


def flush_denormals() -> bool:
    """Set flush-to-zero for this thread and the intra-op threads started after it; True when
    every intra-op thread now flushes (False: the CPU cannot, or the thread pool was already
    running: call it earlier, before the process's first large torch operation)."""
    import numpy as np
    import torch

    if not torch.set_flush_denormal(True):  # a CPU without SSE3
        return False
    product = (torch.from_numpy(denormal_array(PROBE_ELEMENTS)) * 1.0).numpy()
    return not np.count_nonzero(product.view(np.uint32))  # bits: a float test would flush too


def denormal_array(size: int) -> np.ndarray:
    """``size`` float32 denormals (5.9e-39), written as bits: no floating-point operation,
    which a thread that flushes would turn into zeros."""
    import numpy as np

    return np.full(size, DENORMAL_BITS, dtype=np.uint32).view(np.float32)


@contextmanager
def denormals_flushed() -> Iterator[bool]:
    """:func:`flush_denormals` for a block (yields its result); this thread stops flushing after
    it, so the simulation a caller runs next in the same thread keeps its usual arithmetic.
    Evaluation does not flush: a policy's forward pass is 7-13 % faster with it (T-OSVI, measured),
    the backward pass is where the denormals cost."""
    import torch

    try:
        yield flush_denormals()
    finally:
        torch.set_flush_denormal(False)

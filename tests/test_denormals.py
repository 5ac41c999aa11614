"""Denormal floats are flushed to zero on every torch thread of a training process, and only there.

Each case runs in a fresh interpreter: the flag belongs to CPU threads, and pytest's own process has
had torch threads running since the first test that used torch.
"""

from __future__ import annotations

import subprocess
import sys

PRELUDE = """
import numpy as np, torch
from awda_bench.models.denormals import denormal_array
torch.set_num_threads(2)
def survivors():
    # denormals multiplied by torch over both intra-op threads; counted as bits (a float
    # comparison on a flushing thread would read them as zeros)
    product = (torch.from_numpy(denormal_array(1 << 20)) * 1.0).numpy()
    return int(np.count_nonzero(product.view(np.uint32)))
"""


def _python(body: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", PRELUDE + body], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_without_the_flag_denormals_survive_a_torch_operation() -> None:
    assert _python("print(survivors())") == str(1 << 20)  # the check below can fail


def test_flushing_first_reaches_every_intra_op_thread() -> None:
    out = _python(
        "from awda_bench.models.denormals import flush_denormals\n"
        "print(flush_denormals(), survivors())"
    )
    assert out == "True 0"


def test_flushing_after_the_thread_pool_started_is_reported_as_incomplete() -> None:
    out = _python(
        "a = torch.randn(1 << 20); (a * 2.0).sum()  # the intra-op threads start without the flag\n"
        "from awda_bench.models.denormals import flush_denormals\n"
        "print(flush_denormals(), survivors() > 0)"
    )
    assert out == "False True"


def test_the_block_ends_with_this_thread_back_to_its_usual_arithmetic() -> None:
    out = _python(
        "from awda_bench.models.denormals import denormals_flushed\n"
        "with denormals_flushed() as flushing:\n"
        "    inside = survivors()\n"
        "torch.set_num_threads(1)  # this thread alone\n"
        "print(flushing, inside, survivors())"
    )
    assert out == f"True 0 {1 << 20}"


def test_training_runs_with_denormals_flushed() -> None:
    # run_training's body sees the flag on every thread: checked from inside it
    out = _python(
        "import awda_bench.training.run as run\n"
        "seen = []\n"
        "run._run_training = lambda request: seen.append(survivors())\n"
        "run.run_training(run.TrainRequest('awda', None, data=None, out=None))\n"
        "print(seen)"
    )
    assert out == "[0]"

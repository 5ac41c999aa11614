import argparse
from pathlib import Path

import pytest
from harness_fakes import write_fake_suite

from awda_bench.benchmarks.throughput import add_harness_args, run_harness_bench


@pytest.mark.slow
def test_harness_bench_reports_throughput_and_identical_outcomes(tmp_path: Path, capsys) -> None:
    write_fake_suite(tmp_path)
    parser = argparse.ArgumentParser()
    add_harness_args(parser)
    args = parser.parse_args(
        [
            "--suite",
            "fake",
            "--method",
            "harness_fakes:SkillPolicy",
            "--episodes",
            "3",
            "--tasks-dir",
            str(tmp_path),
            "--workers",
            "1",
            "2",
        ]
    )
    assert run_harness_bench(args) == 0
    out = capsys.readouterr().out
    assert (
        "speed-up 2 vs 1 workers" in out
        and "identical per-episode outcomes across worker counts: yes" in out
        and "machine ceiling, 2 processes at once vs 1" in out
    )


def test_core_scaling_times_one_process_alone_and_n_together() -> None:
    from awda_bench.benchmarks.core_scaling import KERNELS, measure_core_scaling

    found = measure_core_scaling(2, units=1, rounds=1)
    assert [c.kernel for c in found] == list(KERNELS)
    for c in found:
        assert c.processes == 2 and c.alone_s > 0 and c.together_s > 0
        assert c.speedup == pytest.approx(2 * c.alone_s / c.together_s)
    with pytest.raises(ValueError, match="2 or more"):
        measure_core_scaling(1)
    with pytest.raises(ValueError, match="unknown kernel"):
        measure_core_scaling(2, kernels=("gpu",))

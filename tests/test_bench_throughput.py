import argparse
from pathlib import Path

import pytest
from harness_fakes import write_fake_suite

from awda_bench.harness.bench_throughput import add_harness_args, run_harness_bench


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
    )

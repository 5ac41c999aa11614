import dataclasses
import json
from pathlib import Path

import pytest
from harness_fakes import write_fake_suite

from awda_bench.episode import derive_seed
from awda_bench.errors import UsageError
from awda_bench.evaluation.episode_specs import (
    build_episode_specs,
    make_protocol,
    protocol_drift,
)
from awda_bench.suites import load_suite


@pytest.fixture
def suite(tmp_path: Path):
    write_fake_suite(tmp_path)
    return load_suite("fake", tmp_path)


def test_specs_cover_every_held_out_task_and_episode_once(suite) -> None:
    protocol = make_protocol(suite, episodes=5, base_seed=0)
    specs = build_episode_specs(suite, protocol)
    assert [(s.task, s.episode) for s in specs] == [(t, i) for t in (2, 3) for i in range(5)]
    assert len({s.seed for s in specs}) == len(specs)
    assert all(s.seed != s.demo_seed for s in specs)


def test_seeds_depend_only_on_identity_not_on_episode_count(suite) -> None:
    a = build_episode_specs(suite, make_protocol(suite, episodes=3, base_seed=7))
    b = build_episode_specs(suite, make_protocol(suite, episodes=6, base_seed=7))
    assert a == [s for s in b if s.episode < 3]
    c = build_episode_specs(suite, make_protocol(suite, episodes=3, base_seed=8))
    assert {s.seed for s in a}.isdisjoint({s.seed for s in c})
    assert derive_seed("fake", 7, 2, 0, "agent") == a[0].seed
    assert 0 <= a[0].seed < 2**31


def test_fingerprint_changes_with_everything_that_defines_comparability(
    tmp_path: Path, suite
) -> None:
    base = make_protocol(suite, episodes=4, base_seed=0)
    assert base.fingerprint == make_protocol(suite, episodes=4, base_seed=0).fingerprint
    assert base.fingerprint == make_protocol(suite, episodes=None, base_seed=0).fingerprint
    assert base.fingerprint != make_protocol(suite, episodes=5, base_seed=0).fingerprint
    assert base.fingerprint != make_protocol(suite, episodes=4, base_seed=1).fingerprint
    write_fake_suite(tmp_path, horizon_steps="7")
    longer = load_suite("fake", tmp_path)
    assert base.fingerprint != make_protocol(longer, episodes=4, base_seed=0).fingerprint
    # any byte of the suite file counts, even a comment
    suite.path.write_text(suite.path.read_text() + "\n# comment\n")
    assert base.fingerprint != make_protocol(suite, episodes=4, base_seed=0).fingerprint


def test_family_unit_cycles_variations(tmp_path: Path) -> None:
    write_fake_suite(tmp_path, held_out="[0, 1, 2]", episode_unit='"family"')
    suite = load_suite("fake", tmp_path)
    specs = build_episode_specs(suite, make_protocol(suite, episodes=5, base_seed=0))
    door = sorted((s.episode, s.task) for s in specs if s.task in (0, 1))
    assert door == [(0, 0), (1, 1), (2, 0), (3, 1), (4, 0)]
    assert sum(1 for s in specs if s.task == 2) == 5


def test_bad_values_are_usage_errors(suite) -> None:
    with pytest.raises(UsageError, match="--episodes"):
        make_protocol(suite, episodes=0, base_seed=0)
    with pytest.raises(UsageError, match="--seed"):
        make_protocol(suite, episodes=1, base_seed=-1)


def _recorded(protocol) -> dict:
    """A protocol as a report's summary.json records it."""
    return {**json.loads(protocol.to_json()), "fingerprint": protocol.fingerprint}


def test_protocol_drift_names_what_today_would_make_differently(tmp_path: Path, suite) -> None:
    protocol = make_protocol(suite, episodes=4, base_seed=0)
    assert protocol_drift(_recorded(protocol), tmp_path) == []
    # an older harness version, recorded consistently
    old = dataclasses.replace(protocol, protocol_version=protocol.protocol_version - 1)
    assert protocol_drift(_recorded(old), tmp_path) == [
        f"protocol v{old.protocol_version}, today v{protocol.protocol_version}"
    ]
    # a definition edited after the fact no longer hashes to its fingerprint
    edited = {**_recorded(protocol), "episodes": 5}
    assert protocol_drift(edited, tmp_path) == ["fingerprint does not match its definition"]
    # any byte of the suite file
    suite.path.write_text(suite.path.read_text() + "\n# comment\n")
    assert protocol_drift(_recorded(protocol), tmp_path) == ["suite file changed"]
    suite.path.unlink()
    assert protocol_drift(_recorded(protocol), tmp_path) == ["suite 'fake' gone"]
    assert protocol_drift({"suite": "fake"}, tmp_path)[0].startswith("not a protocol definition")

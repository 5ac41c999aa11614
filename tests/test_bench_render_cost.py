"""``bench render-cost``: a frame's render time split per render body, and the robot decimated."""

import argparse

import cv2
import pytest

from awda_bench.benchmarks.render_cost import add_render_cost_args, run_render_cost_bench
from awda_bench.errors import UsageError


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_render_cost_args(parser)
    return parser.parse_args(list(argv))


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (("--frames", "0"), "--frames"),
        (("--decimate", "1.5"), r"--decimate takes a ratio in \(0, 1\)"),
        (("--task", "99"), "--task must be in"),
        (("--suite", "metaworld_ml45"), "SAPIEN scenes"),
    ],
)
def test_bad_options_are_refused_before_any_env_is_built(argv, match) -> None:
    with pytest.raises(UsageError, match=match):
        run_render_cost_bench(_args(*argv))


@pytest.mark.slow
def test_every_body_is_listed_and_the_decimated_robot_keeps_the_picture(tmp_path, capsys) -> None:
    args = _args("--frames", "2", "--decimate", "0.1", "--out", str(tmp_path))
    assert run_render_cost_bench(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("pick_place task 0 (agent: panda_awda), camera third_person 240x320")
    header = lines.index(next(x for x in lines if x.startswith("render body (alone)")))
    robot_line = next(i for i, x in enumerate(lines) if x.startswith("robot:"))
    bodies = {x.split()[0]: int(x.split()[1]) for x in lines[header + 1 : robot_line]}
    # the Panda's links, the table and the task's objects, each with its triangles
    assert {"panda_link0", "panda_hand", "panda_leftfinger", "scene-0_ground"} <= set(bodies)
    robot_triangles = sum(n for name, n in bodies.items() if name.startswith("panda_"))
    assert lines[robot_line].startswith(f"robot: {robot_triangles} triangles")
    decimated = lines[robot_line + 1].split()
    assert decimated[:4] == ["robot", "decimated", "to", "0.1:"]
    before, after = int(decimated[4]), int(decimated[6])
    assert before == robot_triangles and after < 0.15 * before
    # the picture barely moves: only the arm's silhouette and shading
    mean_diff = float(lines[robot_line + 1].split("mean |diff| ")[1].split("/")[0])
    assert mean_diff < 3.0
    panel = cv2.imread(str(tmp_path / "render-cost-decimate-0.1.png"))
    assert panel.shape == (240, 3 * 320, 3)

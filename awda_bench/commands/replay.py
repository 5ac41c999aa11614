"""``python -m awda_bench replay ...``: ManiSkill's ``replay_trajectory`` with our envs registered.

ManiSkill's own CLI (``python -m mani_skill.trajectory.replay_trajectory``) does not import this
package, so it cannot make ``AWDA-*`` envs. This command registers them (``import
awda_bench.envs``) and hands every argument after ``replay`` to ManiSkill's tool unchanged::

    python -m awda_bench replay --traj-path DATA/agent/pick_place/task_00.h5              # actions
    python -m awda_bench replay --traj-path DATA/agent/pick_place/task_00.h5 --use-env-states
    python -m awda_bench replay --help                                # ManiSkill's own options

With ``--num-envs N > 1`` ManiSkill forks N processes, which inherit the registration.
Synthesized trajectories solve no task, and pressed buttons pop back before the end (ManiSkill
judges success after the last step): replay those with ``--allow-failure``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from awda_bench.errors import UsageError

HELP = "replay a collected trajectory file with ManiSkill's replay_trajectory"
DESCRIPTION = (
    "Register the awda_bench envs, then run ManiSkill's replay_trajectory with the remaining "
    "arguments (see `python -m awda_bench replay --help-maniskill`)."
)
PARSER_OPTIONS = {"add_help": False, "prefix_chars": "+"}
"""Every ``-...`` argument goes to ManiSkill untouched (``replay --help`` is ManiSkill's)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("maniskill_args", nargs=argparse.REMAINDER)


def _traj_path(argv: list[str]) -> str | None:
    for i, arg in enumerate(argv):
        if arg.startswith("--traj-path=") or arg.startswith("--traj_path="):
            return arg.split("=", 1)[1]
        if arg in ("--traj-path", "--traj_path") and i + 1 < len(argv):
            return argv[i + 1]
    return None


def run(args: argparse.Namespace) -> int:
    argv = list(args.maniskill_args)
    help_asked = any(a in ("-h", "--help", "--help-maniskill") for a in argv)
    path = _traj_path(argv)
    if not help_asked:
        if path is None:
            raise UsageError(
                "replay needs --traj-path DATA_DIR/<role>/<family>/task_XX.h5 "
                "(see python -m awda_bench replay --help)"
            )
        h5 = Path(path)
        if h5.suffix != ".h5" or not h5.is_file() or not h5.with_suffix(".json").is_file():
            raise UsageError(
                f"--traj-path {path}: need an existing .h5 trajectory file with its .json beside "
                "it (written by python -m awda_bench collect)"
            )
        _refuse_other_simulators(h5)
    argv = ["--help" if a == "--help-maniskill" else a for a in argv]

    from mani_skill.trajectory import replay_trajectory

    import awda_bench.envs  # noqa: F401  (registers the AWDA-* envs and the robots)

    replay_trajectory.main(replay_trajectory.parse_args(argv))
    return 0


def _refuse_other_simulators(h5: Path) -> None:
    """A Meta-World collection's files share ManiSkill's layout but not its simulator: refused in
    one line naming how those episodes are replayed."""
    import json

    from awda_bench.metaworld_tasks import ALL_TASKS

    try:
        env_id = str(json.loads(h5.with_suffix(".json").read_text())["env_info"]["env_id"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise UsageError(f"--traj-path {h5}: its .json is unreadable ({exc})") from exc
    if env_id in ALL_TASKS:
        raise UsageError(
            f"--traj-path {h5} holds {env_id!r} episodes (Meta-World), which ManiSkill cannot "
            "replay; replay one with awda_bench.metaworld.layout.reset_to_layout(env, "
            "episode_seed) and its actions"
        )

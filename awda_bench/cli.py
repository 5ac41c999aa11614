"""``python -m awda_bench <command>``: the single command-line entry point.

Each sub-command lives in :mod:`awda_bench.commands.<name>`. Errors deriving from
:class:`awda_bench.errors.AwdaError` are printed as one line (``error: ...``) with the error's exit
code; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from awda_bench.commands import COMMANDS
from awda_bench.errors import AwdaError
from awda_bench.harness.parent_death import die_with_parent_from_env


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m awda_bench",
        description="One-shot visual imitation benchmark (AWDA) on ManiSkill3 with a mink-driven Panda.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        module = importlib.import_module(f"awda_bench.commands.{name}")
        command_parser = module.add_parser(sub)
        command_parser.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    die_with_parent_from_env()  # a reproduce stage stops when reproduce dies
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except AwdaError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("interrupted; results written so far are kept", file=sys.stderr)
        return 130
